"""One producer module per joint type (paper Eq. 34, 36, 41; App. A).

Every module offers the same functions, called with a compiled joint ``c`` (``c.bi``, ``c.bj``
body slots, -1 = base; ``c.p`` the joint's constant parameters as arrays) and the evaluation's
:class:`overcon.model.Frames` ``f``:

- ``prepare(params) -> dict``: constant arrays from the file's fields (done once at compile);
- ``phi(c, f) -> (k,)``: constraint equations Phi_X;
- ``jac_q(c, f) -> (Ji, Jj)``: exact derivative of Phi_X by q_i and q_j (Euler angles, spatial);
- ``jac_h(c, f) -> (Ji, Jj)``: derivative by the velocities h_i, h_j (spatial: the modified
  Jacobian of Eq. 7, Phi_phi H; planar: the same as ``jac_q``);
- ``gamma(c, f) -> (k,)``: right-hand side of Phi_h h' = gamma (Eq. 11);
- ``reaction_transform(c, f) -> A_i``: maps the generalized reaction (f_X)_i on body i to the
  physical reaction in the joint's auxiliary frame (Eq. 19; A.1, A.5, A.10);
- ``friction(c, f, fi, law) -> (Qi, Qj)``: generalized Coulomb friction forces on bodies i and j
  (Eq. 20-22) given fi = (J_X)_i lam_X, the left-hand-side generalized reaction on body i;
- ``relative_speed(c, f)``: the sliding speed the friction law sees (for reports and tests).

``REACTION_COMPONENTS`` names the reported physical reaction components.

Batched forms (the hot path of :func:`overcon.dynamics.evaluate`), for all joints of the type at
once; ``d`` is the dict made once at compile time (``Model.plan``), k the number of joints:

- ``batch_prepare(joints) -> d``: stacked constants (body slots, s_i, s_j, ..., friction laws);
- ``batch_phi(d, f) -> (k, n_eq)``, ``batch_jac_h(d, f) -> (Ji, Jj)`` each (k, n_eq, n_coord),
  ``batch_gamma(d, f) -> (k, n_eq)``;
- ``batch_friction_setup(d, f) -> ctx``: what friction needs from the frames (once per
  evaluation); ``batch_friction(d, ctx, lam) -> (Qi, Qj)`` each (k, n_coord), given the joints'
  multipliers lam (k, n_eq) (once per friction iteration).

They reproduce the single-joint functions bit for bit (the same floating-point operations in the
same order; stacked ``np.matmul`` runs the same kernel per item), so a run gives the same numbers
either way; tests/test_hot_path.py checks them against the single forms.
"""
from . import revolute, spherical, translational

TYPES = {"translational": translational, "revolute": revolute, "spherical": spherical}
