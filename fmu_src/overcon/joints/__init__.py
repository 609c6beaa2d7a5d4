"""Joint types: ONE table of per-type facts, :data:`TYPES`, and one module per type holding what
compiling a joint needs (paper Eq. 34, 36, 41; App. A). The rows of every type (Phi, Phi_h,
gamma), its reactions and its friction are evaluated by the compiled core only
(core/joints_planar.c, core/joints_spherical.c, core/joints_distance.c, core/joints_spatial.c,
dispatched by core/joints.c); :mod:`overcon.kernel` packs each joint's constants for it. Adding a joint type is
one module, one entry here, its C rows and its packing (docs/adding-a-joint.md).

A type's module offers:

- ``constants(params, init) -> dict``: one joint's constant arrays from the file's fields and
  ``init`` (:class:`InitialFrames`: the rotation matrices of its bodies at q0) (compile time;
  ``CompiledJoint.p``, packed by :func:`overcon.kernel._joint_constants`);
- optional ``ROW_MEANINGS``: per equation what it holds (:attr:`JointType.row_meanings`);
- optional ``ROW_KINDS``: per equation translational or rotational (:attr:`JointType.row_kinds`).

The spatial axis types (revolute, prismatic, cylindrical, universal, fixed) share their constants,
row meanings and reaction frame in :mod:`overcon.joints.spatial_rows`; the point-on-line joint
(:mod:`overcon.joints.point_on_line`) shares the completion rule and the row formulas (the
cylindrical joint's point rows, the planar translational joint's first row).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from types import ModuleType
from typing import Mapping

from . import (cylindrical, distance, fixed, point_on_line, prismatic, revolute, spatial_revolute, spatial_rows,
               spherical, translational, universal)


@dataclass(frozen=True)
class InitialFrames:
    """The rotation matrices (body -> global; 2x2 planar, 3x3 spatial) of a joint's body i and
    body j at the initial configuration q0, given to the module's ``constants`` (the base: I)."""

    R_i: object
    R_j: object


@dataclass(frozen=True)
class JointType:
    """The facts of one joint type, read by the scene loader (fields and shapes), the compiler
    (equations, reaction components, constants from ``module``) and the FMU (units, texts).

    ``required``: field -> (shape code, description); ``optional``: field -> (shape code,
    description, default). Shape codes: ``"vec"`` a vector of the mechanism's dimension,
    ``"dir"`` the same but not the zero vector, ``"rot"`` a rotation quantity (planar scalar,
    spatial 3-vector), ``"scalar"``, ``"positive"`` (a scalar > 0), ``"angle"`` (a scalar angle in
    radians; the file may give it in degrees as ``<field>_deg``). ``name``: the type's name in
    files and in every message and output (several types share a name, one per mechanism kind:
    :func:`resolve`).
    ``friction_size``: (key of the friction table, description) of the size stored as
    ``FrictionSpec.size``, None for a type without friction (refused by the loader) or with a
    friction that needs no size; ``sizeless_friction``: the type has friction and no size key
    (``friction_size`` None, ``FrictionSpec.size`` None: a force at a point contact, no lever arm);
    ``friction_extra``: further size keys, key -> (description, default), default None for a
    required key or the name of the key whose value it takes (stored as ``FrictionSpec.extra``
    when given). ``reaction``: (component, unit) of the reported reaction in the auxiliary frame.
    ``sliding_unit``: unit of the friction law's velocity (``v_reg``, ``v_stribeck``).
    ``axis_compliance``: a compliant joint of the type may give per-axis (3-vector) values, along
    its reaction frame on body i (``E``) or body i's axes; False for the point-on-line joint, whose
    directions are the line's on body j (decided: scalar values only)."""

    module: ModuleType
    kind: str
    name: str
    n_equations: int
    required: Mapping[str, tuple[str, str]]
    friction_size: tuple[str, str] | None
    reaction: tuple[tuple[str, str], ...]
    sliding_unit: str
    friction_unit: str
    friction_text: str
    optional: Mapping[str, tuple[str, str, object]] = field(default_factory=dict)
    friction_extra: Mapping[str, tuple[str, str | None]] = field(default_factory=dict)
    sizeless_friction: bool = False
    axis_compliance: bool = True  # per-axis (3-vector) compliance values taken (their frame on body i)

    @property
    def has_friction(self) -> bool:
        """Whether the type has a friction model (with a size key, or ``sizeless_friction``)."""
        return self.friction_size is not None or self.sizeless_friction

    @property
    def reaction_components(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.reaction)

    @property
    def friction_keys(self) -> tuple[str, ...]:
        """Every friction size key of the type (the primary one first); () without friction or
        with a sizeless one."""
        if self.friction_size is None:
            return ()
        return (self.friction_size[0], *self.friction_extra)

    @property
    def row_meanings(self) -> tuple[str, ...]:
        """Per equation (in order), what it holds: the module's ``ROW_MEANINGS`` for the spatial
        axis types (point, parallel, perpendicular, lock: :mod:`overcon.joints.spatial_rows`),
        ``"point"`` for every equation of the other types (a violation at q0 is the coordinates'
        or the joint points')."""
        return getattr(self.module, "ROW_MEANINGS", (spatial_rows.POINT_ROW,) * self.n_equations)

    @property
    def row_kinds(self) -> tuple[str, ...]:
        """Per equation: ``"translational"`` (its violation is a length, m) or ``"rotational"``
        (an angle, rad, for small violations): the module's ``ROW_KINDS``, else from
        :attr:`row_meanings` (point rows translational, axis rows rotational). Compliant joints
        (:class:`overcon.spec.ComplianceSpec`) take their stiffness per equation from it."""
        kinds = getattr(self.module, "ROW_KINDS", None)
        if kinds is not None:
            return kinds
        return tuple("translational" if m == spatial_rows.POINT_ROW else "rotational" for m in self.row_meanings)

    @staticmethod
    def violation_text(meaning: str, p, init: InitialFrames) -> str:
        """What violated equations of a non-point ``meaning`` of one joint (constants ``p``,
        rotation matrices ``init`` at q0) say: :func:`overcon.joints.spatial_rows.violation_text`."""
        return spatial_rows.violation_text(meaning, p, init)

    def friction_sizes(self, spec) -> dict[str, float]:
        """Size key -> value (m) of a :class:`overcon.spec.FrictionSpec` of this type, defaults
        filled in (none for a type with ``sizeless_friction``)."""
        if self.friction_size is None:
            return {}
        sizes = {self.friction_size[0]: spec.size, **dict(spec.extra)}
        for key, (_text, default) in self.friction_extra.items():
            if key not in sizes:
                sizes[key] = sizes[default]
        return sizes


