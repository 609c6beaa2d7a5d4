"""The FMUs (``overcon build``): the FMI layer over the compiled core
(fmu_src/overcon/fmu/native/fmi2_*.c), compiled once at the package installation. Their results
equal the in-process run, they carry no Python (no .py file, no libpython needed or loaded: the plain
C host runs them from an empty environment), their FMU state restores bit for bit, they cover any
number of friction joints and ``solver.singular = "pass"``, a scene that cannot be integrated is
refused, and ``--runtime python`` is a deprecated alias. The FMI calls one by one are in
test_fmi_calls.py."""
from __future__ import annotations

import dataclasses
import math
import shutil
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from overcon import scene as scene_mod  # noqa: E402
from overcon.checks import compile_checked  # noqa: E402
from overcon.fmu import build as fmu_build  # noqa: E402
from overcon.simulate import Simulation, SimulationError, run  # noqa: E402

from test_fmu import Logs  # noqa: E402

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
MECH = ROOT / "mechanisms"
SCENES = {"planar_f145_wo6": MECH / "planar_f145_wo6.toml", "planar_f45_wo4": MECH / "planar_f45_wo4.toml",
          "spatial_GH_wo9": MECH / "spatial_GH_wo9.toml", "spatial_MN_wo5": MECH / "spatial_MN_wo5.toml",
          "door_h1_wo_hinge2": MECH / "examples" / "door_h1_wo_hinge2.toml",
          "carriage_guide_wo_rod": MECH / "examples" / "carriage_guide_wo_rod.toml"}
POSITION = ("x", "y", "z", "phi", "alpha", "beta", "gamma", "e0", "e1", "e2", "e3")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus_c")
    lines = []
    code, results = fmu_build.build_all([str(p) for p in SCENES.values()], out, refs=False, allow_nonunique=True,
                                        runtime="c", echo=lines.append, echo_err=lines.append)
    assert code == 0, lines
    assert all("runtime c)" in line for line in lines if ": built " in line), lines
    return {r.name: r.fmu for r in results}


def unzip(fmu: Path, tmp_path: Path) -> Path:
    return Path(fmpy.extract(str(fmu), str(tmp_path / fmu.stem)))


def test_c_fmu_carries_no_python(built):
    """No Python file, no recorded Python, and a binary that needs libm and libc only."""
    for fmu in built.values():
        names = zipfile.ZipFile(fmu).namelist()
        assert not [n for n in names if n.endswith((".py", ".pyc"))] and "resources/overcon_python.txt" not in names
        assert "resources/overcon_model.bin" in names
    readelf = shutil.which("readelf")
    if readelf is None:
        pytest.skip("needs readelf (binutils)")
    so = fmu_build.C_RUNTIME_LIBRARY
    needed = [line.split("[")[1].rstrip("]") for line in subprocess.run(
        [readelf, "-d", str(so)], capture_output=True, text=True, check=True).stdout.splitlines() if "NEEDED" in line]
    assert needed and all(n.startswith(("libm.so", "libc.so")) for n in needed), needed


@pytest.mark.parametrize("name", list(SCENES))
def test_fmpy_equals_the_in_process_run(built, name):
    """fmpy.simulate_fmu over the default experiment equals ``overcon simulate`` in process (the
    same C arithmetic on both sides): positions to 1e-9 m, every output to 1e-9 relative."""
    spec = scene_mod.load(SCENES[name])
    got = fmpy.simulate_fmu(str(built[name]), output_interval=spec.solver.output_interval)
    ref = run(compile_checked(spec), spec.solver)
    assert len(got) == len(ref.time) and np.array_equal(got["time"], ref.time)
    for col in ref.names:
        scale = max(1.0, float(np.max(np.abs(ref.column(col)))))
        bound = 1e-9 if col.rsplit(".", 1)[1] in POSITION else 1e-9 * scale
        assert np.max(np.abs(got[col] - ref.column(col))) <= bound, col


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    cc = shutil.which("cc")
    if cc is None:
        pytest.skip("needs a C compiler (cc) for the test host")
    exe = tmp_path_factory.mktemp("c_host_c") / "fmu_host"
    subprocess.run([cc, "-O2", "-Wall", "-o", str(exe), str(ROOT / "tests" / "c_host" / "fmu_host.c"), "-ldl", "-lm"],
                   check=True, capture_output=True)
    return exe


