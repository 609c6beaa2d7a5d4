"""Analytic derivatives of the joint producers and of the model assembly against finite
differences (Phi_q, Phi_h = Phi_q T, gamma), reaction transforms (A.1, A.5, A.10), friction
dissipation (App. A) and generalized forces (virtual work), for the paper's two mechanisms and
for small random single-type mechanisms."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from compiled import compiled_models

import reference_joints as ref
from overcon import evaluation as M
from overcon.joints import TYPES as JOINT_TYPES
from overcon.model import Model
from overcon.checks import compile_checked
from overcon.friction_laws import make_law
from overcon.kinematics import OMEGA, EulerSingularity, cross2, cross3, euler_H, euler_R, rot2
from overcon.scene import as_scene, load
from overcon.spec import FrictionSpec

ROOT = Path(__file__).resolve().parent.parent
PLANAR = ROOT / "mechanisms" / "planar_sliders.toml"
SPATIAL = ROOT / "mechanisms" / "spatial_parallelogram.toml"
SEEDS = [0, 1, 2]
EPS = 1e-6
RTOL = 1e-7


# ------------------------------------------------------------------------------------- helpers

_CACHE: dict = {}


def compiled(path) -> Model:
    key = str(path)
    if key not in _CACHE:
        _CACHE[key] = compile_checked(as_scene(load(path)))
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


def T_matrix(model, q) -> np.ndarray:
    """q' = T(q) h: block diagonal, I for positions, H for Euler angles (spatial), I (planar)."""
    T = np.eye(model.n)
    if model.kind == "spatial":
        for b in range(model.nb):
            s = b * 6
            T[s + 3: s + 6, s + 3: s + 6] = euler_H(q[s + 3: s + 6])
    return T


def fd_jacobian(fun, x, eps=EPS) -> np.ndarray:
    cols = []
    for k in range(x.size):
        e = np.zeros_like(x)
        e[k] = eps
        cols.append((fun(x + e) - fun(x - e)) / (2 * eps))
    return np.column_stack(cols)


def assert_close(a, b, rtol=RTOL, what=""):
    scale = max(1.0, float(np.max(np.abs(b))) if np.size(b) else 1.0)
    err = float(np.max(np.abs(a - b))) if np.size(b) else 0.0
    assert err <= rtol * scale, f"{what}: max error {err:.3g} (scale {scale:.3g})\n{a}\n{b}"


def check_jacobian_q(model, q):
    f = M.frames(model, q)
    Jq = ref.jacobian(model, f, "jac_q")
    fd = fd_jacobian(lambda x: M.constraints(model, M.frames(model, x)), q)
    assert Jq.shape == (model.m, model.n)
    assert_close(Jq, fd, what="Phi_q vs FD")


def check_jacobian_h(model, q):
    f = M.frames(model, q)
    Jh = M.jacobian_h(model, f)
    assert Jh.shape == (model.m, model.nh)
    assert_close(Jh, ref.jacobian(model, f, "jac_q") @ T_matrix(model, q), rtol=1e-12, what="Phi_h vs Phi_q T")


def check_gamma(model, q, h):
    """q(s) with q' = coordinate_rates(q, h), h constant: d/ds[Phi_h(q(s)) h] = -gamma(q, h)."""
    qdot = M.coordinate_rates(model, q, h)
    assert_close(qdot, T_matrix(model, q) @ h, rtol=1e-14, what="coordinate_rates vs T h")

    def phih_h(s):
        return M.jacobian_h(model, M.frames(model, q + s * qdot)) @ h

    fd = (phih_h(EPS) - phih_h(-EPS)) / (2 * EPS)
    g = M.gamma(model, M.frames(model, q, h))
    assert g.shape == (model.m,)
    assert_close(-g, fd, what="gamma vs -d/ds(Phi_h h)")


# ----------------------------------------------------------------- 2. the paper's mechanisms

PAPER = [pytest.param(PLANAR, id="planar"), pytest.param(SPATIAL, id="spatial")]


@pytest.mark.parametrize("path", PAPER)
def test_paper_q0_satisfies_constraints(path):
    model = compiled(path)
    assert np.max(np.abs(M.constraints(model, M.frames(model, model.q0)))) < 1e-12


@pytest.mark.parametrize("path", PAPER)
def test_paper_derivatives_at_q0(path):
    model = compiled(path)
    rng = np.random.default_rng(99)
    check_jacobian_q(model, model.q0)
    check_jacobian_h(model, model.q0)
    check_gamma(model, model.q0, model.h0)
    check_gamma(model, model.q0, random_h(model, rng))


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("path", PAPER)
def test_paper_derivatives_at_random_configurations(path, seed):
    model = compiled(path)
    rng = np.random.default_rng(seed)
    q = random_q(model, rng)
    check_jacobian_q(model, q)
    check_jacobian_h(model, q)
    check_gamma(model, q, random_h(model, rng))


