"""Published outputs: what fmi2GetReal/fmi2GetBoolean answer after each call that changes them
(fmi2DoStep, a failed step, fmi2SetFMUstate, fmi2Reset, initialization with another parameter),
in the C FMU (native/fmu_run.c: outputs kept per communication point, reactions and friction
forces computed only once a host reads them). A host that reads late gets what a host that read
everything every step got, bit for bit, and no read returns a stale value."""
from __future__ import annotations

from pathlib import Path

import pytest

fmpy = pytest.importorskip("fmpy")

from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from overcon.fmu import build as fmu_build  # noqa: E402

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
MECH = ROOT / "mechanisms"


@pytest.fixture(scope="module")
def unz(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus_published")
    code, _ = fmu_build.build_all([str(MECH / "planar_f45_wo4.toml")], out, refs=False, echo=lambda s: None,
                                  echo_err=lambda s: None)
    assert code == 0
    return Path(fmpy.extract(str(out / "planar_f45_wo4.fmu"), str(out / "unz")))


class Host:
    """One instance, its calls recorded as (status, values)."""

    def __init__(self, unz: Path, name: str):
        self.md = fmpy.read_model_description(str(unz))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        real_out = [v for v in self.md.modelVariables if v.causality == "output" and v.type == "Real"]
        self.reals = [v.valueReference for v in real_out]
        self.positions = [self.vr[n] for n in ("slider1.x", "slider1.y", "link4.phi")]
        self.reaction = self.vr["joint4.Fx"]
        self.bools = [v.valueReference for v in self.md.modelVariables if v.type == "Boolean" and v.causality == "output"]
        assert self.bools and any(v.name.endswith(".Fx") for v in real_out)
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=str(unz),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate()
        self.t = 0.0

    def do(self, call, *args):
        try:
            return 0, call(*args)
        except FMICallException as exc:
            return exc.status, None

    def reads(self):
        """What a host reads: every Real output, positions only, one reaction, the Booleans, a list
        with a parameter, a Boolean through getReal (refused)."""
        f = self.fmu
        return [self.do(f.getReal, self.reals), self.do(f.getReal, self.positions),
                self.do(f.getReal, [self.reaction]), self.do(f.getBoolean, self.bools),
                self.do(f.getReal, [self.reals[0], self.vr["joint4.mu"]]),
                self.do(f.getReal, [self.bools[0]])]

    def init(self, **params):
        f = self.fmu
        out = [self.do(f.setupExperiment, None, 0.0), self.do(f.enterInitializationMode)]
        for name, value in params.items():
            out.append(self.do(f.setInteger if isinstance(value, int) else f.setReal, [self.vr[name]], [value]))
        out.append(self.do(f.exitInitializationMode))
        self.t = 0.0
        return out

    def step(self, h=0.01):
        r = self.do(self.fmu.doStep, self.t, h)
        if r[0] == 0:
            self.t += h
        return r


def test_simulate_fmu_twice_bit_for_bit(unz):
    """Two whole fmpy.simulate_fmu runs in one process give the same bytes (no state kept between
    instances)."""
    first = fmpy.simulate_fmu(str(unz), stop_time=1.0, output_interval=0.01)
    second = fmpy.simulate_fmu(str(unz), stop_time=1.0, output_interval=0.01)
    assert len(first) == 101 and first.tobytes() == second.tobytes()


def test_lazy_reactions_read_late(unz):
    """A host that reads only positions for some steps (no reactions computed) and then a reaction
    gets the value of a host that read everything every step; and every output from then on."""
    lazy, full = Host(unz, "lazy"), Host(unz, "full")
    lazy.init(), full.init()
    for _ in range(5):
        lazy.step(), full.step()
        every = full.fmu.getReal(full.reals)
        pos = lazy.fmu.getReal(lazy.positions)
        assert pos == [every[full.reals.index(v)] for v in full.positions]
    assert lazy.fmu.getReal([lazy.reaction]) == [every[full.reals.index(full.reaction)]]
    assert lazy.fmu.getReal(lazy.reals) == every
    lazy.step(), full.step()
    assert lazy.fmu.getReal(lazy.reals) == full.fmu.getReal(full.reals)
    for h in (lazy, full):
        h.fmu.terminate(), h.fmu.freeInstance()


def test_no_stale_values(unz):
    """The cases where values kept from an earlier call would be wrong: a state set back gives the
    saved point's values; a failed step (work budget exhausted: fmi2Error) leaves the last good
    step's values readable and refuses further steps; the state set again gives its values; after
    fmi2Terminate a step is refused; after fmi2Reset every read is refused until initialization,
    and another friction coefficient set there changes the first step's outputs."""
    h = Host(unz, "h")
    f = h.fmu
    assert [s for s, _ in h.reads()] == [3] * 6  # instantiated: nothing to read
    assert [s for s, _ in h.init()] == [0, 0, 0]
    initial = h.reads()
    assert [s for s, _ in initial] == [0, 0, 0, 0, 0, 3]
    assert h.step()[0] == 0
    first = h.reads()
    for _ in range(2):
        assert h.step()[0] == 0
    state, t_saved, saved = f.getFMUstate(), h.t, h.reads()
    assert h.step()[0] == 0
    moved = h.reads()
    assert moved[0][1] != saved[0][1]
    assert h.do(f.setFMUstate, state)[0] == 0
    h.t = t_saved
    assert h.reads() == saved
    assert h.do(f.setInteger, [h.vr["solver.max_internal_steps"]], [5])[0] == 0
    assert h.step(10.0)[0] == 3  # budget exhausted
    assert h.reads() == saved  # the outputs keep their values at the last good point
    assert h.step()[0] == 3  # refused in the error state
    assert h.do(f.setFMUstate, state)[0] == 0
    h.t = t_saved
    assert h.reads() == saved
    assert h.do(f.setInteger, [h.vr["solver.max_internal_steps"]], [10000])[0] == 0
    assert h.step()[0] == 0 and h.reads() == moved
    assert h.do(f.terminate)[0] == 0 and h.reads() == moved
    assert h.step()[0] == 3  # refused when terminated
    assert h.do(f.reset)[0] == 0
    assert [s for s, _ in h.reads()] == [3] * 6  # instantiated again
    assert h.do(f.setupExperiment, None, 0.0)[0] == 0 and h.do(f.enterInitializationMode)[0] == 0
    assert h.reads() == initial
    assert h.do(f.setReal, [h.vr["joint4.mu"]], [0.2])[0] == 0
    now = h.reads()
    assert now[:4] == initial[:4] and now[4][1][1] == 0.2  # at rest at the start: friction exerts nothing yet
    assert h.do(f.exitInitializationMode)[0] == 0 and h.reads() == now
    h.t = 0.0
    assert h.step()[0] == 0
    other = h.reads()
    assert other[0][1] != first[0][1] and other[2][1] != first[2][1]  # the new coefficient acts
    f.freeFMUstate(state)
    f.freeInstance()


def test_state_saved_before_any_read(unz):
    """An FMU state saved before any output was read keeps the point whose reactions were skipped:
    restored after another step, a read of every output computes them there, equal bit for bit to
    those of a host that stayed at that point."""
    a, ref = Host(unz, "a"), Host(unz, "ref")
    a.init(), ref.init()
    a.step(), ref.step()
    state = a.fmu.getFMUstate()
    a.step()
    a.fmu.setFMUstate(state)
    assert a.fmu.getReal(a.reals) == ref.fmu.getReal(ref.reals)
    a.fmu.freeFMUstate(state)
    for h in (a, ref):
        h.fmu.freeInstance()
