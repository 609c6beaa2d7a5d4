"""The facts record of an overcon FMU: ``resources/overcon_facts.json``, one versioned JSON object
written by the build (:mod:`overcon.fmu.build`) and the only source from which the tooling
(:mod:`overcon.tooling.fmus`) learns what an overcon FMU is; the tooling never reads the scene
file bundled beside it, so it needs neither the scene loader nor the engine.

Format :data:`FORMAT` (``"format": 1``), keys:

``model``            scene name (= the co-simulation model identifier)
``mechanism``        mechanism name
``group``            the scene's group (its name when it gives none): FMUs compared together
``friction``         joints with friction switched on, in scene order
``eliminate``        the scene's ``eliminate``: 1-based equation numbers, or ``"auto"``
``eliminated``       the equations the build's model eliminated (1-based)
``equation_joints``  the joint of every constraint equation, in equation order (legend labels
                     name the eliminated joint); optional, absent in older records
``motion_unique``    the pre-check's prediction for the motion
``reaction_unique``  joint name -> the pre-check's prediction for its reaction
``solver``           the scene's solver defaults (the ``solver.*`` parameters' start values),
                     with ``start_time`` and ``stop_time``
``outputs``          the Real outputs, in modelDescription order

A reader refuses a record of another format number (written by a newer or older overcon) with a
message naming the file and both numbers; keys may be added within one format number. A record is
untrusted input (an FMU from someone else): it is read through :func:`overcon.formats.load_json`
(size, nesting and non-finite numbers bounded before parsing) and validated against
:data:`SCHEMA` (a JSON Schema of format 1) before any key is used.
"""
from __future__ import annotations

import dataclasses
import json

from ..formats import SchemaError, load_json, validate
from ..verdict import equation_joints

PATH = "resources/overcon_facts.json"
FORMAT = 1
MANIFEST = "resources/overcon_fmu.json"  # present in every overcon FMU, with or without facts


class FactsError(ValueError):
    """A facts record that cannot be used; the message names the FMU file and the key at fault."""


_NAME = {"type": "string", "maxLength": 1024}
SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "https://overcon.invalid/schemas/overcon_facts-1.json",
    "title": "overcon FMU facts record (resources/overcon_facts.json), format 1",
    "type": "object",
    "maxProperties": 64,
    "required": ["format", "model", "mechanism", "group", "friction", "eliminate", "motion_unique",
                 "reaction_unique", "solver", "outputs"],
    "properties": {
        "format": {"const": FORMAT},
        "model": _NAME,
        "mechanism": _NAME,
        "group": _NAME,
        "friction": {"type": "array", "maxItems": 100_000, "items": _NAME},
        "eliminate": {"anyOf": [{"const": "auto"},
                                {"type": "array", "maxItems": 1_000_000,
                                 "items": {"type": "integer", "minimum": 1, "maximum": 2 ** 31 - 1}}]},
        "eliminated": {"type": "array", "maxItems": 1_000_000,
                       "items": {"type": "integer", "minimum": 1, "maximum": 2 ** 31 - 1}},
        "motion_unique": {"type": "boolean"},
        "reaction_unique": {"type": "object", "maxProperties": 100_000, "additionalProperties": {"type": "boolean"}},
        "solver": {"type": "object", "maxProperties": 64,
                   "additionalProperties": {"type": ["string", "number", "boolean", "null"], "maxLength": 1024}},
        "outputs": {"type": "array", "maxItems": 1_000_000, "items": _NAME},
        "equation_joints": {"type": "array", "maxItems": 1_000_000, "items": _NAME},
    },
}


def record(spec, model, report) -> dict:
    """The facts of the FMU built from ``spec`` (a SceneSpec), its compiled ``model`` and its
    pre-check ``report``."""
    solver = dataclasses.asdict(spec.solver)
    solver.update(start_time=spec.start_time, stop_time=spec.stop_time)
    return {
        "format": FORMAT,
        "model": spec.name,
        "mechanism": spec.mechanism.name,
        "group": spec.group or spec.name,
        "friction": list(spec.friction),
        "eliminate": spec.eliminate if spec.eliminate == "auto" else list(spec.eliminate),
        "eliminated": list(model.eliminated),
        "equation_joints": equation_joints(model.joints),
        "motion_unique": bool(report.motion_unique),
        "reaction_unique": dict(report.reaction_unique),
        "solver": solver,
        "outputs": list(model.output_names()),
    }


def encode(facts: dict) -> bytes:
    return json.dumps(facts, indent=1, sort_keys=True).encode()


def decode(data: bytes, where: str) -> dict:
    """The facts of ``data`` (the bytes of :data:`PATH` in the FMU ``where``), checked: the format
    number, and the type of every key the tooling uses. ``eliminate`` comes back as a tuple of
    ints or ``"auto"``, ``friction`` as a tuple. Raises :class:`FactsError`."""
    try:
        facts = load_json(data, f"{where}: {PATH}")
    except SchemaError as exc:
        raise FactsError(str(exc)) from exc
    if not isinstance(facts, dict):
        raise FactsError(f"{where}: {PATH} is not a JSON object")
    fmt = facts.get("format")
    if fmt != FORMAT:
        raise FactsError(f"{where}: {PATH} has format {fmt!r}; this overcon reads format {FORMAT} "
                         "(rebuild the FMU with this overcon: overcon build)")
    elim = facts.get("eliminate")
    if isinstance(elim, str) and elim != "auto":
        raise FactsError(f"{where}: {PATH}: key 'eliminate' is {elim!r}, not a list or \"auto\"")
    try:
        validate(facts, SCHEMA, f"{where}: {PATH}")
    except SchemaError as exc:
        raise FactsError(str(exc)) from exc
    out = {k: facts[k] for k in ("model", "mechanism", "group")}
    out["friction"] = tuple(facts["friction"])
    elim = facts["eliminate"]
    out["eliminate"] = elim if isinstance(elim, str) else tuple(elim)
    out["motion_unique"] = facts["motion_unique"]
    out["reaction_unique"] = dict(facts["reaction_unique"])
    out["solver"] = dict(facts["solver"])
    out["outputs"] = tuple(facts["outputs"])
    out["equation_joints"] = tuple(facts.get("equation_joints", ()))
    return out
