"""Published values (the Python runtime, `overcon build --runtime python`): the FMU binary answers fmi2GetReal/fmi2GetBoolean of outputs from arrays the
slave publishes after a successful fmi2DoStep (no Python call), and every other state through
Python. Each test compares an instance with the published values (the default) against one with
them switched off (``OVERCON_NO_PUBLISH=1``: every get through Python, the behaviour before), call
by call: the same statuses and the same values bit for bit; and checks that the fast path is
really taken (the slave's get_real/get_boolean are not called)."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
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
    code, _ = fmu_build.build_all([str(MECH / "planar_f45_wo4.toml")], out, refs=False, runtime="python",
                                  echo=lambda s: None, echo_err=lambda s: None)
    assert code == 0
    return Path(fmpy.extract(str(out / "planar_f45_wo4.fmu"), str(out / "unz")))


@pytest.fixture
def counted(unz, monkeypatch):
    """Counts of the slave's Python get_real/get_boolean calls (the FMU's private package)."""
    package = json.loads((unz / "resources" / "overcon_fmu.json").read_text())["package"]
    monkeypatch.syspath_prepend(str(unz / "resources"))
    __import__(f"{package}.fmu.slave")
    cls = sys.modules[f"{package}.fmu.slave"].OverconSlave
    counts = {"get_real": 0, "get_boolean": 0}
    for name in counts:
        original = getattr(cls, name)

        def wrapper(self, *args, _f=original, _n=name):
            counts[_n] += 1
            return _f(self, *args)
        monkeypatch.setattr(cls, name, wrapper)
    return counts


class Host:
    """One instance, its calls recorded as (status, values); ``published=False``: the Python path."""

    def __init__(self, unz: Path, published: bool, monkeypatch, name: str):
        monkeypatch.setenv("OVERCON_NO_PUBLISH", "0" if published else "1")
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
        monkeypatch.delenv("OVERCON_NO_PUBLISH")
        self.t = 0.0

    def do(self, call, *args):
        try:
            return 0, call(*args)
        except FMICallException as exc:
            return exc.status, None

    def reads(self):
        """What a host reads: every Real output, positions only, one reaction, the Booleans, a list
        with a parameter (always Python), a Boolean through getReal (refused)."""
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


def pair(unz, monkeypatch):
    return Host(unz, True, monkeypatch, "published"), Host(unz, False, monkeypatch, "python")


def test_simulate_fmu_bit_for_bit_and_without_python(unz, counted, monkeypatch):
    """A whole fmpy.simulate_fmu run: equal bit for bit to the Python path; after the first read
    (which switches the reactions on) no getReal/getBoolean enters Python."""
    fast = fmpy.simulate_fmu(str(unz), stop_time=1.0, output_interval=0.01)
    assert counted == {"get_real": 1, "get_boolean": 0}
    counted.update(get_real=0, get_boolean=0)
    monkeypatch.setenv("OVERCON_NO_PUBLISH", "1")
    slow = fmpy.simulate_fmu(str(unz), stop_time=1.0, output_interval=0.01)
    assert counted["get_real"] == counted["get_boolean"] == 101
    assert fast.dtype == slow.dtype and len(fast) == 101
    assert fast.tobytes() == slow.tobytes()


def test_lazy_reactions_read_late(unz, counted, monkeypatch):
    """A host that reads only positions for some steps (served in C, no reactions computed) and
    then a reaction gets the value of a host that read everything every step; from then on the
    reactions are published too."""
    lazy, full = Host(unz, True, monkeypatch, "lazy"), Host(unz, True, monkeypatch, "full")
    lazy.init(), full.init()
    for _ in range(5):
        lazy.step(), full.step()
        every = full.fmu.getReal(full.reals)
        before = counted["get_real"]
        pos = lazy.fmu.getReal(lazy.positions)
        assert pos == [every[full.reals.index(v)] for v in full.positions]
    assert counted["get_real"] == before  # the positions came from C
    value = lazy.fmu.getReal([lazy.reaction])  # Python: computed at the current point
    assert counted["get_real"] == before + 1
    assert value == [every[full.reals.index(full.reaction)]]
    assert lazy.fmu.getReal(lazy.reals) == every
    assert counted["get_real"] == before + 1  # published now
    lazy.step(), full.step()
    assert lazy.fmu.getReal(lazy.reals) == full.fmu.getReal(full.reals)
    assert counted["get_real"] == before + 1
    for h in (lazy, full):
        h.fmu.terminate(), h.fmu.freeInstance()


def run_both(unz, monkeypatch, script):
    """Run ``script(host)`` on a published and a Python-path instance: the same records."""
    a, b = pair(unz, monkeypatch)
    ra, rb = script(a), script(b)
    assert len(ra) == len(rb)
    for k, (x, y) in enumerate(zip(ra, rb)):
        assert x == y, (k, x, y)
    for h in (a, b):
        h.fmu.freeInstance()
    return ra


def test_states_answer_as_python(unz, counted, monkeypatch):
    def script(h: Host):
        f, rec = h.fmu, []
        rec += h.reads()  # instantiated: refused
        rec += h.init()
        rec += h.reads()
        for _ in range(3):
            rec += [h.step()] + h.reads()
        state = f.getFMUstate()
        t_saved = h.t
        rec += [h.step()] + h.reads()
        rec.append(h.do(f.setFMUstate, state))  # back: the values at the saved point
        h.t = t_saved
        rec += h.reads()
        rec += [h.step()] + h.reads()
        rec.append(h.do(f.setInteger, [h.vr["solver.max_internal_steps"]], [5]))  # tunable
        rec += h.reads()
        rec.append(h.step(10.0))  # budget exhausted: fmi2Error, state error
        rec += h.reads()
        rec.append(h.step())  # refused in error
        rec += h.reads()
        rec.append(h.do(f.setFMUstate, state))
        h.t = t_saved
        rec += h.reads()
        rec.append(h.do(f.setInteger, [h.vr["solver.max_internal_steps"]], [10000]))
        rec += [h.step()] + h.reads()
        rec.append(h.do(f.terminate))
        rec += h.reads()
        rec.append(h.step())  # refused when terminated
        rec += h.reads()
        rec.append(h.do(f.reset))
        rec += h.reads()  # instantiated again: refused
        rec += [h.do(f.setupExperiment, None, 0.0), h.do(f.enterInitializationMode)]
        rec += h.reads()  # initialization mode: computed by Python
        rec.append(h.do(f.setReal, [h.vr["joint4.mu"]], [0.2]))
        rec += h.reads()
        rec.append(h.do(f.exitInitializationMode))
        rec += h.reads()
        h.t = 0.0
        for _ in range(3):
            rec += [h.step()] + h.reads()
        f.freeFMUstate(state)
        return rec

    rec = run_both(unz, monkeypatch, script)
    statuses = [s for s, _ in rec]
    assert 3 in statuses and 0 in statuses
    # the script saw different values (the state and the parameter mattered)
    reals = [tuple(v) for s, v in rec if s == 0 and isinstance(v, list) and len(v) > 10]
    assert len(set(reals)) > 5


def test_failed_step_and_reset_after_publication(unz, monkeypatch):
    """The cases where stale published values would differ from Python's answer: a state set
    back, a reset (refused), initialization mode with another parameter."""
    def script(h: Host):
        f, rec = h.fmu, []
        rec += h.init()
        state = f.getFMUstate()
        for _ in range(4):
            rec += [h.step()] + h.reads()
        rec.append(h.do(f.getReal, h.reals))  # the 4th step's values
        rec.append(h.do(f.setFMUstate, state))
        rec.append(h.do(f.getReal, h.reals))  # the initial values, not the last step's
        rec.append(h.do(f.getBoolean, h.bools))
        rec.append(h.do(f.reset))
        rec.append(h.do(f.getReal, h.positions))  # refused (instantiated)
        rec.append(h.do(f.getBoolean, h.bools))  # refused
        f.freeFMUstate(state)
        return rec

    rec = run_both(unz, monkeypatch, script)
    last, _, initial, bools, _, positions, bools_after_reset = rec[-7:]
    assert last[0] == initial[0] == bools[0] == 0 and initial[1] != last[1]
    assert positions == (3, None) and bools_after_reset == (3, None)
