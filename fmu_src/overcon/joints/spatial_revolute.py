"""Spatial revolute joint: the joint points coincide and the axes stay parallel (5 equations).

Rows (in this order): the three global components of P_i - P_j (as the spherical joint), then
(R_i a_i)·(R_j b1_j) = 0 and (R_i a_i)·(R_j b2_j) = 0 (axis_i parallel to axis_j); constants
and primitives: :mod:`overcon.joints.spatial_rows`. Reaction on body i in the joint frame (z along
axis_i, at the joint point): Fx, Fy, Fz, Tx, Ty (Tz = 0: the joint turns freely about its axis).

Friction (docs/joint-friction.md): a pin of radius a in a bearing of length L centred at the joint
point, with a collar of radius c for the axial load. The bearing ends at z = +-L/2 carry
f+- = F_perp/2 +- (T_perp x z)/L, radial load N_r = |f+| + |f-|; axial load |Fz|. Friction torque
about the axis T_f = mu(omega_rel) (a N_r + c |Fz|), omega_rel = (omega_j - omega_i)·u (rad/s,
u = R_i a_i), on body i as +T_f about u and on body j as -T_f about u.

All functions are batched (k joints at once): see :mod:`overcon.joints`; the type's facts are
its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

import numpy as np

from . import spatial_rows as sr
from .spatial_rows import PARALLEL, POINT, Dot, axis_constants as constants  # noqa: F401  (module protocol)

ROWS = (POINT, Dot("a_i", "b1_j", PARALLEL), Dot("a_i", "b2_j", PARALLEL))
phi, jac_h, gamma = sr.row_functions(ROWS)
reaction = sr.reported((0, 1, 2, 3, 4))


def stack(joints) -> dict:
    """Constant stacked arrays of k compiled joints; friction sizes radius, length, collar_radius
    (m) from the laws."""
    return sr.stack_axes(joints, ("radius", "length", "collar_radius"))


friction_setup = sr.friction_setup_of(jac_h, "spin")
"""Frames-only part of the friction: :func:`spatial_rows.friction_context` and mu(omega_rel)."""


def friction_force(d, ctx, lam):
    """(k,): friction torque T_f (N.m) on body i about u, positive the way body j turns relative
    to body i, at the multipliers lam (k, 5)."""
    p = sr.reaction_of(d, ctx, lam)
    return ctx["mu"] * (d["radius"] * sr.bearing_radial_load(p, d["length"])
                        + d["collar_radius"] * np.abs(p[:, 2]))


def friction(d, ctx, lam):
    """(Qi, Qj), each (k, 6): the torque T_f u on body i and -T_f u on body j."""
    torque = friction_force(d, ctx, lam)
    return sr.axial_loads(d, ctx["f"], np.zeros_like(torque), torque, ctx["u"])
