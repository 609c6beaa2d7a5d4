"""FMI 2.0 calls one by one through fmpy's FMU2Slave: the state machine (wrong-state calls return
fmi2Error), value references (unknown, wrong type, writes to outputs: fmi2Error with a message),
log categories and fmi2SetDebugLogging, the setupExperiment tolerance, the doStep work budget, a
run that cannot continue (fmi2Error; fmpy's command line exits non-zero with the reason), scene
names that are Python keywords, reference runs that end early, friction on a joint whose
equations are all eliminated."""
from __future__ import annotations

import ctypes
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from overcon import scene as scene_mod  # noqa: E402
from overcon.fmu import build as fmu_build  # noqa: E402
from overcon.fmu.description import LOG_CATEGORIES  # noqa: E402
from overcon.precheck import friction_warnings  # noqa: E402
from overcon.checks import compile_checked  # noqa: E402
from overcon.simulate import run_scene  # noqa: E402

from test_fmu import Logs  # noqa: E402

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
MECH = ROOT / "mechanisms"
NATIVE = ROOT / "fmu_src" / "overcon" / "fmu" / "native" / "fmu_inst.c"  # the log categories


@pytest.fixture(scope="module")
def unz(tmp_path_factory):
    """The co-simulation FMUs of two paper scenes. (Model Exchange and FMI 3.0: test_fmi3_me.py.)"""
    out = tmp_path_factory.mktemp("fmus_calls")
    code, _ = fmu_build.build_all([str(MECH / "planar_f45_wo4.toml"), str(MECH / "planar_none_wo4.toml")], out,
                                  refs=False, echo=lambda s: None, echo_err=lambda s: None, kind="cs")
    assert code == 0
    done = {}

    def get(name):
        if name not in done:
            done[name] = Path(fmpy.extract(str(out / f"{name}.fmu"), str(out / f"unz_{name}")))
        return done[name]
    get.out = out
    return get


class Slave:
    def __init__(self, unz: Path, logging_on=False):
        self.md = fmpy.read_model_description(str(unz))
        self.var = {v.name: v for v in self.md.modelVariables}
        self.outputs = [v.valueReference for v in self.md.modelVariables if v.causality == "output" and v.type == "Real"]
        self.logs = Logs()
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=str(unz),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName="calls")
        self.fmu.instantiate(callbacks=self.logs.callbacks, loggingOn=logging_on)

    def vr(self, name):
        return self.var[name].valueReference

    def init(self, **params):
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, value in params.items():
            if isinstance(value, int) and self.var[name].type == "Integer":
                self.fmu.setInteger([self.vr(name)], [value])
            else:
                self.fmu.setReal([self.vr(name)], [value])
        self.fmu.exitInitializationMode()
        return self

    def error(self, call, *args) -> str:
        """Call; it must return fmi2Error (status 3). Returns the messages it logged."""
        before = len(self.logs.records)
        with pytest.raises(FMICallException, match=r"failed with status 3 \(error\)") as exc:
            call(*args)
        assert exc.value.status == 3, exc.value
        new = self.logs.records[before:]
        assert new and all(s == 3 for s, _, _ in new), new
        return "\n".join(m for _, _, m in new)

    def free(self):
        self.fmu.freeInstance()


# ------------------------------------------------------------------------------- state machine

def test_wrong_state_calls_return_error(unz):
    s = Slave(unz("planar_f45_wo4"))
    msg = s.error(s.fmu.doStep, 0.0, 0.01)
    assert "fmi2DoStep: not allowed in state 'instantiated'" in msg
    s.error(s.fmu.getReal, [0])  # no values before initialization mode
    s.error(s.fmu.exitInitializationMode)
    s.init()
    assert "fmi2SetupExperiment: not allowed in state 'slave initialized'" in s.error(s.fmu.setupExperiment, None, 0.0)
    s.error(s.fmu.enterInitializationMode)
    s.fmu.doStep(0.0, 0.01)
    s.fmu.terminate()
    assert "fmi2DoStep: not allowed in state 'terminated'" in s.error(s.fmu.doStep, 0.01, 0.01)
    assert np.all(np.isfinite(s.fmu.getReal(s.outputs)))  # values can still be read
    s.fmu.reset()
    s.init()
    s.fmu.doStep(0.0, 0.01)  # usable again after fmi2Reset
    s.free()


