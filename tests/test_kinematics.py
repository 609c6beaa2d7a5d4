"""Tests of overcon.kinematics: rotation matrices, their derivatives (B.13) and the Euler-rate
matrix H of B.15 (phi_dot = H omega, omega in body axes), checked against finite differences."""
from __future__ import annotations

import math

import numpy as np
import pytest

from overcon.kinematics import (
    OMEGA,
    SIN_BETA_MIN,
    EulerSingularity,
    cross2,
    cross3,
    euler_dR,
    euler_H,
    euler_R,
    rot2,
    rx,
    rz,
    skew,
)

SEEDS = [0, 1, 2, 3, 4]


def random_angles(rng) -> np.ndarray:
    """z-x-z angles with beta kept away from 0 and +-pi (either sign)."""
    a, g = rng.uniform(-math.pi, math.pi, 2)
    b = rng.uniform(0.3, 2.8) * rng.choice([-1.0, 1.0])
    return np.array([a, b, g])


def vee(W: np.ndarray) -> np.ndarray:
    """Inverse of skew: the vector of a (numerically) skew-symmetric 3x3 matrix."""
    return np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2.0


# ------------------------------------------------------------------------------- basics

@pytest.mark.parametrize("seed", SEEDS)
def test_rot2_cross2_basics(seed):
    rng = np.random.default_rng(seed)
    a, b = rng.uniform(-4, 4, 2)
    R = rot2(a)
    assert np.allclose(R.T @ R, np.eye(2), atol=1e-15)
    assert np.isclose(np.linalg.det(R), 1.0)
    assert np.allclose(rot2(a) @ rot2(b), rot2(a + b), atol=1e-14)
    assert np.allclose(R @ [1.0, 0.0], [math.cos(a), math.sin(a)])  # body x axis, ccw positive
    # dR/dphi = OMEGA R = R OMEGA
    eps = 1e-6
    dR = (rot2(a + eps) - rot2(a - eps)) / (2 * eps)
    assert np.allclose(dR, OMEGA @ R, atol=1e-9)
    assert np.allclose(OMEGA @ R, R @ OMEGA, atol=1e-15)
    u, v = rng.normal(size=(2, 2))
    assert np.isclose(cross2(u, v), np.cross(np.r_[u, 0.0], np.r_[v, 0.0])[2])
    assert np.isclose(cross2(u, v), (OMEGA @ u) @ v)
    assert cross2([1.0, 0.0], [0.0, 1.0]) == 1.0
    assert np.isclose(cross2(u, v), -cross2(v, u))


@pytest.mark.parametrize("seed", SEEDS)
def test_cross3_skew_basics(seed):
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(2, 3))
    assert np.allclose(cross3(a, b), np.cross(a, b), atol=1e-14)
    assert np.allclose(skew(a) @ b, np.cross(a, b), atol=1e-14)
    assert np.allclose(skew(a).T, -skew(a))
    assert np.allclose(vee(skew(a)), a)
    assert np.allclose(cross3([1.0, 0, 0], [0, 1.0, 0]), [0, 0, 1.0])
    # rotation covariance: R (a x b) = (R a) x (R b)
    R = euler_R(random_angles(rng))
    assert np.allclose(R @ cross3(a, b), cross3(R @ a, R @ b), atol=1e-13)


def test_elementary_rotations():
    t = 0.7
    assert np.allclose(rz(t)[:2, :2], rot2(t)) and rz(t)[2, 2] == 1.0
    assert np.allclose(rx(t)[1:, 1:], rot2(t)) and rx(t)[0, 0] == 1.0


@pytest.mark.parametrize("seed", SEEDS)
def test_euler_R_is_zxz_rotation(seed):
    rng = np.random.default_rng(seed)
    ang = random_angles(rng)
    R = euler_R(ang)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-14)
    assert np.isclose(np.linalg.det(R), 1.0)
    a, b, g = ang
    assert np.allclose(R, rz(a) @ rx(b) @ rz(g))
    # third column (body z axis in global) of z-x-z: [sin a sin b, -cos a sin b, cos b]
    assert np.allclose(R[:, 2], [math.sin(a) * math.sin(b), -math.cos(a) * math.sin(b), math.cos(b)])
    assert np.allclose(euler_R([0.0, 0.0, 0.0]), np.eye(3))


