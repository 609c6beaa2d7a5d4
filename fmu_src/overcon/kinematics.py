"""Rotation matrices and their derivatives (paper Eq. 35, 40, B.13, B.15).

Planar: ``R(phi)`` (2x2) maps body-frame vectors to the global frame; ``OMEGA`` is the 90 degree
rotation [[0, -1], [1, 0]], so ``dR/dphi = OMEGA @ R = R @ OMEGA``; the planar cross product
``a x b = (OMEGA @ a) . b`` is :func:`cross2`.

Spatial: z-x-z Euler angles ``(alpha, beta, gamma)``, ``R = Rz(alpha) Rx(beta) Rz(gamma)``
(Eq. 40). Angular velocity ``omega`` is expressed in body axes and ``phi_dot = H(beta, gamma)
omega`` (Eq. 4, B.15). ``H`` is singular at ``sin(beta) = 0``: :func:`euler_H` raises
:class:`EulerSingularity` when ``|sin beta|`` falls below :data:`SIN_BETA_MIN`.

Spatial, ``rotation = "quaternion"``: a quaternion ``e = (e0, e1, e2, e3)``, scalar first, body
to global (``R(e) s = e (0, s) e*``), valid in every orientation. The rotation matrix is always
built from ``e / |e|`` (:func:`quat_R_rows`), so the dynamics never see a non-unit quaternion.
Kinematics (omega in body axes): ``e' = 1/2 e (x) (0, omega)`` plus the norm stabilisation
``QUAT_NORM_RATE / 2 (1 - |e|^2) e`` (:func:`quat_rates_rows`). The added term is along e, so it
never changes e / |e| (the orientation, hence the motion); it pulls |e| back to 1 at the rate
:data:`QUAT_NORM_RATE` against the integrator's error. A stabilisation term (rather than projecting
e after every step) keeps y' one smooth function of y, so every integrator (FSAL stages, dense
output, Radau's Newton iteration), the lockstep runs and the saved FMU state work unchanged.
"""
from __future__ import annotations

import math

import numpy as np

OMEGA = np.array([[0.0, -1.0], [1.0, 0.0]])
OMEGA_X = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
OMEGA_Z = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])

SIN_BETA_MIN = 1e-3
"""Smallest |sin(beta)| integrated through (beta within 0.057 degrees of 0 or pi is refused):
H(beta) grows as 1/sin(beta) and the z-x-z parametrisation is singular there."""


class EulerSingularity(ArithmeticError):
    """z-x-z Euler parametrisation singular (sin beta ~ 0)."""


def euler_singular(sin_beta):
    """Whether the z-x-z angles are refused at sin(beta) = ``sin_beta`` (a float or an array):
    ``|sin beta| < SIN_BETA_MIN``. The one test of the singularity: :func:`euler_H` (integration)
    and the check of q0 after compiling (:func:`overcon.checks.check_initial_state`) use it."""
    return np.abs(sin_beta) < SIN_BETA_MIN


def rot2(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s], [s, c]])


def cross2(a: np.ndarray, b: np.ndarray) -> float:
    """Planar cross product a x b (scalar, counter-clockwise positive)."""
    return a[0] * b[1] - a[1] * b[0]


def rz(psi: float) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rx(psi: float) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def euler_R(angles) -> np.ndarray:
    """Direction cosine matrix body -> global of z-x-z Euler angles (paper Eq. 40)."""
    a, b, g = angles
    return rz(a) @ rx(b) @ rz(g)


