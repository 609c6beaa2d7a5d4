"""Distance joint, planar and spatial: a massless rigid link of length L between the point s_i on
body i and the point s_j on body j (``type = "distance"``; either body may be the base or a
particle). One equation, evaluated by core/joints_distance.c:

    Phi = |r_i + R_i s_i - r_j - R_j s_j| - L.

With u the unit vector from P_j to P_i, Phi_h = u^T dP_i/dh_i - u^T dP_j/dh_j, so the multiplier is
the force along the link: the joint pulls body i by -lam u and body j by +lam u. Reported reaction:
``tension`` = lam (N; positive when the link pulls its ends together, negative when it pushes),
then the global force on body i ``Fx0, Fy0(, Fz0)`` = -lam u, as for every type. No friction model
(a link between two pins: put friction in those pins' joints instead). Where P_i and P_j meet
(|d| = 0) the link's direction is undefined: its row is zero there, a singular position.

The type's facts are its entries in :data:`overcon.joints.TYPES` (``distance`` planar,
``spatial_distance`` spatial, both called ``distance`` in files).
"""
from __future__ import annotations

import numpy as np

ROW_KINDS = ("translational",)  # a length (a compliant distance joint takes ``stiffness``, N/m)


def constants(params, init=None) -> dict:
    """One joint's constants: the link's end points in body i and body j axes, ``s_i``, ``s_j``
    (m), and its ``length`` L (m, > 0: the scene loader refuses others)."""
    return {"s_i": np.asarray(params["s_i"], float), "s_j": np.asarray(params["s_j"], float),
            "length": float(params["length"])}
