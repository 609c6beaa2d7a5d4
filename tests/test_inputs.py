"""Scene inputs ([[inputs]]) and joint sensors ([outputs] joints), in process and in the FMU
(issue 38): the inputs' physics (a torque about the door's hinge axis accelerates it by
tau / I_axis; kinetic + potential - applied stays constant), the sensors against finite
differences, the scene's checks naming file and field, and the FMU (FMI 2.0 and 3.0) run by fmpy
with an input table equal to ``overcon simulate --input`` at every output point, held and linear."""
from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from overcon import kernel as kernel_mod
from overcon import scene
from overcon.checks import compile_checked
from overcon.simulate import Simulation, run
from overcon.tooling.inputs import read_input_table

ROOT = Path(__file__).resolve().parents[1]
DOOR = ROOT / "mechanisms" / "examples" / "door.toml"
DOOR_MOTOR = ROOT / "mechanisms" / "examples" / "motor_door.toml"


def _door_scene(tmp_path: Path, *, friction: str = "[]", eliminate: str = '["hinge2"]', inputs: str | None = None,
                outputs: str = 'joints = ["hinge1"]\nenergy = true', stop: float = 2.0, method: str = "") -> Path:
    inputs = inputs if inputs is not None else ('[[inputs]]\nname = "motor"\ntype = "joint_torque"\n'
                                                'joint = "hinge1"\nstart = 3.0\n')
    path = tmp_path / "door_in.toml"
    path.write_text(f'[scene]\nname = "door_in"\nmechanism = "{DOOR.as_posix()}"\nfriction = {friction}\n'
                    f'eliminate = {eliminate}\nstop_time = {stop}\n\n{inputs}\n[outputs]\n'
                    f'positions = ["door.x", "door.y", "door.z"]\nreactions = ["hinge1"]\n{outputs}\n\n'
                    f'[solver]\ntolerance = 1e-10\noutput_interval = 0.01\n{method}')
    return path


def _axis_inertia() -> float:
    """The door's moment of inertia about the hinge line (through the origin along a = [sin 0.1, 0,
    cos 0.1]) from its mass, central inertia and centre of mass (door.toml, identity orientation)."""
    a = np.array([np.sin(0.1), 0.0, np.cos(0.1)])
    c = np.array([0.5, 0.0, 1.0])
    inertia = np.diag([6.669333333333333, 7.733333333333334, 1.069333333333334])
    d2 = c @ c - (c @ a) ** 2
    return float(a @ inertia @ a + 20.0 * d2)


def test_a_torque_about_the_hinge_axis_accelerates_the_door_by_tau_over_the_axis_inertia(tmp_path):
    """The angular acceleration about the axis with tau minus without: tau / I_axis to 1e-9 relative
    (gravity and the initial spin act the same on both)."""
    spec = scene.load(_door_scene(tmp_path))
    model = compile_checked(spec)
    kern, _ = kernel_mod.select(model, spec.solver)
    y0 = np.concatenate([model.q0, model.h0])
    a = np.array([np.sin(0.1), 0.0, np.cos(0.1)])  # body axes = global at q0 (identity orientation)
    acc = []
    for tau in (0.0, 7.5):
        kern.set_inputs(0.0, [tau])
        ydot = kern.evaluate(0.0, y0)[0]
        acc.append(ydot[model.n + 3: model.n + 6] @ a)
    assert (acc[1] - acc[0]) == pytest.approx(7.5 / _axis_inertia(), rel=1e-9)


def test_energy_with_a_torque_input_kinetic_plus_potential_minus_applied_is_constant(tmp_path):
    """The frictionless door driven by a constant 3 N.m about hinge1 for 2 s: kinetic + potential -
    applied constant to 1e-8 J, the applied work = tau times the hinge angle (the sensor)."""
    spec = scene.load(_door_scene(tmp_path))
    res = run(compile_checked(spec), spec.solver)
    col = res.column
    total = col("energy.kinetic") + col("energy.potential") - col("energy.applied")
    assert np.max(np.abs(total - total[0])) <= 1e-8
    assert np.ptp(col("energy.applied")) > 1.0  # the input does work
    assert np.max(np.abs(col("energy.applied") - 3.0 * col("hinge1.angle"))) <= 1e-8


