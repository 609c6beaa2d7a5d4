"""The pre-check from one factorisation (``check --methods svd``) against the three tests
(``--methods all``): the same verdicts on every mechanism of the repository and on generated
parallelogram linkages, and a size beyond the three tests' reach."""
from __future__ import annotations

from pathlib import Path

import pytest

from overcon import scene
from overcon.checks import compile_checked
from overcon.cli import main
from overcon.precheck import AUTO_ALL_JOINTS, precheck

MECH = Path(__file__).resolve().parents[1] / "mechanisms"
FILES = sorted(MECH.glob("*.toml")) + sorted((MECH / "examples").glob("*.toml"))


def parallelogram(k: int, path: Path) -> Path:
    """A planar coupler (length k - 1 m, along x at y = 1 m) carried by k parallel cranks of 1 m
    from (i, 0) to (i, 1), i = 0..k-1, each with a revolute joint to the ground and one to the
    coupler: 3(k + 1) coordinates, 4k equations, rank 3k + 2 (1 DOF), k - 2 redundant."""
    lines = ['[mechanism]', f'name = "parallelogram{k}"', 'kind = "planar"', 'gravity = [0.0, -9.81]',
             '[[bodies]]', 'name = "coupler"', f'mass = {k - 1.0}', 'inertia = 1.0', f'q0 = [{(k - 1) / 2}, 1.0, 0.0]']
    for i in range(k):
        lines += ['[[bodies]]', f'name = "crank{i}"', 'mass = 1.0', 'inertia = 0.0833', f'q0 = [{i}.0, 0.5, 1.5707963267948966]']
    for i in range(k):
        lines += ['[[joints]]', f'name = "G{i}"', 'type = "revolute"', f'body_i = "crank{i}"', 'body_j = "base"',
                  's_i = [-0.5, 0.0]', f's_j = [{i}.0, 0.0]',
                  '[[joints]]', f'name = "C{i}"', 'type = "revolute"', f'body_i = "crank{i}"', 'body_j = "coupler"',
                  's_i = [0.5, 0.0]', f's_j = [{i - (k - 1) / 2}, 0.0]']
    path.write_text("\n".join(lines) + "\n")
    return path


def _model(path: Path):
    return compile_checked(scene.as_scene(scene.load(path)))


def _verdicts(report):
    return [(j.name, j.unique, j.rank_defect) for j in report.joints], report.motion_unique


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_one_factorisation_agrees_with_the_three_tests_on_every_repository_mechanism(path):
    model = _model(path)
    one, three = precheck(model, str(path), "svd"), precheck(model, str(path), "all")
    assert one.methods_run == ("svd",) and three.methods_run == ("rank", "svd", "qr") and three.methods_agree
    assert _verdicts(one) == _verdicts(three)


@pytest.mark.parametrize("k", [3, 12, 30])
def test_one_factorisation_agrees_on_generated_parallelograms(tmp_path, k):
    model = _model(parallelogram(k, tmp_path / "p.toml"))
    one, three = precheck(model, "", "svd"), precheck(model, "", "all")
    assert (one.rank, one.dof, one.redundant) == (3 * k + 2, 1, k - 2)
    assert _verdicts(one) == _verdicts(three) and three.methods_agree


def test_beyond_the_three_tests_auto_runs_the_one_factorisation(tmp_path, capsys):
    """300 joints (the former limit was 200): ``check`` answers with the one-factorisation test,
    which ``methods_run`` says; up to AUTO_ALL_JOINTS joints it runs all three."""
    import json
    k = 150
    assert 2 * k > AUTO_ALL_JOINTS
    path = parallelogram(k, tmp_path / "big.toml")
    assert main(["check", str(path), "--json", "--friction", "none"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["methods_run"] == ["svd"] and (report["rank"], report["dof"]) == (3 * k + 2, 1)
    assert all(set(j["methods"]) == {"svd"} for j in report["joints"])
    small = parallelogram(3, tmp_path / "small.toml")
    assert main(["check", str(small), "--json", "--friction", "none"]) == 0
    assert json.loads(capsys.readouterr().out)["methods_run"] == ["rank", "svd", "qr"]
