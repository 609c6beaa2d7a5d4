"""Spatial cylindrical joint: the joint point of body i stays on the axis of body j and the axes
stay parallel (4 equations); the joint slides along and turns about its axis.

Rows (in this order; evaluated by core/joints_spatial.c): d·(R_j b1_j) = 0, d·(R_j b2_j) = 0
(d = P_i - P_j has no component perpendicular to axis_j), then (R_i a_i)·(R_j b1_j) = 0,
(R_i a_i)·(R_j b2_j) = 0; constants: :mod:`overcon.joints.spatial_rows`. Reaction on body i in the
joint frame (z along axis_i, at the joint point): Fx, Fy, Tx, Ty (Fz and Tz vanish).

Friction (docs/joint-friction.md): a guide of length l (contacts at the joint point and at l
along the axis) and radius a: N = |f_A| + |f_B|, f_B = (T_perp x z)/l, f_A = F_perp - f_B; the
contact slips by s = (v_rel, a omega_rel) (m/s), friction mu(|s|) N along s: an axial force
mu(|s|)/|s| N v_rel at P_i and a torque a mu(|s|)/|s| N a omega_rel about u on body i, the
opposites on body j.

The type's facts are its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

from .spatial_rows import PARALLEL, POINT_ROW, axis_constants as constants  # noqa: F401  (compile)

ROW_MEANINGS = (POINT_ROW, POINT_ROW, PARALLEL, PARALLEL)
