"""The three constraint-row primitives of the spatial joints (revolute, prismatic, cylindrical,
universal, fixed), their constants, reaction frame and friction kinematics, written once and
reused by every type (batched over k joints, see :mod:`overcon.joints`).

Notation (units m, rad; global frame pi_0 unless "body axes" is said): body k has position r_k,
rotation matrix R_k (body axes -> global), velocities h_k = [v_k (global), omega_k (body axes)],
so d/dt (R_k x) = R_k (omega_k x x) for a body-fixed x. The joint point on body k is
P_k = r_k + R_k s_k. Every row value phi has a modified Jacobian (phi' = Ji h_i + Jj h_j, each
(k, n, 6)) and gamma = -(phi'' at h' = 0), so Phi_h h' = gamma (Eq. 11).

Primitives (``ROW`` objects; a joint type is a tuple of them, its rows in that order):

- :data:`POINT` (3 rows) d = P_i - P_j: Ji = [I, -R_i skew(s_i)], Jj = [-I, R_j skew(s_j)],
  gamma = -R_i (w_i x (w_i x s_i)) + R_j (w_j x (w_j x s_j)) (as the spherical joint);
- :class:`Dot` (1 row) (R_i a)·(R_j b), a fixed in body i, b in body j:
  Ji = [0, a x (R_i^T B)], Jj = [0, b x (R_j^T A)] (A = R_i a, B = R_j b),
  gamma = -(R_i(w_i x (w_i x a))·B + 2 R_i(w_i x a)·R_j(w_j x b) + A·R_j(w_j x (w_j x b)));
- :class:`PointDot` (1 row) d·(R_j b), b fixed in body j:
  Ji = [B, s_i x (R_i^T B)], Jj = [-B, -s_j x (R_j^T B) + b x (R_j^T d)],
  gamma = -(d''·B + 2 d'·B' + d·B''), d' = v_i + R_i(w_i x s_i) - v_j - R_j(w_j x s_j),
  d'' = R_i(w_i x (w_i x s_i)) - R_j(w_j x (w_j x s_j)), B' = R_j(w_j x b), B'' = R_j(w_j x (w_j x b)).

Row meanings (the one place they are declared): every primitive states what its rows hold, read
by the compiler's initial-state message (:func:`row_meanings`, :func:`violation_text`):
:data:`POINT` and :class:`PointDot` rows are ``"point"`` rows (on the joint points: q0 at fault),
a :class:`Dot` row holds axis_i ``"parallel"`` or ``"perpendicular"`` to axis_j, or is a rotation
``"lock"`` row. A violated axis row at q0 names the fields axis_i and axis_j and the angle between
the axes; a lock row holds at q0 by construction of ``c_i``.

Axis constants (decided here): the axes are normalised; ``b1_j``, ``b2_j`` complete ``a_j`` to
an orthonormal basis of body j by a deterministic rule (:func:`completion`: the standard basis
vector least aligned with the axis, the first on ties, Gram-Schmidt against the axis, then
b2 = a x b1). The rotation lock about the axis uses ``c_i = R_i0^T R_j0 b1_j`` (b1_j seen from
body i at the initial configuration q0), so the lock row (R_i c_i)·(R_j b2_j) is zero at q0.

Reaction frame (on body i, at P_i): z along axis_i, x and y the completion of axis_i by the same
rule. The physical reaction on body i is -(J_X)_i^T lam_X = [F (global), T (body axes, about the
centre of mass)]; the moment about P_i is T - s_i x (R_i^T F) (body axes). :func:`frame_reaction`
gives [F', T'] = [Fx, Fy, Fz, Tx, Ty, Tz] in the reaction frame; each type reports its
non-vanishing components.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics import cross3_rows, dot3_rows, matvec


# ----------------------------------------------------------------------------- constants

def completion(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(b1, b2): unit vectors completing the unit vector a to a right-handed orthonormal basis
    (b1, b2, a): b1 from the standard basis vector least aligned with a (the first on ties),
    made orthogonal to a (Gram-Schmidt), b2 = a x b1."""
    e = np.zeros(3)
    e[int(np.argmin(np.abs(a)))] = 1.0  # argmin returns the first minimum
    b1 = e - (e @ a) * a
    b1 = b1 / np.linalg.norm(b1)
    return b1, np.cross(a, b1)


