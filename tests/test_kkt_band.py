"""The eliminated form's S = J_R M^-1 J_R^T is built and factored in the band order of the
retained rows (core/kkt.c, the order of core/linalg.c ovk_band_order: by each row's lower, then
higher body index), so its cost and round-off depend on how the bodies are listed, its results
not: a mechanism listed along its chain (half bandwidth a few rows) and the same mechanism with
its bodies scrambled (a band about as wide as S) give the same multipliers and accelerations to
1e-12 relative, with and without friction (the friction columns W = S^-1 J_R M^-1 [:, cols] go
through the same band solve), under an elimination, and under redundancy "compliant" (the rigid
rows' own band order). A model whose own row order is no wider than the band order keeps it
(the paper's mechanisms, the examples): there both listings may factor in the same order. The equations are numbered by the joints, which keep their order, so the
multipliers compare entry by entry; the states and accelerations by body name."""
from __future__ import annotations

import dataclasses
import importlib.util
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from overcon import scene as scene_mod
from overcon.checks import compile_checked

from test_kernel import EXAMPLES, MECH, kernel_for, states

REL = 1e-12
"""Multipliers and accelerations of the two listings, relative to the largest of each: S's entries
are the same sums (each over a row's bodies), only the order of the factorisation's and the
solves' sums differs, by round-off amplified by S's conditioning (about 1e3 here)."""


