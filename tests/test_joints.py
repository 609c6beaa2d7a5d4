"""The joint types of the paper (planar translational and revolute, spherical with z-x-z Euler
angles) in the compiled core, on the paper's two mechanisms and on small random single-type
mechanisms with the base on either side: Phi_h and gamma against finite differences of the core's
Phi, the reaction outputs against the generalized reaction J_i^T lam by hand (A.1, A.5, A.10),
friction dissipation and the law at the returned multipliers (App. A), and the loads' generalized
forces by virtual power. The other spatial types: tests/test_spatial_joints.py, test_core_rows.py."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from overcon import kernel
from overcon.checks import compile_checked
from overcon.scene import as_scene, load

from test_core_rows import (EQ_REL, FD_REL, EPS_FD, applied_forces, check_friction_at, consistent, equation_residuals,
                            position, rates, rotation, rows_fd_errors, solve)
from test_kernel import check_reactions, kernel_for, random_planar_model

ROOT = Path(__file__).resolve().parent.parent
PLANAR = ROOT / "mechanisms" / "planar_sliders.toml"
SPATIAL = ROOT / "mechanisms" / "spatial_parallelogram.toml"
SEEDS = [0, 1, 2]
OMEGA = np.array([[0.0, -1.0], [1.0, 0.0]])  # a quarter turn counter-clockwise


# ------------------------------------------------------------------------------------- helpers

_CACHE: dict = {}


def compiled(path, friction=None):
    """(spec, model) of a mechanism file (friction: the joints to switch it on for, or none)."""
    key = (str(path), tuple(friction or ()))
    if key not in _CACHE:
        spec = as_scene(load(path), friction=list(friction or ()))
        _CACHE[key] = spec, compile_checked(spec, check_initial=False)
    return _CACHE[key]


def random_q(model, rng) -> np.ndarray:
    """Random coordinates (not satisfying the constraints); spatial beta in +-[0.3, 2.8]."""
    Q = np.empty((model.nb, model.nq_b))
    Q[:, : model.dim] = rng.uniform(-3, 3, (model.nb, model.dim))
    if model.kind == "planar":
        Q[:, 2] = rng.uniform(-math.pi, math.pi, model.nb)
    else:
        Q[:, 3] = rng.uniform(-math.pi, math.pi, model.nb)
        Q[:, 4] = rng.uniform(0.3, 2.8, model.nb) * rng.choice([-1.0, 1.0], model.nb)
        Q[:, 5] = rng.uniform(-math.pi, math.pi, model.nb)
    return Q.reshape(-1)


def random_h(model, rng) -> np.ndarray:
    return rng.normal(size=model.nh) * 2.0


def check_derivatives(k, model, q, h):
    eJ, eg = rows_fd_errors(k, model, np.concatenate([q, h]))
    assert eJ <= FD_REL and eg <= FD_REL, (eJ, eg)


# ----------------------------------------------------------------- the paper's mechanisms

PAPER = [pytest.param(PLANAR, id="planar"), pytest.param(SPATIAL, id="spatial")]


@pytest.mark.parametrize("path", PAPER)
def test_paper_q0_satisfies_constraints(path):
    spec, model = compiled(path)
    k = kernel_for(model, spec.solver)
    assert np.max(np.abs(k.rows(np.concatenate([model.q0, model.h0]))[0])) < 1e-12


@pytest.mark.parametrize("path", PAPER)
def test_paper_derivatives_at_q0(path):
    """The core's Phi_h and gamma (FD_REL: tests/test_core_rows.py) at q0, with h0 and a random h."""
    spec, model = compiled(path)
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(99)
    check_derivatives(k, model, model.q0, model.h0)
    check_derivatives(k, model, model.q0, random_h(model, rng))


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("path", PAPER)
def test_paper_derivatives_at_random_configurations(path, seed):
    spec, model = compiled(path)
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(seed)
    check_derivatives(k, model, random_q(model, rng), random_h(model, rng))


def test_coordinate_rates_singularity_names_the_body():
    """|sin beta| below 1e-3 for one body: the core's rates refuse (status 3) naming that body."""
    spec, model = compiled(SPATIAL)
    k = kernel_for(model, spec.solver)
    q = model.q0.copy()
    b = model.body_names.index("link5")
    q[b * 6 + 4] = 1e-5
    assert k.evaluate(0.0, np.concatenate([q, model.h0 + 1.0])) is None and k.last_status == 3
    assert f"body {b} has |sin beta| = 1e-05" in k.last_message


