"""Spatial spherical joint (paper Eq. 41, B.13; friction App. A.9-A.18).

Phi = r_i + R_i s_i - r_j - R_j s_j (3 equations; evaluated by core/joints_spherical.c).
Velocities h_k = [r_k' (global), omega_k (body axes)]; the modified Jacobian blocks are
[I, -R_i skew(s_i)] and [-I, R_j skew(s_j)]. Auxiliary frame: origin at the ball centre P, axes
parallel to body i (A.10). Physical reaction p' = [Fx, Fy, Fz] in body i axes (the moment about P
is zero).

Friction (A.11-A.18): contact point s'_C = -rho F'/|F'| with F' taken from the left-hand-side
generalized reaction (f_X)_i = (J_X)_i lam_X (a project decision, see docs/explanation/decisions.md: the paper's figures
cannot tell this side from the opposite one), sliding velocity v' = omega'_ij x s'_C with
omega'_ij = R_i^T R_j omega_j - omega_i, friction force F'_fr = mu(|v'|)|F'| v'/|v'| applied to
body i at C, and the opposite force on body j.

The type's facts are its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

from .point import constants  # noqa: F401  (compile)
