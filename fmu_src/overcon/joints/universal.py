"""Spatial universal (Hooke) joint: the joint points coincide and the two cross axes stay
perpendicular (4 equations).

Rows (in this order): the three global components of P_i - P_j, then (R_i a_i)·(R_j a_j) = 0
(axis_i on body i, axis_j on body j: the cross's two axes, perpendicular at q0); constants and
primitives: :mod:`overcon.joints.spatial_rows`. Reaction on body i in the joint frame (z along
axis_i, at the joint point): Fx, Fy, Fz, Tx, Ty (Tz vanishes: the constraint moment is along
axis_i x axis_j). No friction (refused by the scene loader).

All functions are batched (k joints at once): see :mod:`overcon.joints`; the type's facts are
its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

from . import spatial_rows as sr
from .spatial_rows import PERPENDICULAR, POINT, Dot, axis_constants as constants, stack_axes as stack  # noqa: F401

ROWS = (POINT, Dot("a_i", "a_j", PERPENDICULAR))
phi, jac_h, gamma = sr.row_functions(ROWS)
reaction = sr.reported((0, 1, 2, 3, 4))