@pytest.mark.parametrize("name", ["planar_f45_wo4", "door_h1_wo_hinge2"])
def test_plain_c_host_without_python(built, host, tmp_path, name):
    """The plain C host from an empty environment (env -i): exit 0, every row written, no
    libpython in the process (/proc/self/maps, -n), the FMU state saved half-way through its
    bytes restores the second half bit for bit (-S), and the values equal fmpy's."""
    d = unzip(built[name], tmp_path)
    md = fmpy.read_model_description(str(d))
    ex = md.defaultExperiment
    outs = [v for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    args = ["-q", "-w", "-n", "-S", str(d), md.coSimulation.modelIdentifier, md.guid, ex.startTime, ex.stopTime,
            ex.stepSize, ex.tolerance, *(f"{v.valueReference}:{v.name}" for v in outs)]
    proc = subprocess.run([str(host), *map(str, args)], capture_output=True, text=True, timeout=600, env={})
    assert proc.returncode == 0, proc.stderr
    rows = np.array([[float(x) for x in line.split(",")] for line in proc.stdout.splitlines()[1:]])
    n_rows = round((float(ex.stopTime) - float(ex.startTime)) / float(ex.stepSize)) + 1
    assert rows.shape == (n_rows, 1 + len(outs))
    ref = fmpy.simulate_fmu(str(built[name]), output_interval=float(ex.stepSize))
    assert np.array_equal(rows[:, 1:], np.column_stack([ref[v.name] for v in outs]))


def slave(d: Path, logs: Logs):
    md = fmpy.read_model_description(str(d))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(d), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="c")
    fmu.instantiate(callbacks=logs.callbacks, loggingOn=True)
    return fmu, {v.name: v.valueReference for v in md.modelVariables}


def test_friction_parameter_equals_the_in_process_run(built, tmp_path):
    """joint4.mu = 0.35 set by the host: the same motion and reactions as the scene with that
    coefficient (and not those of the scene's own)."""
    d = unzip(built["planar_f45_wo4"], tmp_path)
    fmu, vr = slave(d, Logs())
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setReal([vr["joint4.mu"]], [0.35])
    fmu.exitInitializationMode()
    for k in range(50):
        fmu.doStep(k * 0.01, 0.01)
    got = fmu.getReal([vr["slider1.x"], vr["joint4.Fx"]])
    fmu.terminate()
    fmu.freeInstance()
    spec = scene_mod.load(SCENES["planar_f45_wo4"])
    spec = dataclasses.replace(spec, friction_params={**spec.friction_params, "joint4": dataclasses.replace(
        spec.friction_params["joint4"], mu=0.35)})
    ref = run(compile_checked(spec), spec.solver, stop_time=0.5)
    assert got == [ref.column("slider1.x")[-1], ref.column("joint4.Fx")[-1]]
    assert got[1] != run(compile_checked(scene_mod.load(SCENES["planar_f45_wo4"])),
                         spec.solver, stop_time=0.5).column("joint4.Fx")[-1]


def test_rk4_unstable_step_is_readable_as_in_python(built, tmp_path):
    """rk4 at 20 ms on sticking friction (mu = 1): fmi2DoStep fails with the unstable-step
    message and solver.stable_step holds the Python run's stable step."""
    d = unzip(built["planar_f145_wo6"], tmp_path)
    logs = Logs()
    fmu, vr = slave(d, logs)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setString([vr["solver.method"]], ["rk4"])
    fmu.setReal([vr["solver.step"], vr["joint1.mu"], vr["joint4.mu"], vr["joint5.mu"]], [0.02, 1.0, 1.0, 1.0])
    fmu.exitInitializationMode()
    with pytest.raises(FMICallException):
        for k in range(50):
            fmu.doStep(k * 0.02, 0.02)
    stable = fmu.getReal([vr["solver.stable_step"]])[0]
    fmu.freeInstance()
    spec = scene_mod.load(SCENES["planar_f145_wo6"])
    spec = dataclasses.replace(spec, friction_params={k: dataclasses.replace(v, mu=1.0)
                                                      for k, v in spec.friction_params.items()})
    solver = dataclasses.replace(spec.solver, method="rk4", step=0.02)
    with pytest.raises(SimulationError) as exc:
        Simulation(compile_checked(spec), solver).advance(1.0)
    assert stable == exc.value.stable_step > 0.0
    assert any(s == 3 and "rk4 is unstable with the fixed step 0.02 s" in m for s, _, m in logs.records)


