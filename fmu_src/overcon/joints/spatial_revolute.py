"""Spatial revolute joint: the joint points coincide and the axes stay parallel (5 equations).

Rows (in this order; evaluated by core/joints_spatial.c): the three global components of
P_i - P_j (as the spherical joint), then (R_i a_i)·(R_j b1_j) = 0 and (R_i a_i)·(R_j b2_j) = 0
(axis_i parallel to axis_j); constants: :mod:`overcon.joints.spatial_rows`. Reaction on body i in
the joint frame (z along axis_i, at the joint point): Fx, Fy, Fz, Tx, Ty (Tz = 0: the joint turns
freely about its axis).

Friction (docs/joint-friction.md): a pin of radius a in a bearing of length L centred at the joint
point, with a collar of radius c for the axial load. The bearing ends at z = +-L/2 carry
f+- = F_perp/2 +- (T_perp x z)/L, radial load N_r = |f+| + |f-|; axial load |Fz|. Friction torque
about the axis T_f = mu(omega_rel) (a N_r + c |Fz|), omega_rel = (omega_j - omega_i)·u (rad/s,
u = R_i a_i), on body i as +T_f about u and on body j as -T_f about u.

The type's facts are its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

from .spatial_rows import PARALLEL, POINT_ROW, axis_constants as constants  # noqa: F401  (compile)

ROW_MEANINGS = (POINT_ROW,) * 3 + (PARALLEL, PARALLEL)
