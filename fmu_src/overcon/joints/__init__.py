"""Joint types: one producer module per type (paper Eq. 34, 36, 41; App. A) and ONE table of
per-type facts, :data:`TYPES`. Adding a joint type is one module plus one entry here (see
docs/adding-a-joint.md).

Every module is batched: it evaluates all joints of its type at once, a single joint being a
batch of one (there is no separate single-joint form; tests/reference_joints.py keeps a plain
per-joint reference for the tests). A module offers, with ``f`` the evaluation's
:class:`overcon.evaluation.Frames` and ``d`` the stacked constants of k joints:

- ``constants(params) -> dict``: one joint's constant arrays from the file's fields (compile);
- ``stack(joints) -> d``: the constants of k compiled joints stacked (body slots ``bi``/``bj``,
  -1 = base; friction laws ``laws``); done once at compile time (``Model.plan``);
- ``phi(d, f) -> (k, n_eq)``: constraint equations Phi_X;
- ``jac_h(d, f) -> (Ji, Jj)``, each (k, n_eq, n_coord): derivative by the velocities h_i, h_j
  (spatial: the modified Jacobian of Eq. 7; planar: Phi_q);
- ``gamma(d, f) -> (k, n_eq)``: right-hand side of Phi_h h' = gamma (Eq. 11);
- ``reaction(d, f, fi) -> (k, n_components)``: the physical reaction in the joint's auxiliary
  frame, ``-A_i fi`` (Eq. 19; A.1, A.5, A.10), given fi = (J_X)_i^T lam_X (k, n_coord), the
  left-hand-side generalized reaction on body i; the components are the table's ``reaction``;
- ``friction_setup(d, f) -> ctx``: what friction needs from the frames (once per evaluation);
- ``friction(d, ctx, lam) -> (Qi, Qj)``, each (k, n_coord): generalized Coulomb friction forces
  on bodies i and j (Eq. 20-22) given the joints' multipliers lam (k, n_eq) (once per friction
  iteration);
- ``friction_force(d, ctx, lam) -> (k,)``: the friction output ``<joint>.friction`` (unit
  ``friction_unit``, meaning ``friction_text``).
- optional ``friction_jacobian(d, ctx, lam) -> (dQi, dQj)``, each (k, n_coord, n_eq): the
  derivatives of ``friction``'s forces by lam, for the friction solve's Newton step (a type
  without it gets forward differences of ``friction``; tests/test_friction_newton.py checks each
  one against central differences).

Floating point: stacked ``np.matmul``/``np.vecdot`` run the same kernel per item as the 2-D
products, so a batch gives each joint the numbers it gets alone (tests/test_hot_path.py checks
the batches against the per-joint reference, bit for bit for the reported outputs).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from types import ModuleType
from typing import Mapping

from . import revolute, spherical, translational


@dataclass(frozen=True)
class JointType:
    """The facts of one joint type, read by the scene loader (fields and shapes), the compiler
    (equations, reaction components) and the FMU (units, texts).

    ``required``: field -> (shape code, description); ``optional``: field -> (shape code,
    description, default). Shape codes: ``"vec"`` a vector of the mechanism's dimension,
    ``"dir"`` the same but not the zero vector, ``"rot"`` a rotation quantity (planar scalar,
    spatial 3-vector), ``"scalar"``, ``"angle"`` (a scalar angle in radians; the file may give it
    in degrees as ``<field>_deg``). ``friction_size``: (key of the friction table, description).
    ``reaction``: (component, unit) of the reported reaction in the auxiliary frame.
    ``sliding_unit``: unit of the friction law's velocity (``v_reg``, ``v_stribeck``)."""

    module: ModuleType
    kind: str
    n_equations: int
    required: Mapping[str, tuple[str, str]]
    friction_size: tuple[str, str]
    reaction: tuple[tuple[str, str], ...]
    sliding_unit: str
    friction_unit: str
    friction_text: str
    optional: Mapping[str, tuple[str, str, object]] = field(default_factory=dict)

    @property
    def reaction_components(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.reaction)


def _point_fields(what: str) -> dict:
    """Required fields of a point-coincidence joint (:mod:`overcon.joints.point`)."""
    return {"s_i": ("vec", f"{what} on body i, in body i frame (m)"),
            "s_j": ("vec", f"{what} on body j, in body j frame (m)")}


_PLANAR_REACTION = (("Fx", "N"), ("Fy", "N"), ("T", "N.m"))  # forces, moment about the joint point

TYPES: Mapping[str, JointType] = {
    "translational": JointType(
        module=translational, kind="planar", n_equations=2, reaction=_PLANAR_REACTION,
        required={
            "s_A": ("vec", "point A on body i, in body i frame (m)"),
            "s_B": ("vec", "point B on body j, in body j frame (m)"),
            "v": ("dir", "vector on body j perpendicular to the guide, in body j frame"),
        },
        optional={"psi": ("angle", "constant angle phi_i - phi_j (rad)", 0.0)},
        friction_size=("length", "slider length l between contact points A and B (m)"),
        sliding_unit="m/s", friction_unit="N",
        friction_text="force along the guide x' (positive along +x', the way body j slides relative to body i)"),
    "revolute": JointType(
        module=revolute, kind="planar", n_equations=2, reaction=_PLANAR_REACTION,
        required=_point_fields("joint point P"), friction_size=("radius", "shaft radius a (m)"),
        sliding_unit="rad/s", friction_unit="N.m",
        friction_text="torque (counter-clockwise positive, the way body j turns relative to body i)"),
    "spherical": JointType(
        module=spherical, kind="spatial", n_equations=3, reaction=(("Fx", "N"), ("Fy", "N"), ("Fz", "N")),
        required=_point_fields("ball centre P"), friction_size=("radius", "ball radius rho (m)"),
        sliding_unit="m/s", friction_unit="N", friction_text="force magnitude at the contact point (>= 0)"),
}
"""Joint type name -> its facts and producer module: the one place a joint type is declared."""