# -------------------------------------------------------- single joint types in isolation

def _fmt(v) -> str:
    return "[" + ", ".join(repr(float(x)) for x in np.atleast_1d(v)) + "]"


def write_single_type(tmp: Path, jtype: str, seed: int, friction: str = "") -> Path:
    """Two bodies and three joints of one type: (b1, base), (b1, b2), (base, b2); random points,
    v and psi; random q0 (not assembled); ``friction``: the lines of each joint's
    ``[joints.friction]`` table (none when empty), and then only two of the three joints (the
    pair left out chosen by the seed), so that the planar mechanisms move (three planar joints of
    two rows hold two bodies fixed)."""
    rng = np.random.default_rng(seed)
    kind = "spatial" if jtype in ("spherical", "spatial_distance", "spatial_point_on_line") else "planar"
    d = 3 if kind == "spatial" else 2
    fname = jtype.removeprefix("spatial_")  # the type's name in files
    lines = ["[mechanism]", f'name = "single_{jtype}"', f'kind = "{kind}"',
             f"gravity = {_fmt(np.r_[np.zeros(d - 1), -9.81])}", ""]
    for b in ("b1", "b2"):
        if kind == "planar":
            q0 = np.r_[rng.uniform(-2, 2, 2), rng.uniform(-3, 3)]
            inertia = f"{rng.uniform(0.5, 2)!r}"
        else:
            q0 = np.r_[rng.uniform(-2, 2, 3), rng.uniform(-3, 3), rng.uniform(0.4, 2.7), rng.uniform(-3, 3)]
            inertia = _fmt(rng.uniform(0.5, 2, 3))
        lines += ["[[bodies]]", f'name = "{b}"', f"mass = {rng.uniform(1, 3)!r}",
                  f"inertia = {inertia}", f"q0 = {_fmt(q0)}", ""]
    pairs = [("b1", "base"), ("b1", "b2"), ("base", "b2")]
    if friction:
        del pairs[seed % 3]
    for k, (bi, bj) in enumerate(pairs):
        lines += ["[[joints]]", f'name = "J{k}"', f'type = "{fname}"', f'body_i = "{bi}"',
                  f'body_j = "{bj}"']
        if jtype == "translational":
            lines += [f"s_A = {_fmt(rng.uniform(-1, 1, 2))}", f"s_B = {_fmt(rng.uniform(-1, 1, 2))}",
                      f"v = {_fmt(rng.uniform(0.2, 1.5, 2) * rng.choice([-1, 1], 2))}",
                      f"psi = {rng.uniform(-1.5, 1.5)!r}"]
        else:
            lines += [f"s_i = {_fmt(rng.uniform(-1, 1, d))}", f"s_j = {_fmt(rng.uniform(-1, 1, d))}"]
        if fname == "distance":
            lines += [f"length = {rng.uniform(0.5, 2.0)!r}"]
        if fname == "point_on_line":
            lines += [f"axis_j = {_fmt(rng.uniform(0.2, 1.5, d) * rng.choice([-1, 1], d))}"]
        if friction:
            lines += ["[joints.friction]", friction]
        lines.append("")
    path = tmp / f"single_{jtype}_{seed}{'_f' if friction else ''}.toml"
    path.write_text("\n".join(lines))
    return path


TYPES = ["translational", "revolute", "spherical", "point_on_line", "spatial_point_on_line"]
ROW_TYPES = TYPES + ["distance", "spatial_distance"]  # the rows' tests also take the types without friction


@pytest.fixture(scope="module")
def single(tmp_path_factory):
    """``get(jtype, seed, friction="")``: (spec, model) of write_single_type, compiled once."""
    tmp = tmp_path_factory.mktemp("single")
    cache: dict = {}

    def get(jtype: str, seed: int, friction: str = ""):
        if (jtype, seed, friction) not in cache:
            path = write_single_type(tmp, jtype, seed, friction)
            names = [j.name for j in as_scene(load(path)).mechanism.joints] if friction else []
            spec = as_scene(load(path), friction=names, friction_outputs="all" if friction else "none")
            cache[jtype, seed, friction] = spec, compile_checked(spec, check_initial=False)
        return cache[jtype, seed, friction]

    return get


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("jtype", ROW_TYPES)
def test_single_type_derivatives(single, jtype, seed):
    spec, model = single(jtype, seed)
    assert [c.type for c in model.joints] == [jtype] * 3
    assert [(c.bi, c.bj) for c in model.joints] == [(0, -1), (0, 1), (-1, 1)]
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(1000 + seed)
    for q in (model.q0, random_q(model, rng), random_q(model, rng)):
        check_derivatives(k, model, q, random_h(model, rng))


