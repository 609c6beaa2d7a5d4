"""Point coincidence, shared by the planar revolute joint (Eq. 36) and the spatial spherical joint
(Eq. 41): ``Phi = r_i + R_i s_i - r_j - R_j s_j`` in 2 or 3 dimensions."""
from __future__ import annotations

import numpy as np

from ..kinematics import matvec


def prepare(params) -> dict:
    return {"s_i": np.asarray(params["s_i"], float), "s_j": np.asarray(params["s_j"], float)}


def phi(c, f):
    return f.r[c.bi] + f.R[c.bi] @ c.p["s_i"] - f.r[c.bj] - f.R[c.bj] @ c.p["s_j"]


def batch_phi(d, f):
    """(k, dim): :func:`phi` of every joint."""
    bi, bj = d["bi"], d["bj"]
    return f.r[bi] + matvec(f.R[bi], d["s_i"]) - f.r[bj] - matvec(f.R[bj], d["s_j"])
