"""Read and validate mechanism and scene files (TOML) into :mod:`overcon.spec` dataclasses.

The file format is described in ``docs/scene-format.md``. A file is a *mechanism* if it has a
``[mechanism]`` table and a *scene* if it has a ``[scene]`` table (never both). :func:`load`
returns a :class:`~overcon.spec.MechanismSpec` or a :class:`~overcon.spec.SceneSpec`; a scene
loads its mechanism (path relative to the scene file).

Validation never stops at the first problem: every problem found is collected as a
:class:`Problem` ``(file, field, message)`` and :func:`load` raises one :class:`SceneError`
listing all of them. No other exception escapes :func:`load`, whatever the file contains.
Problems in a scene's mechanism file are reported against the mechanism file. Field names look
like ``bodies[2].mass``, ``joints[0].friction.mu``, ``scene.eliminate[1]``, ``solver.tolerance``;
problems with the file as a whole (not found, not readable, not UTF-8, bad TOML syntax, neither or
both of ``[mechanism]``/``[scene]``) use the field ``(file)``.

What is validated
-----------------
* Everywhere: unknown keys at every level (with the allowed keys in the message), missing
  required fields, types (a table where a table is expected, arrays where arrays are expected,
  strings, integers); numbers must be finite (no nan/inf); integers are accepted where floats are
  expected, booleans are never numbers; vector lengths (2 planar / 3 spatial for points, vectors
  and gravity; 3 / 6 for ``q0`` and ``h0``; spatial with ``rotation = "quaternion"``: 7 for ``q0``).
* Mechanism: ``name`` an identifier (letter, then letters/digits/_), ``kind`` in
  ``spec.KINDS``; at least one body; body names identifiers, unique, not ``base``; mass > 0;
  inertia > 0 (planar: one number, stored as a 1-tuple; spatial: 3 numbers); ``h0`` defaults to
  zeros. ``kind`` in ``spec.BODY_KINDS`` (default ``rigid``); a ``particle`` has no ``inertia``
  (refused), ``q0``/``h0`` of the position and velocity only (2 planar, 3 spatial), stored in the
  rigid layout with a frozen orientation (``spec.BodySpec``); its joints, points, friction and
  loads are checked by ``_check_particles``. ``rotation`` (spatial only; a planar mechanism giving it is an error) in
  ``spec.ROTATIONS``, default ``euler_zxz``; with ``quaternion`` a body's ``q0`` is
  ``[x, y, z, e0, e1, e2, e3]`` whose quaternion norm must be within ``spec.QUATERNION_NORM_TOL``
  of 1 (refused with the norm otherwise) and is stored normalised. Joints: names identifiers and
  unique; ``type`` a joint type name allowed for the mechanism kind (resolved to its key in
  ``overcon.joints.TYPES`` by :func:`overcon.joints.resolve`: ``revolute`` is the planar or the
  spatial revolute joint); ``body_i``/``body_j`` a body or ``base`` and different; the type's required
  and optional fields (``overcon.joints.TYPES``) with their shapes (shape ``dir``, e.g.
  translational ``v``: non-zero); an ``angle`` field (translational ``psi``) may be given in
  degrees as ``<field>_deg`` (not both; stored in radians); vectors (``q0``, ``h0``) are in radians.
  Joint friction tables: ``law`` in ``spec.FRICTION_LAWS`` (default ``regularised``), ``mu``,
  ``v_reg`` (default 1e-3), ``mu_static``, ``v_stribeck`` by :mod:`overcon.params`, the type's size key (``length`` for translational, ``radius`` for
  revolute/spherical; stored as ``FrictionSpec.size``) > 0 and no other size key (spatial
  revolute, prismatic, cylindrical: their further size keys ``friction_extra``, stored as
  ``FrictionSpec.extra``; point_on_line has no size key, ``FrictionSpec.size`` None; universal,
  fixed and distance joints take no friction table); ``stribeck``
  needs ``mu_static`` (>= ``mu``, :func:`overcon.params.check_mu_static`) and ``v_stribeck``,
  which other laws do not take. Loads:
  ``type`` in ``spec.LOAD_FIELDS`` with its fields; force/torque act on a moving body; a spring
  joins two different bodies (one may be ``base``), stiffness and free length >= 0, attachment
  points default to the body origins (stored as zero vectors).
* Scene: ``name`` an identifier; ``mechanism`` a readable mechanism file; ``friction`` a list of
  distinct joints that have friction parameters (mechanism table or scene ``friction_params``);
  ``friction_params.<joint>`` names a joint and is merged onto the mechanism's parameters (a joint
  without a mechanism friction table needs ``mu`` and its size key there);
  ``eliminate`` ``"auto"`` or integers in 1..m (m = total number of constraint
  equations) and joint names (all the joint's equations, expanded in place), distinct once expanded; ``stop_time`` > ``start_time``; ``[outputs]`` ``positions`` are distinct
  ``<body>.<coordinate>`` (``spec.coordinates``) or ``"all"``, ``reactions`` distinct joint names
  or ``"all"`` (a missing ``[outputs]`` table or key means ``"all"``), ``friction`` distinct
  joints of ``scene.friction`` or ``"all"`` (a ``<joint>.friction`` output for each; a missing
  ``[outputs]`` table means ``"all"``, a missing ``friction`` key in an ``[outputs]`` table means
  none, so a scene that lists its outputs keeps exactly those); ``[solver]``: every field against its envelope in the one rules table
  :mod:`overcon.params` (with the types above), and the bounded-work relations of
  :func:`overcon.params.check_relations` (output points, fewest internal steps), reported against
  the solver field, or ``scene.stop_time`` when the file does not give that field.
* Scene ``[[inputs]]`` (:func:`_scene_inputs`), ``[[drivers]]`` (:func:`_scene_drivers`) and
  ``[outputs] joints`` (:func:`_scene_sensors`): docs/coupling.md; every problem names the file
  and the field (``inputs[0].joint``, ``drivers[1].t1``, ``outputs.joints[0]``).
* Files (bounded work): only regular files are read (a FIFO would block, ``/dev/zero`` never
  ends: both are refused without opening them), at most :data:`MAX_FILE_BYTES` (8 MiB), and within
  the key depth, key length, key count and nesting of :func:`toml_prescan` (:data:`MAX_KEY_DEPTH` ...)
  before ``tomllib`` parses it; at most
  :data:`MAX_BODIES` bodies, :data:`MAX_JOINTS` joints, :data:`MAX_LOADS` loads (why: there).

If the scene's mechanism file has problems, the scene's references to bodies, joints and equation
numbers are not checked (only its own structure), to avoid follow-on noise.

``SceneSpec.friction_params`` holds the effective (merged) parameters of exactly the joints listed
in ``friction``.

:func:`as_scene` turns a mechanism into a scene or overrides a scene's friction set, elimination,
stop time and tolerance (command-line options, reported with fields ``--friction``,
``--eliminate``, ``--stop-time``, ``--tolerance``); :func:`parse_joint_list` and
:func:`parse_eliminate` parse those options' text.
"""
from __future__ import annotations

import dataclasses
import math
import os
import re
import stat
import tomllib
from dataclasses import dataclass
from pathlib import Path

from . import params
from .joints import TYPES as JOINT_TYPES
from .joints import names as joint_type_names
from .joints import resolve as resolve_joint_type
from . import spec as S
from .spec import (
    BASE,
    BodySpec,
    FrictionSpec,
    JointSpec,
    LoadSpec,
    MechanismSpec,
    SceneSpec,
    SolverSpec,
)

__all__ = ["Problem", "SceneError", "load", "as_scene", "parse_joint_list", "parse_eliminate"]

CLI_SOURCE = "<command line>"

# The keys each table may have: read by the checks below and by overcon.schema, which generates the
# JSON Schema of the file formats from these tables, overcon.joints.TYPES, spec.LOAD_FIELDS and
# overcon.params (one source for the validator and the editors' schema).
MECHANISM_SECTIONS = ("mechanism", "bodies", "joints", "loads")
MECHANISM_KEYS = ("name", "kind", "gravity", "description", "rotation")
BODY_KEYS = ("name", "kind", "mass", "inertia", "q0", "h0")
SCENE_SECTIONS = ("scene", "outputs", "solver", "inputs", "drivers")
OUTPUT_KEYS = ("positions", "reactions", "friction", "velocities", "energy", "joints")
FILE_FIELD = "(file)"

_DIM = {"planar": 2, "spatial": 3}
_MISSING = object()


# ---------------------------------------------------------------------------------------------
# Problems


@dataclass(frozen=True)
class Problem:
    """One validation problem: the file it is in, the field (``bodies[2].mass``) and a message;
    ``name`` is the name the file gives the body, joint or load the field is in (``""``: none),
    shown after its index: ``joints[0] (hinge1).axis_i``."""

    file: str
    field: str
    message: str
    name: str = ""

    def where(self) -> str:
        """The field as shown: with the item's name after its index when the file names it."""
        if not self.name:
            return self.field
        item, dot, rest = self.field.partition(".")
        return f"{item} ({self.name}){dot}{rest}"

    def __str__(self) -> str:
        return f"{self.file}: {self.where()}: {self.message}"


class SceneError(Exception):
    """Raised with every problem found; ``str()`` lists them one per line."""

    def __init__(self, problems):
        self.problems: list[Problem] = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))

    def __reduce__(self):
        return (SceneError, (self.problems,))


class _Ctx:
    """Collects problems for one file."""

    def __init__(self, file: str, problems: list[Problem]):
        self.file = file
        self.problems = problems

    def add(self, field: str, message: str) -> None:
        self.problems.append(Problem(self.file, field, message))


# ---------------------------------------------------------------------------------------------
# Small validators. Each reports into ctx and returns the converted value or None.


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _desc(value) -> str:
    if isinstance(value, bool):
        kind = "boolean"
    elif isinstance(value, int):
        kind = "integer"
    elif isinstance(value, float):
        kind = "float"
    elif isinstance(value, str):
        kind = "string"
    elif isinstance(value, list):
        return "an array"
    elif isinstance(value, dict):
        return "a table"
    else:  # TOML date, time or date-time
        iso = getattr(value, "isoformat", None)
        return f"a date/time {iso() if iso else _short(value)}"
    return f"{kind} {_short(value)}"


_IDENTIFIER = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


def _is_identifier(s: str) -> bool:
    """An ASCII letter, then ASCII letters, digits or _."""
    return _IDENTIFIER.fullmatch(s) is not None


_POSITIVE = (lambda x: x > 0, "must be > 0")
_NONNEG = (lambda x: x >= 0, "must be >= 0")


def _num(ctx: _Ctx, value, field: str, check=None) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        ctx.add(field, f"expected a number, got {_desc(value)}")
        return None
    try:
        x = float(value)
    except OverflowError:
        ctx.add(field, "number too large")
        return None
    if not math.isfinite(x):
        ctx.add(field, f"must be finite, got {x!r}")
        return None
    if check is not None and not check[0](x):
        ctx.add(field, f"{check[1]}, got {x!r}")
        return None
    return x


def _param(ctx: _Ctx, value, field: str, name: str):
    """A solver or friction parameter (``params.RULES[name]``): type first (the loader's
    messages), then the one rule of :mod:`overcon.params`."""
    rule = params.rule_of(name)
    if rule.kind == "choice":
        val = _choice(ctx, value, field, rule.choices)
    elif rule.kind == "int":
        val = _int(ctx, value, field)
    else:
        val = _num(ctx, value, field)
    if val is None:
        return None
    reason = rule.check(val)
    if reason is not None:
        ctx.add(field, reason)
        return None
    return val


def _int(ctx: _Ctx, value, field: str) -> int | None:
    if isinstance(value, bool) or not isinstance(value, int):
        ctx.add(field, f"expected an integer, got {_desc(value)}")
        return None
    return value


def _vec(ctx: _Ctx, value, field: str, n: int | None, check=None) -> tuple[float, ...] | None:
    what = f"{n} numbers" if n is not None else "numbers"
    if not isinstance(value, list):
        ctx.add(field, f"expected an array of {what}, got {_desc(value)}")
        return None
    ok = True
    if n is not None and len(value) != n:
        ctx.add(field, f"expected an array of {what}, got {len(value)} element(s)")
        ok = False
    out = []
    for k, item in enumerate(value):
        x = _num(ctx, item, f"{field}[{k}]", check)
        ok = ok and x is not None
        out.append(x)
    return tuple(out) if ok else None