def test_coordinate_rates_singularity_names_the_body():
    model = compiled(SPATIAL)
    q = model.q0.copy()
    b = model.body_names.index("link5")
    q[b * 6 + 4] = 1e-5
    with pytest.raises(EulerSingularity, match="Euler angle singularity of body 'link5'") as exc:
        M.coordinate_rates(model, q, model.h0 + 1.0)
    assert "link5" in str(exc.value)


# -------------------------------------------------------- 3. single joint types in isolation

def _fmt(v) -> str:
    return "[" + ", ".join(repr(float(x)) for x in np.atleast_1d(v)) + "]"


def write_single_type(tmp: Path, jtype: str, seed: int) -> Path:
    """Two bodies and three joints of one type: (b1, base), (b1, b2), (base, b2); random points,
    v and psi; random q0 (not assembled)."""
    rng = np.random.default_rng(seed)
    kind = "spatial" if jtype == "spherical" else "planar"
    d = 3 if kind == "spatial" else 2
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
    for k, (bi, bj) in enumerate((("b1", "base"), ("b1", "b2"), ("base", "b2"))):
        lines += ["[[joints]]", f'name = "J{k}"', f'type = "{jtype}"', f'body_i = "{bi}"',
                  f'body_j = "{bj}"']
        if jtype == "translational":
            lines += [f"s_A = {_fmt(rng.uniform(-1, 1, 2))}", f"s_B = {_fmt(rng.uniform(-1, 1, 2))}",
                      f"v = {_fmt(rng.uniform(0.2, 1.5, 2) * rng.choice([-1, 1], 2))}",
                      f"psi = {rng.uniform(-1.5, 1.5)!r}"]
        else:
            lines += [f"s_i = {_fmt(rng.uniform(-1, 1, d))}", f"s_j = {_fmt(rng.uniform(-1, 1, d))}"]
        lines.append("")
    path = tmp / f"single_{jtype}_{seed}.toml"
    path.write_text("\n".join(lines))
    return path


TYPES = ["translational", "revolute", "spherical"]


@pytest.fixture(scope="module")
def single(tmp_path_factory):
    return compiled_models(tmp_path_factory.mktemp("single"), write_single_type)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("jtype", TYPES)
def test_single_type_derivatives(single, jtype, seed):
    model = single(jtype, seed)
    assert [c.type for c in model.joints] == [jtype] * 3
    assert [(c.bi, c.bj) for c in model.joints] == [(0, -1), (0, 1), (-1, 1)]
    rng = np.random.default_rng(1000 + seed)
    for q in (model.q0, random_q(model, rng), random_q(model, rng)):
        check_jacobian_q(model, q)
        check_jacobian_h(model, q)
        check_gamma(model, q, random_h(model, rng))


@pytest.mark.parametrize("jtype", TYPES)
def test_single_type_block_shapes(single, jtype):
    model = single(jtype, 0)
    f = M.frames(model, model.q0, model.h0)
    for c in model.joints:
        ne, d = JOINT_TYPES[c.type].n_equations, model.plan.single[c.index]
        for J in (*ref.ref(c).jac_q(c, f), *c.module.jac_h(d, f)):
            assert J.shape[-2:] == (ne, model.nq_b)
        assert c.module.phi(d, f).shape == (1, ne)
        assert c.module.gamma(d, f).shape == (1, ne)
        assert c.module.reaction(d, f, np.zeros((1, model.nq_b))).shape == (1, len(JOINT_TYPES[c.type].reaction))


# -------------------------------------------------------------------- 4. reaction transforms

def _random_state(model, rng):
    q = random_q(model, rng)
    h = random_h(model, rng)
    return q, h, M.frames(model, q, h)


@pytest.mark.parametrize("seed", SEEDS)
def test_revolute_reaction_transform_by_hand(single, seed):
    model = single("revolute", seed)
    rng = np.random.default_rng(2000 + seed)
    q, h, f = _random_state(model, rng)
    lam = rng.normal(size=model.m) * 10
    for c in model.joints:
        fi = M.reaction_on_body_i(model, c, f, lam)
        Ji, _ = one(model, c, "jac_h", f)
        assert np.allclose(fi, Ji.T @ lam[list(c.rows)])
        F, T_O = fi[:2], fi[2]
        Ri = rot2(f.phi[c.bi])
        arm = Ri @ c.p["s_i"]
        local = one(model, c, "reaction_transform", f) @ fi
        assert np.allclose(local[:2], Ri.T @ F, atol=1e-12)
        assert np.isclose(local[2], T_O - cross2(arm, F), atol=1e-12)
        assert abs(local[2]) < 1e-12  # a revolute joint carries no moment about P
        # the generalized reaction is the force lam applied at P
        assert np.allclose(F, lam[list(c.rows)])
        p = -M.physical_reaction(model, c, f, lam)
        assert len(p) == len(c.components) == 5
        assert np.allclose(p, np.r_[local, F])