def test_sensors_angle_and_rate_agree_with_finite_differences_and_the_body_rotation(tmp_path):
    """hinge1.rate is d(hinge1.angle)/dt (central differences, fine grid) and the angle starts at 0;
    the planar sliders' revolute angles are the bodies' relative rotations and their translational
    displacements integrate their speeds."""
    spec = scene.load(_door_scene(tmp_path, stop=0.5))
    res = run(compile_checked(spec), spec.solver, output_interval=1e-3)
    t, ang, rate = res.time, res.column("hinge1.angle"), res.column("hinge1.rate")
    assert ang[0] == 0.0 and abs(rate[0] - 1.0) < 1e-9  # h0: 1 rad/s about the axis
    central = (ang[2:] - ang[:-2]) / (t[2:] - t[:-2])
    assert np.max(np.abs(central - rate[1:-1])) < 1e-5
    planar = ROOT / "mechanisms" / "planar_sliders.toml"
    text = planar.read_text()
    (tmp_path / "m.toml").write_text(text)
    sc = tmp_path / "sl.toml"
    sc.write_text('[scene]\nname = "sl"\nmechanism = "m.toml"\nfriction = []\neliminate = [4]\nstop_time = 0.5\n\n'
                  '[outputs]\npositions = "all"\nreactions = []\njoints = "all"\n\n[solver]\ntolerance = 1e-10\n'
                  'output_interval = 0.001\n')
    spec = scene.load(sc)
    model = compile_checked(spec)
    res = run(model, spec.solver)
    names = [n for n, _, _ in model.sensor_outputs]
    assert any(n.endswith(".displacement") for n in names) and any(n.endswith(".angle") for n in names)
    t = res.time
    for n in names:
        if n.endswith(".angle") or n.endswith(".displacement"):
            rate = res.column(n.replace(".angle", ".rate").replace(".displacement", ".speed"))
            x = res.column(n)
            assert x[0] == pytest.approx(0.0, abs=1e-15)
            central = (x[2:] - x[:-2]) / (t[2:] - t[:-2])
            assert np.max(np.abs(central - rate[1:-1])) < 1e-4 * max(1.0, np.max(np.abs(rate)))
    for _, j, k in model.sensor_outputs:  # a revolute joint's angle: phi_i - phi_j from q0
        c = model.joints[j]
        if k == 0 and c.type == "revolute":
            phi = lambda b: res.column(f"{model.body_names[b]}.phi") if b >= 0 else 0.0 * t  # noqa: E731
            rel = phi(c.bi) - phi(c.bj)
            assert np.max(np.abs(res.column(f"{c.name}.angle") - (rel - rel[0]))) < 1e-13


@pytest.mark.parametrize("inputs, field, words", [
    ('[[inputs]]\nname = "m"\ntype = "joint_torque"\njoint = "nope"\n', "inputs[0].joint", "unknown joint"),
    ('[[inputs]]\nname = "m"\ntype = "joint_force"\njoint = "hinge1"\n', "inputs[0].joint", "revolute joint"),
    ('[[inputs]]\nname = "m"\ntype = "joint_torque"\njoint = "hinge1"\nbody = "door"\n', "inputs[0].body", "no body"),
    ('[[inputs]]\nname = "m"\ntype = "force"\nbody = "door"\n', "inputs[0].direction", "missing"),
    ('[[inputs]]\nname = "m"\ntype = "force"\nbody = "door"\ndirection = [0, 0, 0]\n', "inputs[0].direction", "zero"),
    ('[[inputs]]\nname = "m"\ntype = "torque"\nbody = "base"\ndirection = [0, 0, 1]\n', "inputs[0].body", "unknown body"),
    ('[[inputs]]\nname = "rank"\ntype = "joint_torque"\njoint = "hinge1"\n', "inputs[0].name", "reserved"),
    ('[[inputs]]\nname = "m"\ntype = "pull"\njoint = "hinge1"\n', "inputs[0].type", "allowed"),
    ('[[inputs]]\nname = "m"\ntype = "joint_torque"\njoint = "hinge1"\nstart = nan\n', "inputs[0].start", "finite"),
    ('[[inputs]]\nname = "m"\ntype = "joint_torque"\njoint = "hinge1"\n[[inputs]]\nname = "m"\ntype = "joint_torque"\n'
     'joint = "hinge2"\n', "inputs[1].name", "duplicate"),
])
def test_bad_inputs_are_refused_naming_the_file_and_field(tmp_path, inputs, field, words):
    path = _door_scene(tmp_path, inputs=inputs)
    with pytest.raises(scene.SceneError) as exc:
        scene.load(path)
    hit = [p for p in exc.value.problems if p.field == field]
    assert hit and words in hit[0].message and hit[0].file == str(path)


