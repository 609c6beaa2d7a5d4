"""Parsed, validated description of a mechanism and of a scene (frozen dataclasses).

This is the output of :mod:`overcon.scene` (which reads TOML and reports every problem against
its file and field) and the input of :func:`overcon.model.compile_model`. Nothing here does
numerics. Units are SI throughout; angles in radians.

Field tables
------------
``LOAD_FIELDS`` states, per load type, which fields the file must (or may) give and their shape,
so that the loader validates every type the same way. Joint types state theirs in their one
table, :data:`overcon.joints.TYPES` (with equations, reaction components and units).

Shape codes used in the tables: ``"vec"`` a vector of the mechanism's dimension (2 planar,
3 spatial); ``"rot"`` a rotation quantity (planar: scalar, spatial: 3-vector); ``"scalar"``.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field
from typing import Mapping

BASE = "base"
"""Reserved body name of the fixed ground (body 0: origin at the global origin, no rotation)."""

KINDS = ("planar", "spatial")

# Coordinates per body, in the order they appear in q_i (paper Eq. 33 and 39), for the default
# rotation of each kind (spatial: z-x-z Euler angles). :func:`coordinates` gives them for any rotation.
COORDINATES = {
    "planar": ("x", "y", "phi"),
    "spatial": ("x", "y", "z", "alpha", "beta", "gamma"),
}
COORDINATE_UNITS = {"x": "m", "y": "m", "z": "m", "phi": "rad", "alpha": "rad", "beta": "rad", "gamma": "rad",
                    "e0": "1", "e1": "1", "e2": "1", "e3": "1"}

ROTATIONS = ("euler_zxz", "quaternion")
"""Orientation coordinates of a spatial body (``[mechanism] rotation``, spatial only; default
``euler_zxz``): z-x-z Euler angles (alpha, beta, gamma), singular at sin(beta) = 0 (paper Eq. 40),
or a unit quaternion (e0, e1, e2, e3), scalar first, body to global, valid in every orientation
(:mod:`overcon.kinematics`). Velocities are the same for both: [v (global), omega (body axes)]."""

QUATERNION_COORDINATES = ("x", "y", "z", "e0", "e1", "e2", "e3")

QUATERNION_NORM_TOL = 1e-6
"""A ``q0`` quaternion whose norm differs from 1 by more than this is refused (a typo rather than
round-off of a written-out value); within it, the loader normalises it."""

VELOCITIES_PER_BODY = {"planar": 3, "spatial": 6}
"""Length of a body's velocity vector h_i (and of ``h0``): planar [x', y', phi'], spatial
[v (global), omega (body axes)], whatever the rotation coordinates."""


VELOCITY_OUTPUTS = {"planar": (("vx", "m/s"), ("vy", "m/s"), ("omega", "rad/s")),
                    "spatial": (("vx", "m/s"), ("vy", "m/s"), ("vz", "m/s"),
                                ("wx", "rad/s"), ("wy", "rad/s"), ("wz", "rad/s"))}
"""Velocity outputs ``<body>.<name>`` (``[outputs] velocities``) and units, in the order of h_i:
planar x', y' (global frame) and the angular velocity phi'; spatial the velocity of the origin
(global frame) and the angular velocity in the body's axes."""

ENERGY_OUTPUTS = (("energy.kinetic", "J"), ("energy.potential", "J"), ("energy.dissipated", "J"),
                  ("energy.applied", "J"))
"""Energy outputs (``[outputs] energy = true``), of the whole mechanism (J): the kinetic energy
1/2 h^T M h, the potential energy of gravity and springs, the work dissipated by joint friction
since the start (>= 0) and the work of the constant forces and torques since the start. kinetic +
potential + dissipated - applied stays constant to the integration accuracy."""


def coordinates(kind: str, rotation: str = "euler_zxz") -> tuple[str, ...]:
    """Coordinate names of one body, in the order of q_i: ``COORDINATES[kind]``, or
    ``QUATERNION_COORDINATES`` for a spatial mechanism with ``rotation = "quaternion"``."""
    if kind == "spatial" and rotation == "quaternion":
        return QUATERNION_COORDINATES
    return COORDINATES[kind]

