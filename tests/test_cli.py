"""`overcon check` / `overcon simulate`: JSON contract, exit codes, clear errors."""
from __future__ import annotations

import contextlib
import csv
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from overcon.cli import main

MECH = Path(__file__).resolve().parent.parent / "mechanisms"


def check_json(capsys, *args):
    code = main(["check", *map(str, args), "--json"])
    return code, json.loads(capsys.readouterr().out)


def verdicts(report):
    return {j["name"]: (j["unique"], j["methods"]["rank"], j["methods"]["svd"], j["methods"]["qr"])
            for j in report["joints"]}


def test_check_planar_json(capsys):
    code, rep = check_json(capsys, MECH / "planar_sliders.toml")
    assert code == 0
    assert (rep["n_coordinates"], rep["n_equations"], rep["rank"], rep["dof"], rep["redundant"]) == (12, 12, 11, 1, 1)
    v = verdicts(rep)
    for j in ("joint4", "joint5", "joint6"):
        assert v[j] == (True, True, True, True)
    for j in ("joint1", "joint2", "joint3"):
        assert v[j] == (False, False, False, False)
    assert rep["friction_on_nonunique"] == []


def test_check_spatial_json(capsys):
    code, rep = check_json(capsys, MECH / "spatial_parallelogram.toml")
    assert code == 0
    assert (rep["n_coordinates"], rep["n_equations"], rep["rank"], rep["dof"], rep["redundant"]) == (42, 36, 35, 7, 1)
    v = verdicts(rep)
    for j in "KLMN":
        assert v[j] == (True, True, True, True)
    for j in "ABCDEFGH":
        assert v[j] == (False, False, False, False)
    assert rep["methods_agree"]


def test_friction_on_joint1_exits_1_and_names_it(capsys):
    code = main(["check", str(MECH / "planar_f1_wo4.toml")])
    out = capsys.readouterr().out
    assert code == 1
    assert "joint1" in out and "NOT UNIQUE" in out and "friction on joint joint1" in out
    code, rep = check_json(capsys, MECH / "planar_sliders.toml", "--friction", "joint1")
    assert code == 1 and rep["friction_on_nonunique"] == ["joint1"]


def test_friction_flag_override_unique(capsys):
    code, rep = check_json(capsys, MECH / "spatial_parallelogram.toml", "--friction", "M,N", "--eliminate", "9")
    assert code == 0 and rep["friction"] == ["M", "N"] and rep["motion_unique"] and rep["eliminated"] == [9]


@pytest.mark.parametrize("args, needle", [
    (["check", "no/such/file.toml"], "file not found"),
    (["check", str(MECH / "planar_sliders.toml"), "--friction", "joint9"], "--friction"),
    (["check", str(MECH / "planar_sliders.toml"), "--eliminate", "x"], "--eliminate"),
    (["check", str(MECH / "planar_sliders.toml"), "--eliminate", "13"], "--eliminate"),
    (["check", str(MECH / "planar_sliders.toml"), "--eliminate", "7"], "independent equation"),
    (["simulate", str(MECH / "planar_sliders.toml"), "--out", "x.csv", "--tolerance", "-1"], "--tolerance"),
    (["simulate", str(MECH / "planar_sliders.toml"), "--out", "x.csv", "--stop-time", "-1"], "--stop-time"),
    (["check"], "file"),
])
def test_bad_input_exit_2(capsys, args, needle):
    with pytest.raises(SystemExit, match="^2$") if args == ["check"] else contextlib.nullcontext():
        code = main(args)
        assert code == 2
    assert needle in capsys.readouterr().err


