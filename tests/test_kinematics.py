"""The compiled core's kinematics: the rotation matrix of z-x-z Euler angles (paper Eq. 40) and of
a planar angle, read off the core's constraint values, and the Euler-angle rates of B.15
(phi' = H omega, omega in body axes) against the closed form and finite differences of R; the
Euler singularity (|sin beta| < 1e-3) refused naming the body.

The probe: one body held to the base by spherical (planar: revolute) joints at its body points
e_1, e_2(, e_3) and the base origin, so that joint k's Phi is r + R e_k: the core's R, column by
column, at any coordinates."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from overcon.checks import compile_checked
from overcon.scene import as_scene, load

from test_core_rows import EPS_FD, rates, rx, rz
from test_kernel import kernel_for

SEEDS = [0, 1, 2, 3, 4]
SIN_BETA_MIN = 1e-3
"""|sin beta| below which the core refuses z-x-z angles (OVK_EULER)."""


def random_angles(rng) -> np.ndarray:
    """z-x-z angles with beta kept away from 0 and +-pi (either sign)."""
    a, g = rng.uniform(-math.pi, math.pi, 2)
    b = rng.uniform(0.3, 2.8) * rng.choice([-1.0, 1.0])
    return np.array([a, b, g])


def vee(W: np.ndarray) -> np.ndarray:
    """Inverse of skew: the vector of a (numerically) skew-symmetric 3x3 matrix."""
    return np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2.0


def probe(tmp_path: Path, kind: str = "spatial"):
    """(model, kernel) of the probe mechanism (module docstring); body "link7"."""
    d = 3 if kind == "spatial" else 2
    q0 = "[0.1, 0.2, 0.3, 0.4, 1.0, -0.3]" if d == 3 else "[0.1, 0.2, 0.4]"
    lines = ["[mechanism]", 'name = "probe"', f'kind = "{kind}"', f"gravity = {[0.0] * d}", "",
             "[[bodies]]", 'name = "link7"', "mass = 1.0", f"inertia = {[1.0] * d if d == 3 else 1.0}", f"q0 = {q0}", ""]
    jtype = "spherical" if d == 3 else "revolute"
    for k in range(d):
        s_i = [1.0 if i == k else 0.0 for i in range(d)]
        lines += ["[[joints]]", f'name = "P{k}"', f'type = "{jtype}"', 'body_i = "link7"', 'body_j = "base"',
                  f"s_i = {s_i}", f"s_j = {[0.0] * d}", ""]
    (tmp_path / "probe.toml").write_text("\n".join(lines))
    spec = as_scene(load(tmp_path / "probe.toml"))  # (the automatic elimination of the redundant rows)
    model = compile_checked(spec, check_initial=False)
    return model, kernel_for(model, spec.solver)


def core_R(model, k, q) -> np.ndarray:
    """The core's rotation matrix body -> global of the probe's body at q."""
    d = model.dim
    phi = k.rows(np.concatenate([q, np.zeros(model.nh)]))[0]
    return np.column_stack([phi[d * j: d * j + d] - q[:d] for j in range(d)])


@pytest.fixture(scope="module")
def spatial(tmp_path_factory):
    return probe(tmp_path_factory.mktemp("probe3"))


# ------------------------------------------------------------------------------- rotations

def test_planar_rotation_and_rates(tmp_path):
    """Planar: R = [[c, -s], [s, c]] of phi (counter-clockwise), and the rates are h itself."""
    model, k = probe(tmp_path, "planar")
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = rng.uniform(-3, 3, 3)
        c, s = math.cos(q[2]), math.sin(q[2])
        assert np.max(np.abs(core_R(model, k, q) - np.array([[c, -s], [s, c]]))) <= 1e-15
        h = rng.normal(size=3)
        assert np.array_equal(rates(k, model, q, h), h)


@pytest.mark.parametrize("seed", SEEDS)
def test_euler_R_is_zxz_rotation(spatial, seed):
    """The core's R of z-x-z angles is Rz(alpha) Rx(beta) Rz(gamma): orthonormal, det 1, its third
    column (the body z axis) [sin a sin b, -cos a sin b, cos b]; R(0) = I."""
    model, k = spatial
    rng = np.random.default_rng(seed)
    ang = random_angles(rng)
    q = np.r_[rng.uniform(-1, 1, 3), ang]
    R = core_R(model, k, q)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-14)
    assert np.isclose(np.linalg.det(R), 1.0)
    a, b, g = ang
    assert np.allclose(R, rz(a) @ rx(b) @ rz(g), atol=1e-15)
    assert np.allclose(R[:, 2], [math.sin(a) * math.sin(b), -math.cos(a) * math.sin(b), math.cos(b)])
    assert np.allclose(core_R(model, k, np.r_[0.0, 0.0, 0.0, 0.0, 0.5, 0.0]), rx(0.5), atol=1e-15)


@pytest.mark.parametrize("ang", [[-math.pi / 4, -math.pi / 4, 0.0], [-math.pi / 4, math.pi / 4, 0.0],
                                 [math.pi / 2, math.pi / 2, 0.0]])
def test_euler_R_at_paper_angles(spatial, ang):
    """The paper's link orientations (Sec. 4.2): the core's R is Rz Rx Rz there too."""
    model, k = spatial
    a, b, g = ang
    assert np.max(np.abs(core_R(model, k, np.r_[0.0, 0.0, 0.0, ang]) - rz(a) @ rx(b) @ rz(g))) <= 1e-15


# ------------------------------------------------------------------------------- rates

@pytest.mark.parametrize("seed", SEEDS)
def test_euler_rates_from_body_omega(spatial, seed):
    """The core's Euler-angle rates phi' = H omega (B.15): omega_body = vee(R^T dR/dt) along
    phi + t phi' (central differences of the core's R), and H^-1 phi' = omega with the closed
    form H^-1 = [[sb sg, cg, 0], [sb cg, -sg, 0], [cb, 0, 1]]."""
    model, k = spatial
    rng = np.random.default_rng(seed)
    ang = random_angles(rng)
    q = np.r_[rng.uniform(-1, 1, 3), ang]
    omega = rng.normal(size=3)
    h = np.r_[rng.normal(size=3), omega]
    qd = rates(k, model, q, h)
    assert np.array_equal(qd[:3], h[:3])
    phi_dot = qd[3:]
    R = core_R(model, k, q)
    Rdot = (core_R(model, k, q + EPS_FD * qd) - core_R(model, k, q - EPS_FD * qd)) / (2 * EPS_FD)
    W = R.T @ Rdot
    assert np.allclose(W, -W.T, atol=1e-8)
    assert np.allclose(vee(W), omega, atol=1e-7 * max(1.0, float(np.max(np.abs(phi_dot)))))
    _, b, g = ang
    sb, cb, sg, cg = math.sin(b), math.cos(b), math.sin(g), math.cos(g)
    Hinv = np.array([[sb * sg, cg, 0.0], [sb * cg, -sg, 0.0], [cb, 0.0, 1.0]])
    assert np.allclose(Hinv @ phi_dot, omega, atol=1e-13 * max(1.0, float(np.max(np.abs(phi_dot)))))


@pytest.mark.parametrize("beta", [0.0, 1e-4, -5e-4, math.pi, math.pi - 2e-4, -math.pi + 1e-5, 2 * math.pi])
def test_euler_singularity_refused_naming_the_body(spatial, beta):
    """|sin beta| < 1e-3: the core refuses the rates (status 3, "Euler angles singular") naming the
    body (its index) and |sin beta|."""
    model, k = spatial
    assert abs(math.sin(beta)) < SIN_BETA_MIN
    y = np.r_[0.0, 0.0, 0.0, 0.3, beta, -1.2, np.ones(6)]
    assert k.evaluate(0.0, y) is None and k.last_status == 3
    assert k.last_message.startswith("Euler angles singular: body 0 has |sin beta| = ")
    assert k.last_message.endswith("< 0.001")


@pytest.mark.parametrize("beta", [2 * SIN_BETA_MIN, -2 * SIN_BETA_MIN, math.pi - 2 * SIN_BETA_MIN, 0.3])
def test_euler_rates_finite_just_outside_threshold(spatial, beta):
    """Just outside the threshold the rates are finite and invert the closed-form H^-1."""
    model, k = spatial
    omega = np.array([0.3, -0.2, 0.5])
    qd = rates(k, model, np.r_[0.0, 0.0, 0.0, 0.3, beta, -1.2], np.r_[0.0, 0.0, 0.0, omega])
    assert np.all(np.isfinite(qd))
    sb, cb, sg, cg = math.sin(beta), math.cos(beta), math.sin(-1.2), math.cos(-1.2)
    Hinv = np.array([[sb * sg, cg, 0.0], [sb * cg, -sg, 0.0], [cb, 0.0, 1.0]])
    assert np.allclose(Hinv @ qd[3:], omega, atol=1e-9)
