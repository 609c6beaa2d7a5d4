"""Parameter sweeps of FMUs on Dask (``overcon sweep``): how much do the eliminations disagree over a
range of friction coefficients, regularisation velocities or solver settings?

Why Dask (``dask.distributed``)
-------------------------------
Thousands of FMU runs outgrow one machine, and overcon must not grow a scheduler of its own. Dask
is an existing distributed engine that runs the same program on a local cluster (the default:
``distributed.LocalCluster`` with ``--workers`` processes) or on any running scheduler given by
address (``--scheduler tcp://host:8786``), reruns the tasks of a worker that dies, and has a
progress bar and a dashboard. Workers need the ``overcon`` package installed (same version as the
client: the task function is imported by name); they do not need the FMU files or a shared file
system: each FMU's bytes are scattered to the workers once.

One run = one task
------------------
A task runs one FMU with one parameter set: the FMU is unpacked once per worker (into the
worker's local directory, under the SHA-256 of its bytes), then
:func:`overcon.tooling.run.run_one` runs ``fmpy.simulate_fmu`` on the unpacked directory in a
child process (an FMU is foreign native code that may crash the process loading it, see
:mod:`overcon.tooling.run`; a child process keeps such a crash away from the Dask worker) and the task returns the position outputs (outputs in
m or rad; FMUs without such outputs: every Real output) on the FMU's output grid.

What is compared (the non-uniqueness measure)
---------------------------------------------
By default every run is a **lockstep** run (:mod:`overcon.verdict`: start values
``solver.method = rk4``, ``solver.step`` = ``--lockstep-step``, 5 ms unless given), so the
eliminations of one scene group take identical steps and differ by round-off only unless their
motion differs. The final positions in ``sweep.csv`` are those of the lockstep run. When every
elimination of a group has run with one parameter set, the group's runs are compared sample by
sample on the output grid by :func:`overcon.tooling.compare.compare_group` (the same comparison as
``overcon compare``): ``max_diff [m]`` / ``max_diff [rad]`` are the largest differences of the
outputs in m / rad against the first elimination, ``verdict`` is *unique* / *not unique* with the
lockstep threshold 1e-8 x max(1, max |y|). ``--lockstep-step 0`` runs the FMUs with their own
(adaptive) solver settings instead; then ``solver.tolerance`` etc. can be swept, the measure
includes the integration error of the adaptive step sequences (see :mod:`overcon.verdict`) and no
verdict is given. In lockstep mode the parameters ``solver.method``, ``solver.step``,
``solver.tolerance`` and ``solver.max_step`` cannot be swept: the first two define the lockstep
grid and the other two have no effect on rk4.

Grid
----
``--param NAME=V1,V2,...`` (values) or ``--param NAME=lo:hi:n`` (n values from lo to hi, both
included, evenly spaced); the full-factorial product of all ``--param``. With ``--samples N
--seed S`` instead N parameter sets drawn at random (numpy ``default_rng(S)``; seed 0 unless
given): ``lo:hi`` is uniform on [lo, hi], a value list picks one of its values with equal
probability. Every swept parameter must be a parameter of every FMU of the sweep (bad input
otherwise, exit 2). Values are typed by the FMU's variable type (Real, Integer, Boolean, String); a
value that does not parse is bad input. A value that parses but is outside the parameter's
admissible range fails its rows, not the sweep: for overcon FMUs it is checked before running
against the FMU's own rule (:func:`overcon.fmu.variables.rule`), otherwise the FMU refuses it and
the reason it logged is recorded.

Results and faults
------------------
``DIR/sweep.csv`` is written by the client only, one row per run, appended as soon as every
elimination of a group has finished one parameter set (so a set is written whole). Each row has a
``key`` (scene and parameter set); a key already in the file is never written again. A worker that
dies has its tasks rerun by Dask (up to ``distributed.scheduler.allowed-failures`` times; then the
row records ``KilledWorker``). Ctrl-C cancels the remaining tasks and keeps the rows written;
``overcon sweep --resume DIR`` reads ``DIR/sweep.json`` (the sweep's definition), rebuilds or
re-reads the FMUs, refuses to continue if an FMU's GUID changed, and runs only the parameter sets
not in ``sweep.csv`` (runs of a set that was not complete at the interruption are run again).
After the runs: ``DIR/sweep.png`` (the measure against each swept numeric parameter, per group,
log scale) and, when pyarrow is installed, ``DIR/sweep.parquet`` (the same rows).
"""
from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import itertools
import json
import math
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..verdict import LOCKSTEP_FACTOR, LOCKSTEP_STEP, lockstep_start_values
from . import InputError, SimulationFailed
from .compare import compare_group, group_fmus, validate_group
from .fmus import FmuInfo, fmu_paths, inspect_fmu
from .run import Experiment, Series, check_unique_models, read_series, run_one