@pytest.mark.parametrize("mutation", [
    ("mass = 3.0", "mass = nan"),
    ("mass = 3.0", 'mass = "heavy"'),
    ('body_j = "base"', 'body_j = "nowhere"'),
    ("q0 = [2.0, 0.0, 0.0]", "q0 = [2.0, 0.0]"),
    ("[[bodies]]", "[[bodiez]]"),
    ('kind = "planar"', "kind = 3"),
])
def test_malformed_file_no_traceback(tmp_path, mutation):
    text = (MECH / "planar_sliders.toml").read_text().replace(*mutation, 1)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    proc = subprocess.run([sys.executable, "-m", "overcon.cli", "check", str(path)], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert str(path) in proc.stderr


def test_simulate_writes_csv(tmp_path, capsys):
    out = tmp_path / "wo4.csv"
    code = main(["simulate", str(MECH / "planar_sliders.toml"), "--friction", "none", "--eliminate", "4",
                 "--stop-time", "0.5", "--out", str(out)])
    assert code == 0
    assert "max constraint drift" in capsys.readouterr().out
    rows = list(csv.reader(out.open()))
    header = rows[0]
    assert header[0] == "time" and "slider1.x" in header and "link4.phi" in header
    assert {"joint1.Fx", "joint1.Fy", "joint1.T", "joint6.T"} <= set(header)
    assert len(rows) == 52 and float(rows[-1][0]) == 0.5


def test_simulate_spatial_scene_headers(tmp_path, capsys):
    out = tmp_path / "s.csv"
    assert main(["simulate", str(MECH / "spatial_MN_wo5.toml"), "--stop-time", "0.05", "--out", str(out)]) == 0
    header = next(csv.reader(out.open()))
    assert header[:4] == ["time", "platform.x", "platform.y", "platform.z"]
    assert "G.Fy" in header and "N.Fz" in header and "G.Fy0" in header


@pytest.mark.parametrize("scene", ["planar_f1_wo4.toml", "examples/door_h1_wo_hinge2.toml"])
def test_simulate_warns_about_non_unique_motion_and_exits_0(tmp_path, capsys, scene):
    """The run goes ahead (exit 0, the CSV written), and stderr says what check says: the motion
    is not unique, with the elimination this run uses and the joint at fault."""
    out = tmp_path / "o.csv"
    assert main(["simulate", str(MECH / scene), "--stop-time", "0.05", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert out.is_file()
    assert "overcon: warning: motion with friction in " in err
    assert ": NOT UNIQUE (depends on the elimination): this run shows the motion with Phi" in err
    assert "another elimination can give another motion" in err
    assert "overcon: warning: friction on joint " in err and ", whose reaction is not unique" in err


def test_simulate_is_quiet_about_unique_motion(tmp_path, capsys):
    assert main(["simulate", str(MECH / "planar_f45_wo4.toml"), "--stop-time", "0.05", "--out",
                 str(tmp_path / "o.csv")]) == 0
    assert "warning" not in capsys.readouterr().err


@pytest.mark.parametrize("name, what", [("door.fmu", "an FMU"), ("door.toml", r"a ZIP archive \(an FMU\?\)")])
@pytest.mark.parametrize("command", ["check", "simulate"])
def test_an_fmu_given_to_check_or_simulate_is_named_as_such(tmp_path, capsys, name, what, command):
    import re
    import zipfile
    path = tmp_path / name
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("modelDescription.xml", "<fmiModelDescription/>")
    args = [command, str(path)] + (["--out", str(tmp_path / "o.csv")] if command == "simulate" else [])
    assert main(args) == 2
    err = capsys.readouterr().err
    assert re.search(rf"{re.escape(str(path))}: \(file\): is {what}, not a mechanism or scene file: overcon check, "
                     r"simulate and build take the TOML files an FMU is built from; overcon run simulates an FMU", err)
    assert "UTF-8" not in err and "TOML:" not in err


def test_simulation_failure_exit_3(tmp_path, capsys):
    text = (MECH / "planar_sliders.toml").read_text().replace("free_length = 3.0", "free_length = 0.0")
    path = tmp_path / "l0.toml"
    path.write_text(text)
    code = main(["simulate", str(path), "--eliminate", "4", "--stop-time", "2", "--out", str(tmp_path / "o.csv")])
    assert code == 3
    captured = capsys.readouterr()
    assert "singular position" in captured.err
    rows = list(csv.reader((tmp_path / "o.csv").open()))  # the file is written, the header at least
    assert rows[0][0] == "time" and "evaluations" in captured.out
    assert (f"{tmp_path / 'o.csv'} ends early" in captured.err or "has the header only" in captured.err)


def test_a_run_stopped_by_its_budget_keeps_its_rows_and_prints_its_stats(tmp_path, capsys):
    out = tmp_path / "o.csv"
    assert main(["simulate", str(MECH / "planar_f45_wo4.toml"), "--max-steps", "100", "--out", str(out)]) == 3
    captured = capsys.readouterr()
    rows = list(csv.reader(out.open()))
    times = [float(r[0]) for r in rows[1:]]
    assert len(times) > 10 and times == sorted(times) and times[-1] < 4.0  # every point up to the stop
    assert np.allclose(np.diff(times), 0.01, rtol=0, atol=1e-12)  # the scene's output grid, no gap
    assert f"{out}: {len(times)} rows x " in captured.out and "100 steps, " in captured.out
    assert "work budget exhausted: 100 internal steps" in captured.err
    # every output point the 100 steps reached is in the file, the one inside the last step too
    reached = float(re.search(r"reached t = ([-+0-9.e]+) s", captured.err).group(1))
    assert times[-1] <= reached < times[-1] + 0.01
    assert f"overcon: {out} ends early at t = {times[-1]:.9g} s (its last output point before the stop)" in captured.err


def test_check_json_is_the_typed_precheck_result_in_its_key_order(capsys):
    """``check --json`` is PrecheckResult.to_json(): the keys (and their order) users' scripts
    read, unchanged by the typed result."""
    from overcon import scene
    from overcon.checks import compile_checked
    from overcon.precheck import PrecheckResult, precheck

    code, rep = check_json(capsys, MECH / "planar_f45_wo4.toml")
    assert list(rep) == ["n_coordinates", "n_equations", "rank", "dof", "redundant", "joints", "file", "scene",
                         "kind", "methods_agree", "friction", "friction_on_nonunique", "friction_set_unique",
                         "motion_unique", "eliminated", "elimination_mode", "problems", "warnings", "methods_run", "redundancy",
                         "drivers", "effort_unique"]
    assert list(rep["joints"][0]) == ["name", "unique", "methods", "rank_defect", "agree", "type", "equations"]  # extended, issue 37
    result = precheck(compile_checked(scene.load(MECH / "planar_f45_wo4.toml")), str(MECH / "planar_f45_wo4.toml"))
    assert isinstance(result, PrecheckResult) and result.to_json() == rep
    assert result.motion_unique is rep["motion_unique"] and result.reaction_unique["joint4"] is True


def test_simulate_runs_blas_on_one_thread(tmp_path, monkeypatch):
    """The run's small matrices gain nothing from BLAS threads (docs/benchmarks.md, "BLAS
    threads"): simulate runs inside single_threaded_blas, and the thread count comes back after."""
    from threadpoolctl import threadpool_info

    import overcon.simulate as simulate_mod

    def blas_threads():
        return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}

    seen, real_run = [], simulate_mod.run

    def spy(*args, **kw):
        seen.append(blas_threads())
        return real_run(*args, **kw)

    monkeypatch.setattr(simulate_mod, "run", spy)
    before = blas_threads()
    assert main(["simulate", str(MECH / "planar_sliders.toml"), "--stop-time", "0.05", "--out",
                 str(tmp_path / "o.csv")]) == 0
    assert seen == [{1}] and blas_threads() == before