@pytest.mark.parametrize("seed", SEEDS)
def test_translational_reaction_transform_by_hand(single, seed):
    model = single("translational", seed)
    rng = np.random.default_rng(3000 + seed)
    q, h, f = _random_state(model, rng)
    lam = rng.normal(size=model.m) * 10
    for c in model.joints:
        fi = M.reaction_on_body_i(model, c, f, lam)
        F, T_O = fi[:2], fi[2]
        v = np.asarray(c.p["v"])
        # guide x' in global: body i axes rotated by -psi from body j's guide OMEGA^T v/|v|
        e_x = rot2(f.phi[c.bi] - c.p["psi"]) @ (OMEGA.T @ v / np.linalg.norm(v))
        e_y = OMEGA @ e_x
        arm = rot2(f.phi[c.bi]) @ c.p["s_A"]
        local = one(model, c, "reaction_transform", f) @ fi
        assert np.allclose(local[:2], [e_x @ F, e_y @ F], atol=1e-12)
        assert np.isclose(local[2], T_O - cross2(arm, F), atol=1e-12)
        p = -M.physical_reaction(model, c, f, lam)
        assert np.allclose(p, np.r_[local, F])


@pytest.mark.parametrize("seed", SEEDS)
def test_translational_reaction_normal_to_guide_when_angle_holds(single, seed):
    """With phi_i - phi_j = psi the frictionless reaction has no component along the guide."""
    model = single("translational", seed)
    rng = np.random.default_rng(3500 + seed)
    q = random_q(model, rng)
    for c in model.joints:
        qc = q.copy()
        if c.bi >= 0:
            phij = 0.0 if c.bj < 0 else qc[3 * c.bj + 2]
            qc[3 * c.bi + 2] = phij + c.p["psi"]
        else:
            qc[3 * c.bj + 2] = -c.p["psi"]
        f = M.frames(model, qc)
        assert abs(one(model, c, "phi", f)[1]) < 1e-12
        lam = rng.normal(size=model.m)
        local = one(model, c, "reaction_transform", f) @ M.reaction_on_body_i(model, c, f, lam)
        assert abs(local[0]) < 1e-12


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("which", ["single", "paper"])
def test_spherical_reaction_transform(single, seed, which):
    model = single("spherical", seed) if which == "single" else compiled(SPATIAL)
    rng = np.random.default_rng(4000 + seed)
    q, h, f = _random_state(model, rng)
    lam = rng.normal(size=model.m) * 10
    for c in model.joints:
        fi = M.reaction_on_body_i(model, c, f, lam)
        Ri = euler_R(f.angles[c.bi])
        F_body = Ri.T @ fi[:3]
        # moment about P of the generalized reaction (body axes) vanishes: A.10 gives [F', 0]
        assert np.allclose(fi[3:] - cross3(c.p["s_i"], F_body), 0.0, atol=1e-12)
        A = one(model, c, "reaction_transform", f)
        assert np.allclose(A @ fi, F_body, atol=1e-12)
        p = -M.physical_reaction(model, c, f, lam)
        assert np.allclose(p, np.r_[F_body, fi[:3]])


# ------------------------------------------------------------------------- 5. friction power

LAWS = {
    "regularised": dict(),
    "stribeck": dict(law="stribeck", mu_static=0.5, v_stribeck=0.01),
    "coulomb": dict(law="coulomb"),
}


def one(model, c, name, f):
    """The joint module's ``name`` for joint c alone (a batch of one; production code)."""
    out = getattr(c.module, name)(model.plan.single[c.index], f)
    return tuple(x[0] for x in out) if isinstance(out, tuple) else out[0]


def friction_of(c, f, lam, law):
    """(Qi, Qj) of joint c with friction law ``law`` at the multipliers lam (all m): the joint
    module's batched friction for c alone."""
    d = c.module.stack([dataclasses.replace(c, law=law)])
    Qi, Qj = c.module.friction(d, c.module.friction_setup(d, f), lam[list(c.rows)][None, :])
    return Qi[0], Qj[0]