def _point_fields(what: str) -> dict:
    """Required fields of a point-coincidence joint (:mod:`overcon.joints.point`)."""
    return {"s_i": ("vec", f"{what} on body i, in body i frame (m)"),
            "s_j": ("vec", f"{what} on body j, in body j frame (m)")}


_PLANAR_REACTION = (("Fx", "N"), ("Fy", "N"), ("T", "N.m"))  # forces, moment about the joint point


def _axis_fields(what: str) -> dict:
    """Required fields of a spatial axis joint (:mod:`overcon.joints.spatial_rows`)."""
    return {**_point_fields("joint point P"),
            "axis_i": ("dir", f"{what} on body i, in body i frame (normalised)"),
            "axis_j": ("dir", f"{what} on body j, in body j frame (normalised)")}


def _spatial_reaction(*components: str) -> tuple[tuple[str, str], ...]:
    return tuple((c, "N" if c.startswith("F") else "N.m") for c in components)


def _line_fields() -> dict:
    """Required fields of a point-on-line joint (:mod:`overcon.joints.point_on_line`)."""
    return {"s_i": ("vec", "point P on body i that stays on the line, in body i frame (m)"),
            "s_j": ("vec", "a point of the line on body j, in body j frame (m)"),
            "axis_j": ("dir", "direction of the line on body j, in body j frame (normalised)")}


_LINE_FRICTION = ("force on body i along the line (positive along +axis_j, the way body j slides relative to "
                  "body i at P)")

_GUIDE_SIZES = {"radius": ("torsion arm r of the guide (m)", None)}

