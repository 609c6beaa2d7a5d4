"""The FMUs of a sweep: built from scene files or read, their bytes and hash, the swept
parameters checked against them, and values checked before running."""
from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass, field
from pathlib import Path

from .. import InputError
from ..fmus import FmuInfo, fmu_paths, inspect_fmu, type_name
from .grid import ParamSpec

LOCKSTEP_FIXED = ("solver.method", "solver.step", "solver.tolerance", "solver.max_step")
"""Parameters that cannot be swept in lockstep runs (:mod:`overcon.tooling.sweep`)."""

@dataclass(frozen=True)
class SweepFmu:
    """An FMU of the sweep: its description (outputs restricted to those compared), parameters
    and inputs (name -> FMI type: what ``--param`` can set), GUID, bytes and their SHA-256."""

    info: FmuInfo
    params: dict
    guid: str
    data: bytes = field(repr=False)
    sha: str = ""


def _load_fmu(path: Path) -> SweepFmu:
    from fmpy import read_model_description

    info = inspect_fmu(path)
    md = read_model_description(str(path), validate=False)
    # what --param can set: parameters, and inputs (their start values: a constant input per run)
    params = {v.name: type_name(v) for v in md.modelVariables if v.causality in ("parameter", "input")}
    positions = tuple(o for o in info.outputs if o.kind == "position") or info.outputs
    data = Path(path).read_bytes()
    return SweepFmu(dataclasses.replace(info, outputs=positions), params, md.guid, data,
                    hashlib.sha256(data).hexdigest())


def _resolve_inputs(inputs: list[str], out_dir: Path, echo) -> list[Path]:
    """Scene files (``*.toml``) built into ``out_dir/fmus`` (pre-check printed, non-unique scenes
    built too: that is what a sweep measures); FMU files and directories of FMUs as they are."""
    from ...fmu.build import build_all

    scenes = [p for p in inputs if Path(p).suffix == ".toml"]
    others = [p for p in inputs if Path(p).suffix != ".toml"]
    for p in scenes:
        if not Path(p).is_file():
            raise InputError(f"{p}: no such scene file")
    fmus: list[Path] = []
    if scenes:
        echo(f"== build: {len(scenes)} scene(s) -> {out_dir / 'fmus'}")
        _, built = build_all(scenes, out_dir / "fmus", allow_nonunique=True, refs=False, echo=echo)
        bad = [r for r in built if r.status != "built"]
        if bad:
            raise InputError("\n".join(m for r in bad for m in r.messages) or
                             ", ".join(f"{r.source}: {r.status}" for r in bad))
        fmus += [r.fmu for r in built]
    if others:
        fmus += fmu_paths(others)
    if not fmus:
        raise InputError("no scene file or FMU given")
    return fmus


def _check_params(specs: list[ParamSpec], fmus: list[SweepFmu], lockstep: bool) -> dict[str, str]:
    """Every swept parameter exists in every FMU with one type; returns name -> type."""
    types = {}
    for s in specs:
        if lockstep and s.name in LOCKSTEP_FIXED:
            raise InputError(f"--param {s.text!r}: {s.name} cannot be swept in lockstep runs (rk4 on the "
                             "--lockstep-step grid: solver.method and solver.step are set by it, solver.tolerance "
                             "and solver.max_step have no effect on rk4); give --lockstep-step 0 to sweep it "
                             "on the FMUs' own solver settings")
        missing = [str(f.info.path) for f in fmus if s.name not in f.params]
        if missing:
            known = sorted(fmus[0].params) if fmus else []
            raise InputError(f"--param {s.text!r}: {s.name} is not a parameter of {', '.join(missing)} "
                             f"(parameters of {fmus[0].info.path.name}: {', '.join(known)})")
        kinds = {f.params[s.name] for f in fmus}
        if len(kinds) > 1:
            raise InputError(f"--param {s.text!r}: {s.name} has different types in the FMUs ({', '.join(sorted(kinds))})")
        types[s.name] = kinds.pop()
    return types


def value_problem(f: SweepFmu, values: dict) -> str | None:
    """Reason why ``values`` are not admissible for ``f`` by the FMU's own parameter rules
    (:func:`overcon.fmu.variables.rule`; overcon FMUs only), or None (then the FMU decides)."""
    if f.info.motion_unique is None:  # not an overcon FMU: no rules known here
        return None
    from ...fmu.variables import rule

    problems = []
    for name, value in values.items():
        try:
            r = rule(name)
        except (KeyError, ValueError):
            continue
        why = r.check(value)
        if why:
            problems.append(f"parameter {name} = {value!r} refused: {why}")
    return "; ".join(problems) or None