def unit(v) -> np.ndarray:
    """v / |v| (the loader refuses a zero or non-normalisable direction)."""
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def axis_constants(params, init) -> dict:
    """One joint's constants from its file fields and its bodies' rotation matrices at q0
    (``init.R_i``, ``init.R_j``, body -> global): joint points ``s_i``, ``s_j`` (m, body axes),
    unit axes ``a_i``, ``a_j`` (a missing axis_i is [0, 0, 1], a missing axis_j the image of
    axis_i in body j at q0), the completion ``b1_j``, ``b2_j`` of a_j, the lock vector
    ``c_i = R_i0^T R_j0 b1_j`` and the reaction frame ``E`` (columns x, y, z = completion of a_i
    and a_i, in body i axes)."""
    C0 = init.R_i.T @ init.R_j  # body j axes -> body i axes at q0
    a_i = unit(params["axis_i"]) if params.get("axis_i") is not None else np.array([0.0, 0.0, 1.0])
    a_j = unit(params["axis_j"]) if params.get("axis_j") is not None else C0.T @ a_i
    b1_j, b2_j = completion(a_j)
    x_i, y_i = completion(a_i)
    return {"s_i": np.asarray(params["s_i"], float), "s_j": np.asarray(params["s_j"], float),
            "a_i": a_i, "a_j": a_j, "b1_j": b1_j, "b2_j": b2_j, "c_i": C0 @ b1_j,
            "E": np.column_stack([x_i, y_i, a_i])}


_VECTORS = ("s_i", "s_j", "a_i", "a_j", "b1_j", "b2_j", "c_i")


def stack_axes(joints, sizes=()) -> dict:
    """Stacked body slots, constants and friction laws of k compiled joints of one spatial axis
    type (compile time), with the friction sizes named in ``sizes`` (m, from the laws)."""
    d = {"bi": np.array([c.bi for c in joints], np.intp), "bj": np.array([c.bj for c in joints], np.intp),
         "laws": tuple(c.law for c in joints),
         "E": np.array([c.p["E"] for c in joints], float).reshape(-1, 3, 3)}
    for key in _VECTORS:
        d[key] = np.array([c.p[key] for c in joints], float).reshape(-1, 3)
    for key in sizes:
        d[key] = law_sizes(d, key)
    return d


# ----------------------------------------------------------------------------- row primitives