def _str(ctx: _Ctx, value, field: str) -> str | None:
    if not isinstance(value, str):
        ctx.add(field, f"expected a string, got {_desc(value)}")
        return None
    return value


def _ident(ctx: _Ctx, value, field: str) -> str | None:
    s = _str(ctx, value, field)
    if s is None:
        return None
    if not _is_identifier(s):
        ctx.add(field, f"{_short(s)} is not an identifier (a letter, then letters, digits or _)")
        return None
    return s



def _register_name(ctx: _Ctx, name, field: str, seen: dict, where: str, what: str):
    """Record a body/joint name; a duplicate is a problem (and gives None)."""
    if name is None:
        return None
    if name in seen:
        ctx.add(field, f"duplicate {what} name '{name}' (also {seen[name]})")
        return None
    seen[name] = where
    return name

def _choice(ctx: _Ctx, value, field: str, choices) -> str | None:
    s = _str(ctx, value, field)
    if s is None:
        return None
    if s not in choices:
        ctx.add(field, f"unknown value {_short(s)} (allowed: {', '.join(choices)})")
        return None
    return s


def _table(ctx: _Ctx, value, field: str) -> dict | None:
    if not isinstance(value, dict):
        ctx.add(field, f"expected a table, got {_desc(value)}")
        return None
    return value


def _unknown_keys(ctx: _Ctx, table: dict, prefix: str, allowed, hint: dict | None = None) -> None:
    for key in table:
        if key not in allowed:
            extra = (hint or {}).get(key)
            msg = f"unknown key (allowed: {', '.join(allowed)})" if extra is None else extra
            ctx.add(_join(prefix, key), msg + _deg_note(key, allowed))


DEG_SUFFIX = "_deg"
"""``<field>_deg``: an angle field (shape code ``"angle"``) given in degrees."""


def _deg_keys(fields) -> tuple[str, ...]:
    """The ``<field>_deg`` keys of the angle fields of a joint type's ``required``/``optional``."""
    return tuple(name + DEG_SUFFIX for name, (shape, *_rest) in fields.items() if shape == "angle")


def _deg_note(key: str, allowed) -> str:
    """Why an unknown ``<field>_deg`` key is unknown when ``<field>`` is allowed ("" otherwise)."""
    base = key[:-len(DEG_SUFFIX)]
    if not key.endswith(DEG_SUFFIX) or base not in allowed:
        return ""
    return (f"; '{base}' is not a scalar angle field, so it has no degrees form (only scalar angles such as "
            f"a translational joint's psi do; vectors mixing lengths and angles, like q0 and h0, are in radians)")


def _get(ctx: _Ctx, table: dict, key: str, prefix: str, required: bool = True):
    if key in table:
        return table[key]
    if required:
        ctx.add(_join(prefix, key), "missing required field")
    return _MISSING


def _array_of_tables(ctx: _Ctx, doc: dict, key: str, required: bool, limit: int):
    """[(index, table)] for the array-of-tables ``key`` (non-table entries reported); more than
    ``limit`` entries is a problem and none of them is read (bounded work)."""
    value = _get(ctx, doc, key, "", required)
    if value is _MISSING:
        return []
    if not isinstance(value, list):
        ctx.add(key, f"expected an array of tables ([[{key}]]), got {_desc(value)}")
        return []
    if len(value) > limit:
        ctx.add(key, f"{len(value)} entries; at most {limit} (bounded work and memory: the pre-check "
                     f"holds the Jacobian dense and factorises its blocks of loops; overcon.scene.MAX_{key.upper()})")
        return []
    out = []
    for k, item in enumerate(value):
        if isinstance(item, dict):
            out.append((k, item))
        else:
            ctx.add(f"{key}[{k}]", f"expected a table, got {_desc(item)}")
    return out


# ---------------------------------------------------------------------------------------------
# Friction tables (mechanism joints and scene overrides)

_FRICTION_KEYS = ("law", "mu", "v_reg", "mu_static", "v_stribeck")


def _friction(ctx: _Ctx, table: dict, prefix: str, jtype: str | None,
              base: FrictionSpec | None, require: bool = True) -> FrictionSpec | None:
    """Validate a friction table, merged onto ``base`` (None: mu and the size key required,
    unless ``require`` is false: the mechanism could not be read, so its table is unknown).

    ``jtype`` None (unknown joint type): either size key is accepted and none is required.
    ``jtype`` is a key of :data:`overcon.joints.TYPES`: its friction size keys are the primary
    one (stored as ``size``) and the type's ``friction_extra`` (stored in ``extra`` when given;
    required unless they have a default); a type with ``sizeless_friction`` has none (``size``
    None). A type without friction is refused here, naming the table."""
    if jtype is not None and not JOINT_TYPES[jtype].has_friction:
        ctx.add(prefix, _no_friction_model(jtype))
        return None
    size_keys = ("length", "radius") if jtype is None else JOINT_TYPES[jtype].friction_keys
    _friction_keys(ctx, table, prefix, jtype, size_keys)
    given = _friction_values(ctx, table, prefix, jtype, size_keys)
    ok = given is not None
    if base is None and require:
        ok = _friction_required(ctx, table, prefix, jtype, size_keys) and ok
    if not ok:
        return None
    extra = given.pop("extra", {})
    if extra:
        given["extra"] = tuple({**dict(base.extra if base is not None else ()), **extra}.items())
    if base is None:
        if "size" not in given and jtype is None:  # unknown joint type: cannot build a spec
            return None
        result = FrictionSpec(**given)
    else:
        result = dataclasses.replace(base, **given)
    return result if _friction_law_fields(ctx, table, prefix, result) else None


def _friction_keys(ctx: _Ctx, table: dict, prefix: str, jtype: str | None, size_keys) -> None:
    """Unknown keys of a friction table; the other type's size key gets a hint naming the right one."""
    hint = {}
    if jtype is not None:
        for other in ("length", "radius"):
            if other not in size_keys:
                hint[other] = (f"unknown key: the friction size of a {JOINT_TYPES[jtype].name} joint is "
                               f"'{size_keys[0]}', not '{other}'" if size_keys else
                               f"unknown key: the friction of a {JOINT_TYPES[jtype].name} joint has no size "
                               "(a force at a point contact, no lever arm)")
    _unknown_keys(ctx, table, prefix, _FRICTION_KEYS + size_keys, hint)


def _friction_values(ctx: _Ctx, table: dict, prefix: str, jtype: str | None, size_keys) -> dict | None:
    """The given law, parameters, ``size`` and ``extra`` (a dict) of a friction table; None if one
    is bad (reported)."""
    ok = True
    given: dict = {}
    checks = {"law": lambda v, f: _choice(ctx, v, f, S.FRICTION_LAWS)}
    for key in params.FRICTION_FIELDS:
        checks[key] = lambda v, f, key=key: _param(ctx, v, f, key)
    for key, conv in checks.items():
        if key in table:
            val = conv(table[key], _join(prefix, key))
            if val is None:
                ok = False
            else:
                given[key] = val
    extra = {}
    for key in size_keys:
        if key in table:
            val = _num(ctx, table[key], _join(prefix, key), _POSITIVE)
            if val is None:
                ok = False
            elif jtype is None or key == size_keys[0]:
                given["size"] = val
            else:
                extra[key] = val
    if extra:
        given["extra"] = extra
    return given if ok else None


def _friction_required(ctx: _Ctx, table: dict, prefix: str, jtype: str | None, size_keys) -> bool:
    """mu and the type's size keys without a default must be given (a table without a base)."""
    ok = True
    if "mu" not in table:
        ctx.add(_join(prefix, "mu"), "missing required field")
        ok = False
    required_sizes = () if jtype is None or not size_keys else (size_keys[0], *(
        key for key, (_text, default) in JOINT_TYPES[jtype].friction_extra.items() if default is None))
    for key in required_sizes:
        if key not in table:
            ctx.add(_join(prefix, key), "missing required field")
            ok = False
    return ok


def _friction_law_fields(ctx: _Ctx, table: dict, prefix: str, result: FrictionSpec) -> bool:
    """The Stribeck fields: required by law 'stribeck' (with mu_static >= mu), refused by the others."""
    ok = True
    if result.law == "stribeck":
        for key in ("mu_static", "v_stribeck"):
            if getattr(result, key) is None:
                ctx.add(_join(prefix, key), "required by law 'stribeck'")
                ok = False
        reason = params.check_mu_static(result.mu, result.mu_static)
        if reason is not None:
            ctx.add(_join(prefix, "mu_static"), reason)
            ok = False
    else:
        for key in ("mu_static", "v_stribeck"):
            if key in table:
                ctx.add(_join(prefix, key), f"only used by law 'stribeck' (law is '{result.law}')")
                ok = False
    return ok


def _no_friction_model(jtype: str) -> str:
    """The refusal of friction on a joint of type ``jtype`` (a key of :data:`overcon.joints.TYPES`
    whose type has no friction model), listing the joint types that have one."""
    return (f"a {JOINT_TYPES[jtype].name} joint has no friction model (joint friction: "
            f"{', '.join(n for n in joint_type_names() if _has_friction(n))} joints)")


def _has_friction(name: str) -> bool:
    """Whether some joint type called ``name`` has a friction model."""
    return any(jt.has_friction for jt in JOINT_TYPES.values() if jt.name == name)


# ---------------------------------------------------------------------------------------------
# Mechanism


def _rotation(ctx: _Ctx, mt: dict, kind: str | None) -> str | None:
    """``mechanism.rotation`` (default ``euler_zxz``); None if invalid (already reported)."""
    v = _get(ctx, mt, "rotation", "mechanism", required=False)
    if v is _MISSING:
        return "euler_zxz"
    if kind == "planar":
        ctx.add("mechanism.rotation", "a planar mechanism has one rotation angle (phi) per body: "
                                      "'rotation' applies to spatial mechanisms only")
        return "euler_zxz"
    return _choice(ctx, v, "mechanism.rotation", S.ROTATIONS)


def _unit_quaternion(ctx: _Ctx, q0: tuple[float, ...], field: str, body: str | None) -> tuple[float, ...] | None:
    """q0 = [x, y, z, e0..e3] with the quaternion normalised, or None (reported) if its norm is
    further than ``spec.QUATERNION_NORM_TOL`` from 1."""
    e = q0[3:]
    norm = math.sqrt(sum(x * x for x in e))
    if not abs(norm - 1.0) <= S.QUATERNION_NORM_TOL:
        who = f"body {body!r}: " if body else ""
        ctx.add(field, f"{who}quaternion [e0, e1, e2, e3] = {_short(list(e))} has norm {norm:.10g}; it must be "
                       f"1 within {S.QUATERNION_NORM_TOL:g} (smaller deviations are normalised)")
        return None
    return q0[:3] + tuple(x / norm for x in e)


@dataclass
class _MechHeader:
    """The ``[mechanism]`` table's values (None: missing or invalid, reported)."""

    name: str | None = None
    kind: str | None = None
    gravity: tuple | None = None
    rotation: str | None = "euler_zxz"
    description: str = ""

    @property
    def dim(self) -> int | None:
        return _DIM.get(self.kind)


def _check_mechanism(doc: dict, ctx: _Ctx) -> MechanismSpec | None:
    """The mechanism file's document checked section by section; None if it has problems (all
    in ``ctx``, those of a named body, joint or load carrying its name)."""
    n_problems = len(ctx.problems)
    _unknown_keys(ctx, doc, "", MECHANISM_SECTIONS)
    head = _check_header(doc, ctx)
    body_names: dict[str, str] = {}  # name -> field where first defined
    bodies = _check_bodies(doc, ctx, head, body_names)
    joints = _check_joints(doc, ctx, head, body_names)
    loads = _check_loads(doc, ctx, head, body_names)
    if len(ctx.problems) == n_problems:  # every item valid: joints[k] and loads[k] are the file's
        _check_particles(ctx, bodies, joints, loads, head.kind)
    if len(ctx.problems) > n_problems:
        _name_items(doc, ctx, n_problems)
        return None
    return MechanismSpec(name=head.name, kind=head.kind, gravity=head.gravity, bodies=tuple(bodies),
                         joints=tuple(joints), loads=tuple(loads), source=ctx.file,
                         description=head.description, rotation=head.rotation or "euler_zxz")