CSV_NAME, JSON_NAME, PNG_NAME, PARQUET_NAME = "sweep.csv", "sweep.json", "sweep.png", "sweep.parquet"
LOCKSTEP_FIXED = ("solver.method", "solver.step", "solver.tolerance", "solver.max_step")
"""Parameters that cannot be swept in lockstep runs (module docstring)."""
ZERO_FLOOR = 1e-17
"""Differences that are exactly 0 are drawn at this height (m or rad) on the log-scale plot."""
EXIT_INTERRUPTED = 130


# ---------------------------------------------------------------------------------------------
# the grid

@dataclass(frozen=True)
class ParamSpec:
    """One ``--param``: ``values`` (raw strings of a list) or a range ``lo``..``hi`` with ``n``
    points (``n`` None: a sampling range ``lo:hi``)."""

    name: str
    text: str
    values: tuple[str, ...] = ()
    lo: float | None = None
    hi: float | None = None
    n: int | None = None

    @property
    def is_range(self) -> bool:
        return self.lo is not None


def parse_param(text: str) -> ParamSpec:
    """``NAME=V1,V2,...`` or ``NAME=lo:hi:n`` (or ``NAME=lo:hi`` for ``--samples``);
    :class:`InputError` naming the ``--param`` at fault."""
    where = f"--param {text!r}"
    if "=" not in text:
        raise InputError(f"{where}: expected NAME=V1,V2,... or NAME=lo:hi:n")
    name, rhs = (s.strip() for s in text.split("=", 1))
    if not name:
        raise InputError(f"{where}: no parameter name before '='")
    if not rhs:
        raise InputError(f"{where}: no values after '='")
    if ":" in rhs:
        parts = rhs.split(":")
        if len(parts) not in (2, 3):
            raise InputError(f"{where}: a range is lo:hi:n (or lo:hi with --samples), got {rhs!r}")
        try:
            lo, hi = float(parts[0]), float(parts[1])
        except ValueError:
            raise InputError(f"{where}: range bounds must be numbers, got {parts[0]!r} and {parts[1]!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi)) or hi < lo:
            raise InputError(f"{where}: range bounds must be finite with lo <= hi, got {lo!r}:{hi!r}")
        n = None
        if len(parts) == 3:
            try:
                n = int(parts[2])
            except ValueError:
                raise InputError(f"{where}: n must be an integer, got {parts[2]!r}") from None
            if n < 1 or (n == 1 and lo != hi):
                raise InputError(f"{where}: n must be >= 2 (or 1 with lo = hi), got {n}")
        return ParamSpec(name, text, lo=lo, hi=hi, n=n)
    values = tuple(v.strip() for v in rhs.split(","))
    if any(not v for v in values):
        raise InputError(f"{where}: empty value in the list {rhs!r}")
    if len(set(values)) != len(values):
        raise InputError(f"{where}: a value is listed twice in {rhs!r}")
    return ParamSpec(name, text, values=values)


def _typed(spec: ParamSpec, raw: str, typ: str):
    where = f"--param {spec.text!r}"
    try:
        if typ == "Real":
            return float(raw)
        if typ == "Integer":
            return int(raw)
        if typ == "Boolean":
            low = raw.lower()
            if low not in ("true", "false", "1", "0"):
                raise ValueError(raw)
            return low in ("true", "1")
        return raw
    except ValueError:
        raise InputError(f"{where}: {raw!r} is not a valid {typ} value for {spec.name}") from None


def grid(specs: list[ParamSpec], types: dict[str, str], *, samples: int | None = None,
         seed: int | None = None) -> list[dict]:
    """The parameter sets: full factorial of ``specs`` (in the order given), or ``samples`` sets
    drawn with ``numpy.random.default_rng(seed)``. ``types``: FMU variable type per name."""
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise InputError(f"--param: {sorted({n for n in names if names.count(n) > 1})[0]} given twice")
    for s in specs:
        if s.is_range and types[s.name] != "Real":
            raise InputError(f"--param {s.text!r}: a range lo:hi needs a Real parameter; {s.name} is "
                             f"{types[s.name]}: list its values")
    if samples is None:
        axes = []
        for s in specs:
            if s.is_range and s.n is None:
                raise InputError(f"--param {s.text!r}: lo:hi is a sampling range (with --samples); give "
                                 "lo:hi:n for a grid of n values")
            if s.is_range:
                axes.append([float(v) for v in np.linspace(s.lo, s.hi, s.n)])
            else:
                axes.append([_typed(s, v, types[s.name]) for v in s.values])
        return [dict(zip(names, combo)) for combo in itertools.product(*axes)]
    if samples < 1:
        raise InputError(f"--samples {samples}: must be >= 1")
    rng = np.random.default_rng(0 if seed is None else seed)
    for s in specs:
        if s.is_range and s.n is not None:
            raise InputError(f"--param {s.text!r}: with --samples a range is lo:hi (drawn uniformly); "
                             "n has no meaning there")
    typed = {s.name: [_typed(s, v, types[s.name]) for v in s.values] for s in specs if not s.is_range}
    out = []
    for _ in range(samples):
        row = {}
        for s in specs:
            row[s.name] = float(rng.uniform(s.lo, s.hi)) if s.is_range else typed[s.name][int(rng.integers(len(s.values)))]
        out.append(row)
    return out


def params_key(values: dict) -> str:
    """Canonical text of a parameter set (sorted names, shortest round-trip floats)."""
    return json.dumps(dict(sorted(values.items())), separators=(",", ":"))


def set_ids(sets: list[dict], sampled: bool) -> list[str]:
    """The identity of each parameter set: its :func:`params_key`; for ``--samples`` prefixed by
    the sample number (``#3 {...}``), so that a set drawn twice is two samples (two rows per FMU),
    as a Monte-Carlo spread needs, never one row silently standing for both."""
    return [f"#{i} {params_key(v)}" if sampled else params_key(v) for i, v in enumerate(sets, start=1)]


def row_key(model: str, set_id: str) -> str:
    """The row's identity in ``sweep.csv``: scene (model identifier) and parameter set id."""
    return f"{model} {set_id}"


# ---------------------------------------------------------------------------------------------
# the FMUs

@dataclass(frozen=True)
class SweepFmu:
    """An FMU of the sweep: its description (outputs restricted to those compared), parameters
    (name -> FMI type), GUID, bytes and their SHA-256."""

    info: FmuInfo
    params: dict
    guid: str
    data: bytes = field(repr=False)
    sha: str = ""


def _load_fmu(path: Path) -> SweepFmu:
    from fmpy import read_model_description

    info = inspect_fmu(path)
    md = read_model_description(str(path), validate=False)
    params = {v.name: v.type for v in md.modelVariables if v.causality == "parameter"}
    positions = tuple(o for o in info.outputs if o.kind == "position") or info.outputs
    data = Path(path).read_bytes()
    return SweepFmu(dataclasses.replace(info, outputs=positions), params, md.guid, data,
                    hashlib.sha256(data).hexdigest())


def _resolve_inputs(inputs: list[str], out_dir: Path, echo) -> list[Path]:
    """Scene files (``*.toml``) built into ``out_dir/fmus`` (pre-check printed, non-unique scenes
    built too: that is what a sweep measures); FMU files and directories of FMUs as they are."""
    from ..fmu.build import build_all

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
    from ..fmu.variables import rule

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


# ---------------------------------------------------------------------------------------------
# on the worker

_UNPACK_LOCK = threading.Lock()


def _unpacked(data: bytes, sha: str) -> Path:
    """The FMU unpacked once per worker: ``<worker local directory>/overcon-fmus/<sha256>``."""
    try:
        from distributed import get_worker

        root = Path(get_worker().local_directory)
    except (ImportError, ValueError):  # not in a Dask worker
        root = Path(tempfile.gettempdir()) / f"overcon-sweep-{os.getuid()}"
    target = root / "overcon-fmus" / sha
    with _UNPACK_LOCK:
        if not (target / "modelDescription.xml").is_file():
            part = target.with_name(f"{sha}.part{os.getpid()}")
            part.mkdir(parents=True, exist_ok=True)
            with zipfile.ZipFile(io.BytesIO(data)) as zf:
                zf.extractall(part)
            try:
                os.replace(part, target)
            except OSError:  # another process (outside a Dask worker: shared temp dir) was faster
                if not (target / "modelDescription.xml").is_file():
                    raise
                shutil.rmtree(part, ignore_errors=True)
    return target


def _one_line(text: str) -> str:
    return " ".join(text.split())


def run_task(data: bytes, sha: str, info: FmuInfo, ex: Experiment) -> dict:
    """One sweep run (a Dask task): unpack the FMU (once per worker), run it with fmpy in a child
    process, return ``{"status": "ok", "wall": s, "time": array, "values": {output: array}}`` or
    ``{"status": reason}`` (the FMU's logged reason; one line)."""
    unpacked = _unpacked(data, sha)
    with tempfile.TemporaryDirectory(prefix="overcon-sweep-run-") as tmp:
        try:
            r = run_one(dataclasses.replace(info, path=unpacked), ex, Path(tmp) / "run.csv", False, None,
                        label=info.model)
            s = read_series(r.csv)
        except (SimulationFailed, InputError) as exc:
            return {"status": _one_line(str(exc).replace(str(unpacked), str(info.path)))}
    return {"status": "ok", "wall": r.wall_seconds, "time": s.time,
            "values": {n: s.values[n] for n in info.output_names}}


# ---------------------------------------------------------------------------------------------
# rows

@dataclass
class Sweep:
    """A sweep's definition (``DIR/sweep.json``) and what it resolved to."""

    out_dir: Path
    definition: dict
    fmus: list[SweepFmu]
    groups: dict  # group -> [SweepFmu] (paper order)
    sets: list[tuple[str, dict]]  # (set id, parameter values), see set_ids
    experiments: dict  # model -> Experiment
    columns: list[str]
    lockstep_step: float | None

    @property
    def csv(self) -> Path:
        return self.out_dir / CSV_NAME


FIXED_COLUMNS = ("key", "scene", "group", "elimination", "sample", "status", "wall [s]", "max_diff [m]",
                 "max_diff [rad]", "max_diff_output", "verdict")


def _columns(param_names: list[str], fmus: list[SweepFmu]) -> list[str]:
    clash = [n for n in param_names if n in FIXED_COLUMNS or n.startswith("final ")]
    if clash:
        raise InputError(f"--param {clash[0]}: the name is also a column of sweep.csv; such a parameter cannot be swept")
    finals = []
    for f in fmus:
        for o in f.info.outputs:
            col = f"final {o.name} [{o.unit or '1'}]"
            if col not in finals:
                finals.append(col)
    return [*FIXED_COLUMNS[:5], *param_names, *FIXED_COLUMNS[5:], *finals]


def _fmt(x) -> str:
    if x is None:
        return ""
    if isinstance(x, float):
        return repr(x)
    return str(x)


def read_rows(path: Path) -> list[dict]:
    """The rows of a ``sweep.csv`` (strings)."""
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _set_rows(sw: Sweep, group: str, set_id: str, values: dict, results: dict) -> list[dict]:
    """The rows of one group at one parameter set; ``results``: model -> task result."""
    members = sw.groups[group]
    ok = [f for f in members if results[f.info.model]["status"] == "ok"]
    diff_m = diff_rad = worst = verdict = None
    if len(ok) == len(members) and len(members) >= 2:
        series = [Series(results[f.info.model]["time"], results[f.info.model]["values"]) for f in members]
        infos = [f.info for f in members]
        lock = sw.lockstep_step is not None
        c = compare_group(group, infos, series, lockstep=series if lock else None,
                          lockstep_step=sw.lockstep_step)
        by_unit = c.max_diff_by_unit()
        diff_m, diff_rad = by_unit.get("m"), by_unit.get("rad")
        w = c.worst()
        worst = w.name if w is not None else None
        verdict = c.verdict_text() if lock else None
    rows = []
    for f in members:
        res = results[f.info.model]
        row = {"key": row_key(f.info.model, set_id), "scene": f.info.model, "group": group,
               "sample": set_id[1:].split(" ", 1)[0] if set_id.startswith("#") else None,
               "elimination": f.info.label, **values, "status": res["status"], "wall [s]": res.get("wall"),
               "max_diff [m]": diff_m, "max_diff [rad]": diff_rad, "max_diff_output": worst, "verdict": verdict}
        if res["status"] == "ok":
            for o in f.info.outputs:
                row[f"final {o.name} [{o.unit or '1'}]"] = float(res["values"][o.name][-1])
        rows.append({c: _fmt(row.get(c)) for c in sw.columns})
    return rows


class RowWriter:
    """Appends rows to ``sweep.csv`` (header first when new), never a key twice; flushed per set."""

    def __init__(self, path: Path, columns: list[str]):
        self.path = path
        self.columns = columns
        self.keys: set[str] = set()
        if path.is_file() and path.stat().st_size > 0:
            with open(path, newline="", encoding="utf-8") as fh:
                header = next(csv.reader(fh), [])
            if header != columns:
                raise InputError(f"{path}: its columns differ from this sweep's ({len(header)} against "
                                 f"{len(columns)}): not a sweep of this definition")
            self.keys = {r["key"] for r in read_rows(path)}
            self.fh = open(path, "a", newline="", encoding="utf-8")
            self.writer = csv.DictWriter(self.fh, columns)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            self.fh = open(path, "w", newline="", encoding="utf-8")
            self.writer = csv.DictWriter(self.fh, columns)
            self.writer.writeheader()
            self.fh.flush()

    def write(self, rows: list[dict]) -> int:
        new = [r for r in rows if r["key"] not in self.keys]
        for r in new:
            self.writer.writerow(r)
            self.keys.add(r["key"])
        self.fh.flush()
        os.fsync(self.fh.fileno())
        return len(new)

    def close(self) -> None:
        self.fh.close()


# ---------------------------------------------------------------------------------------------
# definition

def _lockstep_step(h) -> float | None:
    if h is None or h == 0:
        return None
    if not (math.isfinite(h) and 1e-6 <= h <= 1.0):
        raise InputError(f"--lockstep-step {h!r}: must be a step in s between 1e-6 and 1 (0: no lockstep)")
    return float(h)


def prepare(out_dir, *, inputs=None, params=None, samples=None, seed=None, stop_time=None,
            lockstep_step: float | None = LOCKSTEP_STEP, resume: bool = False, echo=print) -> Sweep:
    """Resolve a sweep: a new one from the arguments (``out_dir`` must not hold one), or with
    ``resume`` the one defined by ``out_dir/sweep.json`` (arguments must then be None)."""
    from .pipeline import _group_experiments

    out_dir = Path(out_dir)
    jpath = out_dir / JSON_NAME
    if resume:
        if inputs or params or samples is not None or seed is not None or stop_time is not None:
            raise InputError("--resume DIR continues the sweep defined in DIR/sweep.json: give no scenes, "
                             "--param, --samples, --seed or --stop-time with it")
        if not jpath.is_file():
            raise InputError(f"{jpath}: no such file: {out_dir} holds no sweep to resume")
        try:
            definition = json.loads(jpath.read_text(encoding="utf-8"))
        except ValueError as exc:
            raise InputError(f"{jpath}: unreadable sweep definition: {exc}") from exc
    else:
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
    specs = [parse_param(t) for t in definition["params"]]
    lstep = definition["lockstep_step"]
    paths = _resolve_inputs(definition["inputs"], out_dir, echo)
    fmus = [_load_fmu(p) for p in paths]
    check_unique_models([f.info for f in fmus], out_dir)
    types = _check_params(specs, fmus, lstep is not None)
    values = grid(specs, types, samples=definition["samples"], seed=definition["seed"])
    sets = list(zip(set_ids(values, definition["samples"] is not None), values))
    guids = {f.info.model: f.guid for f in fmus}
    if resume:
        changed = [m for m, g in definition.get("guids", {}).items() if guids.get(m) != g]
        if changed or set(guids) != set(definition.get("guids", {})):
            raise InputError(f"{jpath}: the FMU(s) {', '.join(changed or sorted(set(guids) ^ set(definition['guids'])))} "
                             "changed since the sweep started (GUID differs): the rows would mix two models; "
                             "start a new sweep")
    else:
        definition["guids"] = guids
    by_model = {f.info.model: f for f in fmus}
    groups = {g: [by_model[i.model] for i in items] for g, items in group_fmus([f.info for f in fmus]).items()}
    for g, members in groups.items():  # before any run: common outputs, one prediction per group
        if len(members) >= 2:
            validate_group(g, [f.info for f in members])
    exps = _group_experiments({g: [f.info for f in v] for g, v in groups.items()}, definition["stop_time"], None)
    columns = _columns([s.name for s in specs], fmus)
    if not resume:
        out_dir.mkdir(parents=True, exist_ok=True)
        jpath.write_text(json.dumps(definition, indent=1) + "\n", encoding="utf-8")
    return Sweep(out_dir, definition, fmus, groups, sets, exps, columns, lstep)


# ---------------------------------------------------------------------------------------------
# running

@dataclass
class SweepOutcome:
    csv: Path
    rows: int  # rows in sweep.csv
    written: int  # rows written by this call
    failed: int  # rows in sweep.csv whose status is not ok
    interrupted: bool
    png: Path | None = None
    parquet: Path | None = None
    seconds: float = 0.0


def _experiment(sw: Sweep, f: SweepFmu, values: dict) -> Experiment:
    sv = dict(lockstep_start_values(sw.lockstep_step)) if sw.lockstep_step is not None else {}
    sv.update(values)
    return dataclasses.replace(sw.experiments[f.info.model], start_values=tuple(sv.items()))


def _start_client(scheduler: str | None, workers: int, echo):
    """(client, cluster or None): a connection to ``scheduler``, or a new local cluster of
    ``workers`` single-threaded worker processes (SIGINT ignored there, so that Ctrl-C reaches
    the client only and the client stops them)."""
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout="30s")
        except OSError as exc:
            raise InputError(f"--scheduler {scheduler}: cannot connect: {exc}") from exc
        n = len(client.scheduler_info().get("workers", {}))
        echo(f"== Dask scheduler {scheduler}: {n} worker(s)")
        return client, None
    old = signal.signal(signal.SIGINT, signal.SIG_IGN) if threading.current_thread() is threading.main_thread() else None
    try:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True)
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)
    client = Client(cluster)
    echo(f"== Dask local cluster: {workers} worker process(es), scheduler {cluster.scheduler_address}")
    return client, cluster


