"""A sweep's definition: ``DIR/sweep.json``, the FMUs it resolves to, new or resumed."""
from __future__ import annotations

import json
import math
from pathlib import Path

from ...outfiles import write_text_atomic
from ...verdict import LOCKSTEP_STEP
from .. import InputError
from ..compare import group_fmus, validate_group
from ..run import check_unique_models, with_inputs
from .grid import grid, parse_param, set_ids
from .inputs import _check_params, _load_fmu, _resolve_inputs
from .rows import CSV_NAME, JSON_NAME, Sweep, _columns


_NUMBER_OR_NULL = {"type": ["number", "null"]}
DEFINITION_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "https://overcon.invalid/schemas/sweep-definition-1.json",
    "title": "overcon sweep definition (sweep.json), as written by overcon sweep",
    "type": "object",
    "maxProperties": 32,
    "required": ["inputs", "params", "samples", "seed", "stop_time", "lockstep_step"],
    "properties": {
        "inputs": {"type": "array", "maxItems": 10_000, "items": {"type": "string", "maxLength": 4096}},
        "params": {"type": "array", "maxItems": 1_000, "items": {"type": "string", "maxLength": 4096}},
        "samples": {"type": ["integer", "null"], "minimum": 1, "maximum": 10_000_000},
        "seed": {"type": ["integer", "null"]},
        "stop_time": _NUMBER_OR_NULL,
        "lockstep_step": _NUMBER_OR_NULL,
        "guids": {"type": "object", "maxProperties": 10_000, "additionalProperties": {"type": ["string", "null"], "maxLength": 256}},
    },
}
"""The schema of sweep.json (read back by ``overcon sweep --resume``; docs/untrusted-input.md)."""

def _lockstep_step(h) -> float | None:
    if h is None or h == 0:
        return None
    if not (math.isfinite(h) and 1e-6 <= h <= 1.0):
        raise InputError(f"--lockstep-step {h!r}: must be a step in s between 1e-6 and 1 (0: no lockstep)")
    return float(h)


def _sha(path: Path) -> str:
    import hashlib

    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the input table: {exc.strerror or exc}") from exc


def _read_definition(out_dir: Path, jpath: Path) -> dict:
    """The definition of the sweep to resume in ``out_dir``: ``jpath`` (its sweep.json), checked
    against :data:`DEFINITION_SCHEMA`."""
    if not jpath.is_file():
        raise InputError(f"{jpath}: no such file: {out_dir} holds no sweep to resume")
    from ...formats import SchemaError, load_json, validate
    try:
        definition = load_json(jpath.read_bytes(), str(jpath))
        validate(definition, DEFINITION_SCHEMA, str(jpath))
    except SchemaError as exc:
        raise InputError(f"unreadable sweep definition: {exc}") from exc
    return definition


def _new_definition(out_dir: Path, jpath: Path, inputs, params, samples, seed, stop_time, lockstep_step,
                    input_table, interpolation: str) -> dict:
    """The definition of a new sweep in ``out_dir`` (which must hold none) from :func:`prepare`'s
    arguments; its FMUs' GUIDs are added once they are loaded."""
    if (out_dir / CSV_NAME).exists() or jpath.exists():
        raise InputError(f"{out_dir}: already holds a sweep ({CSV_NAME}/{JSON_NAME}); continue it with "
                         f"--resume {out_dir} or choose another --out")
    if not inputs:
        raise InputError("no scene file or FMU given")
    if not params:
        raise InputError("no --param given: nothing to sweep")
    if seed is not None and samples is None:
        raise InputError(f"--seed {seed}: seeds the random parameter sets of --samples, which is not given")
    definition = {"inputs": [str(Path(p).resolve()) for p in inputs], "params": list(params),
                  "samples": samples, "seed": (0 if seed is None else seed) if samples is not None else None,
                  "stop_time": stop_time, "lockstep_step": _lockstep_step(lockstep_step)}
    if input_table is not None:
        definition.update(input_table=str(Path(input_table).resolve()), input_sha256=_sha(Path(input_table)),
                          input_interpolation=interpolation)
    elif interpolation != "hold":
        raise InputError(f"--input-interpolation {interpolation}: given without an --input table")
    return definition


def _check_guids(definition: dict, guids: dict, jpath: Path) -> None:
    """A resumed sweep's FMUs (model -> GUID ``guids``) must be those it started with."""
    changed = [m for m, g in definition.get("guids", {}).items() if guids.get(m) != g]
    if changed or set(guids) != set(definition.get("guids", {})):
        raise InputError(f"{jpath}: the FMU(s) {', '.join(changed or sorted(set(guids) ^ set(definition['guids'])))} "
                         "changed since the sweep started (GUID differs): the rows would mix two models; "
                         "start a new sweep")