def particle_friction_refused(jtype: str) -> bool:
    """Whether friction in a joint of ``jtype`` (a key of :data:`overcon.joints.TYPES`) on a
    particle is refused: a friction with a size (a pin's or ball's radius: a friction moment about
    the particle) is; a sizeless friction (the point-on-line joint's force at the contact) is not."""
    return JOINT_TYPES[jtype].friction_size is not None


def particle_friction_reason(jtype: str, body: str) -> str:
    """Why friction in a revolute or spherical joint on a particle is refused (decided): a point
    mass has no rotational inertia, so a pin or ball on it turns with the other body and carries
    no friction moment; a friction moment on it would meet no inertia at all. Friction on a
    particle belongs to a joint it slides in."""
    return (f"friction in a {JOINT_TYPES[jtype].name} joint on particle '{body}' is refused: a point mass has "
            "no rotational inertia, so the joint turns freely with the other body and carries no friction "
            "moment (model the body as a rigid body with its inertia to have pin friction)")


def _particle_of(bodies: dict, js: JointSpec) -> list[tuple[str, str]]:
    """(side ``i``/``j``, body name) of the particles a joint connects."""
    return [(side, b) for side, b in (("i", js.body_i), ("j", js.body_j)) if b in bodies and bodies[b].particle]


def _check_particles(ctx: _Ctx, bodies: list, joints: list, loads: list, kind: str | None) -> None:
    """What a particle (``kind = "particle"``, spec.BodySpec) takes: joints of
    :data:`overcon.spec.PARTICLE_JOINTS` acting at its position (their point on it is 0), no
    friction moment on it (:func:`particle_friction_reason`), no torque load, springs attached at
    its position. Each refusal names the body and the joint or load."""
    by_name = {b.name: b for b in bodies}
    zero = "[0, 0]" if kind == "planar" else "[0, 0, 0]"
    for k, js in enumerate(joints):
        p, jt = f"joints[{k}]", JOINT_TYPES[js.type]
        for side, body in _particle_of(by_name, js):
            if js.type not in S.PARTICLE_JOINTS:
                allowed = ", ".join(JOINT_TYPES[t].name for t in S.PARTICLE_JOINTS if JOINT_TYPES[t].kind == kind)
                ctx.add(f"{p}.body_{side}", f"joint {js.name}: body '{body}' is a particle (no orientation), and a "
                                            f"{jt.name} joint holds its body's orientation; a particle takes "
                                            f"{allowed} joints")
                continue
            if side == "j" and jt.name in S.PARTICLE_BODY_I_ONLY:
                ctx.add(f"{p}.body_j", f"joint {js.name}: body '{body}' is a particle (no orientation), and body j "
                                       f"of a {jt.name} joint carries its direction (axis_j); put the particle as "
                                       "body i and the line on a rigid body or the base")
                continue
            point = f"s_{side}"
            if any(x != 0.0 for x in js.params[point]):
                ctx.add(f"{p}.{point}", f"joint {js.name}: must be {zero} on particle '{body}': a joint acts at a "
                                        "particle's position (it has no body frame to offset the point in)")
            if js.friction is not None and particle_friction_refused(js.type):
                ctx.add(f"{p}.friction", f"joint {js.name}: {particle_friction_reason(js.type, body)}")
    for k, ld in enumerate(loads):
        p = f"loads[{k}]"
        if ld.type == "torque" and ld.params.get("body") in by_name and by_name[ld.params["body"]].particle:
            ctx.add(f"{p}.body", f"body '{ld.params['body']}' is a particle: a point mass takes no torque (apply "
                                 "a force)")
        if ld.type == "spring":
            for side in ("i", "j"):
                body = ld.params.get(f"body_{side}")
                at = ld.params.get(f"s_{side}")
                if body in by_name and by_name[body].particle and at is not None and any(x != 0.0 for x in at):
                    ctx.add(f"{p}.s_{side}", f"must be {zero} on particle '{body}': a spring acts at a particle's "
                                             "position")


def _name_items(doc: dict, ctx: _Ctx, since: int) -> None:
    """Problems (from ``since`` on) in a body, joint or load that the file names carry that name,
    shown as ``joints[0] (hinge1)`` (:class:`Problem`)."""
    names = {}
    for section in ("bodies", "joints", "loads"):
        entries = doc.get(section)
        if not isinstance(entries, list):
            continue
        for k, entry in enumerate(entries):
            name = entry.get("name") if isinstance(entry, dict) else None
            if isinstance(name, str) and name:
                names[f"{section}[{k}]"] = name
    for i in range(since, len(ctx.problems)):
        p = ctx.problems[i]
        item = p.field.split(".", 1)[0]
        if item in names and not p.name:
            ctx.problems[i] = dataclasses.replace(p, name=names[item])


def _check_header(doc: dict, ctx: _Ctx) -> _MechHeader:
    head = _MechHeader()
    mt = _get(ctx, doc, "mechanism", "")
    if mt is _MISSING or _table(ctx, mt, "mechanism") is None:
        return head
    _unknown_keys(ctx, mt, "mechanism", MECHANISM_KEYS)
    v = _get(ctx, mt, "name", "mechanism")
    if v is not _MISSING:
        head.name = _ident(ctx, v, "mechanism.name")
    v = _get(ctx, mt, "kind", "mechanism")
    if v is not _MISSING:
        head.kind = _choice(ctx, v, "mechanism.kind", S.KINDS)
    v = _get(ctx, mt, "description", "mechanism", required=False)
    if v is not _MISSING:
        head.description = _str(ctx, v, "mechanism.description") or ""
    v = _get(ctx, mt, "gravity", "mechanism")
    if v is not _MISSING:
        head.gravity = _vec(ctx, v, "mechanism.gravity", head.dim)
    head.rotation = _rotation(ctx, mt, head.kind)
    return head


def _check_items(ctx: _Ctx, doc: dict, section: str, limit: int, required: bool, check) -> list:
    """``check(table, "section[k]")`` of every table of the array ``section``; the valid items."""
    entries = _array_of_tables(ctx, doc, section, required=required, limit=limit)
    items = (check(entry, f"{section}[{k}]") for k, entry in entries)
    return [item for item in items if item is not None]


def _check_bodies(doc: dict, ctx: _Ctx, head: _MechHeader, body_names: dict) -> list[BodySpec]:
    if "bodies" in doc and isinstance(doc["bodies"], list) and not doc["bodies"]:
        ctx.add("bodies", "at least one body is required")
    return _check_items(ctx, doc, "bodies", MAX_BODIES, True,
                        lambda bt, p: _check_body(bt, p, ctx, head, body_names))


def _check_body(bt: dict, p: str, ctx: _Ctx, head: _MechHeader, body_names: dict) -> BodySpec | None:
    kind, rotation = head.kind, head.rotation
    ncoord = len(S.coordinates(kind, rotation)) if kind and rotation else None
    nvel = S.VELOCITIES_PER_BODY.get(kind)
    _unknown_keys(ctx, bt, p, BODY_KEYS)
    bname = mass = inertia = q0 = None
    body_kind = "rigid"
    v = _get(ctx, bt, "kind", p, required=False)
    if v is not _MISSING:
        body_kind = _choice(ctx, v, f"{p}.kind", S.BODY_KINDS)
        if body_kind is None:
            return None
    particle = body_kind == "particle"
    if particle:  # a point mass: its position and velocity only (spec.BodySpec)
        ncoord = nvel = head.dim
    h0 = tuple(0.0 for _ in range(nvel)) if nvel else None
    v = _get(ctx, bt, "name", p)
    if v is not _MISSING:
        bname = _ident(ctx, v, f"{p}.name")
        if bname == BASE:
            ctx.add(f"{p}.name", f"'{BASE}' is reserved for the fixed ground")
            bname = None
        bname = _register_name(ctx, bname, f"{p}.name", body_names, p, "body")
    v = _get(ctx, bt, "mass", p)
    if v is not _MISSING:
        mass = _num(ctx, v, f"{p}.mass", _POSITIVE)
    if particle:
        if "inertia" in bt:
            ctx.add(f"{p}.inertia", "a particle (kind = \"particle\") is a point mass: it has no inertia (give a "
                                    "rigid body for a body whose rotation matters)")
            return None
    else:
        v = _get(ctx, bt, "inertia", p)
        if v is not _MISSING:
            inertia = _inertia(ctx, v, f"{p}.inertia", kind)
    v = _get(ctx, bt, "q0", p)
    if v is not _MISSING:
        q0 = _vec(ctx, v, f"{p}.q0", ncoord)
        if q0 is not None and kind == "spatial" and rotation == "quaternion" and not particle:
            q0 = _unit_quaternion(ctx, q0, f"{p}.q0", bname)
    v = _get(ctx, bt, "h0", p, required=False)
    if v is not _MISSING:
        h0 = _vec(ctx, v, f"{p}.h0", nvel)
    if particle and None not in (mass, q0, h0) and kind is not None and rotation is not None:
        # the rigid layout with a frozen orientation (spec.BodySpec): its placeholder inertia is
        # never multiplied by a non-zero rate
        nrot = S.VELOCITIES_PER_BODY[kind] - head.dim
        inertia = (mass,) * (1 if kind == "planar" else 3)
        q0 = tuple(q0) + S.particle_orientation(kind, rotation)
        h0 = tuple(h0) + (0.0,) * nrot
    if None in (bname, mass, inertia, q0, h0):
        return None
    return BodySpec(bname, mass, inertia, q0, h0, body_kind)


def _inertia(ctx: _Ctx, v, field: str, kind: str | None):
    """Planar: one positive number J, as a 1-tuple; spatial: three positive principal inertias."""
    if kind == "planar":
        if isinstance(v, list):
            ctx.add(field, "expected a number (planar moment of inertia J), got an array")
            return None
        j = _num(ctx, v, field, _POSITIVE)
        return None if j is None else (j,)
    if kind == "spatial":
        return _vec(ctx, v, field, 3, _POSITIVE)
    return None


def _body_ref(ctx: _Ctx, body_names: dict, value, field: str, allow_base: bool = True) -> str | None:
    """A body name given in ``field``: a body of the file, or the base where ``allow_base``."""
    s = _str(ctx, value, field)
    if s is None:
        return None
    if s == BASE:
        if allow_base:
            return s
        ctx.add(field, f"cannot act on '{BASE}' (the fixed ground)")
        return None
    if s not in body_names:
        ctx.add(field, f"unknown body {_short(s)}")
        return None
    return s


_JOINT_COMMON = ("name", "type", "body_i", "body_j", "friction", "compliance")
_COMPLIANCE_KEYS = ("stiffness", "rotational_stiffness", "damping", "rotational_damping")


def _check_joints(doc: dict, ctx: _Ctx, head: _MechHeader, body_names: dict) -> list[JointSpec]:
    joint_names: dict[str, str] = {}
    return _check_items(ctx, doc, "joints", MAX_JOINTS, False,
                        lambda jt, p: _check_joint(jt, p, ctx, head.kind, body_names, joint_names))


def _joint_type(ctx: _Ctx, jt: dict, p: str, kind: str | None) -> tuple[str | None, bool]:
    """(joint type key or None, whether it is allowed for the mechanism's kind)."""
    v = _get(ctx, jt, "type", p)
    if v is _MISSING:
        return None, True
    tname = _choice(ctx, v, f"{p}.type", joint_type_names())
    if tname is None:
        return None, True
    # kind unknown (reported): check the fields of the first type of that name
    jtype = resolve_joint_type(kind, tname) if kind is not None else next(
        key for key, d in JOINT_TYPES.items() if d.name == tname)
    if jtype is None:
        ctx.add(f"{p}.type", f"joint type '{tname}' is not allowed in a {kind} mechanism "
                             f"(allowed: {', '.join(joint_type_names(kind))})")
        return None, False
    return jtype, True


def _joint_keys(types) -> tuple[str, ...]:
    """The keys a joint table of the joint types ``types`` may have."""
    return _JOINT_COMMON + tuple(dict.fromkeys(
        f for d in types for f in (*d.required, *d.optional, *_deg_keys(d.required), *_deg_keys(d.optional))))