def pendulums(k: int, out: Path, stop_time: float = 0.5) -> Path:
    """``k`` identical copies of a double pendulum with friction in both revolute joints (``2 k``
    friction joints), every copy pinned at the origin and started alike (upper link at 0.3 rad,
    lower at -0.4 rad, at rest): copies independent of each other whose arithmetic is the same
    operation for operation (no offset enters one copy's positions), so they move bit for bit alike."""
    lines = ['[mechanism]', f'name = "pendulums{k}"', 'kind = "planar"', 'gravity = [0.0, -9.81]']
    c1, s1, c2, s2 = math.cos(0.3), math.sin(0.3), math.cos(-0.4), math.sin(-0.4)
    for i in range(k):  # link axis along the body's x, 1 m, pin at its -x end
        lines += ['[[bodies]]', f'name = "upper{i}"', 'mass = 1.0', 'inertia = 0.0833',
                  f'q0 = [{0.5 * c1!r}, {0.5 * s1!r}, 0.3]',
                  '[[bodies]]', f'name = "lower{i}"', 'mass = 0.5', 'inertia = 0.04',
                  f'q0 = [{c1 + 0.5 * c2!r}, {s1 + 0.5 * s2!r}, -0.4]']
    for i in range(k):
        for name, bi, bj, sj in ((f"pin{i}", f"upper{i}", "base", "[0.0, 0.0]"),
                                 (f"knee{i}", f"lower{i}", f"upper{i}", "[0.5, 0.0]")):
            lines += ['[[joints]]', f'name = "{name}"', 'type = "revolute"', f'body_i = "{bi}"', f'body_j = "{bj}"',
                      's_i = [-0.5, 0.0]', f's_j = {sj}',
                      '[joints.friction]', 'law = "regularised"', 'mu = 0.2', 'radius = 0.05', 'v_reg = 1e-3']
    out.mkdir(parents=True, exist_ok=True)
    (out / f"pendulums{k}.toml").write_text("\n".join(lines) + "\n")
    joints = ", ".join(f'"{j}{i}"' for i in range(k) for j in ("pin", "knee"))
    scene = out / f"pendulums{k}_scene.toml"
    scene.write_text("\n".join([
        "[scene]", f'name = "pendulums{k}_scene"', f'mechanism = "pendulums{k}.toml"', f"friction = [{joints}]", "eliminate = []",
        f"stop_time = {stop_time!r}", "[outputs]",
        "positions = [" + ", ".join(f'"upper{i}.phi", "lower{i}.phi"' for i in range(k)) + "]",
        "[solver]", "tolerance = 1e-9", "output_interval = 0.05", ""]))
    return scene


def _c_run(path: Path, times, **solver) -> tuple[list[str], np.ndarray]:
    """(output names, positions at ``times``) of the scene at ``path`` run in process in C
    (kernel.Run), with the scene's solver settings changed by ``solver``."""
    from overcon import kernel
    spec = scene_mod.as_scene(scene_mod.load(path))
    model = compile_checked(spec)
    runner = kernel.Run(model, dataclasses.replace(spec.solver, **solver))
    names = model.output_names()[:len(model.position_outputs)]
    cols = [i for _, i in model.position_outputs]
    return names, np.array([runner.advance(float(t))[cols] for t in times])


