"""Spatial cylindrical joint: the joint point of body i stays on the axis of body j and the axes
stay parallel (4 equations); the joint slides along and turns about its axis.

Rows (in this order): d·(R_j b1_j) = 0, d·(R_j b2_j) = 0 (d = P_i - P_j has no component
perpendicular to axis_j), then (R_i a_i)·(R_j b1_j) = 0, (R_i a_i)·(R_j b2_j) = 0; constants and
primitives: :mod:`overcon.joints.spatial_rows`. Reaction on body i in the joint frame (z along
axis_i, at the joint point): Fx, Fy, Tx, Ty (Fz and Tz vanish).

Friction (docs/joint-friction.md): a guide of length l (contacts at the joint point and at l
along the axis) and radius a: N = |f_A| + |f_B|, f_B = (T_perp x z)/l, f_A = F_perp - f_B; the
contact slips by s = (v_rel, a omega_rel) (m/s), friction mu(|s|) N along s: an axial force
mu(|s|)/|s| N v_rel at P_i and a torque a mu(|s|)/|s| N a omega_rel about u on body i, the
opposites on body j.

All functions are batched (k joints at once): see :mod:`overcon.joints`; the type's facts are
its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

import math

import numpy as np

from . import spatial_rows as sr
from .spatial_rows import PARALLEL, Dot, PointDot, axis_constants as constants  # noqa: F401  (module protocol)

ROWS = (PointDot("b1_j"), PointDot("b2_j"), Dot("a_i", "b1_j", PARALLEL),
        Dot("a_i", "b2_j", PARALLEL))
phi, jac_h, gamma = sr.row_functions(ROWS)
reaction = sr.reported((0, 1, 3, 4))


def stack(joints) -> dict:
    """Constant stacked arrays of k compiled joints; friction sizes length, radius (m)."""
    return sr.stack_axes(joints, ("length", "radius"))


_context = sr.friction_setup_of(jac_h)


def friction_setup(d, f, Ji=None):
    """Frames-only part of the friction: the context of :func:`spatial_rows.friction_context`,
    the slip speed |s| = sqrt(v_rel^2 + a^2 omega_rel^2) (m/s), mu(|s|) and mu(|s|)/|s| (0 when
    the contact does not slip: no direction)."""
    ctx = _context(d, f, Ji)
    speed = [math.hypot(v, a * w) for v, a, w in
             zip(ctx["slide"].tolist(), d["radius"].tolist(), ctx["spin"].tolist())]
    ctx["mu"] = np.array([law.coefficient(s) for law, s in zip(d["laws"], speed)], float)
    ctx["mos"] = np.array([law.mu_over_speed(s) if s > 0.0 else 0.0 for law, s in zip(d["laws"], speed)], float)
    return ctx


def _normal(d, ctx, lam):
    return sr.guide_normal_load(sr.reaction_of(d, ctx, lam), d["length"])


def friction_force(d, ctx, lam):
    """(k,): magnitude mu(|s|) N of the contact friction force (N, >= 0): its direction is the
    slip, which has no fixed axis to sign it against."""
    return ctx["mu"] * _normal(d, ctx, lam)


def friction(d, ctx, lam):
    """(Qi, Qj), each (k, 6): the axial force and torque along the slip on body i, the opposites on
    body j."""
    scale = ctx["mos"] * _normal(d, ctx, lam)
    return sr.axial_loads(d, ctx["f"], scale * ctx["slide"], scale * d["radius"] ** 2 * ctx["spin"], ctx["u"])