def test_value_references_and_writes_to_outputs(unz):
    s = Slave(unz("planar_f45_wo4"))
    s.fmu.setupExperiment(startTime=0.0)
    s.fmu.enterInitializationMode()
    n = len(s.md.modelVariables)
    assert f"value reference {n + 5} does not exist" in s.error(s.fmu.getReal, [n + 5])
    assert "(motion_unique) is a Boolean variable, not Real" in s.error(s.fmu.getReal, [s.vr("motion_unique")])
    assert "(solver.method) is a String variable, not Real" in s.error(s.fmu.setReal, [s.vr("solver.method")], [1.0])
    # a write to an output: fmi2Error with a message, never fmi2Fatal, nothing set
    x = s.vr("slider1.x")
    assert "(slider1.x) is output (continuous): it cannot be set" in s.error(s.fmu.setReal, [x], [1.0])
    assert "(motion_unique) is output (discrete)" in s.error(s.fmu.setBoolean, [s.vr("motion_unique")], [False])
    assert s.fmu.getBoolean([s.vr("motion_unique")]) == [True]
    s.fmu.exitInitializationMode()
    for _ in range(3):
        assert "cannot be set" in s.error(s.fmu.setReal, [x], [1.0])
    s.fmu.doStep(0.0, 0.01)
    ref = run_scene(scene_mod.load(MECH / "planar_f45_wo4.toml"), stop_time=0.01)
    assert s.fmu.getReal([x]) == [ref.values[-1][0]]
    s.free()


def test_instantiate_refuses_a_wrong_guid_or_model_exchange(unz):
    d = unz("planar_none_wo4")
    md = fmpy.read_model_description(str(d))
    for guid, kind, expected in [("{00000000-0000-0000-0000-000000000000}", 1, "does not match this FMU's"),
                                 (md.guid, 0, "supports co-simulation only")]:
        logs = Logs()
        fmu = FMU2Slave(guid=guid, unzipDirectory=str(d), modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="bad")
        component = fmu.fmi2Instantiate(b"bad", kind, guid.encode(), (d / "resources").as_uri().encode(),
                                        ctypes.byref(logs.callbacks), 0, 0)
        assert not component
        assert any(st >= 3 and expected in m for st, _, m in logs.records), logs.records


def test_get_status(unz):
    from fmpy.fmi2 import fmi2LastSuccessfulTime, fmi2Terminated

    s = Slave(unz("planar_none_wo4")).init()
    s.fmu.doStep(0.0, 0.25)
    assert s.fmu.getRealStatus(fmi2LastSuccessfulTime) == 0.25
    assert s.fmu.getBooleanStatus(fmi2Terminated) is False or s.fmu.getBooleanStatus(fmi2Terminated) == 0
    s.free()


# ------------------------------------------------------------------------------- logging

def test_log_categories_match_the_binary(unz):
    md = fmpy.read_model_description(str(unz("planar_none_wo4")))
    names = [c.name for c in md.logCategories]
    assert names == list(LOG_CATEGORIES)
    c_source = NATIVE.read_text()
    for name in names[:-1]:
        assert f'"{name}"' in c_source
    assert names[-1] == "logAll"
    s = Slave(unz("planar_none_wo4"))
    for name in names:
        s.fmu.setDebugLogging(True, [name])
    assert 'unknown log category "logNothing"' in s.error(s.fmu.setDebugLogging, True, ["logNothing"])
    s.free()