def _dashboard(client) -> str | None:
    """The dashboard's address, when the scheduler serves one (its pages need bokeh there)."""
    import importlib.util

    services = client.scheduler_info().get("services", {})
    if "dashboard" not in services:
        return None
    note = "" if importlib.util.find_spec("bokeh") else " (its pages need bokeh on the scheduler: pip install bokeh)"
    return client.dashboard_link + note


def _progress_thread(futures, client):
    from distributed.diagnostics.progressbar import TextProgressBar

    def bar():
        try:
            # complete=False: the runs only, not the FMU bytes scattered before them
            TextProgressBar(futures, scheduler=client.scheduler.address, complete=False)
        except Exception:  # noqa: BLE001 -- the bar is cosmetic; the rows do not depend on it
            pass

    t = threading.Thread(target=bar, name="overcon-sweep-progress", daemon=True)
    t.start()
    return t


def run(sw: Sweep, *, client=None, scheduler: str | None = None, workers: int = 2, progress: bool = True,
        echo=print, on_rows=None) -> SweepOutcome:
    """Run the parameter sets of ``sw`` not yet in ``sweep.csv`` on Dask (``client``, else a
    connection to ``scheduler``, else a local cluster of ``workers`` processes); append rows per
    finished group and set; ``on_rows(rows, client)`` after each append (tests). Ctrl-C
    (KeyboardInterrupt) cancels the remaining tasks and returns with ``interrupted``."""
    from distributed import as_completed

    t0 = time.perf_counter()
    writer = RowWriter(sw.csv, sw.columns)
    written = 0
    pending: dict[tuple[str, str], dict] = {}  # (group, params key) -> model -> result
    values_of = dict(sw.sets)
    todo: list[tuple[str, SweepFmu, str]] = []  # (group, FMU, set id)
    before = len(writer.keys)
    try:
        for pk, values in sw.sets:
            for g, members in sw.groups.items():
                if all(row_key(f.info.model, pk) in writer.keys for f in members):
                    continue
                results = pending.setdefault((g, pk), {})
                for f in members:
                    why = value_problem(f, values)
                    if why:
                        results[f.info.model] = {"status": f"{why} (checked before running, by the FMU's parameter rule)"}
                    else:
                        todo.append((g, f, pk))
                if len(results) == len(members):
                    written += writer.write(_set_rows(sw, g, pk, values, pending.pop((g, pk))))
        echo(f"== sweep: {len(sw.sets)} parameter set(s) x {sum(len(v) for v in sw.groups.values())} FMU(s); "
             f"{before} row(s) already in {sw.csv}, {len(writer.keys) - before} refused before running, "
             f"{len(todo)} run(s) to do; "
             + (f"lockstep runs (rk4, {sw.lockstep_step:g} s)" if sw.lockstep_step is not None
                else "the FMUs' own solver settings (no lockstep)"))
        interrupted = False
        if todo:
            own = client is None
            cluster = None
            if own:
                client, cluster = _start_client(scheduler, workers, echo)
            futures = []
            try:
                link = _dashboard(client)
                if link:
                    echo(f"   dashboard: {link}")
                blobs = {f.info.model: client.scatter(f.data, broadcast=True, hash=True) for f in sw.fmus
                         if any(t[1] is f for t in todo)}
                meta = {}
                for g, f, pk in todo:
                    values = values_of[pk]
                    key = "overcon-sweep-" + hashlib.sha256(
                        (f.sha + " " + row_key(f.info.model, pk)).encode()).hexdigest()[:24]
                    fut = client.submit(run_task, blobs[f.info.model], f.sha, f.info, _experiment(sw, f, values),
                                        key=key, pure=False)
                    meta[fut.key] = (g, f.info.model, pk)
                    futures.append(fut)
                bar = _progress_thread(futures, client) if progress else None
                for fut in as_completed(futures):
                    g, model, pk = meta[fut.key]
                    try:
                        res = fut.result()
                    except Exception as exc:  # noqa: BLE001 -- KilledWorker etc.: recorded in the row
                        res = {"status": _one_line(f"{type(exc).__name__}: {exc}")}
                    results = pending[(g, pk)]
                    results[model] = res
                    if len(results) == len(sw.groups[g]):
                        rows = _set_rows(sw, g, pk, values_of[pk], pending.pop((g, pk)))
                        written += writer.write(rows)
                        if on_rows is not None:
                            on_rows(rows, client)
                if bar is not None:
                    bar.join(timeout=5)
                    if progress:
                        print(file=sys.stdout, flush=True)
            except KeyboardInterrupt:
                interrupted = True
                client.cancel(futures)
            finally:
                if own:
                    client.close()
                    if cluster is not None:
                        cluster.close()
    except KeyboardInterrupt:
        interrupted = True
    finally:
        writer.close()
    rows = read_rows(sw.csv)
    failed = sum(r["status"] != "ok" for r in rows)
    out = SweepOutcome(sw.csv, len(rows), written, failed, interrupted, seconds=time.perf_counter() - t0)
    if rows:
        for line in summary(sw, rows):
            echo(line)
        out.png = plot(sw, rows)
        out.parquet = write_parquet(sw.csv)
    return out