def test_sensors_of_a_joint_without_them_and_rk4_with_inputs_are_refused(tmp_path):
    path = _door_scene(tmp_path, outputs='joints = ["nope"]')
    with pytest.raises(scene.SceneError, match="outputs.joints"):
        scene.load(path)
    path = _door_scene(tmp_path, method='method = "rk4"\nstep = 0.001\n')
    with pytest.raises(scene.SceneError, match="solver.method.*rk4 with"):
        scene.load(path)


def _table(tmp_path: Path, rows) -> Path:
    path = tmp_path / "inputs.csv"
    path.write_text("time,motor\n" + "".join(f"{t!r},{u!r}\n" for t, u in rows))
    return path


def _simulate(path: Path, table: Path, out: Path, *extra) -> dict:
    proc = subprocess.run([sys.executable, "-m", "overcon.cli", "simulate", str(path), "--out", str(out), "--input",
                           str(table), *extra], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    with open(out, newline="") as fh:
        rows = list(csv.reader(fh))
    data = np.array(rows[1:], float)
    return {n: data[:, k] for k, n in enumerate(rows[0])}


def test_a_bad_input_table_exits_2_naming_the_column(tmp_path):
    path = _door_scene(tmp_path, stop=0.1)
    bad = tmp_path / "bad.csv"
    bad.write_text("time,motr\n0,1\n")
    proc = subprocess.run([sys.executable, "-m", "overcon.cli", "simulate", str(path), "--out",
                           str(tmp_path / "o.csv"), "--input", str(bad)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and "'motr'" in proc.stderr and str(bad) in proc.stderr


@pytest.mark.integration
@pytest.mark.parametrize("fmi", [2, 3])
def test_simulate_input_equals_fmpy_with_the_input_table(tmp_path, fmi):
    """door_motor.toml (friction in hinge1) with a piecewise constant motor torque: overcon simulate
    --input and the FMU through fmpy's input= agree to 1e-10 m at every output point (FMI 2.0 and 3.0
    co-simulation; the sensors and the friction output too); fmpy validate is clean."""
    fmpy = pytest.importorskip("fmpy")
    from fmpy.validation import validate_fmu

    from overcon.fmu import build as fmu_build

    res = fmu_build.build_scene(DOOR_MOTOR, tmp_path / "out", allow_nonunique=True, echo=lambda s: None, fmi=fmi,
                                kind="both")
    assert res.status == "built", res.messages
    assert validate_fmu(str(res.fmu)) == []
    md = fmpy.read_model_description(str(res.fmu))
    motor = [v for v in md.modelVariables if v.name == "motor"][0]
    assert (motor.causality, motor.variability, float(motor.start)) == ("input", "continuous", 0.0)
    deps = {u.variable.name: u.dependencies for u in md.outputs}  # ModelStructure (None: depends on every known)
    assert motor not in (deps["hinge1.angle"] or [None]) and motor not in (deps["door.x"] or [None])
    assert deps["hinge1.angle"] is not None and deps["hinge1.Fx"] is None and deps["hinge1.friction"] is None
    table = _table(tmp_path, [(0.0, 5.0), (0.1, 5.0), (0.1 + 1e-9, -4.0), (0.3, -4.0)])
    ours = _simulate(DOOR_MOTOR, table, tmp_path / "ours.csv", "--stop-time", "0.3")
    outs = ["door.x", "door.y", "door.z", "hinge1.angle", "hinge1.rate", "hinge1.friction"]
    theirs = fmpy.simulate_fmu(str(res.fmu), stop_time=0.3, output_interval=0.01, output=outs,
                               input=read_input_table(table, ["motor"]).structured())
    assert len(theirs) == len(ours["time"])
    for n in ("door.x", "door.y", "door.z"):
        assert np.max(np.abs(theirs[n] - ours[n])) <= 1e-10
    for n in ("hinge1.angle", "hinge1.rate", "hinge1.friction"):
        assert np.max(np.abs(theirs[n] - ours[n])) <= 1e-9 * max(1.0, np.max(np.abs(ours[n])))
    free = run(compile_checked(scene.load(DOOR_MOTOR)), scene.load(DOOR_MOTOR).solver, stop_time=0.3)
    assert np.max(np.abs(free.column("hinge1.angle") - ours["hinge1.angle"])) > 1e-3  # the input does act


def _master_with_derivatives(fmu_path: str, table, stop: float, h: float, names) -> dict:
    """fmpy's co-simulation loop with set_input_derivatives=True, written out: fmpy 0.3.32's own
    (simulate_fmu) sizes its derivative buffer for exactly 9 inputs (simulation.py: ``value_type *
    9``) and fails on any other count. At each communication point t_n: fmi2SetReal(u(t_n)),
    fmi2SetRealInputDerivatives(order 1, fmpy's slope there: InputTable.step), fmi2DoStep."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(fmu_path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu_path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="master")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setReal([vr["motor"]], [table.at(0.0)["motor"]])
    fmu.exitInitializationMode()
    out = {n: [fmu.getReal([vr[n]])[0]] for n in names}
    n_steps = int(round(stop / h))
    for k in range(n_steps):
        t = k * h
        value, slope = table.step(t, "linear")
        fmu.setReal([vr["motor"]], [value["motor"]])
        fmu.setRealInputDerivatives([vr["motor"]], [1], [slope["motor"]])
        fmu.doStep(currentCommunicationPoint=t, communicationStepSize=(k + 1) * h - t)
        for n in names:
            out[n].append(fmu.getReal([vr[n]])[0])
    fmu.terminate()
    fmu.freeInstance()
    return {n: np.array(v) for n, v in out.items()}


@pytest.mark.integration
def test_input_derivatives_in_fmpy_equal_simulate_linear(tmp_path):
    """A ramp input (one straight segment across the run): the FMU with the input's first
    derivative set at every communication point (FMI 2.0 co-simulation, fmi2SetRealInputDerivatives,
    fmpy's slope rule) equals simulate --input-interpolation linear to 1e-10 m, and differs from the
    held run."""
    pytest.importorskip("fmpy")
    from overcon.fmu import build as fmu_build

    res = fmu_build.build_scene(DOOR_MOTOR, tmp_path / "out", allow_nonunique=True, echo=lambda s: None)
    assert res.status == "built", res.messages
    path = _table(tmp_path, [(-0.1, -2.0), (0.4, 18.0)])
    ours = _simulate(DOOR_MOTOR, path, tmp_path / "lin.csv", "--stop-time", "0.3", "--input-interpolation", "linear")
    held = _simulate(DOOR_MOTOR, path, tmp_path / "hold.csv", "--stop-time", "0.3")
    theirs = _master_with_derivatives(str(res.fmu), read_input_table(path, ["motor"]), 0.3, 0.01,
                                      ["door.x", "door.y", "door.z"])
    assert len(theirs["door.x"]) == len(ours["time"])
    for n in ("door.x", "door.y", "door.z"):
        assert np.max(np.abs(theirs[n] - ours[n])) <= 1e-10
    assert np.max(np.abs(held["door.y"] - ours["door.y"])) > 1e-7


@pytest.mark.integration
def test_model_exchange_derivatives_see_the_inputs_and_the_state_keeps_them(tmp_path):
    """FMI 2.0 Model Exchange: the door's derivatives with motor = 7.5 differ from those without by
    tau / I_axis about the axis; a saved and restored FMU state keeps the input value."""
    pytest.importorskip("fmpy")
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Model, fmi2Real

    from overcon.fmu import build as fmu_build

    res = fmu_build.build_scene(DOOR_MOTOR, tmp_path / "out", allow_nonunique=True, echo=lambda s: None, kind="both")
    md = read_model_description(str(res.fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Model(guid=md.guid, unzipDirectory=extract(str(res.fmu)), modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="me")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.enterContinuousTimeMode()
    nx = md.numberOfContinuousStates

    def derivatives():
        dx = (fmi2Real * nx)()
        fmu.getDerivatives(dx, nx)
        return np.array(dx)

    d0 = derivatives()
    fmu.setReal([vr["motor"]], [7.5])
    d1 = derivatives()
    state = fmu.getFMUstate()
    fmu.setReal([vr["motor"]], [0.0])
    fmu.setFMUstate(state)
    assert fmu.getReal([vr["motor"]]) == [7.5]
    d2 = derivatives()
    fmu.freeFMUstate(state)
    fmu.terminate()
    fmu.freeInstance()
    a = np.array([np.sin(0.1), 0.0, np.cos(0.1)])
    n = 7  # q: x, y, z, e0..e3; then h: v, omega (body axes)
    # friction in hinge1 (regularised, slipping at 1 rad/s) changes with the input's reaction: within 1e-3
    assert (d1 - d0)[n + 3: n + 6] @ a == pytest.approx(7.5 / _axis_inertia(), rel=1e-3)
    assert np.array_equal(d1, d2)


@pytest.mark.parametrize("inputs, accel", [
    ('[[inputs]]\nname = "push"\ntype = "joint_force"\njoint = "guide"\nstart = 10.0\n', (40.0 + 10.0) / 5.0),
    ('[[inputs]]\nname = "push"\ntype = "force"\nbody = "carriage"\npoint = [0.1, 0.2, 0.0]\n'
     'direction = [3.0, 4.0, 0.0]\nframe = "body"\nstart = 10.0\n', (40.0 + 6.0) / 5.0),
    ('[[inputs]]\nname = "twist"\ntype = "torque"\nbody = "carriage"\ndirection = [0, 0, 1]\nstart = 10.0\n', 8.0),
])
def test_force_inputs_on_the_carriage_accelerate_it_along_its_guide(tmp_path, inputs, accel):
    """The carriage (5 kg, 40 N along its prismatic guide x, frictionless): a joint_force of 10 N
    along the guide adds 10 N, a force of 10 N along the unit [0.6, 0.8, 0] of the body adds 6 N
    along x (the guides take the rest), a torque adds nothing along x: x'' at t = 0 to 1e-12."""
    import shutil
    shutil.copy(ROOT / "mechanisms" / "examples" / "carriage.toml", tmp_path / "carriage.toml")
    path = tmp_path / "c.toml"
    path.write_text('[scene]\nname = "c"\nmechanism = "carriage.toml"\nfriction = []\neliminate = ["rod"]\n'
                    f'stop_time = 1.0\n\n{inputs}\n[outputs]\npositions = ["carriage.x"]\nreactions = []\n')
    spec = scene.load(path)
    model = compile_checked(spec)
    kern, _ = kernel_mod.select(model, spec.solver)
    ydot = kern.evaluate(0.0, np.concatenate([model.q0, model.h0]))[0]
    assert ydot[model.n] == pytest.approx(accel, abs=1e-12)


def test_inputs_changing_at_output_points_keep_the_energy_balance_and_equal_ones_cost_nothing(tmp_path):
    """A torque table that changes at every output point (the run taken back to each one, its steps
    spanning them otherwise): kinetic + potential - applied stays constant to 1e-8 J; a table equal
    to the start value everywhere gives the run without a table, bit for bit and step for step."""
    spec = scene.load(_door_scene(tmp_path, stop=1.0))
    model = compile_checked(spec)
    rows = [(k * 0.01, 3.0 + 2.0 * float(np.sin(7.0 * k * 0.01))) for k in range(101)]
    res = run(model, spec.solver, inputs=read_input_table(_table(tmp_path, rows), ["motor"]))
    col = res.column
    total = col("energy.kinetic") + col("energy.potential") - col("energy.applied")
    assert np.max(np.abs(total - total[0])) <= 1e-8
    flat = run(model, spec.solver, inputs=read_input_table(_table(tmp_path, [(0.0, 3.0), (1.0, 3.0)]), ["motor"]))
    free = run(model, spec.solver)
    assert np.array_equal(flat.values, free.values) and flat.steps == free.steps
    assert res.steps > free.steps  # the changes cost steps
