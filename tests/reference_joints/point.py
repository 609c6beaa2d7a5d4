"""Per-joint reference (tests only): point coincidence, shared by the planar revolute joint (Eq. 36) and the spatial spherical joint (Eq. 41).

The plain single-joint form of :mod:`overcon.joints.point` (see tests/reference_joints/__init__.py)."""
from __future__ import annotations

import numpy as np


def phi(c, f):
    return f.r[c.bi] + f.R[c.bi] @ c.p["s_i"] - f.r[c.bj] - f.R[c.bj] @ c.p["s_j"]