@pytest.mark.parametrize("jtype", ROW_TYPES)
def test_single_type_shapes(single, jtype):
    """The core's rows: Phi (m), Phi_h (m, nh), gamma (m), each joint its type's equations; its
    outputs: a row of reaction components per joint, the type's components then zeros."""
    spec, model = single(jtype, 0)
    k = kernel_for(model, spec.solver)
    y = np.concatenate([model.q0, model.h0])
    phi, J, gam = k.rows(y)
    ne = {"translational": 2, "revolute": 2, "spherical": 3, "distance": 1, "spatial_distance": 1, "point_on_line": 1,
          "spatial_point_on_line": 2}[jtype]
    assert phi.shape == gam.shape == (model.m,) == (3 * ne,) and J.shape == (model.m, model.nh)
    assert all(len(c.rows) == ne for c in model.joints)
    reac, fric = k.outputs(y, np.ones(model.m))
    assert reac.shape == (3, kernel.NREAC) and fric.shape == (3,) and not np.any(fric)
    for n, c in enumerate(model.joints):
        assert np.all(reac[n, len(c.components):] == 0.0) and np.any(reac[n, :len(c.components)])


# -------------------------------------------------------------------- reaction transforms

def generalized_on_i(model, J, c, lam) -> np.ndarray:
    """(J_X)_i^T lam_X: the generalized reaction on body i (force global; moment about the body
    origin: planar scalar, spatial in body axes) from the core's Phi_h."""
    kh = model.nh_b
    rows = list(c.rows)
    return J[rows][:, c.bi * kh:(c.bi + 1) * kh].T @ lam[rows]


def _state(model, rng):
    return np.concatenate([random_q(model, rng), random_h(model, rng)])


def _reaction_case(single, jtype: str, seed: int, base: int):
    """A single ``jtype`` joint at a random state with random multipliers, its reactions already
    checked against Phi_h (:func:`check_reactions`): (model, q, lam, Phi_h, the reaction table)."""
    spec, model = single(jtype, seed)
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(base + seed)
    y = _state(model, rng)
    lam = rng.normal(size=model.m) * 10
    J = k.rows(y)[1]
    reac = k.outputs(y, lam)[0].copy()
    check_reactions(k, model, y, lam)
    return model, y[: model.n], lam, J, reac


@pytest.mark.parametrize("seed", SEEDS)
def test_revolute_reaction_transform_by_hand(single, seed):
    """Revolute (A.5): the generalized reaction on body i is the force lam at P (no moment about P),
    and the outputs are the physical reaction -(J_X)_i^T lam: its force in body i axes, the moment
    about P (0), and the force in global axes."""
    model, q, lam, J, reac = _reaction_case(single, "revolute", seed, 2000)
    for n, c in enumerate(model.joints):
        if c.bi < 0:
            continue
        fi = generalized_on_i(model, J, c, lam)
        F, T_O = fi[:2], fi[2]
        assert np.allclose(F, lam[list(c.rows)], rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(F))))
        Ri = rotation(model, q, c.bi)
        arm = Ri @ np.asarray(c.p["s_i"])
        assert abs(T_O - (arm[0] * F[1] - arm[1] * F[0])) <= 1e-12 * max(1.0, abs(T_O))  # no moment about P
        want = -np.r_[Ri.T @ F, T_O - (arm[0] * F[1] - arm[1] * F[0]), F]
        assert np.allclose(reac[n, :5], want, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(want)))), c.name
        assert abs(reac[n, 2]) < 1e-12 * max(1.0, np.max(np.abs(F)))