def test_forty_friction_joints_run_in_process_and_in_the_c_fmu(tmp_path):
    """20 copies of a double pendulum with friction in both joints: 40 friction joints (80 friction
    multipliers), beyond the 32 the core once took on its stack. In process (kernel.Run) and
    through the C FMU in fmpy every copy moves bit for bit as the first (the copies are the same
    arithmetic); the FMU equals the in-process run at its communication points (the same C run).
    With rk4's fixed steps (no error norm over all copies to choose the steps; to 0.25 s) the first copy moves
    bit for bit as the mechanism alone, one copy with 2 friction joints; and friction changed the
    motion (it differs from the frictionless run by more than 1e-3 rad)."""
    path = pendulums(20, tmp_path / "k20")
    lines = []
    code, results = fmu_build.build_all([str(path)], tmp_path / "out", refs=False, echo=lines.append,
                                        echo_err=lines.append)
    assert code == 0 and any(": built " in line and "runtime c)" in line for line in lines), lines
    got = fmpy.simulate_fmu(str(results[0].fmu), output_interval=0.05)
    times = got["time"][1:]
    names, ref = _c_run(path, times)
    fmu = np.column_stack([got[n][1:] for n in names])
    assert np.max(np.abs(fmu - ref)) <= 1e-12
    for pos in (ref, fmu):
        copies = pos.reshape(len(times), 20, 2)
        assert np.array_equal(copies, np.broadcast_to(copies[:, :1], copies.shape))
    early = times[times <= 0.25]  # rk4's fixed steps cost more evaluations than dopri5's
    _, fixed = _c_run(path, early, method="rk4", step=1e-3)
    _, alone = _c_run(pendulums(1, tmp_path / "k1"), early, method="rk4", step=1e-3)
    assert np.array_equal(fixed.reshape(len(early), 20, 2)[:, 0], alone)
    free = pendulums(1, tmp_path / "free")
    free.write_text(free.read_text().replace("friction = [", "friction = [] # ["))
    _, frictionless = _c_run(free, early, method="rk4", step=1e-3)
    assert np.max(np.abs(alone - frictionless)) > 1e-3


def test_singular_pass_runs_in_the_c_fmu(tmp_path):
    """``solver.singular = "pass"`` (the augmented Lagrangian solve and step-end projections) is in
    the model file: the parallelogram of three cranks (tests/test_singular_pass.py) goes through
    both flat positions in the C FMU, equal to the in-process C run at the communication points,
    every crank at the first one's angle, and the two ``singular`` events logged under logEvents."""
    from test_singular_pass import parallelogram
    path = parallelogram(3, tmp_path / "pg", 1.6)
    code, results = fmu_build.build_all([str(path)], tmp_path / "out", refs=False, echo=lambda s: None,
                                        echo_err=lambda s: None)
    assert code == 0
    d = unzip(results[0].fmu, tmp_path)
    logs = Logs()
    fmu, vr = slave(d, logs)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    times = np.linspace(0.05, 1.6, 32)
    got, t = [], 0.0
    for t_next in times:
        fmu.doStep(t, float(t_next) - t)  # fmpy raises on a status other than fmi2OK
        got.append(fmu.getReal([vr["crank0.phi"]])[0])
        t = float(t_next)
    fmu.terminate()
    fmu.freeInstance()
    _, ref = _c_run(path, times)
    assert np.max(np.abs(np.array(got) - ref[:, 0])) <= 1e-12
    events = [m for _, _, m in logs.records if ": event singular" in m]
    assert len(events) == 2, logs.text()


def test_coulomb_law_is_refused_at_build(tmp_path):
    """The friction law 'coulomb' (discontinuous at v = 0; overcon simulate refuses to integrate
    it) gives no FMU: exit 2 naming the joint and the law, nothing written."""
    (tmp_path / "planar_sliders.toml").write_text((MECH / "planar_sliders.toml").read_text()
                                                  .replace('law = "regularised"', 'law = "coulomb"'))
    path = tmp_path / "f45.toml"
    path.write_text((MECH / "planar_f45_wo4.toml").read_text())
    lines = []
    code, results = fmu_build.build_all([str(path)], tmp_path / "out", refs=False, echo=lines.append,
                                        echo_err=lines.append)
    assert code == fmu_build.EXIT_INPUT and results[0].status == "invalid"
    assert any("joint joint4: friction law 'coulomb'" in line and "not for integration" in line for line in lines)
    assert not (tmp_path / "out" / "planar_f45_wo4.fmu").exists()


