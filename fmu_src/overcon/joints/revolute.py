"""Planar revolute joint (paper Eq. 36; friction App. A.5-A.8).

Phi = r_i + R_i s_i - r_j - R_j s_j (2 equations; evaluated by core/joints_planar.c). Auxiliary
frame: origin at the joint point P, axes parallel to body i. Physical reaction p' = [Fx, Fy, T]
(T = 0 for a revolute joint). Friction: a torque a mu(omega_ij) sqrt(Fx^2 + Fy^2) on body i (minus
on body j), omega_ij = phi_j' - phi_i'.

The type's facts are its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

from .point import constants  # noqa: F401  (compile)