# ---------------------------------------------------------------------------------------------
# outputs

def summary(sw: Sweep, rows: list[dict]) -> list[str]:
    """One line per group: sets unique / not unique / without a measure, the range of
    ``max_diff [m]``; for a sweep of one numeric parameter also the largest value still unique and
    the smallest not unique (the question "above which value does the non-uniqueness matter?")."""
    names = [parse_param(t).name for t in sw.definition["params"]]
    lines = []
    for g in sw.groups:
        sets: dict[str, dict] = {}
        for r in rows:
            if r["group"] == g:
                sets.setdefault(r["key"].split(" ", 1)[1], r)
        if not sets:
            continue
        verdicts = [r["verdict"] for r in sets.values()]
        measured = [_number(r["max_diff [m]"]) for r in sets.values()]
        diffs = [d for d in measured if d is not None]
        text = (f"{g}: {len(sets)} parameter set(s): {verdicts.count('unique')} unique, "
                f"{verdicts.count('not unique')} not unique, {len(measured) - len(diffs)} without a measure "
                "(a run failed, or the group has one FMU)")
        if diffs:
            text += f"; max_diff {min(diffs):.2g} to {max(diffs):.2g} m"
        if len(names) == 1 and all(_number(r[names[0]]) is not None for r in sets.values()):
            x = names[0]
            uniq = [_number(r[x]) for r in sets.values() if r["verdict"] == "unique"]
            nonu = [_number(r[x]) for r in sets.values() if r["verdict"] == "not unique"]
            if uniq:
                text += f"; unique up to {x} = {max(uniq):g}"
            if nonu:
                text += f"; not unique from {x} = {min(nonu):g}"
        lines.append(text)
    return lines


