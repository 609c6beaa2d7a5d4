"""``overcon run/compare/sweep --input``: the table reaches the FMU's inputs through fmpy's
``input=`` at every communication point with the documented semantics, an input's start value is
set like a parameter, and a bad table or a bad combination is bad input (exit 2, named).

The FMU with inputs here is the coupling example's PI controller (pythonfmu, built into tmp): its
output is a known function of its inputs, so the values the host applied can be read back.
The overcon door with a motor input is exercised in tests/test_coupling_system.py."""
from __future__ import annotations

import numpy as np
import pytest

from overcon.cli import main
from overcon.tooling.inputs import InputTable, read_input_table
from overcon.tooling.run import read_series

pytestmark = pytest.mark.integration

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

KP, KI, KD, SETPOINT = 2000.0, 8000.0, 150.0, 0.5  # the controller's defaults (controller.py)
TABLE = "time,angle,rate\n0,0.1,0\n0.025,0.2,1\n0.05,0.0,-2\n"  # rows off the 10 ms grid


@pytest.fixture(scope="module")
def controller(tmp_path_factory):
    from overcon.tooling.cosim import build_controller

    return build_controller(tmp_path_factory.mktemp("ctl"))


def expected_torque(table: InputTable, times: np.ndarray) -> np.ndarray:
    """The controller's output at ``times`` (a uniform grid) when the host sets the inputs to
    the table's u(t_n) at every communication point t_n and holds them (controller.py's law: the
    output after the step from t_n uses the inputs read at t_n)."""
    h = times[1] - times[0]
    u = [table.at(t) for t in times]
    out, integral = [], 0.0
    for n in range(len(times)):
        if n == 0:
            a, r = u[0]["angle"], u[0]["rate"]
        else:
            a, r = u[n - 1]["angle"], u[n - 1]["rate"]
            integral += (SETPOINT - a) * h
        out.append(KP * (SETPOINT - a) + KI * integral - KD * r)
    return np.array(out)


def test_run_applies_the_table_at_every_communication_point(controller, tmp_path):
    (tmp_path / "in.csv").write_text(TABLE)
    code = main(["run", str(controller), "--input", str(tmp_path / "in.csv"), "--step", "0.01", "--stop-time",
                 "0.08", "--out", str(tmp_path / "res")])
    assert code == 0
    s = read_series(tmp_path / "res" / "DoorController.csv")
    table = read_input_table(tmp_path / "in.csv", ["angle", "rate"])
    want = expected_torque(table, s.time)
    assert np.max(np.abs(s.values["torque"] - want)) <= 1e-12 * np.max(np.abs(want))
    # the interpolated values matter: reading the rows as a staircase would give other torques
    stair = InputTable(table.time, {n: v for n, v in table.values.items()})
    stair_at = lambda t: {n: float(v[np.searchsorted(table.time, t, side="right") - 1])  # noqa: E731
                          for n, v in stair.values.items()}
    object.__setattr__(stair, "at", stair_at)
    assert np.max(np.abs(expected_torque(stair, s.time) - want)) > 1.0


def test_compare_with_a_reference_runs_the_fmu_with_the_table(controller, tmp_path):
    (tmp_path / "in.csv").write_text(TABLE)
    t = np.round(np.arange(9) * 0.01, 12)
    want = expected_torque(read_input_table(tmp_path / "in.csv", ["angle", "rate"]), t)
    ref = tmp_path / "ref.csv"
    ref.write_text('"time","torque"\n' + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(t, want)))
    base = ["compare", str(controller), "--ref", str(ref), "--tolerance", "1e-9"]
    assert main(base + ["--input", str(tmp_path / "in.csv"), "--out", str(tmp_path / "c1")]) == 0
    assert main(base + ["--out", str(tmp_path / "c2")]) == 1  # inputs at their start values: another torque


def test_set_gives_an_input_its_start_value(controller, tmp_path):
    assert main(["run", str(controller), "--set", "angle=0.3", "--step", "0.01", "--stop-time", "0.02",
                 "--out", str(tmp_path / "r")]) == 0
    s = read_series(tmp_path / "r" / "DoorController.csv")
    assert s.values["torque"][0] == KP * (SETPOINT - 0.3)