LOAD_FIELDS: Mapping[str, Mapping] = {
    "force": {
        "required": {
            "body": ("body", "body the force acts on"),
            "value": ("vec", "force in the global frame (N), applied at the body origin"),
        },
    },
    "torque": {
        "required": {
            "body": ("body", "body the torque acts on"),
            "value": ("rot", "torque in the global frame (N.m); planar: scalar, counter-clockwise +"),
        },
    },
    "spring": {
        "required": {
            "body_i": ("body", "first body"),
            "body_j": ("body", "second body (may be base)"),
            "stiffness": ("scalar", "spring stiffness k (N/m), >= 0"),
            "free_length": ("scalar", "free length L0 (m), >= 0"),
        },
        "optional": {
            "s_i": ("vec", "attachment point on body i, body i frame (m)", None),
            "s_j": ("vec", "attachment point on body j, body j frame (m)", None),
        },
    },
}

FRICTION_LAWS = ("coulomb", "regularised", "stribeck")
"""Friction laws mu(v) of paper Fig. 1: A ``coulomb`` (sign; analysis only, refused for
integration), B ``regularised`` (mu*clip(v/v_reg, -1, 1), the paper's choice), C ``stribeck``
(B with a Stribeck peak)."""

METHODS = ("dopri5", "dop853", "rk4", "radau")
KERNELS = ("auto", "c", "numpy")
SINGULAR = ("stop", "pass")
"""``[solver] singular``: what a run does at a singular position of the mechanism (its constraint
Jacobian loses rank). ``"stop"`` (default): the paper's eliminated form; the run stops there (exit 3).
``"pass"``: the augmented Lagrangian formulation over the kept equations with mass-orthogonal
projections after every step (core/kkt_al.c, core/project.c; compiled kernel only), and near a
singular position the acceleration interpolated along the motion from states where the direct
solve is accurate (core/sim_pass.c): the run goes through and records a ``singular`` event; where
the rank is regular its multipliers are the eliminated form's (docs/howto/singular.md)."""
"""Values of the solver setting ``kernel`` (:mod:`overcon.kernel`)."""
"""Integrators offered (the core's: core/integrate_rk.c, core/integrate_radau.c): adaptive explicit ``dopri5`` and
``dop853``, fixed-step ``rk4``, implicit (stiff) ``radau``."""


@dataclass(frozen=True)
class FrictionSpec:
    """Friction parameters of one joint (paper App. A).

    ``size`` is the joint's geometric friction size: translational slider length l, revolute shaft
    radius a, spherical ball radius rho, the spatial types' first size key of
:data:`overcon.joints.TYPES` (all m), None for a type whose friction needs no size
    (the point-on-line joint: a force at a point contact); ``extra`` the further size keys given (key, value in m),
    e.g. a spatial revolute joint's ``length`` (defaults are filled in at compile time). ``v_reg`` is the regularisation velocity of law B
    (m/s for sliding, rad/s for the revolute relative angular velocity). ``mu_static`` and
    ``v_stribeck`` are used by law C only.
    """

    mu: float
    size: float | None = None
    law: str = "regularised"
    v_reg: float = 1e-3
    mu_static: float | None = None
    v_stribeck: float | None = None
    extra: tuple[tuple[str, float], ...] = ()