#: Joint type key -> the keys its table may have, and None -> the keys of any type: made once, at
#: import (a mechanism of 10,000 joints asks for them 10,000 times).
_JOINT_KEYS = {**{key: _joint_keys((jt,)) for key, jt in JOINT_TYPES.items()}, None: _joint_keys(JOINT_TYPES.values())}


def _joint_params(ctx: _Ctx, jt: dict, p: str, fields, kind: str | None) -> dict | None:
    """The type's required and optional fields (defaults filled in), or None if one is bad."""
    params: dict = {}
    ok = True
    for fname, (shape, _doc) in fields.required.items():
        val = _field(ctx, jt, fname, p, shape, kind, required=True)
        if val is None or val is _MISSING:
            ok = False
        else:
            params[fname] = val
    for fname, (shape, _doc, default) in fields.optional.items():
        val = _field(ctx, jt, fname, p, shape, kind, required=False)
        if val is None:
            ok = False
        else:
            params[fname] = default if val is _MISSING else val
    return params if ok else None


def _check_joint(jt: dict, p: str, ctx: _Ctx, kind: str | None, body_names: dict,
                 joint_names: dict) -> JointSpec | None:
    jname = bi = bj = None
    jtype, ok = _joint_type(ctx, jt, p, kind)
    # a type not allowed for the kind is reported once; its fields are then not checked
    fields = JOINT_TYPES[jtype] if jtype and ok else None
    _unknown_keys(ctx, jt, p, _JOINT_KEYS[jtype if fields is not None else None])
    v = _get(ctx, jt, "name", p)
    if v is not _MISSING:
        jname = _register_name(ctx, _ident(ctx, v, f"{p}.name"), f"{p}.name", joint_names, p, "joint")
    v = _get(ctx, jt, "body_i", p)
    if v is not _MISSING:
        bi = _body_ref(ctx, body_names, v, f"{p}.body_i")
    v = _get(ctx, jt, "body_j", p)
    if v is not _MISSING:
        bj = _body_ref(ctx, body_names, v, f"{p}.body_j")
    if bi is not None and bi == bj:
        ctx.add(f"{p}.body_j", f"body_j must differ from body_i ('{bi}')")
        ok = False
    params = None
    if fields is not None and ok:
        params = _joint_params(ctx, jt, p, fields, kind)
        ok = params is not None
    friction = None
    v = _get(ctx, jt, "friction", p, required=False)
    if v is not _MISSING and _table(ctx, v, f"{p}.friction") is not None:
        friction = _friction(ctx, v, f"{p}.friction", jtype if fields else None, None)
    compliance, good = _compliance(ctx, jt, p, kind)
    if good and compliance is not None and compliance.per_axis and fields is not None and not fields.axis_compliance:
        ctx.add(f"{p}.compliance", f"a {fields.name} joint takes scalar (isotropic) compliance values only: its "
                                   "equations' directions are the line's normals on body j, not a frame on body i")
        good = False
    if ok and good and None not in (jname, jtype, bi, bj):
        return JointSpec(jname, jtype, bi, bj, params, friction, compliance)
    return None


def _compliance(ctx: _Ctx, jt: dict, p: str, kind: str | None) -> tuple[S.ComplianceSpec | None, bool]:
    """``[joints.compliance]``: (the spec or None, whether it is valid). Stiffnesses required and
    > 0, dampings optional (default 0) and >= 0; each a scalar (isotropic) or, in a spatial
    mechanism, a 3-vector along the joint frame's axes."""
    v = _get(ctx, jt, "compliance", p, required=False)
    if v is _MISSING:
        return None, True
    f = f"{p}.compliance"
    if _table(ctx, v, f) is None:
        return None, False
    _unknown_keys(ctx, v, f, _COMPLIANCE_KEYS)
    values = {}
    for key in _COMPLIANCE_KEYS:
        x = _get(ctx, v, key, f, required=key.endswith("stiffness"))
        if x is not _MISSING:
            values[key] = _compliance_value(ctx, x, f"{f}.{key}", key, kind)
    if len(values) < sum(1 for k in _COMPLIANCE_KEYS if k in v) or None in values.values() \
            or not {"stiffness", "rotational_stiffness"} <= set(values):
        return None, False
    return S.ComplianceSpec(**values), True


def _compliance_value(ctx: _Ctx, x, field: str, key: str, kind: str | None):
    """One compliance value: a number, or (spatial only) 3 numbers along the joint frame's x, y, z
    axes; stiffnesses > 0, dampings >= 0, all finite."""
    check = (lambda y: y > 0, "must be > 0") if key.endswith("stiffness") else _NONNEG
    if not isinstance(x, list):
        return _num(ctx, x, field, check)
    if kind == "planar":
        ctx.add(field, "per-axis values (a 3-vector) are for spatial joints: a planar joint takes one scalar")
        return None
    if len(x) != 3:
        ctx.add(field, f"expected a scalar (isotropic) or an array of 3 numbers (along the joint frame's x, y, z "
                       f"axes), got {len(x)} element(s)")
        return None
    return _vec(ctx, x, field, 3, check)


def _check_loads(doc: dict, ctx: _Ctx, head: _MechHeader, body_names: dict) -> list[LoadSpec]:
    return _check_items(ctx, doc, "loads", MAX_LOADS, False,
                        lambda lt, p: _check_load(lt, p, ctx, head, body_names))


def _check_load(lt: dict, p: str, ctx: _Ctx, head: _MechHeader, body_names: dict) -> LoadSpec | None:
    kind, dim = head.kind, head.dim
    ltype = None
    v = _get(ctx, lt, "type", p)
    if v is not _MISSING:
        ltype = _choice(ctx, v, f"{p}.type", tuple(S.LOAD_FIELDS))
    if ltype is None:
        allowed = ("type",) + tuple(dict.fromkeys(
            f for d in S.LOAD_FIELDS.values()
            for f in (*d["required"], *d.get("optional", {}))))
        _unknown_keys(ctx, lt, p, allowed)
        return None
    lf = S.LOAD_FIELDS[ltype]
    optional = lf.get("optional", {})
    _unknown_keys(ctx, lt, p, ("type",) + tuple(lf["required"]) + tuple(optional))
    ok = True
    params = {}
    for fname, (shape, _doc) in lf["required"].items():
        v = _get(ctx, lt, fname, p)
        if v is _MISSING:
            ok = False
            continue
        f = f"{p}.{fname}"
        if shape == "body":
            val = _body_ref(ctx, body_names, v, f, allow_base=(ltype == "spring"))
        elif shape == "scalar":
            val = _num(ctx, v, f, _NONNEG if ltype == "spring" else None)
        else:
            val = _shaped(ctx, v, f, shape, kind)
        if val is None:
            ok = False
        else:
            params[fname] = val
    for fname, (shape, _doc, _default) in optional.items():
        v = _get(ctx, lt, fname, p, required=False)
        if v is _MISSING:
            if dim is not None and shape == "vec":
                params[fname] = tuple(0.0 for _ in range(dim))  # body origin
            continue
        val = _shaped(ctx, v, f"{p}.{fname}", shape, kind)
        if val is None:
            ok = False
        else:
            params[fname] = val
    if ltype == "spring" and "body_i" in params and params.get("body_i") == params.get("body_j"):
        ctx.add(f"{p}.body_j", f"body_j must differ from body_i ('{params['body_i']}')")
        ok = False
    return LoadSpec(ltype, params) if ok else None


def _shaped(ctx: _Ctx, value, field: str, shape: str, kind: str | None):
    """A value of shape code ``vec`` / ``dir`` / ``rot`` / ``scalar`` / ``positive`` (a scalar > 0)
    (:class:`overcon.joints.JointType`)."""
    if shape in ("scalar", "angle"):
        return _num(ctx, value, field)
    if shape == "positive":
        return _num(ctx, value, field, _POSITIVE)
    if shape == "vec":
        return _vec(ctx, value, field, _DIM.get(kind))
    if shape == "dir":
        val = _vec(ctx, value, field, _DIM.get(kind))
        if val is not None and all(x == 0.0 for x in val):
            ctx.add(field, "must not be the zero vector")
            return None
        if val is not None:
            norm = math.sqrt(math.fsum(x * x for x in val))  # as the joint normalises it (underflow: 0)
            if not (0.0 < norm < math.inf):
                ctx.add(field, f"a direction, normalised as v/|v|: |v| = {norm:g} in double precision (give "
                               "components between about 1e-150 and 1e150)")
                return None
        return val
    if shape == "rot":
        if kind == "planar":
            return _num(ctx, value, field)
        if kind == "spatial":
            return _vec(ctx, value, field, 3)
        # unknown kind (already reported): check the element types only
        return _vec(ctx, value, field, None) if isinstance(value, list) else _num(ctx, value, field)
    raise ValueError(f"unknown shape code {shape!r}")  # programming error in spec tables


def _field(ctx: _Ctx, table: dict, name: str, prefix: str, shape: str, kind: str | None,
           required: bool):
    """Field ``name`` of shape ``shape`` from ``table``: its value, None if invalid, _MISSING if
    absent (reported if ``required``). An angle (shape ``"angle"``) may be given in degrees as
    ``<name>_deg`` instead (stored in radians, ``math.radians``); giving both is a problem."""
    deg = name + DEG_SUFFIX
    if shape != "angle" or deg not in table:
        v = _get(ctx, table, name, prefix, required)
        return v if v is _MISSING else _shaped(ctx, v, _join(prefix, name), shape, kind)
    if name in table:
        ctx.add(_join(prefix, deg), f"give either '{name}' (radians) or '{deg}' (degrees), not both")
        return None
    val = _num(ctx, table[deg], _join(prefix, deg))
    return None if val is None else math.radians(val)


def _n_equations(mech: MechanismSpec) -> int:
    return sum(JOINT_TYPES[j.type].n_equations for j in mech.joints)


def _all_positions(mech: MechanismSpec) -> tuple[str, ...]:
    return tuple(f"{b.name}.{c}" for b in mech.bodies for c in S.body_coordinates(mech.kind, mech.rotation, b))


# ---------------------------------------------------------------------------------------------
# Scene

_SCENE_KEYS = ("name", "mechanism", "group", "description", "friction", "eliminate",
               "start_time", "stop_time", "friction_params", "redundancy")


def _joint_equations(mech: MechanismSpec) -> dict[str, tuple[int, ...]]:
    """Joint name -> its 1-based equation numbers (the joints' equations in file order)."""
    out, first = {}, 1
    for j in mech.joints:
        n = JOINT_TYPES[j.type].n_equations
        out[j.name] = tuple(range(first, first + n))
        first += n
    return out


def _eliminate_item(ctx: _Ctx, item, field: str, equations: dict | None) -> tuple[int, ...] | None:
    """One element of ``eliminate``: an equation number -> ``(i,)``; a joint name -> all its
    equation numbers (``equations``: :func:`_joint_equations`, None: mechanism not read, names
    not checked and nothing returned)."""
    if isinstance(item, str):
        if equations is None:
            return None
        if item not in equations:
            ctx.add(field, f"unknown joint {_short(item)} (an element is an equation index or a joint name)")
            return None
        return equations[item]
    if isinstance(item, bool) or not isinstance(item, int):
        ctx.add(field, f"expected an equation index (integer) or a joint name, got {_desc(item)}")
        return None
    return (item,)


def _check_eliminate(ctx: _Ctx, value, field: str, mech: MechanismSpec | None,
                     elem_field) -> tuple | str | None:
    """``"auto"``, or an array of equation indices in 1..m and joint names (all the joint's
    equations), distinct once names are expanded in place -> ``"auto"`` or the equation indices.
    ``elem_field(k)`` names element k; ``mech`` None: the mechanism could not be read."""
    if isinstance(value, str):
        if value == "auto":
            return "auto"
        ctx.add(field, f"expected \"auto\" or an array of equation indices and joint names, got {_desc(value)}")
        return None
    if not isinstance(value, (list, tuple)):
        ctx.add(field, f"expected \"auto\" or an array of equation indices and joint names, got {_desc(value)}")
        return None
    equations = _joint_equations(mech) if mech is not None else None
    m = _n_equations(mech) if mech is not None else None
    ok, numbered, names = True, [], set()  # numbered: (element field, equation index)
    for k, item in enumerate(value):
        if isinstance(item, str):
            if item in names:
                ctx.add(elem_field(k), f"joint '{item}' listed twice")
                ok = False
                continue
            names.add(item)
        got = _eliminate_item(ctx, item, elem_field(k), equations)
        ok = ok and got is not None
        numbered.extend((elem_field(k), i) for i in got or ())
    indices = _distinct_items(
        ctx, numbered, lambda k: numbered[k][0], lambda _ctx, pair, _f: pair[1],
        invalid=lambda i: f"equation index {i} outside 1..{m}" if m is not None and not 1 <= i <= m else None,
        duplicate=lambda i: f"equation {i} listed twice")
    return indices if ok else None


