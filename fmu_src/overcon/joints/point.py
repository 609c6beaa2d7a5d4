"""Point coincidence, shared by the planar revolute joint (Eq. 36) and the spatial spherical joint
(Eq. 41): ``Phi = r_i + R_i s_i - r_j - R_j s_j`` in 2 or 3 dimensions (batched, see
:mod:`overcon.joints`)."""
from __future__ import annotations

import numpy as np

from ..kinematics import matvec


def constants(params, init=None) -> dict:
    """One joint's constants: the joint point in body i and in body j axes (``init``, the
    initial frames, is not needed)."""
    return {"s_i": np.asarray(params["s_i"], float), "s_j": np.asarray(params["s_j"], float)}


def stack_points(joints, dim: int) -> dict:
    """Stacked body slots, joint points (k, dim) and friction laws of k compiled joints."""
    return {
        "bi": np.array([c.bi for c in joints], np.intp), "bj": np.array([c.bj for c in joints], np.intp),
        "s_i": np.array([c.p["s_i"] for c in joints], float).reshape(-1, dim),
        "s_j": np.array([c.p["s_j"] for c in joints], float).reshape(-1, dim),
        "laws": tuple(c.law for c in joints),
    }


def _arms(d, f):
    return matvec(f.R[d["bi"]], d["s_i"]), matvec(f.R[d["bj"]], d["s_j"])


def arms(d, f):
    """(R_i s_i, R_j s_j), each (k, dim): the joint point from each body origin in global axes
    (once per evaluation: :meth:`overcon.evaluation.Frames.cached`; read-only by convention)."""
    return f.cached("point.arms", d, _arms)


def phi(d, f):
    """(k, dim): r_i + R_i s_i - r_j - R_j s_j of every joint."""
    a_i, a_j = arms(d, f)
    return f.r[d["bi"]] + a_i - f.r[d["bj"]] - a_j