@dataclass(frozen=True)
class BodySpec:
    """A moving body. ``inertia``: planar (J,) in kg.m^2; spatial principal moments (Jx, Jy, Jz)
    about the body axes (kg.m^2). Origin at the centre of mass. ``q0`` in the order of
    :func:`coordinates` (a quaternion stored normalised), ``h0`` the velocities
    (:data:`VELOCITIES_PER_BODY`).

    ``kind``: ``"rigid"`` or ``"particle"`` (:data:`BODY_KINDS`). A particle (a point mass, no
    orientation) is held in the same layout as a rigid body, so every later stage (packing, the
    core, the FMU) reads it unchanged: its orientation coordinates are frozen at
    :func:`particle_orientation`, its angular velocities are 0, and its ``inertia`` is a
    placeholder (its mass, numerically) that nothing ever multiplies by a non-zero rate. That
    holds because the loader lets no force or moment reach a particle's rotation: joints on a
    particle act at its position (s = 0 there) and are of :data:`PARTICLE_JOINTS`, no torque load
    and no spring off its position, no friction moment (scene.py); the constraint Jacobian's
    columns of those coordinates are then zero, and a particle counts ``dim`` coordinates in the
    pre-check (:func:`frozen_coordinates`)."""

    name: str
    mass: float
    inertia: tuple[float, ...]
    q0: tuple[float, ...]
    h0: tuple[float, ...]
    kind: str = "rigid"

    @property
    def particle(self) -> bool:
        return self.kind == "particle"


BODY_KINDS = ("rigid", "particle")
"""``[[bodies]] kind``: a rigid body (default) or a particle (a point mass: ``mass``, no
``inertia``, ``q0``/``h0`` of the position and velocity only)."""

PARTICLE_JOINTS = ("revolute", "spherical", "distance", "spatial_distance", "point_on_line", "spatial_point_on_line")
"""The joint types (keys of :data:`overcon.joints.TYPES`: the planar ``revolute``, not the spatial
one) a particle may take: those that act at a point and need no orientation of the particle (the
planar revolute and the spherical joint at its position, the distance joint from its position, the
point-on-line joint as its body i: the bead on a wire). The others hold the body's orientation (a
guide's angle row, an axis: the spatial revolute too): refused on a particle, naming the body and
the joint."""

PARTICLE_BODY_I_ONLY = ("point_on_line",)
"""Joint types of :data:`PARTICLE_JOINTS` that take a particle as body i only: body j carries a
direction fixed in its frame (the line), which a particle, without orientation, cannot carry
(decided: a line "on" a particle would have its direction turned by the reactions)."""


def particle_orientation(kind: str, rotation: str = "euler_zxz") -> tuple[float, ...]:
    """The frozen orientation coordinates of a particle: planar phi = 0; spatial z-x-z Euler
    angles (0, pi/2, 0) (away from the parametrisation's singularity at sin(beta) = 0), or the
    identity quaternion (1, 0, 0, 0)."""
    if kind == "planar":
        return (0.0,)
    if rotation == "quaternion":
        return (1.0, 0.0, 0.0, 0.0)
    return (0.0, math.pi / 2, 0.0)


def body_coordinates(kind: str, rotation: str, body: BodySpec) -> tuple[str, ...]:
    """The coordinates of ``body`` a scene may output: all of :func:`coordinates`, or a particle's
    position only (x, y, and z spatial)."""
    coords = coordinates(kind, rotation)
    return coords[:2 if kind == "planar" else 3] if body.particle else coords


def frozen_coordinates(mech) -> int:
    """How many velocity coordinates the particles' frozen orientations add (planar 1, spatial 3
    each): the pre-check's coordinate count and DOF leave them out."""
    per = 1 if mech.kind == "planar" else 3
    return per * sum(1 for b in mech.bodies if b.particle)


@dataclass(frozen=True)
class ComplianceSpec:
    """A joint's compliance (``[joints.compliance]``; used under ``redundancy = "compliant"``):
    its equations become a spring-damper on their violation. ``stiffness`` (N/m) and ``damping``
    (N.s/m) act on the equations that hold points together (``"point"`` rows, and the distance
    row of a planar translational joint), ``rotational_stiffness`` (N.m/rad) and
    ``rotational_damping`` (N.m.s/rad) on those that hold axes or angles (a small violation of
    those is an angle in rad). Each is a scalar (isotropic) or, for a spatial joint, a 3-tuple
    along the x, y, z axes of the joint frame (the reaction frame: z along axis_i; a spherical
    joint's is body i's axes)."""

    stiffness: float | tuple[float, float, float]
    rotational_stiffness: float | tuple[float, float, float]
    damping: float | tuple[float, float, float] = 0.0
    rotational_damping: float | tuple[float, float, float] = 0.0

    @property
    def per_axis(self) -> bool:
        """Whether any value is a 3-vector (not isotropic)."""
        return any(isinstance(getattr(self, k), tuple) for k in
                   ("stiffness", "rotational_stiffness", "damping", "rotational_damping"))


