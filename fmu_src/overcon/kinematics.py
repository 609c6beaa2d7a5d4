"""Rotation matrices at a given configuration (paper Eq. 35, 40), for compiling a model (the
joints' constants from the bodies' rotations at q0: :func:`overcon.model._rotations`) and the
checks of its initial state (:mod:`overcon.checks`). The rotations, their derivatives and the
coordinate rates of a run are the compiled core's (core/frames.c, core/rates.c).

Planar: ``R(phi)`` (2x2, :func:`rot2_rows`) maps body-frame vectors to the global frame;
``OMEGA`` is the 90 degree rotation [[0, -1], [1, 0]].

Spatial: z-x-z Euler angles ``(alpha, beta, gamma)``, ``R = Rz(alpha) Rx(beta) Rz(gamma)``
(Eq. 40, :func:`euler_R_rows`). The Euler-rate matrix H (B.15) is singular at ``sin(beta) = 0``:
the angles are refused where ``|sin beta|`` falls below :data:`SIN_BETA_MIN`
(:func:`euler_singular`; the core applies the same bound in core/rates.c).

Spatial, ``rotation = "quaternion"``: a quaternion ``e = (e0, e1, e2, e3)``, scalar first, body
to global (``R(e) s = e (0, s) e*``), valid in every orientation. The rotation matrix is always
built from ``e / |e|`` (:func:`quat_R_rows`), so the dynamics never see a non-unit quaternion.
The core integrates ``e' = 1/2 e (x) (0, omega)`` (omega in body axes) plus the norm
stabilisation ``QUAT_NORM_RATE / 2 (1 - |e|^2) e`` (core/rates.c). The added term is along e, so
it never changes e / |e| (the orientation, hence the motion); it pulls |e| back to 1 at the rate
:data:`QUAT_NORM_RATE` against the integrator's error. A stabilisation term (rather than
projecting e after every step) keeps y' one smooth function of y, so every integrator (FSAL
stages, dense output, Radau's Newton iteration) and the saved FMU state work unchanged.

Floating point: sines and cosines are ``math.sin``/``math.cos`` (:func:`cos_sin`), not the SIMD
kernels of ``np.sin``/``np.cos``, whose last bit may differ between machines.
"""
from __future__ import annotations

import math

import numpy as np

OMEGA = np.array([[0.0, -1.0], [1.0, 0.0]])

SIN_BETA_MIN = 1e-3
"""Smallest |sin(beta)| integrated through (beta within 0.057 degrees of 0 or pi is refused):
H(beta) grows as 1/sin(beta) and the z-x-z parametrisation is singular there (core/core.h
mirrors it)."""

QUAT_NORM_RATE = 1.0
"""Rate k (1/s) of the quaternion norm stabilisation: ``d|e|^2/dt = k (1 - |e|^2) |e|^2``, so a
norm error decays as exp(-k t) (core/core.h mirrors it). Never stiff inside the step envelope
(steps <= 1 s, so h k <= 1, inside the stability region of rk4, dopri5, dop853 and radau); the
norm error is then bounded by the integrator error made in about 1/k seconds."""


def euler_singular(sin_beta):
    """Whether the z-x-z angles are refused at sin(beta) = ``sin_beta`` (a float or an array):
    ``|sin beta| < SIN_BETA_MIN``; the check of q0 after compiling
    (:func:`overcon.checks.check_initial_state`) uses it."""
    return np.abs(sin_beta) < SIN_BETA_MIN


