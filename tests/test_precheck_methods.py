"""The pre-check from one factorisation (``check --methods svd``) against the three tests
(``--methods all``): the same verdicts on every mechanism of the repository, on generated
parallelogram linkages and on 100 random linkages (chains, trees, trees with loops, parallel
cranks, several linkages on one ground; planar and spatial), and a size beyond the three tests'
reach."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from overcon import scene
from overcon.checks import compile_checked
from overcon.cli import main
from overcon.kinematics import quat_R_rows, rot2_rows
from overcon.precheck import AUTO_ALL_JOINTS, precheck

ROOT = Path(__file__).resolve().parents[1]
MECH = ROOT / "mechanisms"
FILES = (sorted(MECH.glob("*.toml")) + sorted((MECH / "examples").glob("*.toml"))
         + sorted((ROOT / "tests" / "data").glob("*/*.toml")))
SHAPES = ("chain", "tree", "loops", "cranks", "forest")


def _vec(v) -> str:
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def linkage(rng: np.random.Generator, kind: str, shape: str, n: int, path: Path, loops: int = 0) -> Path:
    """A random mechanism of ``n`` moving bodies whose joints all hold at q0 (each joint's points
    are one global point, its axes one global axis, written in each body's frame), so it
    compiles; ``kind`` "planar" (revolute joints) or "spatial" (quaternion coordinates, random
    orientations, spherical and revolute joints). ``shape``:
    "chain"   body k hangs from body k - 1 (body 0 from the ground);
    "tree"    body k hangs from a random earlier body or the ground;
    "loops"   a tree plus ``loops`` joints between random bodies (or a body and the ground);
    "cranks"  a coupler (body 0) on n - 1 parallel cranks of equal length, each pinned to the
              ground and to the coupler (planar: k - 2 redundant equations);
    "forest"  chains on the ground, a loop in the first and in the last: decoupled blocks of J.
    """
    planar = kind == "planar"
    dim = 2 if planar else 3
    r = rng.uniform(-3.0, 3.0, (n, dim))
    if planar:
        ang = rng.uniform(-np.pi, np.pi, n)
        rot = list(rot2_rows(np.asarray(ang, float)))
        q0 = [list(r[k]) + [ang[k]] for k in range(n)]
    else:
        e = rng.standard_normal((n, 4))
        e /= np.linalg.norm(e, axis=1)[:, None]
        rot = list(quat_R_rows(e))
        q0 = [list(r[k]) + list(e[k]) for k in range(n)]
    pairs: list[tuple[int, int]] = []  # (body_i, body_j), -1 = ground
    if shape == "chain":
        pairs = [(k, k - 1) for k in range(n)]
    elif shape in ("tree", "loops"):
        pairs = [(k, int(rng.integers(-1, k))) for k in range(n)]
        for _ in range(loops if shape == "loops" else 0):
            i, j = rng.choice(np.arange(-1, n), 2, replace=False)
            pairs.append((int(max(i, j)), int(min(i, j))))
    elif shape == "cranks":
        step, length = rng.uniform(0.5, 2.0, dim), rng.uniform(0.5, 2.0)
        up = np.zeros(dim)
        up[1] = length
        r[0] = up  # coupler at the cranks' upper ends
        for k in range(1, n):
            r[k] = k * step + up / 2
            q0[k][:dim] = list(r[k])
        q0[0][:dim] = list(r[0])
        pts = {}
        for k in range(1, n):
            pairs += [(k, -1), (k, 0)]
            pts[len(pairs) - 2] = k * step
            pts[len(pairs) - 1] = k * step + up
    elif shape == "forest":
        third = max(2, n // 3)
        for k in range(n):
            pairs.append((k, -1 if k % third == 0 else k - 1))
        pairs += [(n - 1, n - 2), (third - 1, -1)]  # a loop in the last chain and in the first
    else:
        raise ValueError(shape)
    lines = ["[mechanism]", f'name = "{shape}{n}"', f'kind = "{kind}"',
             f"gravity = {_vec([0.0, -9.81] if planar else [0.0, 0.0, -9.81])}"]
    if not planar:
        lines.append('rotation = "quaternion"')
    for k in range(n):
        inertia = "1.0" if planar else "[1.0, 1.0, 1.0]"
        lines += ["[[bodies]]", f'name = "b{k}"', "mass = 1.0", f"inertia = {inertia}", f"q0 = {_vec(q0[k])}"]
    for idx, (i, j) in enumerate(pairs):
        p = pts[idx] if shape == "cranks" else rng.uniform(-3.0, 3.0, dim)
        local = [rot[b].T @ (p - r[b]) if b >= 0 else p for b in (i, j)]
        spherical = not planar and idx % 2 == 0
        lines += ["[[joints]]", f'name = "J{idx}"', f'type = "{"spherical" if spherical else "revolute"}"',
                  f'body_i = "b{i}"', f'body_j = "{"base" if j < 0 else f"b{j}"}"',
                  f"s_i = {_vec(local[0])}", f"s_j = {_vec(local[1])}"]
        if not planar and not spherical:
            a = rng.standard_normal(3)
            a /= np.linalg.norm(a)
            lines += [f"axis_i = {_vec(rot[i].T @ a)}", f"axis_j = {_vec(rot[j].T @ a if j >= 0 else a)}"]
    path.write_text("\n".join(lines) + "\n")
    return path


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


def _model(path: Path, check_initial: bool = True):
    return compile_checked(scene.as_scene(scene.load(path)), check_initial=check_initial)


def _verdicts(report):
    return [(j.name, j.unique, j.rank_defect) for j in report.joints], report.motion_unique


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_one_factorisation_agrees_with_the_three_tests_on_every_repository_mechanism(path):
    model = _model(path, check_initial=False)  # tests/data holds a q0 off its constraints on purpose
    one, three = precheck(model, str(path), "svd"), precheck(model, str(path), "all")
    assert one.methods_run == ("svd",) and three.methods_run == ("rank", "svd", "qr") and three.methods_agree
    assert _verdicts(one) == _verdicts(three)


@pytest.mark.parametrize("k", [3, 12, 30, 60])
def test_one_factorisation_agrees_on_generated_parallelograms(tmp_path, k):
    """From 7 cranks on, the coupler's coordinates are hub rows (analysis._HUB_DEGREE): the block
    of loops is factorised through them, and the verdicts are still the three tests'."""
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


def _random_linkages():
    """100 (kind, shape, bodies, loops, seed): both kinds, every shape, 2..14 bodies."""
    out = []
    for seed in range(100):
        rng = np.random.default_rng(1000 + seed)
        kind = ("planar", "spatial")[seed % 2]
        shape = SHAPES[(seed // 2) % len(SHAPES)]
        n = int(rng.integers(3 if shape in ("cranks", "forest") else 2, 15))
        out.append((kind, shape, n, int(rng.integers(1, 6)), seed))
    return out


@pytest.mark.parametrize("kind,shape,n,loops,seed", _random_linkages(),
                         ids=lambda v: str(v))
def test_one_factorisation_agrees_with_the_three_tests_on_random_linkages(tmp_path, kind, shape, n, loops, seed):
    rng = np.random.default_rng(seed)
    model = _model(linkage(rng, kind, shape, n, tmp_path / "m.toml", loops))
    one, three = precheck(model, "", "svd"), precheck(model, "", "all")
    assert three.methods_agree, [j for j in three.joints if not j.agree]
    assert (one.rank, one.dof, one.redundant) == (three.rank, three.dof, three.redundant)
    assert _verdicts(one) == _verdicts(three)


def test_check_factorises_the_jacobian_once(tmp_path, capsys, monkeypatch):
    """``check`` of a scene whose elimination is chosen ("auto") factorises Phi_h^T at q0 once:
    the elimination's independent columns and the analysis read the same factorisation."""
    from overcon import analysis
    calls = []
    made = analysis.factorise_nonzeros  # every factorisation of a Factored goes through it
    monkeypatch.setattr(analysis, "factorise_nonzeros", lambda *a, **k: calls.append(1) or made(*a, **k))
    path = parallelogram(30, tmp_path / "p.toml")
    assert main(["check", str(path), "--json", "--friction", "none"]) == 0
    assert len(calls) == 1 and '"redundant": 28' in capsys.readouterr().out


def test_a_factorisation_is_read_with_its_own_rule():
    """A Factored gives what its J gives with the same rtol and equilibration, and refuses another."""
    from overcon import analysis
    J = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0], [1.0, 2.0, 1.0]])
    fz = analysis.factorise(J)
    assert analysis.auto_eliminate(fz) == analysis.auto_eliminate(J)
    groups = {"a": [0], "b": [1, 2]}
    assert analysis.to_json(analysis.analyse(fz, groups)) == analysis.to_json(analysis.analyse(J, groups))
    with pytest.raises(ValueError, match="rtol"):
        analysis.analyse(fz, groups, rtol=1e-6)
    with pytest.raises(ValueError, match="equilibrate"):
        analysis.independent_columns(fz, equilibrate=False)