@dataclass(frozen=True)
class JointSpec:
    """A joint between body i and body j (either may be ``base``). ``type`` is the key in
    ``overcon.joints.TYPES`` (the file's name resolved for the mechanism kind:
    :func:`overcon.joints.resolve`). ``params`` holds the fields of
    ``overcon.joints.TYPES[type]`` as tuples/floats (None for an optional field without default); ``friction`` the parameters used when a scene switches
    friction on for this joint (None: the file gives none)."""

    name: str
    type: str
    body_i: str
    body_j: str
    params: Mapping[str, object]
    friction: FrictionSpec | None = None
    compliance: ComplianceSpec | None = None


@dataclass(frozen=True)
class LoadSpec:
    type: str
    params: Mapping[str, object]


@dataclass(frozen=True)
class MechanismSpec:
    name: str
    kind: str
    gravity: tuple[float, ...]
    bodies: tuple[BodySpec, ...]
    joints: tuple[JointSpec, ...]
    loads: tuple[LoadSpec, ...]
    source: str = ""
    description: str = ""
    rotation: str = "euler_zxz"  # spatial orientation coordinates (ROTATIONS); planar: unused default


@dataclass(frozen=True)
class SolverSpec:
    """Integration settings. ``tolerance`` is the accuracy target (relative and absolute
    tolerance of the adaptive methods dopri5, dop853, radau; for ``rk4`` it is unused). ``step`` is the fixed step of
    ``rk4`` (s). ``baumgarte`` is the constraint-stabilisation frequency (1/s, 0 disables).
    ``friction_tol``/``friction_max_iter`` control the friction solve. ``kernel`` picks the
    right-hand side's implementation, one of :data:`KERNELS` (:mod:`overcon.kernel`). ``singular``:
    stop at or pass a singular position, one of :data:`SINGULAR`. Defaults from the
    measurements in docs/benchmarks.md: dopri5 at 1e-9 reaches about 1e-7 m with friction (at 1e-8
    only about 2e-6 m: the kink of the regularised friction law spoils the error estimate)."""

    method: str = "dopri5"
    tolerance: float = 1e-9
    step: float = 1e-3
    output_interval: float = 0.01
    baumgarte: float = 10.0
    friction_tol: float = 1e-12
    friction_max_iter: int = 50
    max_step: float = 0.05
    kernel: str = "auto"
    singular: str = "stop"


REDUNDANCY_METHODS = ("eliminate", "min-norm", "compliant")
"""``[scene] redundancy``: how the redundant constraints are handled. ``"eliminate"`` (default):
the paper's method, the scene's ``eliminate`` equations are removed. ``"min-norm"``: no equation is
removed; the multipliers are the minimum-norm solution of the rank-deficient Eq. 18 (a
rank-revealing solve). It gives one motion where the paper's rigid theory has several, but that
choice has no physical ground: real joints share their loads by their compliance. ``"compliant"``:
the joints with a ``[joints.compliance]`` table are spring-dampers on their equations' violation
(:class:`ComplianceSpec`), the others rigid; their reactions, friction and motion are unique."""


INPUT_TYPES = {"joint_torque": "N.m", "joint_force": "N", "force": "N", "torque": "N.m"}
"""Input types (scene ``[[inputs]]``) and their units: a torque about a joint's axis (revolute,
cylindrical), a force along a joint's axis (translational, prismatic, cylindrical), a force on a
body at a point, a torque on a body."""
INPUT_FRAMES = ("global", "body")