def euler_dR(angles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Partial derivatives dR/dalpha, dR/dbeta, dR/dgamma (paper B.13)."""
    a, b, g = angles
    Ra, Rb, Rg = rz(a), rx(b), rz(g)
    return OMEGA_Z @ Ra @ Rb @ Rg, Ra @ OMEGA_X @ Rb @ Rg, Ra @ Rb @ OMEGA_Z @ Rg


def euler_H(angles, body: str = "") -> np.ndarray:
    """H of paper B.15: Euler-angle rates = H @ omega (omega in body axes)."""
    _, b, g = angles
    sb, cb = math.sin(b), math.cos(b)
    if euler_singular(sb):
        raise EulerSingularity(
            f"Euler angle singularity{' of body ' + repr(body) if body else ''}: "
            f"beta = {b:.6g} rad, |sin(beta)| = {abs(sb):.3g} < {SIN_BETA_MIN:g}"
        )
    sg, cg = math.sin(g), math.cos(g)
    return np.array([
        [sg / sb, cg / sb, 0.0],
        [cg, -sg, 0.0],
        [-cb * sg / sb, -cb * cg / sb, 1.0],
    ])


QUAT_NORM_RATE = 1.0
"""Rate k (1/s) of the quaternion norm stabilisation: ``d|e|^2/dt = k (1 - |e|^2) |e|^2``, so a
norm error decays as exp(-k t). Never stiff inside the step envelope (steps <= 1 s, so
h k <= 1, inside the stability region of rk4, dopri5, dop853 and radau); the norm error is then
bounded by the integrator error made in about 1/k seconds."""


def quat_mul(a, b) -> np.ndarray:
    """Quaternion product a (x) b, scalar first."""
    a0, av, b0, bv = a[0], np.asarray(a[1:], float), b[0], np.asarray(b[1:], float)
    return np.concatenate([[a0 * b0 - av @ bv], a0 * bv + b0 * av + cross3(av, bv)])


def euler_to_quat(angles) -> np.ndarray:
    """Unit quaternion (scalar first) of z-x-z Euler angles: the rotation :func:`euler_R`, as
    qz(alpha) (x) qx(beta) (x) qz(gamma) (e0 >= 0 not enforced)."""
    a, b, g = angles
    qa = [math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)]
    qb = [math.cos(b / 2), math.sin(b / 2), 0.0, 0.0]
    qg = [math.cos(g / 2), 0.0, 0.0, math.sin(g / 2)]
    return quat_mul(quat_mul(qa, qb), qg)


def cross3(a, b) -> np.ndarray:
    """a x b for two 3-vectors (np.cross carries a large per-call overhead for single vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def skew(v) -> np.ndarray:
    """Skew-symmetric matrix with skew(a) @ b = a x b."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


# ----------------------------------------------------------------------------- batched forms
# The batched helpers below reproduce the single-item functions above bit for bit: elementwise
# arithmetic in the same order, math.sin/math.cos (not np.sin/np.cos, whose SIMD kernels may differ
# in the last bit) and stacked np.matmul (which runs the same inner kernel per stacked item).

_ROT1 = np.array([1, 2, 0])
_ROT2 = np.array([2, 0, 1])


def cross3_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b along the last axis of (..., 3) arrays; each row equals :func:`cross3` of the rows
    (components a1 b2 - a2 b1, a2 b0 - a0 b2, a0 b1 - a1 b0)."""
    return a.take(_ROT1, -1) * b.take(_ROT2, -1) - a.take(_ROT2, -1) * b.take(_ROT1, -1)


if hasattr(np, "vecdot"):
    def rowdot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Row-wise a . b ((k, n) -> (k,)), bitwise equal to ``a[k] @ b[k]`` (same dot kernel)."""
        return np.vecdot(a, b)
else:  # numpy < 2: equal to round-off
    def rowdot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Row-wise a . b ((k, n) -> (k,))."""
        return np.einsum("...i,...i->...", a, b)


def dot3_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a . b of (k, 3) arrays by elementwise arithmetic, a0 b0 + a1 b1 + a2 b2 in that
    order: the same bits for a row whatever the batch and whatever the BLAS kernel. (A BLAS dot
    may peel elements for memory alignment and so sum a row in another order depending on where
    it lies: measured with OPENBLAS_CORETYPE=Prescott, where np.vecdot gave a joint other bits in
    a batch than alone.) The spatial joints' rows use it (:mod:`overcon.joints.spatial_rows`)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Stacked A[k] @ x[k] ((k, r, c) and (k, c) -> (k, r)), bitwise equal to the single products."""
    return np.matmul(A, x[..., None])[..., 0]


def rot2_rows(phi: np.ndarray) -> np.ndarray:
    """Planar rotation matrices (len(phi), 2, 2) of the angles phi (rad), body -> global."""
    c, s = np.cos(phi), np.sin(phi)
    R = np.empty((len(phi), 2, 2))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = c, -s, s, c
    return R


def cos_sin(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cos, sin) of every entry (math.cos/math.sin, the single-item functions' numbers)."""
    flat = values.ravel().tolist()
    c = np.array([math.cos(x) for x in flat]).reshape(values.shape)
    s = np.array([math.sin(x) for x in flat]).reshape(values.shape)
    return c, s


def euler_R_rows(angles: np.ndarray, cs=None) -> np.ndarray:
    """Stacked :func:`euler_R` of (n, 3) z-x-z Euler angles -> (n, 3, 3), bitwise equal; ``cs``:
    their :func:`cos_sin` if already known."""
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


def euler_H_rows(angles: np.ndarray, bodies=(), cs=None) -> np.ndarray:
    """Stacked :func:`euler_H` of (n, 3) Euler angles -> (n, 3, 3), bitwise equal; raises
    :class:`EulerSingularity` for the first singular row (named from ``bodies`` as euler_H does).
    ``cs``: the :func:`cos_sin` of ``angles[:, 1:]`` if already known."""
    n = angles.shape[0]
    c, s = cos_sin(angles[:, 1:]) if cs is None else cs
    cb, sb, cg, sg = c[:, 0], s[:, 0], c[:, 1], s[:, 1]
    bad = euler_singular(sb)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        euler_H(angles[k], bodies[k] if k < len(bodies) else "")  # raises with the usual message
    H = np.zeros((n, 3, 3))
    H[:, 0, 0] = sg / sb
    H[:, 0, 1] = cg / sb
    H[:, 1, 0] = cg
    H[:, 1, 1] = -sg
    H[:, 2, 0] = -cb * sg / sb
    H[:, 2, 1] = -cb * cg / sb
    H[:, 2, 2] = 1.0
    return H


def quat_R_rows(e: np.ndarray) -> np.ndarray:
    """Rotation matrices body -> global (n, 3, 3) of (n, 4) quaternions (scalar first), each
    normalised first (R of e / |e|; |e| > 0 assumed)."""
    u = e / np.sqrt(rowdot(e, e))[:, None]
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


def quat_rates_rows(e: np.ndarray, w: np.ndarray, rate: float = QUAT_NORM_RATE) -> np.ndarray:
    """e' (n, 4) of quaternions e (n, 4) and body-axes angular velocities w (n, 3, rad/s):
    ``1/2 e (x) (0, w) = 1/2 [-ev . w, e0 w + ev x w]`` plus the norm stabilisation
    ``rate / 2 (1 - |e|^2) e`` (1/s; see the module docstring)."""
    ev = e[:, 1:]
    out = np.empty_like(e)
    out[:, 0] = -0.5 * rowdot(ev, w)
    out[:, 1:] = 0.5 * (e[:, :1] * w + cross3_rows(ev, w))
    out += (0.5 * rate * (1.0 - rowdot(e, e)))[:, None] * e
    return out