@pytest.mark.parametrize("table, args, message", [
    ("time,angle\n0,0.1\n", [], ["in.csv", "no column", "rate"]),
    ("time,angle,rate,brake\n0,0.1,0,1\n", [], ["in.csv", "'brake'", "not an input"]),
    ("time,angle,rate\n0,0.1,0\n0.01,nan,0\n", [], ["in.csv", "'angle'", "row 3", "non-finite"]),
    ("time,angle,rate\n0,0.1,0\n0,0.2,0\n", [], ["in.csv", "'time'", "row 3"]),
    (TABLE, ["--set", "angle=0.3"], ["angle", "start value", "in.csv"]),
    (TABLE, ["--input-interpolation", "linear"], ["canInterpolateInputs", "hold"]),
    (None, ["--input-interpolation", "linear"], ["without an --input table"]),
    (None, ["--set", "angle=nan"], ["angle", "finite"]),
])
def test_bad_input_exits_2_naming_what(controller, tmp_path, capsys, table, args, message):
    extra = []
    if table is not None:
        (tmp_path / "in.csv").write_text(table)
        extra = ["--input", str(tmp_path / "in.csv")]
    ref = tmp_path / "ref.csv"
    ref.write_text('"time","torque"\n0.0,0.0\n0.01,0.0\n0.02,0.0\n')
    commands = [["run", str(controller), "--out", str(tmp_path / "r")]]
    if "--set" not in args:  # compare --ref takes no --set
        commands.append(["compare", str(controller), "--ref", str(ref), "--out", str(tmp_path / "c")])
    for cmd in commands:
        assert main(cmd + extra + args) == 2
        err = capsys.readouterr().err
        for m in message:
            assert m in err, err
    assert not (tmp_path / "r").exists() and not (tmp_path / "c").exists()  # refused before any run


# ---------------------------------------------------------------------------------------------
# an overcon FMU with an input: the coupling example's door (motor on hinge1)

RAMP = "time,motor\n-0.1,-1.0\n0.1,1.0\n0.2,3.0\n0.3,3.0\n"  # rows on the 0.01 s grid (and one before it)


@pytest.fixture(scope="module")
def door(tmp_path_factory):
    from overcon.tooling.cosim import build_door

    return build_door(tmp_path_factory.mktemp("door"))


@pytest.fixture(scope="module")
def door3(tmp_path_factory):
    from overcon.tooling.cosim import build_door

    return build_door(tmp_path_factory.mktemp("door3"), fmi=3)


@pytest.mark.parametrize("fmi, interpolation", [(2, "hold"), (2, "linear"), (3, "hold")])
def test_run_input_equals_simulate_input(request, tmp_path, fmi, interpolation):
    """``overcon run FMU --input T`` (fmpy's input=, with set_input_derivatives for linear) gives
    the positions of ``overcon simulate SCENE --input T`` in process, to 1e-10 m, FMI 2.0 and 3.0
    (FMI 3.0 takes no input derivatives from fmpy: refused, exit 2)."""
    from overcon.tooling.cosim import EXAMPLE

    door = request.getfixturevalue("door" if fmi == 2 else "door3")
    if fmi == 3:
        (tmp_path / "t.csv").write_text(RAMP)
        assert main(["run", str(door), "--input", str(tmp_path / "t.csv"), "--input-interpolation", "linear",
                     "--out", str(tmp_path / "no")]) == 2
    table = tmp_path / "ramp.csv"
    table.write_text(RAMP)
    flags = ["--input", str(table), "--input-interpolation", interpolation]
    assert main(["run", str(door), "--stop-time", "0.3", "--out", str(tmp_path / "r"), *flags]) == 0
    assert main(["simulate", str(EXAMPLE / "door_motor.toml"), "--stop-time", "0.3", "--out",
                 str(tmp_path / "sim.csv"), *flags]) == 0
    fmu = read_series(tmp_path / "r" / "coupled_door.csv")
    sim = read_series(tmp_path / "sim.csv")
    assert np.allclose(fmu.time, sim.time, rtol=0, atol=1e-12) and len(fmu.time) == 31
    for name in ("door.x", "door.y", "door.z"):
        assert np.max(np.abs(fmu.values[name] - sim.values[name])) <= 1e-10, name
    # the input did act: without it the door moves otherwise
    assert main(["run", str(door), "--stop-time", "0.3", "--out", str(tmp_path / "free")]) == 0
    free = read_series(tmp_path / "free" / "coupled_door.csv")
    assert np.max(np.abs(free.values["door.x"] - fmu.values["door.x"])) > 1e-6


