"""Point-on-line joint, planar and spatial (``type = "point_on_line"``): the point P on body i
(``s_i``, body i axes) stays on the line of body j through ``s_j`` along ``axis_j`` (body j axes) -
a bead on a wire. Body i may be a particle (the bead, ``s_i = 0``); body j carries the line, so it
is a rigid body or the base (a particle has no orientation to carry a direction: refused).

Equations (d = P_i - P_j, P_k = r_k + R_k s_k; evaluated by the core):

- planar, one: d·(R_j n_j) = 0, n_j = OMEGA a_j the unit axis turned +90 degrees (the first row
  of the planar translational joint, core/joints_planar.c);
- spatial, two: d·(R_j b1_j) = 0, d·(R_j b2_j) = 0, b1_j, b2_j the completion of a_j
  (:func:`overcon.joints.spatial_rows.completion`; the first two rows of the cylindrical joint,
  core/joints_spatial.c).

The normals are unit vectors, so each multiplier is a force (N). Joint frame (decided here): on
body j at P, z along the line R_j a_j, x = R_j b1_j and y = R_j b2_j (spatial), the normal
y = R_j n_j (planar). Reported reaction on body i (the force the line exerts on the bead): planar
``N`` (along R_j n_j), spatial ``Fx``, ``Fy`` (along R_j b1_j, R_j b2_j) - the line takes no force
along itself and no moment - then the global force ``Fx0, Fy0(, Fz0)`` as for every type.

Friction (docs/joint-friction.md): a contact at P with normal force N = |normal reaction| (planar
|N|, spatial hypot(Fx, Fy)); a force mu(v) N along the line, v the sliding velocity along
u = R_j a_j of body j's material point at P relative to body i's (m/s; the law's sign as every
type's: the force on body i points the way body j slides relative to it, so it opposes the bead's
sliding), applied to body i at P and the opposite to body j at the same point. The type has no
friction size (no lever arm: the force acts at the contact itself). Output ``<joint>.friction``:
that force on body i along +axis_j (N, signed).

The type's facts are its entries in :data:`overcon.joints.TYPES` (``point_on_line`` planar,
``spatial_point_on_line`` spatial, both called ``point_on_line`` in files).
"""
from __future__ import annotations

import numpy as np

from ..kinematics import OMEGA
from .spatial_rows import completion, unit


def constants(params, init=None) -> dict:
    """One joint's constants: ``s_i``, ``s_j`` (m, body axes), the unit line direction ``a_j``
    (body j axes; the loader refuses a zero ``axis_j``), and its normals in body j axes: planar
    ``n_j`` = OMEGA a_j; spatial ``b1_j``, ``b2_j`` (the completion rule of the axis joints)
    (``init``, the initial frames, is not needed)."""
    a_j = unit(params["axis_j"])
    out = {"s_i": np.asarray(params["s_i"], float), "s_j": np.asarray(params["s_j"], float), "a_j": a_j}
    if a_j.size == 2:
        out["n_j"] = OMEGA @ a_j
    else:
        out["b1_j"], out["b2_j"] = completion(a_j)
    return out