@pytest.mark.parametrize("seed", SEEDS)
def test_translational_reaction_transform_by_hand(single, seed):
    """Translational (A.1): the outputs are -(J_X)_i^T lam in the auxiliary frame: components along
    the guide x' (body j's guide Omega^T v/|v| turned into body i's axes by -psi) and y' = Omega x',
    the moment about A, then the global force."""
    model, q, lam, J, reac = _reaction_case(single, "translational", seed, 3000)
    for n, c in enumerate(model.joints):
        if c.bi < 0:
            continue
        fi = generalized_on_i(model, J, c, lam)
        F, T_O = fi[:2], fi[2]
        v = np.asarray(c.p["v"])
        phi_i = q[3 * c.bi + 2]
        cs, sn = math.cos(phi_i - c.p["psi"]), math.sin(phi_i - c.p["psi"])
        e_x = np.array([[cs, -sn], [sn, cs]]) @ (OMEGA.T @ v / np.linalg.norm(v))
        e_y = OMEGA @ e_x
        arm = rotation(model, q, c.bi) @ np.asarray(c.p["s_A"])
        want = -np.r_[e_x @ F, e_y @ F, T_O - (arm[0] * F[1] - arm[1] * F[0]), F]
        assert np.allclose(reac[n, :5], want, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(want)))), c.name


@pytest.mark.parametrize("seed", SEEDS)
def test_translational_reaction_normal_to_guide_when_angle_holds(single, seed):
    """With phi_i - phi_j = psi (the joint's angle row Phi = 0) the reaction has no component along
    the guide (Fx = 0)."""
    spec, model = single("translational", seed)
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(3500 + seed)
    q = random_q(model, rng)
    for n, c in enumerate(model.joints):
        qc = q.copy()
        if c.bi >= 0:
            phij = 0.0 if c.bj < 0 else qc[3 * c.bj + 2]
            qc[3 * c.bi + 2] = phij + c.p["psi"]
        else:
            qc[3 * c.bj + 2] = -c.p["psi"]
        y = np.concatenate([qc, model.h0])
        assert abs(k.rows(y)[0][c.rows[1]]) < 1e-12
        reac = k.outputs(y, rng.normal(size=model.m))[0]
        assert abs(reac[n, 0]) < 1e-12


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("which", ["single", "paper"])
def test_spherical_reaction_transform(single, seed, which):
    """Spherical (A.10): the generalized reaction on body i has no moment about the ball centre,
    and the outputs are the physical reaction's force in body i axes, then in global axes."""
    spec, model = single("spherical", seed) if which == "single" else compiled(SPATIAL)
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(4000 + seed)
    y = _state(model, rng)
    q = y[: model.n]
    lam = rng.normal(size=model.m) * 10
    J = k.rows(y)[1]
    reac = k.outputs(y, lam)[0].copy()
    check_reactions(k, model, y, lam)
    for n, c in enumerate(model.joints):
        if c.bi < 0:
            continue
        fi = generalized_on_i(model, J, c, lam)
        F_body = rotation(model, q, c.bi).T @ fi[:3]
        scale = max(1.0, float(np.max(np.abs(fi))))
        assert np.allclose(fi[3:] - np.cross(c.p["s_i"], F_body), 0.0, atol=1e-12 * scale)
        assert np.allclose(reac[n, :6], -np.r_[F_body, fi[:3]], rtol=0, atol=1e-12 * scale), c.name


# ------------------------------------------------------------------------- friction power

LAWS = {
    "regularised": 'mu = 0.3\nradius = 0.1\nlength = 0.1\nv_reg = 1e-3',
    "stribeck": 'law = "stribeck"\nmu = 0.3\nmu_static = 0.5\nv_stribeck = 0.01\nradius = 0.1\nlength = 0.1\nv_reg = 1e-3',
}
"""The friction tables of the single-type mechanisms (each type reads its size: radius or length).
The Coulomb law (variant A) is for analysis only, refused for integration (tests/test_friction.py),
so the core has no Coulomb friction to evaluate."""


def friction_table(jtype: str, law: str, mu: float | None = None) -> str:
    sizes = "length" if jtype == "translational" else "" if "point_on_line" in jtype else "radius"
    text = LAWS[law].replace("radius = 0.1\n", "radius = 0.1\n" if sizes == "radius" else "")
    text = text.replace("length = 0.1\n", "length = 0.1\n" if sizes == "length" else "")
    return text if mu is None else text.replace("mu = 0.3", f"mu = {mu}")