def _distinct_items(ctx: _Ctx, value, elem_field, parse, *, invalid, duplicate, late=lambda x: None):
    """Parse every element (``parse(ctx, item, field)`` -> value or None), report an invalid one
    (``invalid(x)`` -> message or None), a repeated one (``duplicate(x)`` -> message) and, for
    the others, ``late(x)``; the tuple of values, or None when anything was reported."""
    ok, seen, out = True, set(), []
    for k, item in enumerate(value):
        f = elem_field(k)
        x = parse(ctx, item, f)
        if x is None:
            ok = False
            continue
        msg = invalid(x) or (duplicate(x) if x in seen else None) or late(x)
        if msg:
            ctx.add(f, msg)
            ok = False
        seen.add(x)
        out.append(x)
    return tuple(out) if ok else None


def _check_friction_list(ctx: _Ctx, value, field: str, mech: MechanismSpec | None,
                         has_params, elem_field) -> tuple[str, ...] | None:
    if not isinstance(value, (list, tuple)):
        ctx.add(field, f"expected an array of joint names, got {_desc(value)}")
        return None
    types = {j.name: j.type for j in mech.joints} if mech is not None else None

    particles = {b.name for b in mech.bodies if b.particle} if mech is not None else set()
    ends = {j.name: (j.body_i, j.body_j) for j in mech.joints} if mech is not None else {}

    def late(s):
        if types is None:
            return None
        if not JOINT_TYPES[types[s]].has_friction:
            return f"joint '{s}': {_no_friction_model(types[s])}"
        on = [b for b in ends[s] if b in particles] if particle_friction_refused(types[s]) else []
        if on:
            return f"joint '{s}': {particle_friction_reason(types[s], on[0])}"
        if not has_params(s):
            return (f"joint '{s}' has no friction parameters (no [joints.friction] table in "
                    f"the mechanism and no scene friction_params.{s})")
        return None

    return _distinct_items(
        ctx, value, elem_field, _str,
        invalid=lambda s: f"unknown joint {_short(s)}" if types is not None and s not in types else None,
        duplicate=lambda s: f"joint '{s}' listed twice", late=late)


def _check_scene(doc: dict, ctx: _Ctx, problems: list[Problem]) -> SceneSpec | None:
    """The scene file's document checked section by section (its mechanism file too); None if
    either has problems (all in ``problems``)."""
    n_problems = len(problems)
    _unknown_keys(ctx, doc, "", SCENE_SECTIONS)
    st = doc.get("scene")
    if _table(ctx, st, "scene") is None:
        return None
    _unknown_keys(ctx, st, "scene", _SCENE_KEYS)
    name = _MISSING
    v = _get(ctx, st, "name", "scene")
    if v is not _MISSING:
        name = _ident(ctx, v, "scene.name")
    group = _optional_str(ctx, st, "group")
    description = _optional_str(ctx, st, "description")
    mech = _scene_mechanism(ctx, st, problems)
    joints = {j.name: j for j in mech.joints} if mech is not None else {}
    friction_params, fp_given = _scene_friction_params(ctx, st, mech, joints)

    def has_params(jn):
        return jn in fp_given or joints[jn].friction is not None

    friction = None
    v = _get(ctx, st, "friction", "scene")
    if v is not _MISSING:
        friction = _check_friction_list(ctx, v, "scene.friction", mech, has_params,
                                        lambda k: f"scene.friction[{k}]")
    redundancy, eliminate = _scene_redundancy(ctx, st, mech)
    start_time, stop_time = _scene_times(ctx, st)
    positions, reactions, friction_out, velocities, energy = _scene_outputs(ctx, doc, mech, joints, friction)
    sensors = _scene_sensors(ctx, doc, mech)
    inputs = _scene_inputs(ctx, doc, mech)
    drivers = _scene_drivers(ctx, doc, mech, {u.name for u in inputs})
    solver_kw = _scene_solver(ctx, doc, problems, start_time, stop_time)
    if drivers and (redundancy == "compliant" or solver_kw.get("singular") == "pass"):
        ctx.add("drivers", "drivers run under the eliminated or min-norm solve with solver.singular = \"stop\" (the "
                           "compliant and augmented Lagrangian solves do not carry a rheonomic equation yet)")
    if inputs and solver_kw.get("method") == "rk4":
        ctx.add("solver.method", "rk4 with [[inputs]]: its fixed steps would step over the instants where the inputs "
                                 "change (co-simulation holds them over each communication step); use dopri5, dop853 "
                                 "or radau")
    if len(problems) > n_problems or mech is None:
        return None
    if positions == "all":
        positions = _all_positions(mech)
    if reactions == "all":
        reactions = tuple(j.name for j in mech.joints)
    if velocities == "all":
        velocities = tuple(b.name for b in mech.bodies)
    fparams = {jn: friction_params.get(jn, joints[jn].friction) for jn in friction}
    return SceneSpec(name=name, mechanism=mech, friction=friction, friction_params=fparams,
                     eliminate=eliminate, redundancy=redundancy, positions=positions, reactions=reactions,
                     friction_outputs=friction_out, velocities=velocities, energy=energy,
                     start_time=start_time, stop_time=stop_time,
                     solver=SolverSpec(**solver_kw), group=group, description=description,
                     source=ctx.file, inputs=inputs, sensors=sensors, drivers=drivers)


def _scene_redundancy(ctx: _Ctx, st: dict, mech: MechanismSpec | None):
    """``scene.redundancy`` (:data:`overcon.spec.REDUNDANCY_METHODS`, default "eliminate") and
    ``scene.eliminate``, which "eliminate" requires; under the other methods it is optional and
    does not apply (decided: kept, so that a scene group switches method by one line; check and
    simulate warn about it)."""
    redundancy = "eliminate"
    v = _get(ctx, st, "redundancy", "scene", required=False)
    if v is not _MISSING:
        redundancy = _str(ctx, v, "scene.redundancy")
        if redundancy is not None and redundancy not in S.REDUNDANCY_METHODS:
            ctx.add("scene.redundancy", f"unknown method {_short(redundancy)} (known: "
                                        f"{', '.join(repr(m) for m in S.REDUNDANCY_METHODS)})")
    eliminate = None if redundancy == "eliminate" else ()
    v = _get(ctx, st, "eliminate", "scene", required=redundancy == "eliminate")
    if v is not _MISSING:
        eliminate = _check_eliminate(ctx, v, "scene.eliminate", mech, lambda k: f"scene.eliminate[{k}]")
    return redundancy, eliminate


def _optional_str(ctx: _Ctx, st: dict, key: str) -> str:
    v = _get(ctx, st, key, "scene", required=False)
    return "" if v is _MISSING else _str(ctx, v, f"scene.{key}") or ""


def _scene_mechanism(ctx: _Ctx, st: dict, problems: list[Problem]) -> MechanismSpec | None:
    """The mechanism file ``scene.mechanism`` names, loaded and checked (its problems against it)."""
    v = _get(ctx, st, "mechanism", "scene")
    if v is _MISSING:
        return None
    rel = _str(ctx, v, "scene.mechanism")
    if rel is None:
        return None
    if not rel:
        ctx.add("scene.mechanism", "empty path")
        return None
    mpath = Path(ctx.file).parent / rel
    mfile = str(mpath)
    if not _exists(mpath):
        ctx.add("scene.mechanism", f"mechanism file not found: {mfile}")
        return None
    mctx = _Ctx(mfile, problems)
    mdoc = _read(mpath, mctx)
    if mdoc is None:
        return None
    if isinstance(mdoc.get("scene"), dict) or "mechanism" not in mdoc:
        mctx.add(FILE_FIELD, "not a mechanism file (no [mechanism] table)")
        return None
    return _check_mechanism(mdoc, mctx)


def _scene_friction_params(ctx: _Ctx, st: dict, mech: MechanismSpec | None,
                           joints: dict) -> tuple[dict[str, FrictionSpec], set[str]]:
    """``[scene.friction_params]``: (the merged spec per joint, the joints given a table)."""
    friction_params: dict[str, FrictionSpec] = {}
    fp_given: set[str] = set()
    v = _get(ctx, st, "friction_params", "scene", required=False)
    if v is _MISSING or _table(ctx, v, "scene.friction_params") is None:
        return friction_params, fp_given
    for jn, tab in v.items():
        f = f"scene.friction_params.{jn}"
        if mech is not None and jn not in joints:
            ctx.add(f, f"unknown joint {_short(jn)}")
            continue
        if _table(ctx, tab, f) is None:
            continue
        fp_given.add(jn)
        joint = joints.get(jn)
        fs = _friction(ctx, tab, f, joint.type if joint else None,
                       joint.friction if joint else None, require=mech is not None)
        if fs is not None:
            friction_params[jn] = fs
    return friction_params, fp_given


def _scene_times(ctx: _Ctx, st: dict) -> tuple[float | None, float | None]:
    start_time = 0.0
    v = _get(ctx, st, "start_time", "scene", required=False)
    if v is not _MISSING:
        start_time = _num(ctx, v, "scene.start_time")
    stop_time = None
    v = _get(ctx, st, "stop_time", "scene")
    if v is not _MISSING:
        stop_time = _num(ctx, v, "scene.stop_time")
        if stop_time is not None and start_time is not None and stop_time <= start_time:
            ctx.add("scene.stop_time", f"must be > start_time ({start_time!r}), got {stop_time!r}")
    return start_time, stop_time


def _scene_outputs(ctx: _Ctx, doc: dict, mech: MechanismSpec | None, joints: dict, friction):
    """The ``[outputs]`` table: (positions, reactions, friction outputs, velocities, energy); the
    first four ``"all"`` or names, ``velocities`` () unless the table lists them, ``energy`` a bool
    (default false: existing scenes keep their outputs)."""
    positions = reactions = friction_out = "all"
    velocities, energy = [], False
    ot = doc.get("outputs", _MISSING)
    if ot is not _MISSING and _table(ctx, ot, "outputs") is not None:
        _unknown_keys(ctx, ot, "outputs", OUTPUT_KEYS)
        # an [outputs] table is the scene's output set: friction outputs only if it lists them
        # (existing scenes keep their outputs, which their FMUs' regression baselines fix)
        friction_out = ot.get("friction", [])
        positions = ot.get("positions", "all")
        reactions = ot.get("reactions", "all")
        velocities = ot.get("velocities", [])
        energy = ot.get("energy", False)
        if not isinstance(energy, bool):
            ctx.add("outputs.energy", f"expected true or false, got {_desc(energy)}")
    valid_pos = set(_all_positions(mech)) if mech is not None else None
    positions = _check_outputs(ctx, positions, "outputs.positions", valid_pos,
                               "'<body>.<coordinate>'", _pos_message(mech))
    valid_reac = set(joints) if mech is not None else None
    reactions = _check_outputs(ctx, reactions, "outputs.reactions", valid_reac, "joint name",
                               lambda s: f"unknown joint {_short(s)}")
    friction_out = _check_outputs(ctx, friction_out, "outputs.friction",
                                  set(friction) if friction is not None else None, "friction joint name",
                                  lambda s: f"{_short(s)} is not in scene.friction (friction outputs are "
                                            "the friction forces of friction joints)")
    valid_bodies = {b.name for b in mech.bodies} if mech is not None else None
    velocities = _check_outputs(ctx, velocities, "outputs.velocities", valid_bodies, "body name",
                                lambda s: f"unknown body {_short(s)} (the base does not move)")
    return positions, reactions, friction_out, velocities, energy is True


SENSOR_JOINTS = {"revolute": ("angle", "rate"), "spatial_revolute": ("angle", "rate"),
                 "translational": ("displacement", "speed"), "spatial_prismatic": ("displacement", "speed"),
                 "spatial_cylindrical": ("angle", "rate", "displacement", "speed")}
