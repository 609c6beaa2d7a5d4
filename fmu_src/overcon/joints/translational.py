"""Planar translational joint (paper Eq. 34; friction App. A.1-A.4).

Phi = [ (r_i + R_i s_A - r_j - R_j s_B)^T R_j v ;  phi_i - phi_j - psi ].

Auxiliary frame (decided here; the paper fixes it only for joint 1, B_i = I): origin at A on body
i, x' along the guide, y' along v. In body j axes the guide is ``OMEGA.T @ v/|v|`` (so v = [0, 1]
gives x' = +x); B_i is that frame expressed in body i axes (rotated by -psi). Physical reaction
p' = [Fx (along the guide, zero without friction), Fy = N (normal), T (moment about A)].
Friction (A.2): magnitude mu(v_ij) (|N - T/l| + |T/l|) along x', v_ij the sliding velocity of
body j relative to body i along x', l the slider length.

Evaluated by core/joints_planar.c; the type's facts are its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

import numpy as np

from ..kinematics import OMEGA, rot2_rows


ROW_KINDS = ("translational", "rotational")
"""Phi1 is the distance from the guide line (m), Phi2 the relative angle (rad)."""


def constants(params, init=None) -> dict:
    """One joint's constants: s_A, s_B, v, psi and the auxiliary frame B_i (in body i axes)
    (``init``, the initial frames, is not needed: psi fixes the relative angle)."""
    v = np.asarray(params["v"], float)
    psi = float(params.get("psi", 0.0))
    axis_j = OMEGA.T @ v / np.linalg.norm(v)
    axis_i = rot2_rows(np.array([-psi]))[0] @ axis_j
    B = np.column_stack([axis_i, OMEGA @ axis_i])
    return {"s_A": np.asarray(params["s_A"], float), "s_B": np.asarray(params["s_B"], float),
            "v": v, "psi": psi, "B": B}