def write_parquet(csv_path: Path) -> Path | None:
    """``sweep.parquet`` next to ``csv_path`` when pyarrow is installed (else None)."""
    try:
        import pyarrow.csv as pacsv
        import pyarrow.parquet as pq
    except ImportError:
        return None
    table = pacsv.read_csv(str(csv_path))
    out = csv_path.with_name(PARQUET_NAME)
    pq.write_table(table, str(out))
    return out


def _number(text: str) -> float | None:
    try:
        return float(text) if text != "" else None
    except ValueError:
        return None


def plot(sw: Sweep, rows: list[dict]) -> Path:
    """``sweep.png``: ``max_diff [m]`` (the non-uniqueness measure) against each swept numeric
    parameter, one marker series per group, log scale; differences of exactly 0 drawn at
    :data:`ZERO_FLOOR` with open markers (said in the legend), sets without a measure (a failed
    run) left out and counted in the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    names = [n for n in (parse_param(t).name for t in sw.definition["params"])
             if any(_number(r[n]) is not None for r in rows)]
    per_set: dict[tuple[str, str], dict] = {}
    for r in rows:  # one point per group and parameter set (the rows of a set share the measure)
        per_set.setdefault((r["group"], r["key"].split(" ", 1)[1]), r)
    fig, axes = plt.subplots(1, max(1, len(names)), figsize=(5.5 * max(1, len(names)), 4.2), squeeze=False)
    groups = list(sw.groups)
    missing = sum(_number(r["max_diff [m]"]) is None for r in per_set.values())
    for ax, name in zip(axes[0], names or [None]):
        for k, g in enumerate(groups):
            pts = [(_number(r[name]) if name else 0.0, _number(r["max_diff [m]"])) for (gg, _), r in per_set.items()
                   if gg == g]
            pts = sorted((x, y) for x, y in pts if x is not None and y is not None)
            color = f"C{k}"
            pos = [(x, y) for x, y in pts if y > 0]
            zero = [(x, y) for x, y in pts if y == 0]
            if pos:
                ax.plot(*zip(*pos), "o-" if sw.definition["samples"] is None and len(names) == 1 else "o",
                        color=color, label=g)
            if zero:
                ax.plot([x for x, _ in zero], [ZERO_FLOOR] * len(zero), "v", mfc="none", color=color,
                        label=f"{g}: difference exactly 0 (drawn at {ZERO_FLOOR:g} m)")
        if sw.lockstep_step is not None:
            ax.axhline(LOCKSTEP_FACTOR, color="0.4", ls="--", lw=1,
                       label=f"lockstep verdict threshold {LOCKSTEP_FACTOR:g} m (outputs up to 1 m)")
        ax.set_yscale("log")
        ax.xaxis.set_major_locator(MaxNLocator(6))
        ax.set_xlabel(name or "")
        ax.set_ylabel("max position difference between eliminations (m)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    mode = (f"lockstep runs, rk4 {sw.lockstep_step:g} s" if sw.lockstep_step is not None
            else "the FMUs' own solver settings")
    title = f"overcon sweep: non-uniqueness of the motion\n({mode}"
    title += f"; {missing} parameter set(s) without a measure: a run failed)" if missing else ")"
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    out = sw.out_dir / PNG_NAME
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