"""Joint types with sensor outputs (``[outputs] joints``) and which (:data:`overcon.spec.JOINT_SENSORS`)."""

INPUT_JOINTS = {"joint_torque": ("revolute", "spatial_revolute", "spatial_cylindrical"),
                "joint_force": ("translational", "spatial_prismatic", "spatial_cylindrical")}
"""The joint types an input of a joint type acts on (about or along the joint's axis)."""
MAX_INPUTS = 1000
RESERVED_NAMES = ("motion_unique", "rank", "redundancy", "time", "effort_unique")
"""FMU variable names that are identifiers: no input may take them."""
_INPUT_KEYS = ("name", "type", "joint", "body", "point", "direction", "frame", "start")


def _scene_sensors(ctx: _Ctx, doc: dict, mech: MechanismSpec | None) -> tuple[str, ...]:
    """``[outputs] joints``: "all" (every joint with sensors, :data:`SENSOR_JOINTS`) or distinct
    joint names of such joints; default none."""
    ot = doc.get("outputs")
    if not isinstance(ot, dict) or "joints" not in ot:
        return ()
    types = {j.name: j.type for j in mech.joints} if mech is not None else None
    value = ot["joints"]
    if value == "all":
        return tuple(n for n, t in types.items() if t in SENSOR_JOINTS) if types is not None else ()

    def bad(name):
        if types is None:
            return None
        if name not in types:
            return f"unknown joint {_short(name)}"
        if types[name] not in SENSOR_JOINTS:
            return (f"joint '{name}' is a {JOINT_TYPES[types[name]].name} joint: sensors (angle, rate; displacement, "
                    "speed) are those of revolute, translational, prismatic and cylindrical joints")
        return None

    if not isinstance(value, list):
        ctx.add("outputs.joints", f"expected \"all\" or an array of joint names, got {_desc(value)}")
        return ()
    return _distinct_items(ctx, value, lambda k: f"outputs.joints[{k}]", _str, invalid=bad,
                           duplicate=lambda s: f"{_short(s)} listed twice") or ()


def _scene_inputs(ctx: _Ctx, doc: dict, mech: MechanismSpec | None) -> tuple:
    """``[[inputs]]`` (:class:`overcon.spec.InputSpec`): names identifiers, unique among inputs and
    not an output's name; ``joint_torque``/``joint_force`` name a joint of a type of
    :data:`INPUT_JOINTS` (no body, point, direction, frame); ``force``/``torque`` a moving body, a
    non-zero ``direction`` (normalised; planar torque: none, counter-clockwise), ``frame``
    global (default) or body, and force a ``point`` (body coordinates, default the origin);
    ``start`` a finite number (default 0)."""
    items = _array_of_tables(ctx, doc, "inputs", False, MAX_INPUTS)
    out, seen = [], {}
    kind = mech.kind if mech is not None else None
    joints = {j.name: j.type for j in mech.joints} if mech is not None else None
    bodies = {b.name: None for b in mech.bodies} if mech is not None else None
    for k, it in items:
        p = f"inputs[{k}]"
        _unknown_keys(ctx, it, p, _INPUT_KEYS)
        name = _input_name(ctx, it, p, seen)
        typ = _get(ctx, it, "type", p)
        typ = None if typ is _MISSING else _choice(ctx, typ, f"{p}.type", tuple(S.INPUT_TYPES))
        start = 0.0
        if "start" in it:
            start = _num(ctx, it["start"], f"{p}.start")
        ok = name is not None and typ is not None and start is not None
        fields = {}
        if typ in INPUT_JOINTS:
            fields, fields_ok = _joint_input_fields(ctx, it, p, typ, joints)
            ok = ok and fields_ok
        elif typ is not None:
            fields, fields_ok = _body_input_fields(ctx, it, p, typ, kind, bodies)
            ok = ok and fields_ok
        if ok:
            out.append(S.InputSpec(name=name, type=typ, start=float(start), **fields))
    return tuple(out)


def _input_name(ctx: _Ctx, it: dict, p: str, seen: dict) -> str | None:
    """The name of input ``p``: an identifier, unique among inputs (``seen``), not a reserved
    variable name; None (reported) otherwise."""
    name = _get(ctx, it, "name", p)
    name = None if name is _MISSING else _register_name(ctx, _ident(ctx, name, f"{p}.name"), f"{p}.name", seen,
                                                        p, "input")
    if name in RESERVED_NAMES:
        ctx.add(f"{p}.name", f"'{name}' is the name of another FMU variable (reserved: "
                             f"{', '.join(RESERVED_NAMES)})")
        name = None
    return name


def _joint_input_fields(ctx: _Ctx, it: dict, p: str, typ: str, joints: dict | None) -> tuple[dict, bool]:
    """({"joint": name}, whether it is valid) of the joint input ``p`` of type ``typ``: a joint of
    ``joints`` (None: the mechanism is unknown) of a type in :data:`INPUT_JOINTS`, and no body,
    point, direction or frame."""
    ok = True
    for key in ("body", "point", "direction", "frame"):
        if key in it:
            ctx.add(f"{p}.{key}", f"a {typ} input acts along or about its joint's axis: it takes no {key}")
            ok = False
    v = _get(ctx, it, "joint", p)
    jn = None if v is _MISSING else _str(ctx, v, f"{p}.joint")
    if jn is not None and joints is not None:
        if jn not in joints:
            ctx.add(f"{p}.joint", f"unknown joint {_short(jn)}")
            jn = None
        elif joints[jn] not in INPUT_JOINTS[typ]:
            allowed = ", ".join(sorted({JOINT_TYPES[t].name for t in INPUT_JOINTS[typ]}))
            ctx.add(f"{p}.joint", f"joint '{jn}' is a {JOINT_TYPES[joints[jn]].name} joint: a {typ} input "
                                  f"acts on {allowed} joints")
            jn = None
    return {"joint": jn}, ok and jn is not None


def _body_input_fields(ctx: _Ctx, it: dict, p: str, typ: str, kind: str | None,
                       bodies: dict | None) -> tuple[dict, bool]:
    """(fields, whether they are valid) of the force or torque input ``p``: a moving body of
    ``bodies`` (None: the mechanism is unknown), the frame, the direction (normalised; none for a
    planar torque) and a force's point."""
    ok = True
    if "joint" in it:
        ctx.add(f"{p}.joint", f"a {typ} input acts on a body: give body (not joint)")
        ok = False
    v = _get(ctx, it, "body", p)
    body = None if v is _MISSING else _str(ctx, v, f"{p}.body")
    if body is not None and bodies is not None and body not in bodies:
        ctx.add(f"{p}.body", f"unknown body {_short(body)} (an input acts on a moving body, not the base)")
        body = None
    fields = {"body": body}
    ok = ok and body is not None
    frame = "global"
    if "frame" in it:
        frame = _choice(ctx, it["frame"], f"{p}.frame", S.INPUT_FRAMES)
        ok = ok and frame is not None
    fields["frame"] = frame
    if typ == "torque" and kind == "planar":
        if "direction" in it:
            ctx.add(f"{p}.direction", "a planar torque acts about z (counter-clockwise positive): no direction")
            ok = False
    else:
        v = _get(ctx, it, "direction", p)
        d = None if v is _MISSING else _shaped(ctx, v, f"{p}.direction", "dir", kind)
        if d is not None:
            norm = math.sqrt(math.fsum(x * x for x in d))
            d = tuple(x / norm for x in d)
        ok = ok and d is not None
        fields["direction"] = d
    if typ == "force":
        pt = tuple(0.0 for _ in range(_DIM.get(kind, 0)))
        if "point" in it:
            pt = _shaped(ctx, it["point"], f"{p}.point", "vec", kind)
        fields["point"] = pt
        ok = ok and pt is not None
    elif "point" in it:
        ctx.add(f"{p}.point", "a torque has no point of application")
        ok = False
    return fields, ok


DRIVER_JOINTS = {"angle": ("revolute", "spatial_revolute", "spatial_cylindrical"),
                 "displacement": ("translational", "spatial_prismatic", "spatial_cylindrical")}
"""The joint types a driver's coordinate is prescribed on (rotation about, displacement along the axis)."""
DRIVABLE = ("drivable joints: revolute (planar or spatial) and cylindrical by their angle, translational "
            "(planar), prismatic and cylindrical by their displacement")
"""The list of :data:`DRIVER_JOINTS` in words, said where a driver names another joint type."""
MAX_DRIVERS = 1000
_DRIVER_KEYS = ("name", "joint", "motion", "coordinate", "speed", "from", "to", "t0", "t1", "amplitude", "frequency",
                "phase", "offset")
_DRIVER_DEFAULTS = {"phase": 0.0, "offset": 0.0}


def _scene_drivers(ctx: _Ctx, doc: dict, mech: MechanismSpec | None, input_names: set) -> tuple:
    """``[[drivers]]`` (:class:`overcon.spec.DriverSpec`): names identifiers, unique, not a joint's
    or an input's name nor reserved; ``joint`` a joint of a type of :data:`DRIVER_JOINTS` (a
    cylindrical joint: ``coordinate`` "angle" (default) or "displacement"), at most one driver per
    joint and coordinate; ``motion`` in :data:`overcon.spec.DRIVER_MOTIONS` with exactly its
    parameters, finite (a ramp's t1 > t0, a harmonic's frequency > 0). Whether the motion starts at
    the coordinate's value at q0 (zero) with its rate is checked with q0 and h0
    (:func:`overcon.checks.check_initial_state`)."""
    items = _array_of_tables(ctx, doc, "drivers", False, MAX_DRIVERS)
    out, seen, driven = [], {}, set()
    joints = {j.name: j.type for j in mech.joints} if mech is not None else None
    for k, it in items:
        p = f"drivers[{k}]"
        name = _get(ctx, it, "name", p)
        name = None if name is _MISSING else _ident(ctx, name, f"{p}.name")
        if name is not None and (name in RESERVED_NAMES or name in input_names or (joints and name in joints)):
            ctx.add(f"{p}.name", f"'{name}' is already the name of a joint, an input or another FMU variable")
            name = None
        name = _register_name(ctx, name, f"{p}.name", seen, p, "driver")
        motion = _get(ctx, it, "motion", p)
        motion = None if motion is _MISSING else _choice(ctx, motion, f"{p}.motion", tuple(S.DRIVER_MOTIONS))
        allowed = ("name", "joint", "motion", "coordinate") + (S.DRIVER_MOTIONS[motion] if motion else
                                                                _DRIVER_KEYS[4:])
        _unknown_keys(ctx, it, p, allowed)
        ok = name is not None and motion is not None
        v = _get(ctx, it, "joint", p)
        jn = None if v is _MISSING else _str(ctx, v, f"{p}.joint")
        coordinate = "angle"
        if "coordinate" in it:
            coordinate = _choice(ctx, it["coordinate"], f"{p}.coordinate", tuple(DRIVER_JOINTS))
        if jn is not None and joints is not None:
            if jn not in joints:
                ctx.add(f"{p}.joint", f"unknown joint {_short(jn)}")
                jn = None
            else:
                jt = joints[jn]
                if "coordinate" not in it and jt not in DRIVER_JOINTS["angle"]:
                    coordinate = "displacement"
                if coordinate is not None and jt not in DRIVER_JOINTS[coordinate]:
                    what = f"{JOINT_TYPES[jt].kind} {JOINT_TYPES[jt].name}"
                    if not any(jt in ts for ts in DRIVER_JOINTS.values()):
                        msg = f"joint '{jn}' is a {what} joint, which a driver cannot drive"
                    else:
                        msg = f"joint '{jn}' is a {what} joint, which has no driven {coordinate}"
                    ctx.add(f"{p}.joint", f"{msg}; {DRIVABLE}")
                    jn = None
                elif (jn, coordinate) in driven:
                    ctx.add(f"{p}.joint", f"joint '{jn}' has a driver of its {coordinate} already")
                    jn = None
                else:
                    driven.add((jn, coordinate))
        ok = ok and jn is not None and coordinate is not None
        params = {}
        for key in (S.DRIVER_MOTIONS[motion] if motion else ()):
            if key not in it and key in _DRIVER_DEFAULTS:
                params[key] = _DRIVER_DEFAULTS[key]
                continue
            v = _get(ctx, it, key, p)
            x = None if v is _MISSING else _num(ctx, v, f"{p}.{key}")
            if x is None:
                ok = False
            params[key] = x
        if motion == "ramp" and ok and not params["t1"] > params["t0"]:
            ctx.add(f"{p}.t1", f"must be > t0 ({params['t0']!r}), got {params['t1']!r}")
            ok = False
        if motion == "harmonic" and ok and not params["frequency"] > 0.0:
            ctx.add(f"{p}.frequency", f"must be > 0 (Hz), got {params['frequency']!r}")
            ok = False
        if ok:
            out.append(S.DriverSpec(name=name, joint=jn, motion=motion, params=params, coordinate=coordinate))
    return tuple(out)