# ------------------------------------------------------------------------------- derivatives

@pytest.mark.parametrize("seed", SEEDS)
def test_euler_dR_matches_central_differences(seed):
    rng = np.random.default_rng(seed)
    ang = random_angles(rng)
    eps = 1e-6
    dRs = euler_dR(ang)
    assert len(dRs) == 3
    for k in range(3):
        e = np.zeros(3)
        e[k] = eps
        fd = (euler_R(ang + e) - euler_R(ang - e)) / (2 * eps)
        assert np.allclose(dRs[k], fd, atol=1e-9, rtol=0), k


def test_euler_dR_at_paper_angles():
    for ang in ([-math.pi / 4, -math.pi / 4, 0.0], [-math.pi / 4, math.pi / 4, 0.0],
                [math.pi / 2, math.pi / 2, 0.0], [0.0, 0.0, 0.0]):
        ang = np.array(ang)
        eps = 1e-6
        for k in range(3):
            e = np.zeros(3)
            e[k] = eps
            fd = (euler_R(ang + e) - euler_R(ang - e)) / (2 * eps)
            assert np.allclose(euler_dR(ang)[k], fd, atol=1e-9, rtol=0)


@pytest.mark.parametrize("seed", SEEDS)
def test_euler_H_rates_from_body_omega(seed):
    """Along a random angle path phi(t): omega_body = vee(R^T dR/dt) and phi_dot = H(phi) omega."""
    rng = np.random.default_rng(seed)
    p0 = random_angles(rng)
    p1, p2 = rng.normal(size=(2, 3))

    def path(t):
        return p0 + p1 * t + p2 * t**2

    for t in (0.0, 0.01, -0.02):
        eps = 1e-6
        R = euler_R(path(t))
        Rdot = (euler_R(path(t + eps)) - euler_R(path(t - eps))) / (2 * eps)
        W = R.T @ Rdot
        assert np.allclose(W, -W.T, atol=1e-8)  # skew-symmetric up to FD error
        omega = vee(W)
        phi_dot = p1 + 2 * p2 * t
        H = euler_H(path(t))
        assert np.allclose(H @ omega, phi_dot, atol=1e-7, rtol=0)
        assert np.allclose(np.linalg.solve(H, phi_dot), omega, atol=1e-7, rtol=0)
        # the same via the exact partials of B.13: R^T sum_k dR/dphi_k phi_dot_k = skew(omega)
        Wx = R.T @ sum(dR * pd for dR, pd in zip(euler_dR(path(t)), phi_dot))
        assert np.allclose(vee(Wx), omega, atol=1e-7)


@pytest.mark.parametrize("beta", [0.0, 1e-4, -5e-4, math.pi, math.pi - 2e-4, -math.pi + 1e-5,
                                  2 * math.pi])
def test_euler_H_singularity_raised_with_body_name(beta):
    assert abs(math.sin(beta)) < SIN_BETA_MIN
    with pytest.raises(EulerSingularity, match="Euler angle singularity of body 'link7'") as exc:
        euler_H([0.3, beta, -1.2], "link7")
    assert "link7" in str(exc.value)
    with pytest.raises(ArithmeticError, match="Euler angle singularity"):  # EulerSingularity is an ArithmeticError
        euler_H([0.3, beta, -1.2])


@pytest.mark.parametrize("beta", [2 * SIN_BETA_MIN, -2 * SIN_BETA_MIN, math.pi - 2 * SIN_BETA_MIN, 0.3])
def test_euler_H_finite_just_outside_threshold(beta):
    H = euler_H([0.3, beta, -1.2], "link7")
    assert np.all(np.isfinite(H))
    # H^-1 = the body-omega matrix [[sb sg, cg, 0], [sb cg, -sg, 0], [cb, 0, 1]]
    a, b, g = 0.3, beta, -1.2
    sb, cb, sg, cg = math.sin(b), math.cos(b), math.sin(g), math.cos(g)
    Hinv = np.array([[sb * sg, cg, 0.0], [sb * cg, -sg, 0.0], [cb, 0.0, 1.0]])
    assert np.allclose(H @ Hinv, np.eye(3), atol=1e-9)