def _run_logged(unz, logging_on, categories=None, off=None, tolerance=0.5):
    """One run that logs each level: info (initialization), a warning (the host tolerance 0.5 is
    outside solver.tolerance's range), an error (a wrong communication point)."""
    s = Slave(unz("planar_none_wo4"), logging_on=logging_on)
    if categories is not None:
        s.fmu.setDebugLogging(True, categories)
    if off is not None:
        s.fmu.setDebugLogging(False, off)
    s.fmu.setupExperiment(tolerance=tolerance, startTime=0.0)
    s.fmu.enterInitializationMode()
    s.fmu.exitInitializationMode()
    with pytest.raises(FMICallException, match=r"fmi2DoStep failed with status 3 \(error\)"):
        s.fmu.doStep(1.0, 0.01)  # wrong communication point: an error
    s.free()
    return {(status, cat) for status, cat, _ in s.logs.records}


def test_debug_logging_honours_categories(unz):
    info, warn, err = (0, "logEvents"), (1, "logStatusWarning"), (3, "logStatusError")
    assert _run_logged(unz, False) == {warn, err}  # logging off: warnings and errors only
    assert _run_logged(unz, True) == {info, warn, err}
    assert _run_logged(unz, False, categories=["logEvents"]) == {info, warn, err}
    assert _run_logged(unz, True, off=["logEvents", "logStatusWarning"]) == {err}  # errors always
    assert _run_logged(unz, False, off=["logAll"]) == {err}


# ------------------------------------------------------------------------------- tolerance

def test_setup_experiment_tolerance_rule(unz):
    """The rule (slave docstring, docs/reference/fmu.md, "Tolerance"): the parameter solver.tolerance if the host
    set it, else fmi2SetupExperiment's tolerance, else the scene's; a host tolerance outside the
    parameter's range is not used (fmi2Warning naming the range)."""
    fmu = str(unz.out / "planar_f45_wo4.fmu")
    names = [v.name for v in fmpy.read_model_description(fmu).modelVariables
             if v.causality == "output" and v.type == "Real"]
    host = fmpy.simulate_fmu(fmu, stop_time=0.5, relative_tolerance=1e-6)
    param = fmpy.simulate_fmu(fmu, stop_time=0.5, start_values={"solver.tolerance": 1e-6})
    scene = fmpy.simulate_fmu(fmu, stop_time=0.5)  # fmpy passes the DefaultExperiment's 1e-9
    both = fmpy.simulate_fmu(fmu, stop_time=0.5, relative_tolerance=1e-6, start_values={"solver.tolerance": 1e-9})
    assert all(np.array_equal(host[n], param[n]) for n in names)
    assert all(np.array_equal(both[n], scene[n]) for n in names)
    assert max(np.max(np.abs(host[n] - scene[n])) for n in names) > 1e-9
    s = Slave(unz("planar_f45_wo4"), logging_on=True)
    assert s.fmu.fmi2SetupExperiment(s.fmu.component, 1, 1e-6, 0.0, 0, 0.0) == 0
    assert any(st == 0 and "fmi2SetupExperiment: tolerance 1e-06 used as solver.tolerance" in m
               for st, _, m in s.logs.records)
    s.fmu.enterInitializationMode()
    assert s.fmu.getReal([s.vr("solver.tolerance")]) == [1e-6]
    s.free()
    s = Slave(unz("planar_f45_wo4"), logging_on=True)
    assert s.fmu.fmi2SetupExperiment(s.fmu.component, 1, 0.5, 0.0, 0, 0.0) == 1  # fmi2Warning
    assert any(st == 1 and "fmi2SetupExperiment: tolerance 0.5 not used (" in m and "1e-09" in m
               for st, _, m in s.logs.records)
    s.fmu.enterInitializationMode()
    assert s.fmu.getReal([s.vr("solver.tolerance")]) == [1e-9]
    s.free()


# ------------------------------------------------------------------------------- work budget

