"""FMU integration tests: build (build_fmu.py), fmpy validation, fmpy results against the
in-process run, several FMUs and instances in one process, FMU state, refused parameters, reset,
failed steps, reference files. The plain C host and libcosim are in test_fmu_hosts.py, the FMI
call-by-call behaviour in test_fmi_calls.py.

The FMUs are built once per session (all scenes, --no-ref) into a temporary directory; runs use
short stop times except where a test needs the full horizon.
"""
from __future__ import annotations

import csv
import dataclasses
import hashlib
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,  # noqa: E402
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy.validation import validate_fmu  # noqa: E402

from overcon import scene as scene_mod  # noqa: E402
from overcon.fmu import build as fmu_build  # noqa: E402
from overcon.checks import compile_checked  # noqa: E402
from overcon.simulate import SimulationError, run_scene  # noqa: E402

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
MECH = ROOT / "mechanisms"
SCENES = sorted(p.stem for p in MECH.glob("*.toml") if "scene" in tomllib.loads(p.read_text()))
NONUNIQUE = {s for s in SCENES if s.startswith(("planar_f1_", "planar_f145_", "spatial_GH_", "spatial_GHMN_"))}


# ------------------------------------------------------------------------------- fixtures

def _build(out: Path, *flags) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "build_fmu.py"), str(MECH), "--out", str(out),
                           "--no-ref", *flags], capture_output=True, text=True, timeout=600, cwd=ROOT)


@pytest.fixture(scope="session")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus_all")
    return out, _build(out, "--allow-nonunique")


@pytest.fixture(scope="session")
def fmus(built):
    out, proc = built
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out


_UNZIPPED: dict[str, Path] = {}


@pytest.fixture(scope="session")
def unzip(fmus, tmp_path_factory):
    def get(name: str) -> Path:
        if name not in _UNZIPPED:
            _UNZIPPED[name] = Path(fmpy.extract(str(fmus / f"{name}.fmu"),
                                                str(tmp_path_factory.mktemp(f"unz_{name}"))))
        return _UNZIPPED[name]
    return get


def scene_of(name: str, **changes):
    spec = scene_mod.load(MECH / f"{name}.toml")
    if changes:
        spec = dataclasses.replace(spec, **changes)
    return spec


def model_of(name: str, **changes):
    return compile_checked(scene_of(name, **changes))


def fmpy_matrix(result, names):
    return np.column_stack([result[n] for n in names])


class Logs:
    """fmi2CallbackFunctions that record (status, category, message)."""

    def __init__(self):
        self.records: list[tuple[int, str, str]] = []

        def logger(env, instance, status, category, message):
            self.records.append((status, (category or b"").decode(), (message or b"").decode()))

        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(logger)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)

    def text(self) -> str:
        return "\n".join(m for _, _, m in self.records)