TYPES: Mapping[str, JointType] = {
    "translational": JointType(
        module=translational, kind="planar", name="translational", n_equations=2, reaction=_PLANAR_REACTION,
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
        module=revolute, kind="planar", name="revolute", n_equations=2, reaction=_PLANAR_REACTION,
        required=_point_fields("joint point P"), friction_size=("radius", "shaft radius a (m)"),
        sliding_unit="rad/s", friction_unit="N.m",
        friction_text="torque (counter-clockwise positive, the way body j turns relative to body i)"),
    "spherical": JointType(
        module=spherical, kind="spatial", name="spherical", n_equations=3, reaction=(("Fx", "N"), ("Fy", "N"), ("Fz", "N")),
        required=_point_fields("ball centre P"), friction_size=("radius", "ball radius rho (m)"),
        sliding_unit="m/s", friction_unit="N", friction_text="force magnitude at the contact point (>= 0)"),
    "spatial_revolute": JointType(
        module=spatial_revolute, kind="spatial", name="revolute", n_equations=5,
        reaction=_spatial_reaction("Fx", "Fy", "Fz", "Tx", "Ty"), required=_axis_fields("joint axis"),
        friction_size=("radius", "pin radius a (m)"),
        friction_extra={"length": ("bearing length L (m)", None),
                        "collar_radius": ("collar radius c for the axial load (m); default: radius", "radius")},
        sliding_unit="rad/s", friction_unit="N.m",
        friction_text="torque about the axis (positive the way body j turns relative to body i)"),
    "spatial_prismatic": JointType(
        module=prismatic, kind="spatial", name="prismatic", n_equations=5,
        reaction=_spatial_reaction("Fx", "Fy", "Tx", "Ty", "Tz"), required=_axis_fields("slide axis"),
        friction_size=("length", "slider length l between contact points A and B (m)"),
        friction_extra=_GUIDE_SIZES, sliding_unit="m/s", friction_unit="N",
        friction_text="force along the axis (positive the way body j slides relative to body i)"),
    "spatial_cylindrical": JointType(
        module=cylindrical, kind="spatial", name="cylindrical", n_equations=4,
        reaction=_spatial_reaction("Fx", "Fy", "Tx", "Ty"), required=_axis_fields("joint axis"),
        friction_size=("length", "guide length l between contact points A and B (m)"),
        friction_extra={"radius": ("shaft radius a (m)", None)}, sliding_unit="m/s", friction_unit="N",
        friction_text="force magnitude at the contact surface (>= 0)"),
    "spatial_universal": JointType(
        module=universal, kind="spatial", name="universal", n_equations=4,
        reaction=_spatial_reaction("Fx", "Fy", "Fz", "Tx", "Ty"), required=_axis_fields("cross axis"),
        friction_size=None, sliding_unit="", friction_unit="", friction_text=""),
    "spatial_fixed": JointType(
        module=fixed, kind="spatial", name="fixed", n_equations=6,
        reaction=_spatial_reaction("Fx", "Fy", "Fz", "Tx", "Ty", "Tz"), required=_point_fields("joint point P"),
        optional={"axis_i": ("dir", "axis of the reaction frame on body i, in body i frame; "
                                    "default [0, 0, 1]", None),
                  "axis_j": ("dir", "the same axis on body j, in body j frame (parallel to axis_i "
                                    "at q0); default: the image of axis_i at q0", None)},
        friction_size=None, sliding_unit="", friction_unit="", friction_text=""),
    "distance": JointType(
        module=distance, kind="planar", name="distance", n_equations=1, reaction=(("tension", "N"),),
        required={**_point_fields("link end"), "length": ("positive", "link length L (m, > 0)")},
        friction_size=None, sliding_unit="", friction_unit="", friction_text=""),
    "spatial_distance": JointType(
        module=distance, kind="spatial", name="distance", n_equations=1, reaction=(("tension", "N"),),
        required={**_point_fields("link end"), "length": ("positive", "link length L (m, > 0)")},
        friction_size=None, sliding_unit="", friction_unit="", friction_text=""),
    "point_on_line": JointType(
        module=point_on_line, kind="planar", name="point_on_line", n_equations=1, reaction=(("N", "N"),),
        required=_line_fields(), friction_size=None, sizeless_friction=True, sliding_unit="m/s",
        friction_unit="N", friction_text=_LINE_FRICTION),
    "spatial_point_on_line": JointType(
        module=point_on_line, kind="spatial", name="point_on_line", n_equations=2,
        reaction=(("Fx", "N"), ("Fy", "N")), required=_line_fields(), friction_size=None, sizeless_friction=True,
        sliding_unit="m/s", friction_unit="N", friction_text=_LINE_FRICTION, axis_compliance=False),
}
"""Joint type key -> its facts and module: the one place a joint type is declared. The
key is internal (CompiledJoint.type, JointSpec.type); files and outputs use ``name``, resolved per
mechanism kind by :func:`resolve`. The planar and spherical types' keys equal their names."""


def resolve(kind: str, name: str) -> str | None:
    """The key in :data:`TYPES` of the joint type called ``name`` in a ``kind`` mechanism, or None."""
    for key, jt in TYPES.items():
        if jt.kind == kind and jt.name == name:
            return key
    return None


def names(kind: str | None = None) -> tuple[str, ...]:
    """The file names of the joint types (of a mechanism kind, or of all), in table order."""
    return tuple(dict.fromkeys(jt.name for jt in TYPES.values() if kind is None or jt.kind == kind))