def _nfourbar():
    spec = importlib.util.spec_from_file_location("nfourbar", EXAMPLES / "nfourbar.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _sections(text: str) -> list[str]:
    """The TOML text cut before each table header line."""
    cuts = [m.start() for m in re.finditer(r"^\[", text, flags=re.M)]
    return [text[a:b] for a, b in zip([0] + cuts, cuts + [len(text)])]


def scrambled(text: str, perm: list[int]) -> str:
    """The mechanism text with its [[bodies]] tables (with their sub-tables) listed in the order
    perm (perm[k]: the body at slot k), everything else where it was."""
    parts, groups, slots = [], [], []
    for s in _sections(text):
        if s.startswith("[[bodies]]"):
            groups.append([s])
            slots.append(len(parts))
            parts.append(None)
        elif s.startswith("[bodies.") and groups:
            groups[-1].append(s)
        else:
            parts.append(s)
    assert sorted(perm) == list(range(len(groups)))
    for slot, k in zip(slots, perm):
        body = "".join(groups[k])
        parts[slot] = body if body.endswith("\n\n") else body + "\n"
    return "".join(parts)


def wide(n: int) -> list[int]:
    """A listing of n >= 3 bodies in which chain neighbours lie far apart: slot k holds body
    k s mod n, s the first stride from n / 2 on that is prime to n (so every body once)."""
    s = max(2, n // 2)
    while math.gcd(s, n) != 1:
        s += 1
    return [k * s % n for k in range(n)]


FRICTION = '[joints.friction]\nlaw = "regularised"\nmu = 0.1\nradius = 0.05\nv_reg = 1e-3\n'
COMPLIANCE = '[joints.compliance]\nstiffness = 1e6\nrotational_stiffness = 1e4\ndamping = 2e2\nrotational_damping = 6.0\n'


def _with_table(text: str, joints: list[str], table: str) -> str:
    """The mechanism text with table added to each of the joints."""
    for name in joints:
        text = re.sub(rf'(\[\[joints\]\]\nname = "{name}"\n(?:.+\n)+)', lambda m: m.group(1) + "\n" + table, text)
    return text


def _nfourbar_files(tmp: Path, n: int, friction: list[str], compliant: list[str] = ()) -> tuple[Path, Path]:
    """The N-four-bar with friction on the joints friction and, when compliant names joints,
    those joints compliant under redundancy "compliant"."""
    gen = _nfourbar()
    mech, scene = gen.write(n, tmp)
    mech.write_text(_with_table(_with_table(mech.read_text(), friction, FRICTION), list(compliant), COMPLIANCE))
    text = scene.read_text().replace("friction = []", f"friction = {friction!r}".replace("'", '"'))
    if compliant:
        text = text.replace("[scene]\n", '[scene]\nredundancy = "compliant"\n')
    scene.write_text(text)
    return mech, scene


def _copy_scene(tmp: Path, scene_path: Path) -> tuple[Path, Path]:
    text = scene_path.read_text()
    mech_name = re.search(r'^mechanism = "([^"]+)"', text, flags=re.M).group(1)
    tmp.mkdir(parents=True, exist_ok=True)
    (tmp / mech_name).write_text((scene_path.parent / mech_name).read_text())
    (tmp / scene_path.name).write_text(text)
    return tmp / mech_name, tmp / scene_path.name


def _listings(tmp: Path, case: str) -> tuple[Path, Path]:
    """(scene along the chain, scene with the bodies scrambled) of case."""
    paths = []
    for listing in ("chain", "scrambled"):
        out = tmp / listing
        if case.startswith("nfourbar"):
            friction = ["G0", "L3", "R5"] if case != "nfourbar" else []
            mech, scene = _nfourbar_files(out, 7, friction, ["L2", "R4"] if case.endswith("compliant") else ())
        else:
            path = EXAMPLES / f"{case}.toml" if (EXAMPLES / f"{case}.toml").exists() else MECH / f"{case}.toml"
            mech, scene = _copy_scene(out, path)
        if listing == "scrambled":
            nb = len(tomllib.loads(mech.read_text())["bodies"])
            mech.write_text(scrambled(mech.read_text(), wide(nb)))
        paths.append(scene)
    return paths[0], paths[1]


def _to(model_from, model_to, y: np.ndarray) -> np.ndarray:
    """y (or y') of model_from's body listing in model_to's."""
    nq, nh = model_from.nq_b, model_from.nh_b
    nb = model_from.nb
    q, h = y[: nb * nq].reshape(nb, nq), y[nb * nq:].reshape(nb, nh)
    idx = [model_from.body_names.index(name) for name in model_to.body_names]
    return np.concatenate([q[idx].ravel(), h[idx].ravel()])


def test_scrambled_listing_is_a_wide_band():
    """The test's scrambled listing of the N-four-bar puts chain neighbours far apart: the band
    order's half bandwidth (largest distance of two rows sharing a body) is most of S."""
    text = _nfourbar().mechanism_text(7)
    names = [b["name"] for b in tomllib.loads(text)["bodies"]]
    order = [names[k] for k in wide(len(names))]
    again = [b["name"] for b in tomllib.loads(scrambled(text, wide(len(names))))["bodies"]]
    assert again == order and sorted(again) == sorted(names)
    joints = tomllib.loads(text)["joints"]
    for listing, half in ((names, 5), (order, None)):
        rows = []  # (lower, higher) listed body index of each equation, in band order
        for j in joints:
            a, b = (listing.index(j[k]) if j[k] != "base" else -1 for k in ("body_i", "body_j"))
            lo, hi = (max(a, b), -1) if min(a, b) < 0 else (min(a, b), max(a, b))
            rows += [(lo, hi)] * 2  # a planar revolute joint: two equations
        rows.sort()
        band = max(max(k for k, r in enumerate(rows) if body in r) - min(k for k, r in enumerate(rows) if body in r)
                   for body in range(len(names)))
        if half is not None:
            assert band == half
        else:
            assert band >= len(rows) // 2, band


@pytest.mark.parametrize("case", ["nfourbar", "nfourbar_friction", "nfourbar_friction_compliant", "planar_f145_wo6",
                                  "spatial_GHMN_wo18", "compliant_loop_A1_wo_A2"])
@pytest.mark.parametrize("baumgarte", [10.0, 0.0])
def test_multipliers_do_not_depend_on_the_body_listing(tmp_path, case, baumgarte):
    """The same multipliers (entry by entry) and accelerations (body by body) to REL at the initial
    state and at random states around it, whether the bodies are listed along the chain or
    scrambled; with friction, the friction solve takes the same number of force evaluations."""
    chain, scram = _listings(tmp_path, case)
    results = []
    for path in (chain, scram):
        spec = scene_mod.as_scene(scene_mod.load(path))
        solver = dataclasses.replace(spec.solver, baumgarte=baumgarte)
        model = compile_checked(spec, check_initial=False)
        results.append((model, kernel_for(model, solver)))
    (m1, k1), (m2, k2) = results
    assert m1.body_names != m2.body_names and sorted(m1.body_names) == sorted(m2.body_names)
    assert m1.m == m2.m and list(m1.retained) == list(m2.retained)
    checked = 0
    for y in states(m1, 8, seed=3):
        a, b = k1.evaluate(0.0, y), k2.evaluate(0.0, _to(m1, m2, y))
        assert (a is None) == (b is None), (k1.last_message, k2.last_message)
        if a is None:
            continue
        lam_scale = max(1.0, float(np.max(np.abs(a[1]))))
        acc_scale = max(1.0, float(np.max(np.abs(a[0]))))
        assert float(np.max(np.abs(a[1] - b[1]))) <= REL * lam_scale
        assert float(np.max(np.abs(a[0] - _to(m2, m1, b[0])))) <= REL * acc_scale
        assert a[3] == b[3]
        checked += 1
    assert checked >= 6


def test_singular_message_names_the_row_of_the_failed_pivot(tmp_path):
    """At the flat position of the N-four-bar (N = 3, listed along the chain: the band order is
    G0, L0, R0, G1, L1, ... by body) the first loop closes at G1, and its x row (equation 2: the
    joints' rows are numbered G0, G1, G2, G3, L0, R0, ...) is the first the x rows' dependency
    makes singular: band position 6, retained row 2. The message gives the pivot's position in
    the factorisation and the retained row in the model's numbering."""
    mech, scene = _nfourbar_files(tmp_path, 3, [])
    spec = scene_mod.as_scene(scene_mod.load(scene))
    model = compile_checked(spec, check_initial=False)
    assert [j.rows for j in model.joints][:5] == [(0, 1), (2, 3), (4, 5), (6, 7), (8, 9)]
    k = kernel_for(model, spec.solver)
    q = np.array([[int(name[-1]) + (0.5 if name.startswith("crank") else 1.5), 0.0, 0.0]
                  for name in model.body_names])  # every link along +x on the ground line
    assert k.evaluate(0.0, np.concatenate([q.ravel(), np.zeros(model.nh)])) is None and k.last_status == 1
    assert k.last_message == ("singular position: S = Phi_h M^-1 Phi_h^T is not positive definite "
                              "(Cholesky pivot 6 of 20, retained row 2)")