def _skew_rows(s: np.ndarray) -> np.ndarray:
    """(k, 3, 3) skew matrices of (k, 3) vectors: skew(a) b = a x b."""
    out = np.zeros((len(s), 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -s[:, 2], s[:, 1]
    out[:, 1, 0], out[:, 1, 2] = s[:, 2], -s[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -s[:, 1], s[:, 0]
    return out


def _ww(w, x):
    """w x (w x x), row-wise."""
    return cross3_rows(w, cross3_rows(w, x))


def point_difference(d, f) -> np.ndarray:
    """(k, 3): d = P_i - P_j (global, m)."""
    bi, bj = d["bi"], d["bj"]
    return f.r[bi] + matvec(f.R[bi], d["s_i"]) - f.r[bj] - matvec(f.R[bj], d["s_j"])


POINT_ROW, PARALLEL, PERPENDICULAR, LOCK = "point", "parallel", "perpendicular", "lock"
"""The meanings of the rows (see the module docstring)."""


class _Point:
    """The 3 rows d = P_i - P_j."""

    n = 3
    meaning = POINT_ROW

    def value(self, d, f):
        return point_difference(d, f)

    def jac(self, d, f):
        k = len(d["bi"])
        Ji, Jj = np.zeros((k, 3, 6)), np.zeros((k, 3, 6))
        Ji[:, :, :3] = np.eye(3)
        Jj[:, :, :3] = -np.eye(3)
        Ji[:, :, 3:] = -np.matmul(f.R[d["bi"]], _skew_rows(d["s_i"]))
        Jj[:, :, 3:] = np.matmul(f.R[d["bj"]], _skew_rows(d["s_j"]))
        return Ji, Jj

    def gamma(self, d, f):
        bi, bj = d["bi"], d["bj"]
        return (matvec(f.R[bj], _ww(f.w[bj], d["s_j"])) - matvec(f.R[bi], _ww(f.w[bi], d["s_i"])))


POINT = _Point()


@dataclass(frozen=True)
class Dot:
    """1 row (R_i a)·(R_j b): ``a`` the key of a body i vector, ``b`` of a body j vector;
    ``meaning`` :data:`PARALLEL`, :data:`PERPENDICULAR` (axis_i to axis_j) or :data:`LOCK`."""

    a: str
    b: str
    meaning: str
    n: int = 1

    def value(self, d, f):
        return dot3_rows(matvec(f.R[d["bi"]], d[self.a]), matvec(f.R[d["bj"]], d[self.b]))[:, None]

    def jac(self, d, f):
        Ri, Rj = f.R[d["bi"]], f.R[d["bj"]]
        a, b = d[self.a], d[self.b]
        A, B = matvec(Ri, a), matvec(Rj, b)
        k = len(a)
        Ji, Jj = np.zeros((k, 1, 6)), np.zeros((k, 1, 6))
        Ji[:, 0, 3:] = cross3_rows(a, matvec(Ri.transpose(0, 2, 1), B))
        Jj[:, 0, 3:] = cross3_rows(b, matvec(Rj.transpose(0, 2, 1), A))
        return Ji, Jj

    def gamma(self, d, f):
        bi, bj = d["bi"], d["bj"]
        Ri, Rj, wi, wj = f.R[bi], f.R[bj], f.w[bi], f.w[bj]
        a, b = d[self.a], d[self.b]
        second = (dot3_rows(matvec(Ri, _ww(wi, a)), matvec(Rj, b))
                  + 2.0 * dot3_rows(matvec(Ri, cross3_rows(wi, a)), matvec(Rj, cross3_rows(wj, b)))
                  + dot3_rows(matvec(Ri, a), matvec(Rj, _ww(wj, b))))
        return -second[:, None]


@dataclass(frozen=True)
class PointDot:
    """1 row (P_i - P_j)·(R_j b): ``b`` the key of a body j vector."""

    b: str
    n: int = 1
    meaning: str = POINT_ROW

    def value(self, d, f):
        return dot3_rows(point_difference(d, f), matvec(f.R[d["bj"]], d[self.b]))[:, None]

    def jac(self, d, f):
        Ri, Rj = f.R[d["bi"]], f.R[d["bj"]]
        b = d[self.b]
        B = matvec(Rj, b)
        RjT = Rj.transpose(0, 2, 1)
        BinJ = matvec(RjT, B)
        k = len(b)
        Ji, Jj = np.zeros((k, 1, 6)), np.zeros((k, 1, 6))
        Ji[:, 0, :3] = B
        Jj[:, 0, :3] = -B
        Ji[:, 0, 3:] = cross3_rows(d["s_i"], matvec(Ri.transpose(0, 2, 1), B))
        Jj[:, 0, 3:] = (cross3_rows(b, matvec(RjT, point_difference(d, f)))
                        - cross3_rows(d["s_j"], BinJ))
        return Ji, Jj

    def gamma(self, d, f):
        bi, bj = d["bi"], d["bj"]
        Ri, Rj, wi, wj = f.R[bi], f.R[bj], f.w[bi], f.w[bj]
        b, s_i, s_j = d[self.b], d["s_i"], d["s_j"]
        dd1 = (f.v[bi] + matvec(Ri, cross3_rows(wi, s_i)) - f.v[bj] - matvec(Rj, cross3_rows(wj, s_j)))
        dd2 = matvec(Ri, _ww(wi, s_i)) - matvec(Rj, _ww(wj, s_j))
        second = (dot3_rows(dd2, matvec(Rj, b)) + 2.0 * dot3_rows(dd1, matvec(Rj, cross3_rows(wj, b)))
                  + dot3_rows(point_difference(d, f), matvec(Rj, _ww(wj, b))))
        return -second[:, None]


def phi(rows, d, f) -> np.ndarray:
    """(k, n_eq): the rows' values, in order."""
    return np.concatenate([r.value(d, f) for r in rows], 1)


def jac_h(rows, d, f):
    """(Ji, Jj), each (k, n_eq, 6): the rows' modified Jacobian blocks, in order."""
    blocks = [r.jac(d, f) for r in rows]
    return np.concatenate([b[0] for b in blocks], 1), np.concatenate([b[1] for b in blocks], 1)


def gamma(rows, d, f) -> np.ndarray:
    """(k, n_eq): the rows' gamma, in order."""
    return np.concatenate([r.gamma(d, f) for r in rows], 1)


def row_meanings(rows) -> tuple[str, ...]:
    """Per equation of a joint made of ``rows`` (in order): what it holds (the meanings above)."""
    return tuple(r.meaning for r in rows for _ in range(r.n))


def axis_angle(p, init) -> float:
    """Angle (deg, in [0, 180]) between axis_i and axis_j of one joint (constants ``p``) at the
    bodies' rotation matrices ``init`` (:class:`overcon.joints.InitialFrames`)."""
    c = float(np.dot(init.R_i @ p["a_i"], init.R_j @ p["a_j"]))
    return float(np.degrees(np.arccos(min(1.0, max(-1.0, c)))))


def violation_text(meaning: str, p, init) -> str:
    """What violated rows of ``meaning`` (not :data:`POINT_ROW`) of one joint say at q0: the axis
    fields and the angle between the axes (constants ``p``, rotations ``init`` at q0)."""
    if meaning == LOCK:
        return "the rotation about axis_i is not at its locked value at q0"
    return f"axis_i and axis_j are not {meaning} at q0 (angle {axis_angle(p, init):.4g} deg)"


# ----------------------------------------------------------------------------- reactions

def frame_reaction(d, f, fi) -> np.ndarray:
    """(k, 6): [Fx, Fy, Fz, Tx, Ty, Tz] of the physical reaction on body i in the reaction frame
    (N, N.m; moment about P_i), given fi = (J_X)_i^T lam_X (k, 6)."""
    RiT = f.R[d["bi"]].transpose(0, 2, 1)
    F_body = -matvec(RiT, fi[:, :3])
    T_point = -fi[:, 3:] - cross3_rows(d["s_i"], F_body)
    ET = d["E"].transpose(0, 2, 1)
    return np.concatenate((matvec(ET, F_body), matvec(ET, T_point)), 1)


# ----------------------------------------------------------------------------- friction kinematics

def axis_global(d, f) -> np.ndarray:
    """(k, 3): u = R_i a_i, the joint axis in the global frame."""
    return matvec(f.R[d["bi"]], d["a_i"])


def relative_spin(d, f, u) -> np.ndarray:
    """(k,): omega_rel = (omega_j - omega_i)·u, global angular velocities (rad/s)."""
    bi, bj = d["bi"], d["bj"]
    return dot3_rows(matvec(f.R[bj], f.w[bj]) - matvec(f.R[bi], f.w[bi]), u)


def relative_slide(d, f, u) -> np.ndarray:
    """(k,): v_rel = axial velocity (along u) of the material point of body j at P_i relative
    to that of body i (m/s)."""
    bi, bj = d["bi"], d["bj"]
    P = f.r[bi] + matvec(f.R[bi], d["s_i"])
    vi = f.v[bi] + matvec(f.R[bi], cross3_rows(f.w[bi], d["s_i"]))
    arm_j = matvec(f.R[bj].transpose(0, 2, 1), P - f.r[bj])
    vj = f.v[bj] + matvec(f.R[bj], cross3_rows(f.w[bj], arm_j))
    return dot3_rows(vj - vi, u)


def axial_loads(d, f, force, torque, u):
    """(Qi, Qj), each (k, 6): a force ``force`` u (N) at P_i and a torque ``torque`` u (N.m) on
    body i, and their opposites on body j (force at the same global point P_i)."""
    bi, bj = d["bi"], d["bj"]
    RiT, RjT = f.R[bi].transpose(0, 2, 1), f.R[bj].transpose(0, 2, 1)
    F = force[:, None] * u
    tau = torque[:, None] * u
    P = f.r[bi] + matvec(f.R[bi], d["s_i"])
    Qi = np.concatenate((F, cross3_rows(d["s_i"], matvec(RiT, F)) + matvec(RiT, tau)), 1)
    arm_j = matvec(RjT, P - f.r[bj])
    Qj = np.concatenate((-F, -cross3_rows(arm_j, matvec(RjT, F)) - matvec(RjT, tau)), 1)
    return Qi, Qj


def guide_normal_load(reaction: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(k,): |f_A| + |f_B| of a guide with contacts A at the joint point (z = 0) and B at
    z = l along the axis carrying the transverse force F_perp = (Fx, Fy) and the bending moment
    T_perp = (Tx, Ty): f_B = (T_perp x z)/l, f_A = F_perp - f_B (``reaction`` (k, 6) in the
    reaction frame; l (k,) in m)."""
    fB = np.stack((reaction[:, 4], -reaction[:, 3]), 1) / length[:, None]
    fA = reaction[:, :2] - fB
    return np.hypot(fA[:, 0], fA[:, 1]) + np.hypot(fB[:, 0], fB[:, 1])


def bearing_radial_load(reaction: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(k,): N_r = |f+| + |f-| of a bearing of length L centred at the joint point carrying
    F_perp and T_perp at its ends z = +-L/2: f+- = F_perp/2 +- (T_perp x z)/L."""
    m = np.stack((reaction[:, 4], -reaction[:, 3]), 1) / length[:, None]
    half = 0.5 * reaction[:, :2]
    fp, fm = half + m, half - m
    return np.hypot(fp[:, 0], fp[:, 1]) + np.hypot(fm[:, 0], fm[:, 1])


def friction_context(d, f, Ji) -> dict:
    """What every axis joint's friction needs from the frames: (J_X)_i^T, the global axis u,
    omega_rel and v_rel."""
    u = axis_global(d, f)
    return {"f": f, "JiT": Ji.transpose(0, 2, 1), "u": u,
            "spin": relative_spin(d, f, u), "slide": relative_slide(d, f, u)}


def friction_setup_of(jac_h, speed: str | None = None):
    """The module protocol's ``friction_setup(d, f, Ji=None)`` of an axis joint type with the
    Jacobian ``jac_h``: :func:`friction_context`, and with ``speed`` ("spin", rad/s, or "slide",
    m/s) also ``mu``, each joint's signed coefficient mu(v) at that relative velocity."""
    def friction_setup(d, f, Ji=None):
        ctx = friction_context(d, f, jac_h(d, f)[0] if Ji is None else Ji)
        if speed is not None:
            ctx["mu"] = np.array([law.coefficient(v) for law, v in zip(d["laws"], ctx[speed].tolist())], float)
        return ctx
    return friction_setup


def reaction_of(d, ctx, lam) -> np.ndarray:
    """(k, 6): the reaction in the reaction frame at the multipliers lam (k, n_eq)."""
    return frame_reaction(d, ctx["f"], matvec(ctx["JiT"], lam))


def law_sizes(d, key: str) -> np.ndarray:
    """(k,): the friction size ``key`` of each joint's law (m; NaN for a frictionless joint)."""
    return np.array([law.size_of(key) if law is not None else np.nan for law in d["laws"]], float)


def row_functions(rows):
    """(phi, jac_h, gamma) of a joint type made of ``rows`` (the module protocol's signatures)."""
    return (lambda d, f: phi(rows, d, f), lambda d, f: jac_h(rows, d, f),
            lambda d, f: gamma(rows, d, f))


def reported(components):
    """``reaction(d, f, fi)`` returning the columns ``components`` (indices into
    [Fx, Fy, Fz, Tx, Ty, Tz]) of :func:`frame_reaction`."""
    index = np.array(components, np.intp)
    return lambda d, f, fi: frame_reaction(d, f, fi)[:, index]
