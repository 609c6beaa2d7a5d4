"""The spatial axis joints' shared facts (revolute, prismatic, cylindrical, universal, fixed): their
constants, row meanings and reaction frame. Their rows, reactions and friction are evaluated by
the compiled core (core/joints_spatial.c), which builds every type from three row primitives:

- POINT (3 rows) d = P_i - P_j (global, m), P_k = r_k + R_k s_k the joint point on body k;
- DOT (1 row) (R_i a)·(R_j b), a fixed in body i, b in body j (an axis row or a rotation lock);
- POINTDOT (1 row) d·(R_j b), b fixed in body j.

Row meanings (the one place they are declared), read by the compiler's initial-state message
(:attr:`overcon.joints.JointType.row_meanings`, :func:`violation_text`): POINT and POINTDOT rows
are :data:`POINT_ROW` rows (on the joint points: q0 at fault); a DOT row holds axis_i
:data:`PARALLEL` or :data:`PERPENDICULAR` to axis_j, or is a rotation :data:`LOCK` row. A violated
axis row at q0 names the fields axis_i and axis_j and the angle between the axes; a lock row holds
at q0 by construction of ``c_i``.

Axis constants (decided here; :func:`axis_constants`): the axes are normalised; ``b1_j``,
``b2_j`` complete ``a_j`` to an orthonormal basis of body j by a deterministic rule
(:func:`completion`: the standard basis vector least aligned with the axis, the first on ties,
Gram-Schmidt against the axis, then b2 = a x b1). The rotation lock about the axis uses
``c_i = R_i0^T R_j0 b1_j`` (b1_j seen from body i at the initial configuration q0), so the lock
row (R_i c_i)·(R_j b2_j) is zero at q0.

Reaction frame ``E`` (on body i, at P_i): z along axis_i, x and y the completion of axis_i by the
same rule. The core reports the physical reaction on body i, -(J_X)_i^T lam_X, as
[Fx, Fy, Fz, Tx, Ty, Tz] in that frame (N, N.m; moments about P_i), each type its non-vanishing
components (the table's ``reaction``).
"""
from __future__ import annotations

import numpy as np

POINT_ROW, PARALLEL, PERPENDICULAR, LOCK = "point", "parallel", "perpendicular", "lock"
"""The meanings of the rows (see the module docstring)."""


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
    and a_i, in body i axes). :func:`overcon.kernel._joint_constants` packs them for the core."""
    C0 = init.R_i.T @ init.R_j  # body j axes -> body i axes at q0
    a_i = unit(params["axis_i"]) if params.get("axis_i") is not None else np.array([0.0, 0.0, 1.0])
    a_j = unit(params["axis_j"]) if params.get("axis_j") is not None else C0.T @ a_i
    b1_j, b2_j = completion(a_j)
    x_i, y_i = completion(a_i)
    return {"s_i": np.asarray(params["s_i"], float), "s_j": np.asarray(params["s_j"], float),
            "a_i": a_i, "a_j": a_j, "b1_j": b1_j, "b2_j": b2_j, "c_i": C0 @ b1_j,
            "E": np.column_stack([x_i, y_i, a_i])}


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