class Instance:
    """One FMU instance driven by hand through fmpy's FMU2Slave."""

    def __init__(self, unz: Path, name: str = "inst", logs: Logs | None = None):
        self.md = fmpy.read_model_description(str(unz))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.outputs = [v.name for v in self.md.modelVariables if v.causality == "output" and v.type == "Real"]
        self.out_vrs = [self.vr[n] for n in self.outputs]
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=str(unz),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.logs = logs
        self.fmu.instantiate(callbacks=None if logs is None else logs.callbacks, loggingOn=logs is not None)
        self.t = 0.0

    def init(self, start=0.0):
        ex = self.md.defaultExperiment
        self.fmu.setupExperiment(tolerance=float(ex.tolerance), startTime=start)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.t0 = self.t = start
        self.k = 0
        return self

    def step(self, h=0.01):
        """One step on the grid t0 + k h (as fmpy.simulate_fmu does); returns the outputs."""
        t_next = self.t0 + (self.k + 1) * h
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=t_next - self.t)
        self.t, self.k = t_next, self.k + 1
        return self.fmu.getReal(self.out_vrs)

    def steps(self, n, h=0.01):
        return np.array([self.step(h) for _ in range(n)])

    def free(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


# ------------------------------------------------------------------------------- building

def test_build_all_scenes_with_allow_nonunique(built):
    out, proc = built
    assert proc.returncode == 0, proc.stderr
    assert len(SCENES) == 20
    assert sorted(p.stem for p in out.glob("*.fmu")) == SCENES
    assert "motion NOT UNIQUE" in proc.stdout  # the pre-check verdict is printed
    assert "FMUs built in" in proc.stdout and "20 FMU(s) built" in proc.stdout


def test_every_fmu_validates_with_zero_problems(fmus):
    for name in SCENES:
        assert validate_fmu(str(fmus / f"{name}.fmu")) == [], name


def test_nonunique_scenes_refused_without_flag(tmp_path):
    proc = _build(tmp_path)
    assert proc.returncode == fmu_build.EXIT_NONUNIQUE, proc.stdout + proc.stderr
    assert sorted(p.stem for p in tmp_path.glob("*.fmu")) == sorted(set(SCENES) - NONUNIQUE)
    assert len(NONUNIQUE) == 10
    for name in NONUNIQUE:
        assert f"{name}.toml: refused: friction on a joint whose reaction is not unique" in proc.stderr
    assert "whose reaction is not unique: its Jacobian columns" in proc.stdout  # pre-check's reason


def test_overcon_build_subcommand_and_reproducible_guid(tmp_path):
    from overcon.cli import main

    for sub in ("a", "b"):
        assert main(["build", str(MECH / "planar_none_wo4.toml"), "--out", str(tmp_path / sub), "--no-ref"]) == 0
    a, b = ((tmp_path / sub / "planar_none_wo4.fmu").read_bytes() for sub in ("a", "b"))
    assert hashlib.sha256(a).digest() == hashlib.sha256(b).digest()  # same inputs, same bytes
    assert main(["build", str(MECH / "planar_f1_wo4.toml"), "--out", str(tmp_path), "--no-ref"]) == 1


SELF_CONTAINED = r'''
import importlib.machinery, sys
class Block:
    """Refuse overcon and pythonfmu unless they come from an FMU's resources/ folder."""
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] not in ("overcon", "pythonfmu"):
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is not None and "/resources/" not in (spec.origin or ""):
            raise ImportError(f"{name} must come from the FMU, not from {spec.origin}")
        return spec
sys.meta_path.insert(0, Block())
import fmpy
res = fmpy.simulate_fmu(sys.argv[1], stop_time=0.1)
assert not any(m == "overcon" or m.startswith("overcon.") for m in sys.modules)
print(len(res))
'''


def test_fmu_is_self_contained(fmus):
    """The FMU runs with neither overcon nor pythonfmu importable from the environment."""
    proc = subprocess.run([sys.executable, "-c", SELF_CONTAINED, str(fmus / "spatial_MN_wo5.fmu")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["11"]


def test_model_description(fmus):
    md = fmpy.read_model_description(str(fmus / "planar_f45_wo4.fmu"))
    model = model_of("planar_f45_wo4")
    outs = [v for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    assert [v.name for v in outs] == model.output_names()
    assert all(v.variability == "continuous" and v.initial == "calculated" and v.unit and v.description
               for v in outs)
    units = {v.name: v.unit for v in outs}
    assert (units["slider1.x"], units["link3.phi"], units["joint1.Fy"], units["joint1.T"]) == ("m", "rad", "N", "N.m")
    byname = {v.name: v for v in md.modelVariables}
    assert byname["joint1.reaction_unique"].start == "false" or byname["joint1.reaction_unique"].start is False
    # judged along the motion (discrete), the pre-check's verdict as the start value
    assert byname["motion_unique"].variability == "discrete" and byname["motion_unique"].initial == "exact"
    assert byname["joint4.reaction_unique"].variability == "discrete"  # a friction joint
    assert byname["joint1.reaction_unique"].variability == "constant"  # no friction
    assert byname["rank"].type == "Integer" and byname["rank"].start == "11"
    for p in ("joint4.mu", "joint4.v_reg", "joint5.mu", "solver.tolerance", "solver.max_step", "solver.baumgarte"):
        assert byname[p].causality == "parameter" and byname[p].variability == "fixed", p
    assert byname["joint4.v_reg"].unit == "rad/s" and byname["joint4.mu"].unit == "1"
    assert {u.name for u in md.unitDefinitions} >= {"m", "rad", "N", "N.m", "rad/s", "s", "1/s", "1"}
    n_units = {u.name: u.baseUnit for u in md.unitDefinitions}
    assert (n_units["N.m"].kg, n_units["N.m"].m, n_units["N.m"].s) == (1, 2, -2)
    ex = md.defaultExperiment
    assert (float(ex.startTime), float(ex.stopTime), float(ex.stepSize), float(ex.tolerance)) == (0.0, 4.0, 0.01, 1e-9)
    cs = md.coSimulation
    assert cs.modelIdentifier == "planar_f45_wo4"
    assert cs.canHandleVariableCommunicationStepSize and cs.canGetAndSetFMUstate and cs.canSerializeFMUstate
    guids = {fmpy.read_model_description(str(fmus / f"{n}.fmu")).guid for n in SCENES}
    assert len(guids) == len(SCENES)


# ------------------------------------------------------------------------------- results

@pytest.mark.parametrize("name, stop", [("planar_none_wo4", 1.0), ("planar_f45_wo6", 1.0), ("spatial_MN_wo9", 1.0)])
def test_fmpy_result_equals_in_process_run(fmus, name, stop):
    res = fmpy.simulate_fmu(str(fmus / f"{name}.fmu"), stop_time=stop)
    ref = run_scene(scene_of(name), stop_time=stop)
    assert np.max(np.abs(res["time"] - ref.time)) <= 1e-12
    assert np.max(np.abs(fmpy_matrix(res, ref.names) - ref.values)) <= 1e-9


def test_full_horizon_reference_files(tmp_path):
    code, results = fmu_build.build_all([MECH / "planar_f45_wo4.toml"], tmp_path, jobs=1,
                                        echo=lambda s: None, echo_err=lambda s: None)
    assert code == 0 and results[0].ref_status == "written"
    opt = (tmp_path / "planar_f45_wo4_ref.opt").read_text().splitlines()
    assert opt == ["StartTime, 0.0", "StopTime, 4.0", "StepSize, 0.01", "RelTol, 1e-09"]
    ref = run_scene(scene_of("planar_f45_wo4"))
    with open(tmp_path / "planar_f45_wo4_ref.csv", newline="") as fh:
        header = fh.readline().rstrip("\n")
        rows = np.array([[float(x) for x in r] for r in csv.reader(fh)])
    assert header == ",".join(f'"{n}"' for n in ["time", *ref.names])
    assert rows.shape == (401, 1 + len(ref.names))
    assert np.max(np.abs(rows[:, 0] - ref.time)) <= 1e-12
    assert np.max(np.abs(rows[:, 1:] - ref.values)) <= 1e-9  # full 4 s horizon through fmpy


def test_parameters_reach_the_engine(fmus):
    res = fmpy.simulate_fmu(str(fmus / "planar_f45_wo4.fmu"), stop_time=0.5,
                            start_values={"joint4.mu": 0.3, "joint5.v_reg": 2e-3, "solver.baumgarte": 5.0})
    spec = scene_mod.load(MECH / "planar_f45_wo4.toml")
    fp = dict(spec.friction_params)
    fp["joint4"] = dataclasses.replace(fp["joint4"], mu=0.3)
    fp["joint5"] = dataclasses.replace(fp["joint5"], v_reg=2e-3)
    ref = run_scene(dataclasses.replace(spec, friction_params=fp,
                                        solver=dataclasses.replace(spec.solver, baumgarte=5.0)), stop_time=0.5)
    assert np.max(np.abs(fmpy_matrix(res, ref.names) - ref.values)) <= 1e-9
    default = run_scene(scene_of("planar_f45_wo4"), stop_time=0.5)
    assert np.max(np.abs(ref.values - default.values)) > 1e-6  # the parameters did change the motion


def test_two_fmus_and_two_instances_in_one_process(unzip):
    a1 = Instance(unzip("planar_f45_wo4"), "a1").init()
    a2 = Instance(unzip("planar_f45_wo4"), "a2").init()
    b = Instance(unzip("spatial_none_wo5"), "b").init()
    ra1, ra2, rb = [], [], []
    for _ in range(50):  # interleaved
        ra1.append(a1.step())
        rb.append(b.step())
        ra2.append(a2.step())
    for inst in (a1, a2, b):
        inst.free()
    ref_a = run_scene(scene_of("planar_f45_wo4"), stop_time=0.5)
    ref_b = run_scene(scene_of("spatial_none_wo5"), stop_time=0.5)
    assert np.array_equal(np.array(ra1), np.array(ra2))
    assert np.max(np.abs(np.array(ra1) - ref_a.values[1:])) <= 1e-9
    assert np.max(np.abs(np.array(rb) - ref_b.values[1:])) <= 1e-9


# ------------------------------------------------------------------------------- FMU state

def test_state_get_set_and_serialize_bit_for_bit(unzip):
    inst = Instance(unzip("planar_f45_wo4")).init()
    inst.steps(20)
    t, k = inst.t, inst.k
    state = inst.fmu.getFMUstate()
    data = inst.fmu.serializeFMUstate(state)
    first = inst.steps(30)
    inst.fmu.setFMUstate(state)
    inst.t, inst.k = t, k
    again = inst.steps(30)
    assert np.array_equal(first, again)
    inst.fmu.freeFMUstate(state)
    inst.free()
    # deserialize into a fresh instance (another one of the same FMU)
    other = Instance(unzip("planar_f45_wo4"), "other").init()
    restored = other.fmu.deSerializeFMUstate(data)
    other.fmu.setFMUstate(restored)
    other.t, other.k, other.t0 = t, k, 0.0
    assert np.array_equal(first, other.steps(30))
    other.fmu.freeFMUstate(restored)
    other.free()


def test_reset(unzip):
    inst = Instance(unzip("planar_f45_wo4"))
    inst.fmu.setupExperiment(startTime=0.0)
    inst.fmu.enterInitializationMode()
    inst.fmu.setReal([inst.vr["joint4.mu"]], [0.2])
    inst.fmu.exitInitializationMode()
    inst.t0 = inst.t = 0.0
    inst.k = 0
    changed = inst.steps(20)
    inst.fmu.reset()  # back to instantiated: parameters at their start values
    inst.init()
    assert inst.fmu.getReal([inst.vr["joint4.mu"]]) == [0.1]
    first = inst.steps(20)
    assert not np.array_equal(first, changed)
    inst.fmu.reset()
    inst.init()
    assert np.array_equal(first, inst.steps(20))
    inst.free()


# ------------------------------------------------------------------------------- errors

@pytest.mark.parametrize("var, value", [("joint4.mu", float("nan")), ("joint4.mu", float("inf")),
                                        ("joint4.mu", -0.1), ("joint4.v_reg", 0.0),
                                        ("solver.tolerance", 2.0), ("solver.max_step", float("-inf"))])
def test_bad_parameter_values_refused_and_host_survives(unzip, var, value):
    logs = Logs()
    inst = Instance(unzip("planar_f45_wo4"), logs=logs)
    inst.fmu.setupExperiment(startTime=0.0)
    inst.fmu.enterInitializationMode()
    before = inst.fmu.getReal([inst.vr[var]])
    for _ in range(3):  # repeated refusals leave the instance usable
        with pytest.raises(FMICallException, match=r"fmi2SetReal failed with status 3 \(error\)") as exc:
            inst.fmu.setReal([inst.vr[var]], [value])
        assert "status 3" in str(exc.value)  # fmi2Error, never fmi2Fatal
    assert f"fmi2SetReal: parameter {var} = {value!r} refused" in logs.text()
    assert inst.fmu.getReal([inst.vr[var]]) == before
    inst.fmu.exitInitializationMode()
    inst.t0 = inst.t = 0.0
    inst.k = 0
    out = inst.steps(10)
    assert np.all(np.isfinite(out))
    with pytest.raises(FMICallException, match=r"fmi2SetReal failed with status 3 \(error\)"):  # fixed after init.
        inst.fmu.setReal([inst.vr["joint4.mu"]], [0.2])
    assert "cannot change after initialization" in logs.text()
    inst.free()


def test_failed_step_returns_error_and_keeps_finite_outputs(tmp_path, unzip):
    # the planar mechanism with spring free length 0 reaches the singular position K = L = O
    mech = (MECH / "planar_sliders.toml").read_text()
    assert "free_length = 3.0" in mech
    (tmp_path / "planar_sliders.toml").write_text(mech.replace("free_length = 3.0", "free_length = 0.0"))
    scene_text = (MECH / "planar_none_wo4.toml").read_text().replace(
        'name = "planar_none_wo4"', 'name = "planar_singular"').replace("stop_time = 4.0", "stop_time = 2.0")
    (tmp_path / "planar_singular.toml").write_text(scene_text)
    res = fmu_build.build_scene(tmp_path / "planar_singular.toml", tmp_path / "out", echo=lambda s: None)
    assert res.status == "built", res.messages
    with pytest.raises(SimulationError, match=r"integration stopped: t = [\d.]+ s: the motion passed a singular "
                                              r"position"):
        run_scene(scene_mod.load(tmp_path / "planar_singular.toml"))  # the engine stops too
    logs = Logs()
    unz = Path(fmpy.extract(str(res.fmu), str(tmp_path / "unz")))
    inst = Instance(unz, logs=logs).init()
    last = None
    status = None
    for _ in range(200):
        try:
            last = inst.step(0.01)
        except FMICallException as exc:
            status = str(exc)
            break
    assert status is not None and "status 3" in status  # fmi2Error: the run cannot continue
    assert "fmi2DoStep(" in logs.text() and "singular" in logs.text()
    assert any(s == 3 for s, _, m in logs.records if "singular" in m)
    out = inst.fmu.getReal(inst.out_vrs)
    assert np.all(np.isfinite(out)) and out == last  # last good values, never NaN
    with pytest.raises(FMICallException, match=r"fmi2DoStep failed with status 3 \(error\)"):  # refused until reset
        inst.fmu.doStep(currentCommunicationPoint=inst.t, communicationStepSize=0.01)
    inst.free()


def test_wrong_communication_point_is_an_error(unzip):
    logs = Logs()
    inst = Instance(unzip("planar_none_wo4"), logs=logs).init()
    inst.steps(3)
    with pytest.raises(FMICallException, match=r"fmi2DoStep failed with status 3 \(error\)") as exc:
        inst.fmu.doStep(currentCommunicationPoint=1.0, communicationStepSize=0.01)
    assert "status 3" in str(exc.value) and "is not the end of the previous step" in logs.text()
    inst.free()


def test_variable_step_sizes(unzip):
    """Arbitrary communication steps: the integration does not depend on the grid."""
    inst = Instance(unzip("planar_f45_wo4")).init()
    t = 0.0
    for h in (0.003, 0.1, 0.017, 0.08):
        inst.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        t += h
    out = np.array(inst.fmu.getReal(inst.out_vrs))
    inst.free()
    ref = run_scene(scene_of("planar_f45_wo4"), stop_time=t, output_interval=t)
    assert np.max(np.abs(out - ref.values[-1])) <= 1e-9