def test_do_step_work_budget(unz):
    md = fmpy.read_model_description(str(unz("planar_f45_wo4")))
    byname = {v.name: v for v in md.modelVariables}
    assert int(byname["solver.max_internal_steps"].start) == 10000
    assert float(byname["solver.max_wall_time"].start) == 30.0
    assert byname["solver.max_wall_time"].variability == "tunable"
    s = Slave(unz("planar_f45_wo4")).init(**{"solver.max_internal_steps": 300})
    msg = s.error(s.fmu.doStep, 0.0, 1e6)
    assert "work budget exhausted" in msg and "solver.max_internal_steps = 300" in msg
    s.free()
    s = Slave(unz("planar_f45_wo4")).init(**{"solver.max_wall_time": 0.2})
    msg = s.error(s.fmu.doStep, 0.0, 1e6)
    assert "work budget exhausted" in msg and "solver.max_wall_time = 0.2 s" in msg
    s.free()


def test_budget_is_tunable_and_long_steps_are_exact(unz):
    s = Slave(unz("planar_f45_wo4")).init(**{"solver.max_internal_steps": 50})
    state = s.fmu.getFMUstate()
    s.error(s.fmu.doStep, 0.0, 1.0)
    s.fmu.setFMUstate(state)  # back before the failed step
    s.fmu.setInteger([s.vr("solver.max_internal_steps")], [10000])  # tunable while stepping
    s.fmu.doStep(0.0, 1.0)  # one long step, budget checked after every internal step
    out = np.array(s.fmu.getReal(s.outputs))
    s.fmu.freeFMUstate(state)
    s.free()
    ref = run_scene(scene_mod.load(MECH / "planar_f45_wo4.toml"), stop_time=1.0, output_interval=1.0)
    assert np.array_equal(out, ref.values[-1])


# ------------------------------------------------------------------------------- no silent failure