def _scene_solver(ctx: _Ctx, doc: dict, problems: list[Problem], start_time, stop_time) -> dict:
    """The ``[solver]`` table's values; then the bounded-work relations with the scene's times,
    reported against the solver field if the file gives it, else the stop time."""
    solver_kw = {}
    n_before_solver = len(problems)
    sv = doc.get("solver", _MISSING)
    if sv is not _MISSING and _table(ctx, sv, "solver") is not None:
        _unknown_keys(ctx, sv, "solver", params.SOLVER_FIELDS)
        for key in params.SOLVER_FIELDS:
            if key not in sv:
                continue
            val = _param(ctx, sv[key], f"solver.{key}", f"solver.{key}")
            if val is not None:
                solver_kw[key] = val
    if len(problems) == n_before_solver and start_time is not None and stop_time is not None \
            and stop_time > start_time:
        for name, msg in params.check_relations(SolverSpec(**solver_kw), start_time, stop_time):
            key = name.split(".", 1)[1]
            ctx.add(name if isinstance(sv, dict) and key in sv else "scene.stop_time", msg)
    return solver_kw


def _pos_message(mech: MechanismSpec | None):
    def message(s: str) -> str:
        body, dot, coord = s.partition(".")
        if not dot:
            return f"{_short(s)} is not of the form '<body>.<coordinate>'"
        bodies = {b.name: b for b in mech.bodies} if mech is not None else {}
        if mech is not None and body not in bodies:
            return f"unknown body {_short(body)}"
        coords = S.body_coordinates(mech.kind, mech.rotation, bodies[body]) if mech is not None else ()
        what = " (a particle has no orientation)" if mech is not None and bodies[body].particle else ""
        return f"unknown coordinate {_short(coord)} (allowed: {', '.join(coords)}){what}"
    return message


def _check_outputs(ctx: _Ctx, value, field: str, valid: set | None, what: str, bad_message):
    if value == "all":
        return "all"
    if not isinstance(value, list):
        ctx.add(field, f"expected \"all\" or an array of {what}s, got {_desc(value)}")
        return None
    return _distinct_items(
        ctx, value, lambda k: f"{field}[{k}]", _str,
        invalid=lambda s: bad_message(s) if valid is not None and s not in valid else None,
        duplicate=lambda s: f"{_short(s)} listed twice")


# ---------------------------------------------------------------------------------------------
# Reading files


def _exists(path: Path) -> bool:
    """Something is there (what it is and whether it can be read: :func:`_read_bytes`)."""
    try:
        return path.exists()
    except (OSError, ValueError):
        return False


MAX_FILE_BYTES = 8 << 20
"""Largest mechanism or scene file (8 MiB). The paper's files are 1.5-6 KB; a planar chain of
10,000 bodies written as tests/test_robust.py's ``chain`` is 1.9 MB, one at the body limit below
about 3.9 MB."""
MAX_BODIES = 20_000
MAX_JOINTS = 40_000
MAX_LOADS = 1000
"""Largest numbers of bodies, joints and loads of a mechanism (bounded work and memory; measured
figures and how they were taken: docs/limits.md). The core holds Phi_h by its nonzeros (each
equation on its joint's two bodies: core/core.h OVK_JROW), so an evaluation and a run cost memory
linear in the bodies and joints; measured, a planar chain of 10,000 bodies is checked in about
10 s at 140 MB peak and runs 1 s at 152 MB peak, and a coupler on 999 parallel cranks (1000
bodies, 1998 joints) is checked in about 13 s at 260 MB. The bounds are set where the pre-check's
time, not memory, becomes the limit (a 20,000-body chain: 45 s at 214 MB, measured with another
job beside it; linear). The
pre-check's one factorisation (:func:`overcon.analysis._factorise`, ``methods="svd"``) peels the
joints whose reaction is decided locally (a tree mechanism entirely) and runs one dense SVD per
independent block of loops left (a block with hub rows, a body many joints share, one small SVD
per part left without them), so its cost is the largest loop block's, not the mechanism's:
measured (docs/benchmarks.md, "Pre-check at scale") a 1000-body chain, a 980-body tree with
20 loops or a 990-body spatial tree with 10 loops is checked from the command line in about
1 s, and one block of 1000 joints (a coupler on 500 parallel cranks, 1503 coordinates x 2000
equations, factorised through the coupler's rows) in about 1.6 s. A block of loops without
hubs costs its dense SVD: a block of loops costs 8 (n_b m_b + m_b^2) bytes and
O(n_b m_b min(n_b, m_b)) time, which is what ends first for a mechanism of many interlocked
loops (a 2000-joint block: about 0.3 GB). A run's watch takes the whole Jacobian dense only on
its rare paths (an expiring elimination, a rank decided by factorisation: core/sim.c
ovk_sim_dense, 8 n m bytes each of three arrays, allocated then and refused with a message when
the memory is not there). The three tests' cross-check (``--methods
all``) costs two SVDs per joint and is the default only up to
:data:`overcon.precheck.AUTO_ALL_JOINTS` joints. The paper's mechanisms have 4 and 7 bodies.
Loads cost one short loop each per evaluation."""

MAX_KEY_DEPTH = 32
MAX_KEY_LENGTH = 1024
MAX_KEYS = 1_000_000
MAX_NESTING = 32
"""Bounds of a TOML file checked by :func:`toml_prescan` before ``tomllib`` parses it, because the
size cap alone does not bound the parser: ``tomllib`` spends time and memory quadratic in a key's
depth (a dotted key ``gravity.a.a.a...`` of 20,000 parts, a 44 KB file, took 36 s and 2.4 GB).
Depth: the parts of a key path, its table header's included (the paper's files use at most 3);
length: the characters of one key path (names are at most 40 characters by the rules above);
keys: every key and table header of the file (a mechanism at the body and joint limits,
:data:`MAX_BODIES` and :data:`MAX_JOINTS`, has about 600,000: a body 6 or 7, a joint up to 12; the
count only bounds a linear cost, the file's size already bounds it too); nesting: arrays and inline tables inside each other."""


_BASIC_STRING = re.compile(r'[^"\\\n]*(?:\\[\s\S][^"\\\n]*)*')  # a "..." string's body: \ takes the next character
_LITERAL_STRING = re.compile(r"[^'\n]*")
_KEY_RUN = {stop: re.compile("[^" + re.escape(stop) + "\n\"'.]*") for stop in ("]", "=}")}
_VALUE_RUN = re.compile(r"[^\n#\"'\[\]{},]+")  # characters a value goes through without a decision
_BLANK_RUN = re.compile(r"[ \t\r]+")
_STRING_ON_LINE = r'"(?!"")[^"\\\n]*"'  # a "..." string with no escape, not a triple quote
_SIMPLE_LINE = re.compile(  # key = value to the line's end (the alternatives differ in their first character)
    r'(?P<key>[^=}\n"\'.]*)='
    r'(?:[^\n#"\'\[\]{},]|' + _STRING_ON_LINE + r'|\[(?:[^\n#"\'\[\]{}]|' + _STRING_ON_LINE + r')*\])*'
    r'(?:#[^\n]*)?(?:(?P<eol>\n)|\Z)')


def _skip_toml_string(text: str, i: int) -> int:
    """The index after the string that opens at ``text[i]`` (a quote; triple-quoted: up to its
    closing triple, else up to the closing quote or the line's end; in a "..." string a
    backslash takes the next character, a last one goes past the end)."""
    n = len(text)
    q = text[i]
    if text.startswith(q * 3, i):
        end = text.find(q * 3, i + 3)
        return n if end < 0 else end + 3
    j = (_BASIC_STRING if q == '"' else _LITERAL_STRING).match(text, i + 1).end()
    if j < n and text[j] == "\\":  # a backslash as the text's last character
        j += 2
    return j + 1


def _toml_key_path(text: str, i: int, stop: str) -> tuple[int, int, int]:
    """(index after the key, its parts, its length) of a key of ``text`` starting at ``i`` and
    ending before one of ``stop`` or the line's end."""
    n = len(text)
    parts, start = 1, i
    run = _KEY_RUN[stop]
    while i < n:
        i = run.match(text, i).end()  # up to a stop, a line's end, a quote or a dot
        if i >= n or text[i] in stop or text[i] == "\n":
            break
        if text[i] in "\"'":
            i = _skip_toml_string(text, i)
            continue
        parts += 1  # a dot
        i += 1
    return i, parts, i - start


def toml_prescan(text: str) -> str | None:
    """Why ``text`` is refused before parsing (one linear pass: strings and comments skipped, key
    paths and nesting counted), or None. Not a TOML parser: a file it lets through may still be
    invalid TOML (tomllib says so); it only bounds what the parser may spend."""
    i, n, keys = 0, len(text), 0
    stack: list[str] = []  # open [ and { of values
    header_parts = 0  # parts of the current table header
    line = 1
    expect_key = True
    while i < n:
        ch = text[i]
        if ch == "\n":
            line += 1
            i += 1
            if not stack:
                expect_key = True
            continue
        if not expect_key:
            run = _VALUE_RUN.match(text, i)
            if run:  # blanks and a value's characters: nothing to decide
                i = run.end()
                continue
        elif ch in " \t\r":
            i = _BLANK_RUN.match(text, i).end()
            continue
        if ch == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        if expect_key and not stack and ch == "[":  # a table header
            j, parts, length = _toml_key_path(text, i + (2 if text.startswith("[[", i) else 1), "]")
            header_parts = parts
            keys += 1
            if parts > MAX_KEY_DEPTH or length > MAX_KEY_LENGTH:
                return (f"line {line}: a table header of {parts} parts and {length} characters (at most "
                        f"{MAX_KEY_DEPTH} parts and {MAX_KEY_LENGTH} characters)")
            i, expect_key = j + 1, False
            continue
        if expect_key:
            # the usual line, ``key = value`` with no dotted or quoted key, no inline table and
            # no array in an array, is read to its end in one match: it opens and closes its
            # arrays on the line (depth 1), so only its key counts
            simple = _SIMPLE_LINE.match(text, i) if not stack and MAX_NESTING >= 1 else None
            if simple is not None:
                j, parts, length = simple.end("key"), 1, simple.end("key") - i
            else:
                j, parts, length = _toml_key_path(text, i, "=}")
            keys += 1
            depth = parts + header_parts + (sum(1 for c in stack if c == "{") if stack else 0)
            if depth > MAX_KEY_DEPTH or length > MAX_KEY_LENGTH:
                return (f"line {line}: a key of {depth} parts (with its table's) and {length} characters (at most "
                        f"{MAX_KEY_DEPTH} parts and {MAX_KEY_LENGTH} characters)")
            if keys > MAX_KEYS:
                return f"more than {MAX_KEYS} keys"
            if simple is None:
                i, expect_key = j + 1, False
            elif simple.group("eol"):  # the line's end too: the next line starts with a key
                i, line = simple.end(), line + 1
            else:
                i, expect_key = simple.end(), False
            continue
        if ch in "\"'":
            i = _skip_toml_string(text, i)
            continue
        if ch in "[{":
            stack.append(ch)
            if len(stack) > MAX_NESTING:
                return f"line {line}: arrays and inline tables nested deeper than {MAX_NESTING}"
            expect_key = ch == "{"
        elif ch in "]}":
            if stack:
                stack.pop()
        elif ch == "," and stack and stack[-1] == "{":
            expect_key = True
        i += 1
    return None


_FILE_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
               (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
               (stat.S_ISSOCK, "a socket"))


