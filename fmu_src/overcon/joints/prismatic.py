"""Spatial prismatic joint: a cylindrical joint whose rotation about the axis is locked at its
value at q0 (5 equations); the joint only slides along its axis.

Rows (in this order; evaluated by core/joints_spatial.c): the four cylindrical rows
(:mod:`overcon.joints.cylindrical`), then the lock (R_i c_i)·(R_j b2_j) = 0 with
c_i = R_i0^T R_j0 b1_j; constants: :mod:`overcon.joints.spatial_rows`. Reaction on body i in the
joint frame (z along axis_i, at the joint point): Fx, Fy, Tx, Ty, Tz (Fz vanishes).

Friction (docs/joint-friction.md; the paper's A.1-A.2 generalised): contacts at the joint point A
and at B, l along the axis: f_B = (T_perp x z)/l, f_A = F_perp - f_B, N = |f_A| + |f_B| + |Tz|/r
(r the torsion arm of the guide); friction force F_f = mu(v_rel) N along u at P_i on body i
(v_rel the axial velocity of body j relative to body i at P_i, m/s), the opposite on body j.

The type's facts are its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

from . import cylindrical
from .spatial_rows import LOCK, axis_constants as constants  # noqa: F401  (compile)

ROW_MEANINGS = cylindrical.ROW_MEANINGS + (LOCK,)