def test_runtime_python_is_a_deprecated_alias_of_c(tmp_path, capsys):
    """``overcon build --runtime python`` warns on stderr that it is deprecated and builds the C
    runtime (no Python file in the FMU; exit 0)."""
    from overcon.cli import main
    assert main(["build", str(SCENES["planar_f45_wo4"]), "--out", str(tmp_path), "--no-ref", "--runtime",
                 "python"]) == 0
    out, err = capsys.readouterr()
    assert "--runtime python is deprecated" in err and "runtime c)" in out and "deprecated" not in out
    names = zipfile.ZipFile(tmp_path / "planar_f45_wo4.fmu").namelist()
    assert "resources/overcon_model.bin" in names and not [n for n in names if n.endswith(".py")]


def test_energy_outputs_are_built_for_the_c_runtime_and_equal_the_in_process_run(tmp_path):
    """A scene with ``[outputs] energy = true`` (friction in three joints, a spring, a torque) is
    built with the C runtime now, and fmpy's energy.kinetic, potential, dissipated and applied
    equal the in-process run's (the same C ledger arithmetic on both sides within round-off)."""
    (tmp_path / "planar_sliders.toml").write_text((MECH / "planar_sliders.toml").read_text())
    path = tmp_path / "energy_f145.toml"
    path.write_text((MECH / "planar_f145_wo6.toml").read_text().replace('name = "planar_f145_wo6"',
                                                                       'name = "energy_f145"')
                    .replace('reactions = "all"', 'reactions = "all"\nenergy = true').replace("stop_time = 4.0",
                                                                                            "stop_time = 1.0"))
    lines = []
    code, results = fmu_build.build_all([str(path)], tmp_path / "out", refs=False, allow_nonunique=True, runtime="c",
                                        echo=lines.append, echo_err=lines.append)
    assert code == 0 and any(": built " in line and "runtime c)" in line for line in lines), lines
    spec = scene_mod.load(path)
    got = fmpy.simulate_fmu(str(results[0].fmu), output_interval=spec.solver.output_interval)
    ref = run(compile_checked(spec), spec.solver)
    assert np.array_equal(got["time"], ref.time)
    for col in ("energy.kinetic", "energy.potential", "energy.dissipated", "energy.applied"):
        scale = max(1.0, float(np.max(np.abs(ref.column(col)))))
        assert np.max(np.abs(got[col] - ref.column(col))) <= 1e-9 * scale, col
    assert ref.column("energy.dissipated")[-1] > 0.01  # friction did work


def test_degrading_elimination_is_chosen_again_by_the_c_fmu(tmp_path):
    """The Bricard linkage eliminating Phi2 (energy outputs on): as the in-process run, the C FMU
    chooses the elimination again when it degrades (at the in-process run's instant, about 1.23 s;
    one elimination-reselected event, logged under logEvents), completes 10 s and moves as the
    in-process run does (<= 1e-8 m)."""
    path = ROOT / "tests" / "data" / "bricard" / "bricard_wo2.toml"
    lines = []
    code, results = fmu_build.build_all([str(path)], tmp_path / "out", refs=False, allow_nonunique=True, runtime="c",
                                        echo=lines.append, echo_err=lines.append)
    assert code == 0 and any(": built " in line and "runtime c)" in line for line in lines), lines
    d = unzip(results[0].fmu, tmp_path)
    logs = Logs()
    fmu, vr = slave(d, logs)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    spec = scene_mod.as_scene(scene_mod.load(path))
    ref = run(compile_checked(spec), spec.solver)
    names = [n for n in ref.names if n.startswith("rod")]
    refs = [vr[n] for n in names]
    worst = 0.0
    for k in range(1000):
        fmu.doStep(k * 0.01, 0.01)
        worst = max(worst, float(np.max(np.abs(np.array(fmu.getReal(refs)) - ref.values[k + 1, [ref.names.index(n) for n in names]]))))
    fmu.terminate()
    fmu.freeInstance()
    assert worst <= 1e-8
    events = [m for _, _, m in logs.records if ": event " in m]
    assert [e[1] for e in ref.events] == ["elimination-reselected"]
    t_event = ref.events[0][0]  # where the kept rows' (equilibrated) ratio falls below 1e-3
    assert 1.15 < t_event < 1.3
    assert len(events) == 1 and events[0].startswith(f"t = {t_event:.9g} s: event elimination-reselected: "
                                                     "eliminated [2] -> [")
