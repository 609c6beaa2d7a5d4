"""Extremes through the FMU (issue 6, point 5): communication steps from 1e-6 s to 0.5 s give the
in-process trajectory (the communication grid never dictates the integrator's steps), every
solver is selectable by FMU parameter, the stiff method runs the sticking case that the explicit
methods refuse with fmi2Error, and its FMU state round-trips bit for bit."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from overcon import scene as scene_mod  # noqa: E402
from overcon.fmu.build import build_all  # noqa: E402
from overcon.checks import compile_checked  # noqa: E402
from overcon.simulate import Simulation  # noqa: E402

pytestmark = pytest.mark.integration

MECH = Path(__file__).resolve().parents[1] / "mechanisms"
STICK = {"joint1.mu": 1.0, "joint4.mu": 1.0, "joint5.mu": 1.0}  # planar_f145_wo6: sticking, stiff


@pytest.fixture(scope="module")
def unz(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus_extremes")
    code, _ = build_all([str(MECH / "planar_f45_wo4.toml"), str(MECH / "planar_f145_wo6.toml")], out, refs=False,
                        allow_nonunique=True, validate=False, echo=lambda s: None, echo_err=lambda s: None)
    assert code == 0
    done: dict[str, Path] = {}

    def get(name: str) -> Path:  # extract once: never overwrite a loaded binary
        if name not in done:
            done[name] = Path(fmpy.extract(str(out / f"{name}.fmu"), str(out / f"unz_{name}")))
        return done[name]
    return get


class Inst:
    def __init__(self, unz: Path, params: dict | None = None):
        self.md = fmpy.read_model_description(str(unz))
        vr = {v.name: v for v in self.md.modelVariables}
        self.outputs = [v.name for v in self.md.modelVariables if v.causality == "output" and v.type == "Real"]
        self.vrs = [vr[n].valueReference for n in self.outputs]
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=str(unz),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="x")
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, value in (params or {}).items():
            v = vr[name]
            if v.type == "String":
                self.fmu.setString([v.valueReference], [value])
            else:
                self.fmu.setReal([v.valueReference], [float(value)])
        self.fmu.exitInitializationMode()
        self.t = 0.0

    def advance(self, n: int, h: float) -> np.ndarray:
        """n communication steps of size h on the grid k h (as fmpy does); the outputs at the end."""
        t0 = self.t
        for k in range(1, n + 1):
            t_next = t0 + k * h
            self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=t_next - self.t)
            self.t = t_next
        return np.array(self.fmu.getReal(self.vrs))

    def free(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def in_process(name: str, times, method=None, mu=None):
    sc = scene_mod.load(MECH / f"{name}.toml")
    if mu is not None:
        sc = dataclasses.replace(sc, friction_params={k: dataclasses.replace(v, mu=mu)
                                                      for k, v in sc.friction_params.items()})
    sim = Simulation(compile_checked(sc), sc.solver, method=method)
    return np.array([sim.outputs(t, sim.advance(t)) for t in times])


def test_communication_step_1e6_s(unz):
    """1000 steps of 1e-6 s (then one of 0.5 s): finite, and the very values of the in-process run
    (outputs read by dense output; the integrator kept its own steps)."""
    inst = Inst(unz("planar_f45_wo4"))
    out = inst.advance(1000, 1e-6)
    t1 = inst.t
    out2 = inst.advance(1, 0.5)
    t2 = inst.t
    inst.free()
    ref = in_process("planar_f45_wo4", [t1, t2])
    assert np.all(np.isfinite(out)) and np.all(np.isfinite(out2))
    assert np.array_equal(out, ref[0]) and np.array_equal(out2, ref[1])


@pytest.mark.parametrize("method", ["dopri5", "dop853", "rk4", "radau"])
def test_communication_step_half_second_every_method(unz, method):
    """0.5 s communication steps over the whole 0-4 s, each solver chosen by FMU parameter:
    finite, the in-process run of the same method (whose outputs do not depend on the grid: bit
    for bit for the explicit methods, radau within 1e-6 relative), and positions within 1e-6 m of
    dop853 at 1e-11."""
    inst = Inst(unz("planar_f45_wo4"), {"solver.method": method})
    coarse = np.array([inst.advance(1, 0.5) for _ in range(8)])
    outputs = inst.outputs
    inst.free()
    times = 0.5 * np.arange(1, 9)
    assert np.all(np.isfinite(coarse))
    ref = in_process("planar_f45_wo4", times, method=method)
    if method == "radau":  # the C runtime's radau has its own LU (not LAPACK's): the same run within its tolerance
        assert np.all(np.abs(coarse - ref) <= 1e-6 * (1.0 + np.abs(ref)))
    else:  # the explicit methods take the Python integrators' steps bit for bit in C
        assert np.array_equal(coarse, ref)
    pos = [i for i, n in enumerate(outputs) if n.endswith((".x", ".y"))]
    assert np.max(np.abs(coarse[:, pos] - tight_reference()[:, pos])) < 1e-6


_TIGHT = []


def tight_reference():
    if not _TIGHT:
        sc = scene_mod.load(MECH / "planar_f45_wo4.toml")
        sc = dataclasses.replace(sc, solver=dataclasses.replace(sc.solver, tolerance=1e-11))
        sim = Simulation(compile_checked(sc), sc.solver, method="dop853")
        _TIGHT.append(np.array([sim.outputs(t, sim.advance(t)) for t in 0.5 * np.arange(1, 9)]))
    return _TIGHT[0]


def test_stiff_case_refused_by_dopri5_run_by_radau(unz):
    """planar_f145_wo6 with mu = 1 (sticking inside the regularisation band): dopri5 ends the step
    with fmi2Error (stiffness reported), radau, selected by parameter, runs 0-1 s and gives the
    in-process radau result (within 1e-6 relative: the C runtime's radau has its own LU)."""
    inst = Inst(unz("planar_f145_wo6"), STICK)
    with pytest.raises(FMICallException, match=r"fmi2DoStep failed with status 3 \(error\)") as exc:
        inst.advance(100, 1e-2)
    assert exc.value.status == 3
    inst.free()
    inst = Inst(unz("planar_f145_wo6"), {**STICK, "solver.method": "radau"})
    out = inst.advance(10, 0.1)
    t = inst.t
    inst.free()
    ref = in_process("planar_f145_wo6", [t], method="radau", mu=1.0)
    # the C runtime's radau has its own LU (not LAPACK's): the in-process radau within its tolerance
    assert np.all(np.isfinite(out)) and np.all(np.abs(out - ref[0]) <= 1e-6 * (1.0 + np.abs(ref[0])))


def test_radau_fmu_state_bit_for_bit(unz):
    inst = Inst(unz("planar_f145_wo6"), {**STICK, "solver.method": "radau"})
    inst.advance(20, 0.01)
    t = inst.t
    state = inst.fmu.getFMUstate()
    data = inst.fmu.serializeFMUstate(state)
    first = inst.advance(30, 0.01)
    inst.fmu.setFMUstate(state)
    inst.t = t
    again = inst.advance(30, 0.01)
    restored = inst.fmu.deSerializeFMUstate(data)
    inst.fmu.setFMUstate(restored)
    inst.t = t
    third = inst.advance(30, 0.01)
    inst.fmu.freeFMUstate(state)
    inst.fmu.freeFMUstate(restored)
    inst.free()
    assert np.array_equal(first, again) and np.array_equal(first, third)