def test_fmpy_command_line_fails_loudly(unz, tmp_path):
    """joint4.mu = 3e5: the friction solve fails at once; fmpy simulate exits non-zero and prints
    the reason (debug logging off)."""
    fmpy_cli = Path(sys.executable).parent / "fmpy"
    cmd = [str(fmpy_cli)] if fmpy_cli.exists() else [sys.executable, "-m", "fmpy.command_line"]
    proc = subprocess.run([*cmd, "simulate", str(unz.out / "planar_f45_wo4.fmu"), "--start-values", "joint4.mu",
                           "3e5", "--output-file", str(tmp_path / "out.csv")], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode != 0
    text = proc.stdout + proc.stderr
    assert "[ERROR] fmi2DoStep(0.0, 0.01)" in text and "did not converge" in text


def test_reference_run_that_ends_early_fails_the_build(tmp_path):
    scene = (MECH / "planar_f45_wo4.toml").read_text().replace('name = "planar_f45_wo4"', 'name = "planar_stuck"')
    scene = scene.replace("[outputs]", "[scene.friction_params.joint4]\nmu = 3e5\n\n[outputs]")
    (tmp_path / "planar_stuck.toml").write_text(scene)
    (tmp_path / "planar_sliders.toml").write_text((MECH / "planar_sliders.toml").read_text())
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "planar_stuck_ref.csv").write_text("stale")
    proc = subprocess.run([sys.executable, str(ROOT / "build_fmu.py"), str(tmp_path / "planar_stuck.toml"), "--out",
                           str(tmp_path / "out"), "--jobs", "1"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == fmu_build.EXIT_RUNTIME, proc.stdout + proc.stderr
    assert ("planar_stuck: reference simulation failed: the reference run of planar_stuck (default experiment "
            "0.0 to 4.0 s) stopped") in proc.stderr
    assert "did not converge" in proc.stderr
    # the summary counts the failed reference run (the FMU itself was built)
    assert "build: 1 FMU(s) built, 0 refused by the pre-check, 0 failed, 1 reference run(s) failed, " in proc.stdout
    assert "wrote planar_stuck_ref.csv" not in proc.stdout
    assert not (tmp_path / "out" / "planar_stuck_ref.csv").exists()  # no stale file either


# ------------------------------------------------------------------------------- scene names

@pytest.mark.parametrize("name", ["class", "None", "overcon", "import"])
def test_scene_names_that_are_keywords_or_the_package(tmp_path, name):
    text = (MECH / "planar_none_wo4.toml").read_text().replace('name = "planar_none_wo4"', f'name = "{name}"')
    (tmp_path / f"{name}.toml").write_text(text)
    (tmp_path / "planar_sliders.toml").write_text((MECH / "planar_sliders.toml").read_text())
    res = fmu_build.build_scene(tmp_path / f"{name}.toml", tmp_path / "out", echo=lambda s: None)
    assert res.status == "built", res.messages
    got = fmpy.simulate_fmu(str(res.fmu), stop_time=0.2)
    ref = run_scene(scene_mod.load(MECH / "planar_none_wo4.toml"), stop_time=0.2)
    assert np.array_equal(got["slider1.x"], ref.column("slider1.x"))


# ------------------------------------------------------------------------------- friction without equations

DUPLICATE_JOINT = '''
[[joints]]
name = "joint7"
type = "revolute"
body_i = "slider1"
body_j = "link3"
s_i = [0.0, 0.0]
s_j = [0.0, -1.0]

[joints.friction]
law = "regularised"
mu = 0.1
radius = 0.15
v_reg = 1e-3

'''


def test_friction_on_a_joint_whose_equations_are_all_eliminated_is_reported(tmp_path):
    """joint7 duplicates joint4; eliminating both its equations leaves it without reaction, so its
    friction is zero: the FMU says so at instantiation (a warning, logged with logging off)."""
    mech = (MECH / "planar_sliders.toml").read_text()
    i = mech.index("[[loads]]")
    (tmp_path / "planar_sliders.toml").write_text(mech[:i] + DUPLICATE_JOINT + mech[i:])
    scene = (MECH / "planar_f45_wo4.toml").read_text().replace('name = "planar_f45_wo4"', 'name = "planar_dup"')
    scene = scene.replace('friction = ["joint4", "joint5"]', 'friction = ["joint7"]')
    scene = scene.replace("eliminate = [4]", "eliminate = [4, 13, 14]")
    (tmp_path / "planar_dup.toml").write_text(scene)
    model = compile_checked(scene_mod.load(tmp_path / "planar_dup.toml"))
    assert [w.split(",")[0] for w in friction_warnings(model)] == ["friction on joint joint7"]
    assert friction_warnings(compile_checked(scene_mod.load(MECH / "planar_f45_wo4.toml"))) == []
    res = fmu_build.build_scene(tmp_path / "planar_dup.toml", tmp_path / "out", allow_nonunique=True,
                                echo=lambda s: None)
    assert res.status == "built", res.messages
    s = Slave(Path(fmpy.extract(str(res.fmu), str(tmp_path / "unz"))))
    assert any(st == 1 and "friction on joint joint7, whose equations Phi13, Phi14 are all eliminated" in m
               for st, _, m in s.logs.records)
    s.free()


def test_switching_friction_off_by_a_parameter_is_logged(unz):
    """joint4.mu = 0 removes joint 4's friction: the build-time verdict may no longer hold, and the
    FMU says so (a warning, which reaches the host with logging off)."""
    s = Slave(unz("planar_f45_wo4")).init(**{"joint4.mu": 0.0})
    assert any(st == 1 and "friction in joint(s) joint4 switched between mu = 0 and mu > 0" in m
               for st, _, m in s.logs.records)
    s.free()
    s = Slave(unz("planar_f45_wo4")).init(**{"joint4.mu": 0.2})
    assert not any("switched between mu = 0" in m for _, _, m in s.logs.records)
    s.free()