def test_sweep_varies_an_input_start_and_passes_a_table(door, tmp_path):
    """``sweep --param motor=...`` sets the input's start value per set (a constant torque): the
    runs differ; with ``--input`` every run gets the table; a swept input that the table also
    sets is bad input."""
    import dataclasses

    from overcon.tooling import InputError, sweep
    from overcon.tooling.sweep.worker import run_task

    quiet = dict(echo=lambda s: None)
    # adaptive runs (--lockstep-step 0): the door FMU refuses rk4 (the lockstep method) with inputs
    sw = sweep.prepare(tmp_path / "s1", inputs=[str(door)], params=["motor=0,20"], stop_time=0.1, lockstep_step=0,
                       **quiet)
    f = sw.fmus[0]
    finals = []
    for _, values in sw.sets:
        ex = sweep._experiment(sw, f, values)
        assert dict(ex.start_values)["motor"] == values["motor"] and ex.input_table is None
        res = run_task(f.data, f.sha, f.info, ex)
        assert res["status"] == "ok", res["status"]
        finals.append(res["values"]["door.x"][-1])
    assert abs(finals[1] - finals[0]) > 1e-5
    table = tmp_path / "in.csv"
    table.write_text("time,motor\n0,20\n")  # the same constant torque, from a table
    sw2 = sweep.prepare(tmp_path / "s2", inputs=[str(door)], params=["solver.tolerance=1e-9"], stop_time=0.1,
                        input_table=str(table), lockstep_step=0, **quiet)
    ex = sweep._experiment(sw2, sw2.fmus[0], sw2.sets[0][1])
    assert ex.input_table is not None and ex.input_table.names == ["motor"]
    # the table's constant 20 N·m and the start value 20 N·m: one run
    ex_start = dataclasses.replace(sweep._experiment(sw, f, {"motor": 20.0, "solver.tolerance": 1e-9}), stop=ex.stop)
    a = run_task(f.data, f.sha, f.info, ex)
    b = run_task(f.data, f.sha, f.info, ex_start)
    assert a["status"] == b["status"] == "ok"
    assert np.array_equal(a["values"]["door.x"], b["values"]["door.x"])
    assert sweep.prepare(tmp_path / "s2", resume=True, **quiet).experiments[f.info.model].input_table is not None
    table.write_text("time,motor\n0,21\n")
    with pytest.raises(InputError, match="changed since the sweep started"):
        sweep.prepare(tmp_path / "s2", resume=True, **quiet)
    with pytest.raises(InputError, match="motor"):
        sweep.prepare(tmp_path / "s3", inputs=[str(door)], params=["motor=0,20"], input_table=str(table),
                      lockstep_step=0, **quiet)


def test_compare_a_group_with_inputs(tmp_path, capsys):
    """``compare --input`` on two eliminations of the door with the motor: both runs get the table
    (the motion differs from the run without it), the group is decided from the adaptive runs (the
    FMUs refuse rk4, the lockstep method, with inputs: said, not failed)."""
    from overcon.fmu.build import build_all
    from overcon.tooling.cosim import EXAMPLE

    src = (EXAMPLE / "door_motor.toml").read_text()
    (tmp_path / "door.toml").write_text((EXAMPLE.parent / "door.toml").read_text())
    other = src.replace('mechanism = "../door.toml"', 'mechanism = "door.toml"')
    (tmp_path / "a.toml").write_text(other)
    (tmp_path / "b.toml").write_text(other.replace('name = "coupled_door"', 'name = "coupled_door_b"')
                                     .replace('eliminate = ["hinge2"]', "eliminate = [3, 4, 5, 9, 10]"))
    code, res = build_all([tmp_path / "a.toml", tmp_path / "b.toml"], tmp_path / "fmus", allow_nonunique=True,
                          refs=False, validate=False, kind="cs", echo=lambda s: None, echo_err=lambda s: None)
    assert code == 0, [m for r in res for m in r.messages]
    table = tmp_path / "in.csv"
    table.write_text("time,motor\n0,30\n0.3,30\n")
    args = ["compare", *(str(r.fmu) for r in res), "--stop-time", "0.3"]
    code = main(args + ["--input", str(table), "--out", str(tmp_path / "c")])
    out = capsys.readouterr().out
    assert code == 0, out  # the friction motion differs between the eliminations, as the pre-check predicts
    assert "refuse rk4" in out and "observed NOT UNIQUE, predicted not unique" in out
    with_input = read_series(tmp_path / "c" / "coupled_door.csv")
    assert main(args + ["--out", str(tmp_path / "c0")]) == 0
    without = read_series(tmp_path / "c0" / "coupled_door.csv")
    assert np.max(np.abs(with_input.values["door.x"] - without.values["door.x"])) > 1e-4


def test_sweep_of_fmus_with_inputs_needs_adaptive_runs(door, tmp_path, capsys):
    assert main(["sweep", str(door), "--param", "motor=0,5", "--out", str(tmp_path / "s")]) == 2
    assert "--lockstep-step 0" in capsys.readouterr().err
