"""Messages and refusals a first user met on main: an --input table never overwritten by a
command's outputs; build's summary and refusal on a driven scene in check's words; regress's
regenerate hints with DIR first and no baseline for an output without a tolerance; the list of
drivable joint types; plain numbers in input-table messages; no empty legend in sweep.png."""
from __future__ import annotations

import shutil
import warnings
from pathlib import Path
from types import SimpleNamespace

import pytest

from overcon.cli import main

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "mechanisms" / "examples"


# ------------------------------------------------------------------ 1. inputs never overwritten

def _motor_door(tmp_path: Path) -> tuple[Path, Path]:
    """The coupling example's plant (a door with a motor input) and an input table for it."""
    for f in ("door.toml", "motor_door.toml"):
        shutil.copy(EX / f, tmp_path / f)
    scene = tmp_path / "motor_door.toml"
    assert scene.is_file()
    table = tmp_path / "m2.csv"
    table.write_text("time,motor\n0,0\n0.1,1\n")
    return scene, table


@pytest.mark.parametrize("option", ["--out", "--events"])
def test_simulate_refuses_to_write_over_its_input_table(tmp_path, capsys, option):
    scene, table = _motor_door(tmp_path)
    before = table.read_bytes()
    other = "--events" if option == "--out" else "--out"
    code = main(["simulate", str(scene), "--input", str(table), option, str(table),
                 other, str(tmp_path / "other.csv")])
    err = capsys.readouterr().err
    assert code == 2
    assert f"{option} {table}: is the input --input {table}" in err and "overwritten" in err
    assert table.read_bytes() == before
    assert not (tmp_path / "other.csv").exists()  # refused before any work


def test_input_table_inside_the_output_directory_is_refused():
    from overcon.outfiles import check_input_outside

    out = ROOT / "tests"
    inside = Path(__file__)
    why = check_input_outside("--out", out, "--input", inside)
    assert why is not None and why.startswith(f"--input {inside}: is inside the output directory --out {out}")
    assert check_input_outside("--out", out / "sub", "--input", inside) is None
    assert check_input_outside("--out", ROOT / "tests", "--input", None) is None


@pytest.mark.parametrize("command", ["run", "compare", "sweep"])
def test_run_compare_sweep_refuse_an_input_table_in_their_out_dir(tmp_path, capsys, command):
    out = tmp_path / "res"
    out.mkdir()
    table = out / "Door.csv"
    table.write_text("time,motor\n0,0\n")
    before = table.read_bytes()
    args = [command, str(tmp_path / "missing.fmu"), "--input", str(table), "--out", str(out)]
    if command == "sweep":
        args = ["sweep", str(tmp_path / "missing.fmu"), "--param", "m=1,2", "--input", str(table), "--out", str(out)]
    code = main(args)
    cap = capsys.readouterr()
    assert code == 2
    assert f"--input {table}: is inside the output directory --out {out}" in cap.err + cap.out
    assert table.read_bytes() == before


# ------------------------------------------------------------------ 2. build on a driven scene

def _driven_door(tmp_path: Path) -> Path:
    """The door on two coaxial hinges driven at constant speed on hinge1, friction in hinge1
    (whose reaction is not unique), hinge2 eliminated (as tests/test_drivers.py)."""
    shutil.copy(EX / "door.toml", tmp_path / "door.toml")
    path = tmp_path / "driven.toml"
    path.write_text('[scene]\nname = "driven"\nmechanism = "door.toml"\nfriction = ["hinge1"]\n'
                    'eliminate = ["hinge2"]\nstop_time = 0.5\n\n[[drivers]]\nname = "motor"\njoint = "hinge1"\n'
                    'motion = "constant_speed"\nspeed = 1.0\n\n[outputs]\nreactions = ["hinge1"]\n\n'
                    '[solver]\noutput_interval = 0.01\n')
    return path


def test_build_summary_and_refusal_of_a_driven_scene_say_what_check_says(tmp_path, capsys):
    path = _driven_door(tmp_path)
    main(["check", str(path)])
    check = capsys.readouterr().out
    assert "driver motor: effort NOT UNIQUE" in check
    code = main(["build", str(path), "--out", str(tmp_path / "fmus"), "--no-ref"])
    out = capsys.readouterr()
    text = out.out + out.err
    assert code != 0 and not list((tmp_path / "fmus").glob("*.fmu"))
    assert ("pre-check: friction in hinge1: reaction of hinge1 NOT unique, motion prescribed by the drivers "
            "(unique), effort NOT UNIQUE (driver motor)") in text
    assert "motion UNIQUE" not in text and "reactions unique" not in text
    assert ("refused: friction on a joint whose reaction is not unique (hinge1); the motion is prescribed by the "
            "drivers, but the effort of driver motor would depend on the eliminated equations") in text
    assert "simulated motion would depend" not in text


# ------------------------------------------------------------------ 3, 4. regress