def _read_bytes(path: Path) -> tuple[bytes | None, str]:
    """(content, "") of a regular file of at most MAX_FILE_BYTES, else (None, why). Never opens
    anything but a regular file (a FIFO would block, /dev/zero never ends)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None, "file not found"
    except (OSError, ValueError) as exc:
        return None, f"cannot read file: {getattr(exc, 'strerror', None) or exc}"
    if not stat.S_ISREG(st.st_mode):
        kind = next((what for test, what in _FILE_KINDS if test(st.st_mode)), "not a regular file")
        return None, f"is {kind}, not a regular file"
    if st.st_size > MAX_FILE_BYTES:
        return None, f"file too large: {st.st_size} bytes (at most {MAX_FILE_BYTES} bytes = {MAX_FILE_BYTES >> 20} MiB)"
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)
    except (OSError, ValueError) as exc:
        return None, f"cannot read file: {getattr(exc, 'strerror', None) or exc}"
    if len(data) > MAX_FILE_BYTES:  # grew since stat
        return None, f"file too large: more than {MAX_FILE_BYTES} bytes ({MAX_FILE_BYTES >> 20} MiB)"
    return data, ""


NOT_AN_FMU = ("is {what}, not a mechanism or scene file: overcon check, simulate and build take the TOML "
              "files an FMU is built from; overcon run simulates an FMU, and overcon compare reports its "
              "pre-check verdict (the FMU's constant output motion_unique)")


def _read(path: Path, ctx: _Ctx) -> dict | None:
    if path.suffix.lower() == ".fmu" and path.is_file():
        ctx.add(FILE_FIELD, NOT_AN_FMU.format(what="an FMU"))
        return None
    data, why = _read_bytes(path)
    if data is not None and data.startswith(b"PK\x03\x04"):
        ctx.add(FILE_FIELD, NOT_AN_FMU.format(what="a ZIP archive (an FMU?)"))
        return None
    if data is None:
        ctx.add(FILE_FIELD, why)
        return None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        ctx.add(FILE_FIELD, f"not UTF-8 text (byte {exc.start})")
        return None
    why = toml_prescan(text)
    if why is not None:
        ctx.add(FILE_FIELD, f"invalid TOML (refused before parsing): {why}")
        return None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        ctx.add(FILE_FIELD, f"invalid TOML: {exc}")
    except (RecursionError, ValueError, OverflowError, MemoryError) as exc:
        ctx.add(FILE_FIELD, f"invalid TOML: {type(exc).__name__}")
    return None


def load(path) -> MechanismSpec | SceneSpec:
    """Read and validate a mechanism or scene file; raise :class:`SceneError` with every problem.

    The ``file`` of each problem is the path as given (a scene's mechanism: the scene's directory
    joined with the ``mechanism`` path)."""
    problems: list[Problem] = []
    ctx = _Ctx(str(path), problems)
    doc = _read(Path(path), ctx)
    result = None
    if doc is not None:
        is_mech = isinstance(doc.get("mechanism"), dict)
        is_scene = isinstance(doc.get("scene"), dict)
        if is_mech and is_scene:
            ctx.add(FILE_FIELD, "has both a [mechanism] and a [scene] table")
        elif is_scene:
            result = _check_scene(doc, ctx, problems)
        elif "mechanism" in doc:
            result = _check_mechanism(doc, ctx)
        elif "scene" in doc:
            result = _check_scene(doc, ctx, problems)
        else:
            ctx.add(FILE_FIELD, "neither a [mechanism] nor a [scene] table: not a mechanism or "
                                "scene file")
    if problems or result is None:
        if not problems:  # defensive: a None result always comes with a problem
            ctx.add(FILE_FIELD, "invalid file")
        raise SceneError(problems)
    return result


# ---------------------------------------------------------------------------------------------
# Command-line style overrides


def parse_joint_list(text: str) -> tuple[str, ...]:
    """``"none"`` or ``""`` -> ``()``; ``"joint4,joint5"`` -> ``("joint4", "joint5")``."""
    text = text.strip()
    if text.lower() in ("", "none"):
        return ()
    return tuple(item.strip() for item in text.split(",") if item.strip())


def parse_eliminate(text: str, *, source: str = CLI_SOURCE) -> tuple[int | str, ...] | str:
    """``"auto"`` -> ``"auto"``; ``"4,6"`` -> ``(4, 6)``; ``"joint6,2"`` -> ``("joint6", 2)``
    (joint names: checked against the mechanism by :func:`as_scene`); ``""``/``"none"`` -> ``()``.

    An item neither an integer nor an identifier raises :class:`SceneError` with field
    ``--eliminate``."""
    text = text.strip()
    if text.lower() == "auto":
        return "auto"
    if text.lower() in ("", "none"):
        return ()
    out = []
    bad = []
    for item in text.split(","):
        item = item.strip()
        try:
            out.append(int(item))
        except ValueError:
            if _is_identifier(item):
                out.append(item)
            else:
                bad.append(Problem(source, "--eliminate", f"{_short(item)} is not an integer equation "
                                                          "index or a joint name (or \"auto\")"))
    if bad:
        raise SceneError(bad)
    return tuple(out)


def as_scene(spec: MechanismSpec | SceneSpec, *, friction=None, eliminate=None, stop_time=None,
             tolerance=None, solver: dict | None = None, friction_outputs=None,
             source: str = CLI_SOURCE) -> SceneSpec:
    """A :class:`SceneSpec` from a mechanism (name = mechanism name, every position and every
    reaction as outputs, no friction, eliminate ``"auto"``, stop time 1 s) or from a scene, with
    the given overrides applied. ``friction``: joint names (or a text for
    :func:`parse_joint_list`); ``eliminate``: ints and joint names, or ``"auto"`` (or a text for
    :func:`parse_eliminate`); ``stop_time`` > start time; ``solver``: ``{field: value}`` of
    :class:`~overcon.spec.SolverSpec` (``tolerance`` is a shorthand for ``solver={"tolerance": ..}``);
    ``friction_outputs``: ``"all"``, joint names or a text for :func:`parse_joint_list`, each a
    friction joint (after ``friction``),
    each checked by :mod:`overcon.params` (its envelope, and the bounded-work relations with the
    new stop time), reported with the flag ``--<field>``. Invalid overrides
    raise :class:`SceneError` with ``source`` as the file and the option name as the field; the
    scene keeps the source file of ``spec``. Friction parameters of newly enabled joints come from
    the scene (if it had them) or the mechanism."""
    scene = _base_scene(spec)
    problems: list[Problem] = []
    ctx = _Ctx(source, problems)
    changes: dict = {}
    if friction is not None:
        _override_friction(ctx, scene, friction, friction_outputs, changes)
    if eliminate is not None:
        _override_eliminate(ctx, scene, eliminate, source, changes)
    if stop_time is not None:
        val = _num(ctx, stop_time, "--stop-time")
        if val is not None and val <= scene.start_time:
            ctx.add("--stop-time", f"must be > start time ({scene.start_time!r}), got {val!r}")
        elif val is not None:
            changes["stop_time"] = val
    if friction_outputs is not None:
        _override_friction_outputs(ctx, scene, friction_outputs, changes)
    solver = dict(solver or {})
    if tolerance is not None:
        solver["tolerance"] = tolerance
    if solver or "stop_time" in changes:
        _override_solver(ctx, scene, solver, changes)
    if problems:
        raise SceneError(problems)
    return dataclasses.replace(scene, **changes) if changes else scene


def _base_scene(spec) -> SceneSpec:
    """``spec`` itself (a scene), or the default scene of a mechanism (see :func:`as_scene`)."""
    if isinstance(spec, MechanismSpec):
        mech = spec
        return SceneSpec(name=mech.name, mechanism=mech, friction=(), friction_params={},
                         eliminate="auto", positions=_all_positions(mech),
                         reactions=tuple(j.name for j in mech.joints), start_time=0.0,
                         stop_time=1.0, description=mech.description, source=mech.source)
    if isinstance(spec, SceneSpec):
        return spec
    raise TypeError(f"as_scene needs a MechanismSpec or SceneSpec, got {type(spec).__name__}")


def _override_friction(ctx: _Ctx, scene: SceneSpec, friction, friction_outputs, changes: dict) -> None:
    """``--friction``: the new friction set and its parameters into ``changes``; refused if it
    drops a joint the scene's outputs.friction lists (unless those outputs are overridden too)."""
    mech = scene.mechanism
    joints = {j.name: j for j in mech.joints}
    if isinstance(friction, str):
        friction = parse_joint_list(friction)

    def has_params(jn):
        return jn in scene.friction_params or joints[jn].friction is not None

    names = _check_friction_list(ctx, friction, "--friction", mech, has_params, lambda k: "--friction")
    listed = () if scene.friction_outputs == "all" or friction_outputs is not None else scene.friction_outputs
    dropped = [jn for jn in listed if names is not None and jn not in names]
    if dropped:
        ctx.add("--friction", f"the scene's outputs.friction lists {', '.join(dropped)}, which would "
                              "have no friction: keep them in the friction set")
    elif names is not None:
        changes["friction"] = names
        changes["friction_params"] = {jn: scene.friction_params.get(jn) or joints[jn].friction for jn in names}


def _override_eliminate(ctx: _Ctx, scene: SceneSpec, eliminate, source: str, changes: dict) -> None:
    if scene.redundancy != "eliminate":
        ctx.add("--eliminate", f"does not apply: the scene's redundancy is {scene.redundancy!r}, which chooses no "
                               "elimination")
        return
    if isinstance(eliminate, str):
        try:
            eliminate = parse_eliminate(eliminate, source=source)
        except SceneError as exc:
            ctx.problems.extend(exc.problems)
            return
    val = _check_eliminate(ctx, eliminate, "--eliminate", scene.mechanism, lambda k: "--eliminate")
    if val is not None:
        changes["eliminate"] = val


def _override_friction_outputs(ctx: _Ctx, scene: SceneSpec, friction_outputs, changes: dict) -> None:
    if isinstance(friction_outputs, str) and friction_outputs != "all":
        friction_outputs = parse_joint_list(friction_outputs)
    if isinstance(friction_outputs, tuple):
        friction_outputs = list(friction_outputs)
    on = changes.get("friction", scene.friction)
    val = _check_outputs(ctx, friction_outputs, "--friction-outputs", set(on), "friction joint name",
                         lambda s: f"{_short(s)} has no friction (friction joints: {', '.join(on) or 'none'})")
    if val is not None:
        changes["friction_outputs"] = val


def _override_solver(ctx: _Ctx, scene: SceneSpec, solver: dict, changes: dict) -> None:
    """Solver overrides and the new stop time, checked by :func:`overcon.params.apply_overrides`
    (each problem against its flag, the bounded-work ones against ``--stop-time`` when only the
    stop time changed)."""
    timed = dataclasses.replace(scene, stop_time=changes.get("stop_time", scene.stop_time))
    new, found = params.apply_overrides(timed, {f"solver.{k}": v for k, v in solver.items()})
    for name, msg in found:
        key = name.split(".", 1)[-1]
        flag = "--stop-time" if key not in solver and "stop_time" in changes else _flag(key)
        ctx.add(flag, msg)
    if new is not None and solver:
        changes["solver"] = new.solver


def _flag(solver_field: str) -> str:
    """Command-line flag of a solver field: ``output_interval`` -> ``--output-interval``."""
    return "--" + solver_field.replace("_", "-")


# ---------------------------------------------------------------------------------------------
# Finding scene files


def toml_files(paths) -> list[Path]:
    """Files given, and the *.toml files of directories given (sorted, not recursive)."""
    out: list[Path] = []
    for p in map(Path, paths):
        out.extend(sorted(p.glob("*.toml")) if p.is_dir() else [p])
    return out


def is_scene_file(path) -> bool | None:
    """True: a scene file ([scene] table); False: a mechanism file (or neither); None: unreadable
    (``load`` reports why)."""
    data, _ = _read_bytes(Path(path))
    if data is None:
        return None
    try:
        text = data.decode("utf-8")
        if toml_prescan(text) is not None:
            return None
        doc = tomllib.loads(text)
    except (UnicodeDecodeError, tomllib.TOMLDecodeError, RecursionError, ValueError,
            OverflowError, MemoryError):
        return None
    return isinstance(doc.get("scene"), dict)
