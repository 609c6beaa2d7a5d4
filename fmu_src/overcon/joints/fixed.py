"""Spatial fixed joint: the joint points coincide and the relative rotation is frozen at its
value at q0 (6 equations).

Rows (in this order; evaluated by core/joints_spatial.c): the three global components of
P_i - P_j, then the three rotation rows (R_i a_i)·(R_j b1_j) = 0, (R_i a_i)·(R_j b2_j) = 0 (axes
parallel, as the revolute joint) and the lock (R_i c_i)·(R_j b2_j) = 0, c_i = R_i0^T R_j0 b1_j
(as the prismatic joint). Together they fix the relative rotation near q0: their gradients by a
relative rotation are -B2, B1 and -A (A the axis, B1, B2 its completion), independent. The axes
are optional: axis_i defaults to [0, 0, 1] (then the joint frame is body i's axes) and axis_j to
the image of axis_i in body j at q0; given axes must be parallel at q0 (the axis rows then hold at
q0; otherwise the initial state is refused). Constants: :mod:`overcon.joints.spatial_rows`.
Reaction on body i in the joint frame (z along axis_i, at the joint point): Fx, Fy, Fz, Tx, Ty,
Tz. No friction (refused by the scene loader).

The type's facts are its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

from . import spatial_revolute
from .spatial_rows import LOCK, axis_constants as constants  # noqa: F401  (compile)

ROW_MEANINGS = spatial_revolute.ROW_MEANINGS + (LOCK,)