def test_regenerate_hint_puts_dir_before_scenes(tmp_path):
    from overcon.tooling import regress

    cmd = regress.regenerate_command(["pend_drive"], tmp_path / "reg", tmp_path / "bl")
    assert cmd == f"overcon regress {tmp_path / 'reg'} --regenerate --baselines {tmp_path / 'bl'} --scenes pend_drive"
    cmd = regress.regenerate_command(["a", "b"], regress.DEFAULT_MECHANISMS, regress.DEFAULT_BASELINES)
    assert cmd == "overcon regress --regenerate --scenes a b"
    cmd = regress.regenerate_command(["a"], tmp_path / "reg", regress.DEFAULT_BASELINES, tmp_path / "tol.toml")
    assert cmd == f"overcon regress {tmp_path / 'reg'} --regenerate --tolerances {tmp_path / 'tol.toml'} --scenes a"
    cmd = regress.regenerate_command(["a"], regress.DEFAULT_MECHANISMS, regress.DEFAULT_BASELINES,
                                     regress.PACKAGED_TOLERANCES)
    assert cmd == "overcon regress --regenerate --scenes a"


def test_no_tolerance_points_at_a_users_table_never_the_packaged_file():
    from overcon.tooling import regress

    table = regress.load_tolerances(regress.PACKAGED_TOLERANCES)
    with pytest.raises(regress.BadInput) as exc:
        table.lookup("same_platform", "door_e", "energy.kinetic", "J")
    msg = str(exc.value)
    assert "scene door_e: no tolerance for output energy.kinetic (unit 'J')" in msg
    assert "the packaged tolerance table" in msg and "give a tolerance for it with --tolerances FILE" in msg
    assert str(regress.PACKAGED_TOLERANCES) not in msg


@pytest.mark.integration
def test_regenerate_refuses_an_output_without_a_tolerance(tmp_path):
    """A scene with energy outputs (unit J, in no tolerance table): no baseline, exit 2, the
    message names the scene, the output and the unit and says --tolerances FILE."""
    from overcon.tooling import regress

    pytest.importorskip("fmpy")
    mdir = tmp_path / "mech"
    mdir.mkdir()
    shutil.copy(ROOT / "mechanisms" / "planar_sliders.toml", mdir)
    text = (ROOT / "mechanisms" / "planar_none_wo4.toml").read_text()
    text = text.replace('name = "planar_none_wo4"', 'name = "sliders_e"').replace("stop_time = 4.0", "stop_time = 0.1")
    text = text.replace('reactions = "all"\n', 'reactions = "all"\nenergy = true\n')
    (mdir / "sliders_e.toml").write_text(text)
    bl = tmp_path / "bl"
    lines: list[str] = []
    out = regress.regenerate(mechanisms=mdir, baselines=bl, out=tmp_path / "out", echo=lines.append,
                             tolerances=regress.PACKAGED_TOLERANCES)
    text = "\n".join(lines)
    assert out.code == regress.EXIT_INPUT, text
    assert "sliders_e: baseline NOT written: scene sliders_e: no tolerance for output energy.kinetic (unit 'J')" in text
    assert "--tolerances FILE" in text
    assert not (bl / "sliders_e_ref.csv").exists()


# ------------------------------------------------------------------ 5. drivers

def test_driver_on_a_spherical_joint_lists_the_drivable_types(tmp_path, capsys):
    shutil.copy(ROOT / "mechanisms" / "spatial_parallelogram.toml", tmp_path)
    text = (ROOT / "mechanisms" / "spatial_none_wo5.toml").read_text()
    path = tmp_path / "s.toml"
    path.write_text(text.replace("[outputs]", '[[drivers]]\nname = "d"\njoint = "A"\nmotion = "constant_speed"\n'
                                              'speed = 1.0\n\n[outputs]'))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "joint 'A' is a spatial spherical joint, which a driver cannot drive" in err, err
    assert ("drivable joints: revolute (planar or spatial) and cylindrical by their angle, translational "
            "(planar), prismatic and cylindrical by their displacement") in err
    assert "displacement is that of" not in err


# ------------------------------------------------------------------ 6. input table numbers

def test_repeated_time_is_reported_with_plain_numbers(tmp_path):
    from overcon.tooling.inputs import InputError, read_input_table

    p = tmp_path / "in.csv"
    p.write_text("time,u\n0,1\n0,2\n")
    with pytest.raises(InputError) as exc:
        read_input_table(p, ["u"])
    assert "time 0.0 does not increase (previous row 2: 0.0)" in str(exc.value)
    assert "np." not in str(exc.value)


# ------------------------------------------------------------------ 8. sweep plot

def test_sweep_plot_without_measures_draws_no_empty_legend(tmp_path):
    pytest.importorskip("matplotlib")
    from overcon.tooling.sweep.plots import plot

    sw = SimpleNamespace(definition={"params": ["m=1,2"], "samples": None}, groups={"g": None},
                         lockstep_step=None, out_dir=tmp_path)
    rows = [{"group": "g", "key": f"g m={m}", "m": str(m), "max_diff [m]": ""} for m in (1, 2)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        png = plot(sw, rows)
    assert png.is_file() and png.stat().st_size > 0
