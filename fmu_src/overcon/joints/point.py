"""Point coincidence, shared by the planar revolute joint (Eq. 36) and the spatial spherical joint
(Eq. 41): ``Phi = r_i + R_i s_i - r_j - R_j s_j`` in 2 or 3 dimensions (evaluated by
core/joints_planar.c and core/joints_spherical.c); the constants both types compile."""
from __future__ import annotations

import numpy as np


def constants(params, init=None) -> dict:
    """One joint's constants: the joint point in body i and in body j axes, ``s_i``, ``s_j`` (m)
    (``init``, the initial frames, is not needed)."""
    return {"s_i": np.asarray(params["s_i"], float), "s_j": np.asarray(params["s_j"], float)}