def cos_sin(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cos, sin) of every entry (math.cos/math.sin, see the module docstring)."""
    flat = values.ravel().tolist()
    c = np.array([math.cos(x) for x in flat]).reshape(values.shape)
    s = np.array([math.sin(x) for x in flat]).reshape(values.shape)
    return c, s


def rot2_rows(phi: np.ndarray) -> np.ndarray:
    """Planar rotation matrices (len(phi), 2, 2) of the angles phi (rad), body -> global."""
    c, s = cos_sin(np.asarray(phi, float))
    R = np.empty((len(c), 2, 2))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = c, -s, s, c
    return R


def euler_R_rows(angles: np.ndarray, cs=None) -> np.ndarray:
    """Rotation matrices body -> global (n, 3, 3) of (n, 3) z-x-z Euler angles (rad, Eq. 40),
    Rz(alpha) Rx(beta) Rz(gamma); ``cs``: their :func:`cos_sin` if already known."""
    n = angles.shape[0]
    c, s = cos_sin(angles) if cs is None else cs
    za = np.zeros((n, 3, 3))
    xb = np.zeros((n, 3, 3))
    zg = np.zeros((n, 3, 3))
    za[:, 0, 0] = za[:, 1, 1] = c[:, 0]
    za[:, 0, 1] = -s[:, 0]
    za[:, 1, 0] = s[:, 0]
    za[:, 2, 2] = 1.0
    xb[:, 0, 0] = 1.0
    xb[:, 1, 1] = xb[:, 2, 2] = c[:, 1]
    xb[:, 1, 2] = -s[:, 1]
    xb[:, 2, 1] = s[:, 1]
    zg[:, 0, 0] = zg[:, 1, 1] = c[:, 2]
    zg[:, 0, 1] = -s[:, 2]
    zg[:, 1, 0] = s[:, 2]
    zg[:, 2, 2] = 1.0
    return np.matmul(np.matmul(za, xb), zg)


def euler_R(angles) -> np.ndarray:
    """The rotation matrix (3, 3) of one set of z-x-z Euler angles: :func:`euler_R_rows` of one
    row (for writing scenes and tests)."""
    return euler_R_rows(np.asarray(angles, float).reshape(1, 3))[0]


def quat_R_rows(e: np.ndarray) -> np.ndarray:
    """Rotation matrices body -> global (n, 3, 3) of (n, 4) quaternions (scalar first), each
    normalised first (R of e / |e|; |e| > 0 assumed)."""
    u = e / np.sqrt(((e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1]) + e[:, 2] * e[:, 2]) + e[:, 3] * e[:, 3])[:, None]
    e0, e1, e2, e3 = u[:, 0], u[:, 1], u[:, 2], u[:, 3]
    R = np.empty((e.shape[0], 3, 3))
    R[:, 0, 0] = e0 * e0 + e1 * e1 - e2 * e2 - e3 * e3
    R[:, 0, 1] = 2.0 * (e1 * e2 - e0 * e3)
    R[:, 0, 2] = 2.0 * (e1 * e3 + e0 * e2)
    R[:, 1, 0] = 2.0 * (e1 * e2 + e0 * e3)
    R[:, 1, 1] = e0 * e0 - e1 * e1 + e2 * e2 - e3 * e3
    R[:, 1, 2] = 2.0 * (e2 * e3 - e0 * e1)
    R[:, 2, 0] = 2.0 * (e1 * e3 - e0 * e2)
    R[:, 2, 1] = 2.0 * (e2 * e3 + e0 * e1)
    R[:, 2, 2] = e0 * e0 - e1 * e1 - e2 * e2 + e3 * e3
    return R


def quat_mul(a, b) -> np.ndarray:
    """Quaternion product a (x) b, scalar first."""
    a0, av, b0, bv = a[0], np.asarray(a[1:], float), b[0], np.asarray(b[1:], float)
    return np.concatenate([[a0 * b0 - av @ bv], a0 * bv + b0 * av + np.cross(av, bv)])


def euler_to_quat(angles) -> np.ndarray:
    """Unit quaternion (scalar first) of z-x-z Euler angles: the rotation :func:`euler_R`, as
    qz(alpha) (x) qx(beta) (x) qz(gamma) (e0 >= 0 not enforced); for writing a quaternion q0."""
    a, b, g = angles
    qa = [math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)]
    qb = [math.cos(b / 2), math.sin(b / 2), 0.0, 0.0]
    qg = [math.cos(g / 2), 0.0, 0.0, math.sin(g / 2)]
    return quat_mul(quat_mul(qa, qb), qg)