def _with_input_table(definition: dict, exps: dict, fmus: list, specs: list, jpath: Path, resume: bool) -> dict:
    """The experiments ``exps`` with the definition's input table (unchanged since the sweep
    started, when ``resume``); no swept parameter may be an input the table sets."""
    table = definition["input_table"]
    if resume and _sha(Path(table)) != definition.get("input_sha256"):
        raise InputError(f"{jpath}: the input table {table} changed since the sweep started (SHA-256 differs): "
                         "the rows would mix two inputs; start a new sweep")
    exps = {f.info.model: with_inputs(f.info, exps[f.info.model], table, definition["input_interpolation"])
            for f in fmus}
    swept = [s.name for s in specs if s.name in next(iter(exps.values())).input_table.values]
    if swept:
        raise InputError(f"--param {swept[0]}: the input {swept[0]} has a column in {table}, which sets it at every "
                         "step: sweep its start value without a table, or sweep another input")
    return exps


def prepare(out_dir, *, inputs=None, params=None, samples=None, seed=None, stop_time=None,
            lockstep_step: float | None = LOCKSTEP_STEP, resume: bool = False, echo=print,
            input_table=None, interpolation: str = "hold") -> Sweep:
    """Resolve a sweep: a new one from the arguments (``out_dir`` must not hold one), or with
    ``resume`` the one defined by ``out_dir/sweep.json`` (arguments must then be None).
    ``input_table`` (``--input``, a CSV path) and ``interpolation``: the inputs of every run
    (:func:`overcon.tooling.run.with_inputs`); the definition records the table's path and SHA-256,
    and a resumed sweep refuses a table that changed since. An input's start value is swept like a
    parameter (``--param motor=0:20:5``), unless the table sets that input."""
    from ..pipeline import _group_experiments

    out_dir = Path(out_dir)
    jpath = out_dir / JSON_NAME
    if resume:
        if (inputs or params or samples is not None or seed is not None or stop_time is not None
                or input_table is not None or interpolation != "hold"):
            raise InputError("--resume DIR continues the sweep defined in DIR/sweep.json: give no scenes, "
                             "--param, --samples, --seed, --stop-time or --input with it")
        definition = _read_definition(out_dir, jpath)
    else:
        definition = _new_definition(out_dir, jpath, inputs, params, samples, seed, stop_time, lockstep_step,
                                     input_table, interpolation)
    specs = [parse_param(t) for t in definition["params"]]
    lstep = definition["lockstep_step"]
    paths = _resolve_inputs(definition["inputs"], out_dir, echo)
    fmus = [_load_fmu(p) for p in paths]
    check_unique_models([f.info for f in fmus], out_dir)
    with_inputs_ = [str(f.info.path) for f in fmus if f.info.real_inputs and f.info.motion_unique is not None]
    if lstep is not None and with_inputs_:
        raise InputError(f"{', '.join(with_inputs_)}: an FMU with inputs refuses rk4, the method of the lockstep runs; "
                         "give --lockstep-step 0 (the FMUs' own solver settings)")
    types = _check_params(specs, fmus, lstep is not None)
    values = grid(specs, types, samples=definition["samples"], seed=definition["seed"])
    sets = list(zip(set_ids(values, definition["samples"] is not None), values))
    guids = {f.info.model: f.guid for f in fmus}
    if resume:
        _check_guids(definition, guids, jpath)
    else:
        definition["guids"] = guids
    by_model = {f.info.model: f for f in fmus}
    groups = {g: [by_model[i.model] for i in items] for g, items in group_fmus([f.info for f in fmus]).items()}
    for g, members in groups.items():  # before any run: common outputs, one prediction per group
        if len(members) >= 2:
            validate_group(g, [f.info for f in members])
    exps = _group_experiments({g: [f.info for f in v] for g, v in groups.items()}, definition["stop_time"], None)
    if definition.get("input_table") is not None:
        exps = _with_input_table(definition, exps, fmus, specs, jpath, resume)
    columns = _columns([s.name for s in specs], fmus)
    if not resume:
        out_dir.mkdir(parents=True, exist_ok=True)
        write_text_atomic(jpath, json.dumps(definition, indent=1) + "\n")
    return Sweep(out_dir, definition, fmus, groups, sets, exps, columns, lstep)