@pytest.mark.parametrize("law", list(LAWS))
@pytest.mark.parametrize("jtype", TYPES)
def test_friction_is_dissipative(single, jtype, law):
    """With friction in both joints (the base as body i or j, or two moving bodies), at random
    states moved onto the constraints and velocities scaled into the laws' linear part too: the friction outputs are
    their law at the returned multipliers, and the friction forces' power in the equations of
    motion, h . (M h' + Phi_h^T lam - Q), is the outputs' and <= 0 (tests/test_core_rows.py)."""
    nonzero = 0
    for seed in SEEDS:
        spec, model = single(jtype, seed, friction_table(jtype, law))
        assert all(c.law is not None and c.law.name == law for c in model.joints)
        k = kernel_for(model, spec.solver)
        rng = np.random.default_rng(5000 + seed)
        for trial in range(8):
            y, assembled = consistent(k, model, _state(model, rng))
            if not assembled:
                continue
            y[model.n:] *= 10.0 ** rng.uniform(-5, 0)  # reach the linear part of the regularised law
            got = solve(k, y)
            if got is None:
                continue
            Qf, acc, _ = equation_residuals(k, model, spec.solver, y, got)
            power = check_friction_at(k, model, spec, y, got)
            h = y[model.n:]
            P = float(h @ Qf)
            scale = max(1.0, float(np.max(np.abs(applied_forces(model, y))))) * max(1.0, float(np.max(np.abs(h))))
            assert abs(P - power) <= EQ_REL * scale and P <= EQ_REL * scale, (P, power)
            nonzero += power < -1e-9 * scale
    assert nonzero > 0  # the check is not vacuous


@pytest.mark.parametrize("law", list(LAWS))
@pytest.mark.parametrize("jtype", TYPES)
def test_friction_jacobian_matches_differences_of_the_forces(single, jtype, law):
    """The friction forces' Jacobian in the joint's multipliers that the core's Newton uses
    (analytic: core/joints_planar.c, joints_spherical.c, joints_spatial.c's point on line;
    Kernel.friction_joint_at) against central differences of the core's forces, at random states
    and multipliers (speeds scaled into and beyond the laws' linear part), to 1e-6 of the forces'
    scale; the forces are not all zero (the check is not vacuous)."""
    spec, model = single(jtype, 1, friction_table(jtype, law))
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(7000)
    moved = 0
    for trial in range(12):
        y = _state(model, rng)
        y[model.n:] *= 10.0 ** rng.uniform(-4, 0)
        for j in model.friction_joints:
            ne = len(model.joints[j].rows)
            lam = rng.normal(size=ne) * 10.0
            Q, dQ = k.friction_joint_at(y, j, lam)
            fd = np.zeros_like(dQ)
            for e in range(ne):
                step = 1e-6 * max(1.0, abs(lam[e]))
                lp, lm = lam.copy(), lam.copy()
                lp[e] += step
                lm[e] -= step
                fd[:, e] = (k.friction_joint_at(y, j, lp)[0] - k.friction_joint_at(y, j, lm)[0]) / (2 * step)
            scale = max(1.0, float(np.max(np.abs(Q))))
            assert np.max(np.abs(dQ - fd)) <= 1e-6 * scale, (jtype, law, trial, dQ, fd)
            moved += bool(np.any(Q))
    assert moved >= 6, moved


def test_friction_joint_at_refuses_arrays_of_the_wrong_size(single):
    """The multipliers and the state are checked against the joint and the model before the core
    reads them (a shorter lam would be read past its end): ValueError naming both sizes; a joint
    without friction is refused by name."""
    jtype = TYPES[0]
    spec, model = single(jtype, 1, friction_table(jtype, list(LAWS)[0]))
    k = kernel_for(model, spec.solver)
    y = _state(model, np.random.default_rng(1))
    j = model.friction_joints[0]
    ne = len(model.joints[j].rows)
    with pytest.raises(ValueError, match=f"lam of shape \\({ne - 1},\\).*has {ne} equations"):
        k.friction_joint_at(y, j, np.zeros(ne - 1))
    with pytest.raises(ValueError, match=f"y of shape \\({y.size + 1},\\)"):
        k.friction_joint_at(np.zeros(y.size + 1), j, np.zeros(ne))
    with pytest.raises(ValueError, match="has no friction law"):
        k.friction_joint_at(y, len(model.joints), np.zeros(ne))


@pytest.mark.parametrize("jtype", TYPES)
def test_friction_zero_when_mu_zero(single, jtype):
    """mu = 0: every friction output is exactly 0 and the equations of motion hold without friction
    forces (Q_f = 0 to round-off)."""
    spec, model = single(jtype, 0, friction_table(jtype, "regularised", mu=0.0))
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(6000)
    for _ in range(5):
        y = _state(model, rng)
        got = k.evaluate(0.0, y)
        assert got is not None, k.last_message
        assert not np.any(k.outputs(y, got[1])[1])
        Qf = equation_residuals(k, model, spec.solver, y, got)[0]
        scale = max(1.0, float(np.max(np.abs(applied_forces(model, y)))), float(np.max(np.abs(model.M * got[0][model.n:]))))
        assert np.max(np.abs(Qf)) <= EQ_REL * scale