def _joint_velocity_null(model, c, f, rng):
    """A random h with this joint's velocity constraint Phi_h h = 0 (spherical friction assumes a
    joint whose two ball centres move together)."""
    Ji, Jj = one(model, c, "jac_h", f)
    J = np.zeros((len(c.rows), model.nh))
    for b, blk in ((c.bi, Ji), (c.bj, Jj)):
        if b >= 0:
            J[:, model.body_slice(b)] += blk
    h = random_h(model, rng)
    return h - np.linalg.pinv(J) @ (J @ h)


def friction_power(model, c, f, h, lam, law):
    Qi, Qj = friction_of(c, f, lam, law)
    P = 0.0
    if c.bi >= 0:
        P += Qi @ h[model.body_slice(c.bi)]
    if c.bj >= 0:
        P += Qj @ h[model.body_slice(c.bj)]
    return P, Qi, Qj


@pytest.mark.parametrize("law", list(LAWS))
@pytest.mark.parametrize("jtype", TYPES)
def test_friction_is_dissipative(single, jtype, law):
    lawobj = make_law(FrictionSpec(mu=0.3, size=0.1, **LAWS[law]))
    worst = -np.inf
    n_nonzero = 0
    for seed in SEEDS:
        model = single(jtype, seed)
        rng = np.random.default_rng(5000 + seed)
        for trial in range(20):
            q = random_q(model, rng)
            f0 = M.frames(model, q)
            for c in model.joints:
                if jtype == "spherical":
                    h = _joint_velocity_null(model, c, f0, rng)
                else:
                    h = random_h(model, rng)
                h *= 10.0 ** rng.uniform(-5, 0)  # reach the linear part of the regularised law
                f = M.frames(model, q, h)
                lam = rng.normal(size=model.m) * 10
                P, Qi, Qj = friction_power(model, c, f, h, lam, lawobj)
                worst = max(worst, P)
                n_nonzero += P < -1e-12
                assert P <= 1e-12, (c.name, P)
    assert n_nonzero > 0  # the check is not vacuous
    assert worst <= 1e-12


@pytest.mark.parametrize("jtype", TYPES)
def test_friction_power_zero_when_mu_zero(single, jtype):
    law = make_law(FrictionSpec(mu=0.0, size=0.1))
    model = single(jtype, 0)
    rng = np.random.default_rng(6000)
    for _ in range(5):
        q, h, f = _random_state(model, rng)
        lam = rng.normal(size=model.m) * 10
        for c in model.joints:
            P, Qi, Qj = friction_power(model, c, f, h, lam, law)
            assert P == 0.0
            assert not np.any(Qi) and not np.any(Qj)


@pytest.mark.parametrize("path", PAPER)
def test_friction_dissipative_on_paper_joints(path):
    model = compiled(path)
    law = make_law(FrictionSpec(mu=0.3, size=0.1))
    rng = np.random.default_rng(7000)
    for _ in range(3):
        q = random_q(model, rng)
        f0 = M.frames(model, q)
        for c in model.joints:
            h = _joint_velocity_null(model, c, f0, rng) if model.kind == "spatial" else random_h(model, rng)
            f = M.frames(model, q, h)
            P, _, _ = friction_power(model, c, f, h, rng.normal(size=model.m) * 10, law)
            assert P <= 1e-12, (c.name, P)


# ----------------------------------------------------------------- 6. generalized forces

@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("path", PAPER)
def test_generalized_force_virtual_work(path, seed):
    """Q . h_b == F . p_dot, p_dot the velocity of the material point at p, by central
    differences along q(s) with q' = coordinate_rates(q, h)."""
    model = compiled(path)
    rng = np.random.default_rng(8000 + seed)
    q, h, f = _random_state(model, rng)
    qdot = M.coordinate_rates(model, q, h)
    for b in range(model.nb):
        point = rng.uniform(-3, 3, model.dim)
        F = rng.normal(size=model.dim) * 10
        Q = M.generalized_force(model, f, b, point, F)
        assert Q.shape == (model.nq_b,)
        body_point = f.R[b].T @ (point - f.r[b])  # material coordinates of p

        def p_of(s):
            fs = M.frames(model, q + s * qdot)
            return fs.r[b] + fs.R[b] @ body_point

        p_dot = (p_of(EPS) - p_of(-EPS)) / (2 * EPS)
        lhs = Q @ h[model.body_slice(b)]
        rhs = F @ p_dot
        assert np.isclose(lhs, rhs, rtol=1e-7, atol=1e-7 * max(1.0, abs(rhs))), (b, lhs, rhs)