JOINT_SENSORS = {"angle": "rad", "rate": "rad/s", "displacement": "m", "speed": "m/s"}
"""Joint sensor outputs ``<joint>.<sensor>`` (``[outputs] joints``) and their units."""


@dataclass(frozen=True)
class InputSpec:
    """One scene input (``[[inputs]]``): ``type`` in :data:`INPUT_TYPES`; ``joint`` for the joint
    types, ``body`` for force and torque; ``point`` (body coordinates) and ``direction`` (unit
    vector, in ``frame``: global or the body's axes) for force and torque; ``start`` the value
    before the host sets one (N or N.m)."""

    name: str
    type: str
    joint: str | None = None
    body: str | None = None
    point: tuple[float, ...] | None = None
    direction: tuple[float, ...] | None = None
    frame: str = "global"
    start: float = 0.0

    @property
    def unit(self) -> str:
        return INPUT_TYPES[self.type]


DRIVER_MOTIONS = {"constant_speed": ("speed",), "ramp": ("from", "to", "t0", "t1"),
                  "harmonic": ("amplitude", "frequency", "phase", "offset")}
"""Driver motions (scene ``[[drivers]]``) and their parameters: the driven coordinate (from its
value at q0; rad or m) as a function of time t (s): ``constant_speed`` speed (t - start_time);
``ramp`` from ``from`` to ``to`` between t0 and t1 by a quintic with zero velocity and acceleration
at both ends, held outside; ``harmonic`` offset + amplitude sin(2 pi frequency t + phase)
(frequency in Hz, phase in rad; ``phase`` and ``offset`` default 0)."""


@dataclass(frozen=True)
class DriverSpec:
    """One driver (``[[drivers]]``): ``joint`` a revolute (planar, spatial), translational,
    prismatic or cylindrical joint; ``coordinate`` "angle" or "displacement" (the joint type's;
    cylindrical: either, default angle); ``motion`` in :data:`DRIVER_MOTIONS` with its ``params``."""

    name: str
    joint: str
    motion: str
    params: Mapping[str, float]
    coordinate: str = "angle"


@dataclass(frozen=True)
class SceneSpec:
    """A mechanism plus what to simulate. ``friction``: joint names with friction switched on;
    ``friction_params`` the parameters per such joint (mechanism values overridden by the scene).
    ``eliminate``: 1-based paper equation indices, or the string ``"auto"``. ``positions`` are
    output names ``<body>.<coordinate>``; ``reactions`` joint names whose reactions are outputs;
    ``friction_outputs`` the friction joints whose friction force ``<joint>.friction`` is an
    output (``"all"``: every joint in ``friction``, the default; a scene file's ``[outputs]``
    table without a ``friction`` key gives ``()``). ``solver``: the solver options, a separate
    frozen record (None in the scene a compiled :class:`overcon.model.Model` keeps: a Model has
    no solver options)."""

    name: str
    mechanism: MechanismSpec
    friction: tuple[str, ...] = ()
    friction_params: Mapping[str, FrictionSpec] = field(default_factory=dict)
    eliminate: tuple[int, ...] | str = "auto"
    redundancy: str = "eliminate"  # REDUNDANCY_METHODS
    positions: tuple[str, ...] = ()
    reactions: tuple[str, ...] = ()
    friction_outputs: tuple[str, ...] | str = "all"
    velocities: tuple[str, ...] = ()  # bodies whose velocities are outputs (spec.VELOCITY_OUTPUTS)
    energy: bool = False  # the outputs spec.ENERGY_OUTPUTS
    start_time: float = 0.0
    stop_time: float = 1.0
    solver: SolverSpec | None = field(default_factory=SolverSpec)
    group: str = ""
    description: str = ""
    source: str = ""
    inputs: tuple[InputSpec, ...] = ()  # scene [[inputs]]
    sensors: tuple[str, ...] = ()  # joints with sensor outputs ([outputs] joints)
    drivers: tuple[DriverSpec, ...] = ()  # scene [[drivers]]