@pytest.mark.parametrize("path", PAPER)
def test_friction_dissipative_on_paper_joints(path):
    """The paper's mechanisms with friction in every joint that has a friction table: at states
    moved onto the constraints, the friction power is the outputs' and <= 0."""
    spec0, _ = compiled(path)
    names = [j.name for j in spec0.mechanism.joints if j.friction is not None]
    spec, model = compiled(path, names)
    assert model.friction_joints
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(7000)
    checked = 0
    for _ in range(6):
        y = np.concatenate([model.q0 + 0.05 * rng.standard_normal(model.n), random_h(model, rng)])
        y, assembled = consistent(k, model, y)
        got = solve(k, y) if assembled else None
        if got is None:
            continue
        Qf = equation_residuals(k, model, spec.solver, y, got)[0]
        power = check_friction_at(k, model, spec, y, got)
        h = y[model.n:]
        scale = max(1.0, float(np.max(np.abs(applied_forces(model, y))))) * max(1.0, float(np.max(np.abs(h))))
        assert abs(float(h @ Qf) - power) <= EQ_REL * scale and power <= EQ_REL * scale
        checked += 1
    assert checked >= 3


# ----------------------------------------------------------------- generalized forces

def potential(model, y) -> float:
    """Gravity's and the springs' potential energy (J) at y: -m g . r, k (|d| - L0)^2 / 2."""
    q = y[: model.n]
    V = sum(-model.mass[b] * float(np.asarray(model.gravity) @ position(model, q, b)) for b in range(model.nb))
    for ld in model.loads:
        if ld.type == "spring":
            pi = position(model, q, ld.bi) + rotation(model, q, ld.bi) @ np.asarray(ld.s_i, float)
            pj = position(model, q, ld.bj) + rotation(model, q, ld.bj) @ np.asarray(ld.s_j, float)
            V += 0.5 * ld.stiffness * (float(np.linalg.norm(pi - pj)) - ld.free_length) ** 2
    return V


@pytest.mark.parametrize("kind", ["planar", "spatial"])
@pytest.mark.parametrize("seed", SEEDS)
def test_generalized_force_virtual_work(tmp_path, kind, seed):
    """The loads' generalized forces of the core, Q = M h' + Phi_h^T lam (frictionless, random
    chains with gravity, a force, a torque and two springs, the base on either side), do the
    loads' work: Q . h = -dV/dt (central differences along the core's rates) + F . v + tau . w
    (global), the gyroscopic moment doing none; to FD_REL of the largest term. (This also
    validates tests/test_core_rows.applied_forces, which those tests compare the core with.)"""
    spec, model = random_planar_model(tmp_path, seed, friction=False, kind=kind)
    assert {ld.type for ld in model.loads} == {"force", "torque", "spring"}
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(8000 + seed)
    for _ in range(3):
        y = np.concatenate([model.q0 + 0.1 * rng.standard_normal(model.n), random_h(model, rng)])
        q, h = y[: model.n], y[model.n:]
        got = k.evaluate(0.0, y)
        assert got is not None, k.last_message
        Q = np.asarray(model.M) * got[0][model.n:] + k.rows(y)[1].T @ got[1]
        qd = rates(k, model, q, h)
        dV = (potential(model, np.r_[q + EPS_FD * qd, h]) - potential(model, np.r_[q - EPS_FD * qd, h])) / (2 * EPS_FD)
        work = -dV
        for ld in model.loads:
            hb = h[ld.bi * model.nh_b:(ld.bi + 1) * model.nh_b]
            if ld.type == "force":
                work += float(np.asarray(ld.value, float) @ hb[: model.dim])
            elif ld.type == "torque":
                w = hb[2] if model.dim == 2 else rotation(model, q, ld.bi) @ hb[3:]
                work += float(np.asarray(ld.value, float).reshape(-1) @ np.atleast_1d(w))
        scale = max(1.0, float(np.max(np.abs(Q * h))), abs(dV))
        assert abs(float(Q @ h) - work) <= FD_REL * scale, (float(Q @ h), work)
        assert np.max(np.abs(Q - applied_forces(model, y))) <= EQ_REL * max(1.0, float(np.max(np.abs(Q))))
