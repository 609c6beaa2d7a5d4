"""Spatial universal (Hooke) joint: the joint points coincide and the two cross axes stay
perpendicular (4 equations).

Rows (in this order; evaluated by core/joints_spatial.c): the three global components of
P_i - P_j, then (R_i a_i)·(R_j a_j) = 0 (axis_i on body i, axis_j on body j: the cross's two axes,
perpendicular at q0); constants: :mod:`overcon.joints.spatial_rows`. Reaction on body i in the
joint frame (z along axis_i, at the joint point): Fx, Fy, Fz, Tx, Ty (Tz vanishes: the constraint
moment is along axis_i x axis_j). No friction (refused by the scene loader).

The type's facts are its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

from .spatial_rows import PERPENDICULAR, POINT_ROW, axis_constants as constants  # noqa: F401  (compile)

ROW_MEANINGS = (POINT_ROW,) * 3 + (PERPENDICULAR,)
