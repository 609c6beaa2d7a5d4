"""Spatial prismatic joint: a cylindrical joint whose rotation about the axis is locked at its
value at q0 (5 equations); the joint only slides along its axis.

Rows (in this order): the four cylindrical rows (:mod:`overcon.joints.cylindrical`), then the
lock (R_i c_i)·(R_j b2_j) = 0 with c_i = R_i0^T R_j0 b1_j; constants and primitives:
:mod:`overcon.joints.spatial_rows`. Reaction on body i in the joint frame (z along axis_i, at the
joint point): Fx, Fy, Tx, Ty, Tz (Fz vanishes).

Friction (docs/joint-friction.md; the paper's A.1-A.2 generalised): contacts at the joint point A
and at B, l along the axis: f_B = (T_perp x z)/l, f_A = F_perp - f_B, N = |f_A| + |f_B| + |Tz|/r
(r the torsion arm of the guide); friction force F_f = mu(v_rel) N along u at P_i on body i
(v_rel the axial velocity of body j relative to body i at P_i, m/s), the opposite on body j.

All functions are batched (k joints at once): see :mod:`overcon.joints`; the type's facts are
its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

import numpy as np

from . import cylindrical
from . import spatial_rows as sr
from .spatial_rows import LOCK, Dot, axis_constants as constants  # noqa: F401  (module protocol)

ROWS = cylindrical.ROWS + (Dot("c_i", "b2_j", LOCK),)
phi, jac_h, gamma = sr.row_functions(ROWS)
reaction = sr.reported((0, 1, 3, 4, 5))


def stack(joints) -> dict:
    """Constant stacked arrays of k compiled joints; friction sizes length, radius (m)."""
    return sr.stack_axes(joints, ("length", "radius"))


friction_setup = sr.friction_setup_of(jac_h, "slide")
"""Frames-only part of the friction: :func:`spatial_rows.friction_context` and mu(v_rel)."""


def friction_force(d, ctx, lam):
    """(k,): friction force F_f (N) on body i along u, positive the way body j slides relative to
    body i, at the multipliers lam (k, 5)."""
    p = sr.reaction_of(d, ctx, lam)
    return ctx["mu"] * (sr.guide_normal_load(p, d["length"]) + np.abs(p[:, 5]) / d["radius"])


def friction(d, ctx, lam):
    """(Qi, Qj), each (k, 6): F_f u at P_i on body i, the opposite on body j."""
    force = friction_force(d, ctx, lam)
    return sr.axial_loads(d, ctx["f"], force, np.zeros_like(force), ctx["u"])
