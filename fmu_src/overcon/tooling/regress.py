"""``overcon regress``: the regression check of scene FMUs against committed baselines.

    overcon regress [DIR] [--baselines DIR] [--scenes NAME|GLOB ...] [--junit FILE]   # the check (CI)
    overcon regress [DIR] --regenerate [--tolerances FILE] [--stop-time T] [--step S] [--scenes ...]  # by hand only

``DIR`` (default ``mechanisms``) is any directory of scene files; ``--baselines`` (default
``ci/baselines``) the directory of their baselines; ``--tolerances`` (default
``ci/tolerances.toml`` when it exists, else the package's :data:`PACKAGED_TOLERANCES`) the
tolerance table. Relative defaults are taken from the working directory, so in this repository
and in a user's own project laid out the same way the command needs no option.

The check, for every scene file of ``DIR`` and its subdirectories (files with a ``[scene]`` table):

1. finds its baseline ``<baselines>/<scene>_ref.csv`` + ``<scene>_ref.opt`` (FMI cross-check
   files: time and every Real output; StartTime, StopTime, StepSize, RelTol). A scene without one
   fails (exit 2) with the command that creates it; a baseline without a scene fails too;
2. builds the scene's FMU (``overcon.fmu.build.build_all``, non-unique scenes included) and
   validates it with ``fmpy.validation.validate_fmu`` (zero problems, else a regression);
3. runs it with fmpy (``overcon.tooling.run.run_fmus``: one worker process per FMU, ``--jobs`` at
   a time, longest first) on the baseline's grid: the FMU's own DefaultExperiment (solver
   tolerance 1e-9, stop 4 s planar / 10 s spatial), outputs every ``StepSize`` = 0.05 s;
4. compares it with ``overcon.tooling.compare.compare_reference`` (the reference mode of
   ``overcon compare --ref``), then replaces the library's one-size tolerance by the per-output
   tolerance of the tolerance table (the ONE place tolerances are stated) and marks every
   reaction output with its joint's ``reaction_unique`` constant: non-unique reactions are
   compared like the others (deterministic for a fixed elimination) but reported as non-unique.

The tolerance *tier* is chosen per scene: ``same_platform`` when this machine's numerical
fingerprint (Python, numpy, scipy, their BLAS, CPU model and flags, libc, kernel-selecting
environment variables; :func:`platform_fingerprint`) equals the one recorded with the baseline in
``<baselines>/provenance.json``: there the results are bit-identical and the tolerances are far
below the acceptance floor; ``cross_platform`` otherwise (round-off of another BLAS, amplified by
the friction solve; measured, see the file).

Exit codes: 0 every scene matches; 1 a regression (each line names the scene, the output, the
difference, where it is largest, and the tolerance with its source); 2 bad input (no baseline,
a baseline without a scene, an invalid scene or tolerance file, a baseline file that is not on its
.opt grid). Worst wins: 2 > 1. The report (``<out>/report.md``) has every output's table;
``--junit FILE`` also writes JUnit XML (:func:`write_junit`): one test case per scene, a
``failure`` naming the scene and its outputs over tolerance, an ``error`` for bad input.

``--regenerate`` builds, validates and runs the selected scenes (all by default) and writes their
baselines (the old grid is kept unless ``--stop-time``/``--step`` are given; a new scene gets its
FMU's DefaultExperiment stop time and a 0.05 s step) and their provenance, and prints how far each
moved from the previous baseline. It is never run by CI or the tests (on the committed baselines):
regenerating is the deliberate act of accepting new results; review the printed changes and the
diff of ``ci/baselines/`` before committing.

Baseline size: the grid is the FMU's full default experiment (what users run) sampled every
0.05 s instead of the 0.01 s stepSize: 81 rows planar, 201 rows spatial, shortest round-trip
``repr`` of every double (bit-exact), 1.7 MB for the 20 scenes. The trajectory does not depend on
the output grid (the integrator takes its own steps and reads the solution by dense output; the
0.05 s and 0.01 s runs agree to 2e-12 at common times), so nothing is lost but resolution, and
the check costs the same as the full default experiment (its wall time: docs/benchmarks.md,
"Input limits and the regression check").
"""
from __future__ import annotations

import datetime
import fnmatch
import hashlib
import json
import math
import os
import platform
import shlex
import shutil
import time
import tomllib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

DEFAULT_MECHANISMS = Path("mechanisms")
DEFAULT_BASELINES = Path("ci") / "baselines"
DEFAULT_TOLERANCES = Path("ci") / "tolerances.toml"
DEFAULT_OUT = Path("dist") / "regress"
PACKAGED_TOLERANCES = Path(__file__).resolve().parent / "regress_tolerances.toml"
"""The tolerance table used when ``--tolerances`` is not given and ``ci/tolerances.toml`` does not
exist (a user's own project): the per-unit values of this repository's table, without its
scene-specific rules (which name this repository's scenes)."""
BASELINE_STEP = 0.05  # s: output interval of new baselines (see the module docstring)
PROVENANCE = "provenance.json"
TIERS = ("same_platform", "cross_platform")
# environment variables that change the numerical kernels numpy/scipy/OpenBLAS/MKL pick
KERNEL_ENV = ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES", "NPY_ENABLE_CPU_FEATURES", "MKL_CBWR",
              "MKL_ENABLE_INSTRUCTIONS", "MKL_DEBUG_CPU_TYPE")

EXIT_OK, EXIT_REGRESSION, EXIT_INPUT = 0, 1, 2
MAX_LINES_PER_CLASS = 2  # regression lines printed per scene and output class (all are in report.md)


class BadInput(Exception):
    """Exit 2: the message says what is wrong and how to fix it."""


def _echo(s: str) -> None:
    print(s, flush=True)


def _rel(p: Path) -> str:
    try:
        return str(Path(p).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(p)


# ---------------------------------------------------------------------------------------------
# scenes and baselines

def discover_scenes(mechanisms: Path) -> tuple[dict[str, Path], list[str]]:
    """Scene name -> file for the *.toml files of ``mechanisms`` and its subdirectories that have
    a [scene] table (the name is the scene's ``name``, which names its FMU), and problems
    (unreadable TOML, a scene without a usable name, duplicate names). The scene is validated
    when its FMU is built (a scene the loader refuses is bad input of that scene)."""
    mechanisms = Path(mechanisms)
    if not mechanisms.is_dir():
        raise BadInput(f"{mechanisms}: no such directory (the directory of the scene files)")
    scenes: dict[str, Path] = {}
    problems: list[str] = []
    for f in sorted(mechanisms.rglob("*.toml")):
        try:
            doc = tomllib.loads(f.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            problems.append(f"{f}: unreadable TOML: {exc}")
            continue
        if not isinstance(doc.get("scene"), dict):
            continue  # a mechanism file
        name = doc["scene"].get("name")
        if not isinstance(name, str) or not name.isidentifier():
            problems.append(f"{f}: invalid scene file: scene.name must be an identifier, got {name!r}")
            continue
        if name in scenes:
            problems.append(f"{f}: scene name {name} also used by {scenes[name]} (names must be unique: "
                            "they name the FMU and the baseline)")
            continue
        scenes[name] = f
    return scenes, problems


def select_scenes(scenes: dict[str, Path], patterns: list[str] | None) -> list[str]:
    """Names matching any of ``patterns`` (names or shell globs); all when None."""
    if not patterns:
        return list(scenes)
    out: list[str] = []
    for pat in patterns:
        hits = [n for n in scenes if fnmatch.fnmatchcase(n, pat)]
        if not hits:
            raise BadInput(f"--scenes {pat}: matches no scene ({len(scenes)} scenes: "
                           f"{', '.join(sorted(scenes)) or 'none'})")
        out.extend(h for h in hits if h not in out)
    return out


def baseline_files(baselines: Path, name: str) -> tuple[Path, Path]:
    return Path(baselines) / f"{name}_ref.csv", Path(baselines) / f"{name}_ref.opt"


def read_opt(path: Path) -> dict[str, float]:
    """``<scene>_ref.opt`` (FMI cross-check: ``Key, value`` lines)."""
    out: dict[str, float] = {}
    for ln, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        key, sep, val = line.partition(",")
        try:
            out[key.strip()] = float(val)
        except ValueError:
            raise BadInput(f"{path}:{ln}: expected 'Key, number', got {line!r}") from None
    missing = [k for k in ("StartTime", "StopTime", "StepSize") if k not in out]
    if missing:
        raise BadInput(f"{path}: missing {', '.join(missing)}")
    return out


def write_opt(path: Path, start: float, stop: float, step: float, rel_tol: float | None) -> None:
    text = f"StartTime, {start!r}\nStopTime, {stop!r}\nStepSize, {step!r}\n"
    if rel_tol is not None:
        text += f"RelTol, {rel_tol!r}\n"
    path.write_text(text, encoding="utf-8")


def regenerate_command(names: list[str], mechanisms: Path, baselines: Path, tolerances=None) -> str:
    """The command that writes these scenes' baselines (printed where one is missing or differs);
    ``tolerances``: the table of the check, passed on unless it is a default one (--regenerate
    refuses an output it has no tolerance for)."""
    # DIR first and --scenes last: ``--scenes NAME [NAME ...]`` would take a DIR after it as a name
    cmd = "overcon regress"
    if Path(mechanisms).resolve() != DEFAULT_MECHANISMS.resolve():
        cmd += f" {shlex.quote(str(mechanisms))}"
    cmd += " --regenerate"
    if Path(baselines).resolve() != DEFAULT_BASELINES.resolve():
        cmd += f" --baselines {shlex.quote(str(baselines))}"
    if tolerances is not None and Path(tolerances).resolve() not in (DEFAULT_TOLERANCES.resolve(),
                                                                      PACKAGED_TOLERANCES.resolve()):
        cmd += f" --tolerances {shlex.quote(str(tolerances))}"
    return cmd + " --scenes " + " ".join(names)


def _table_path(r) -> Path | None:
    """The tolerance table a check read (None: none read)."""
    return r.table.path if r.table is not None else None


def load_provenance(baselines: Path) -> dict:
    p = Path(baselines) / PROVENANCE
    if not p.is_file():
        return {"platforms": {}, "scenes": {}}
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except ValueError as exc:
        raise BadInput(f"{p}: unreadable JSON: {exc}") from exc
    doc.setdefault("platforms", {})
    doc.setdefault("scenes", {})
    return doc


def save_provenance(baselines: Path, doc: dict) -> None:
    used = {s.get("platform") for s in doc["scenes"].values()}
    doc["platforms"] = {k: v for k, v in doc["platforms"].items() if k in used}
    doc["note"] = ("written by overcon regress --regenerate: per scene, the platform fingerprint "
                   "(overcon.tooling.regress.platform_fingerprint) and the FMU the baseline came from")
    (Path(baselines) / PROVENANCE).write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n",
                                              encoding="utf-8")


# ---------------------------------------------------------------------------------------------
# platform fingerprint

def _blas(mod) -> str:
    try:
        cfg = mod.show_config(mode="dicts")
        b = cfg["Build Dependencies"]["blas"]
        return f"{b.get('name')} {b.get('version')}"
    except Exception:  # noqa: BLE001 -- older numpy/scipy: no dict mode
        return "unknown"


def _cpu() -> tuple[str, str]:
    """CPU identification (vendor, family, model: what OpenBLAS's DYNAMIC_ARCH picks its kernels
    by) and a hash of the feature flags (what numpy's SIMD dispatch picks by)."""
    ident: dict[str, str] = {}
    flags = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, val = line.partition(":")
            key = key.strip()
            if key in ("vendor_id", "cpu family", "model", "model name", "CPU implementer", "CPU part") \
                    and key not in ident:
                ident[key] = val.strip()
            elif key in ("flags", "Features") and not flags:
                flags = " ".join(sorted(val.split()))
    except OSError:
        pass
    model = " / ".join(f"{k}: {v}" for k, v in ident.items()) or platform.processor() or "unknown"
    return model, hashlib.sha256(flags.encode()).hexdigest()[:16]


def platform_fingerprint() -> dict:
    """Everything known to change the rounding of the simulation: same fingerprint, same bits
    (measured: reruns and 1 vs 2 BLAS threads are bit-identical). Thread counts are not part of
    it (the matrices are too small for OpenBLAS to split)."""
    import scipy

    model, flags = _cpu()
    libc = " ".join(platform.libc_ver()) or "unknown"
    return {"machine": platform.machine(), "system": platform.system(), "libc": libc,
            "python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__,
            "numpy_blas": _blas(np), "scipy_blas": _blas(scipy), "cpu": model, "cpu_flags_sha256": flags,
            "env": {k: os.environ[k] for k in KERNEL_ENV if os.environ.get(k)}}


def fingerprint_id(fp: dict) -> str:
    return hashlib.sha256(json.dumps(fp, sort_keys=True).encode()).hexdigest()[:12]


# ---------------------------------------------------------------------------------------------
# tolerances

@dataclass
class Rule:
    tier: str
    index: int
    tolerance: float
    why: str
    scenes: tuple[str, ...] = ("*",)
    outputs: tuple[str, ...] = ("*",)
    units: tuple[str, ...] | None = None

    def matches(self, scene: str, output: str, unit: str | None) -> bool:
        return (any(fnmatch.fnmatchcase(scene, p) for p in self.scenes)
                and any(fnmatch.fnmatchcase(output, p) for p in self.outputs)
                and (self.units is None or (unit or "") in self.units))


@dataclass
class ToleranceTable:
    path: Path
    by_unit: dict  # tier -> {unit: tolerance}
    rules: dict  # tier -> [Rule]

    def lookup(self, tier: str, scene: str, output: str, unit: str | None) -> tuple[float, str]:
        """(absolute tolerance, where it is stated) for one output: the first matching rule of
        the tier, else the tier's value for the output's unit (``default`` if given)."""
        for r in self.rules[tier]:
            if r.matches(scene, output, unit):
                return r.tolerance, f"{self.path.name} [[{tier}.rule]] #{r.index + 1}"
        u = unit or ""
        table = self.by_unit[tier]
        if u in table:
            return table[u], f"{self.path.name} [{tier}] {u}"
        if "default" in table:
            return table["default"], f"{self.path.name} [{tier}] default"
        raise BadInput(no_tolerance_message(self.path, tier, scene, output, unit))


def no_tolerance_message(path: Path, tier: str, scene: str, output: str, unit: str | None) -> str:
    """What to do when the table at ``path`` has no tolerance for an output: give one in the user's
    own table with ``--tolerances FILE`` (never edit the installed package's file; no tolerance is
    made up for a unit the table does not know)."""
    u = unit or ""
    where = "the packaged tolerance table" if Path(path).resolve() == PACKAGED_TOLERANCES else str(path)
    return (f"scene {scene}: no tolerance for output {output} (unit {unit or 'none'!r}) in [{tier}] of "
            f"{where}: give a tolerance for it with --tolerances FILE, your own table (a copy of "
            f"{PACKAGED_TOLERANCES.name} with the key {u or 'default'!r} in [{tier}], or a [[{tier}.rule]] "
            f"with outputs = [{output!r}])")


def _positive_float(v, where: str, path: Path) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
        raise BadInput(f"{path}: {where} must be a positive finite number, got {v!r}")
    return float(v)


def _str_list(v, where: str, path: Path) -> tuple[str, ...]:
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not v or not all(isinstance(x, str) for x in v):
        raise BadInput(f"{path}: {where} must be a string or a non-empty list of strings, got {v!r}")
    return tuple(v)


def tolerance_file(path) -> Path:
    """The tolerance table to read: ``path``; the default ``ci/tolerances.toml`` when it does not
    exist falls back to :data:`PACKAGED_TOLERANCES` (a file given explicitly must exist)."""
    path = Path(path)
    if path == DEFAULT_TOLERANCES and not path.is_file():
        return PACKAGED_TOLERANCES
    return path


def load_tolerances(path: Path) -> ToleranceTable:
    """Read and check ``ci/tolerances.toml`` (see the file for its layout)."""
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise BadInput(f"{path}: cannot read the tolerance table: {exc}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise BadInput(f"{path}: invalid TOML: {exc}") from exc
    unknown = set(doc) - set(TIERS)
    if unknown:
        raise BadInput(f"{path}: unknown table(s) {', '.join(sorted(unknown))} (allowed: {', '.join(TIERS)})")
    by_unit, rules = {}, {}
    for tier in TIERS:
        t = doc.get(tier)
        if not isinstance(t, dict):
            raise BadInput(f"{path}: missing table [{tier}]")
        by_unit[tier], rules[tier] = {}, []
        for key, val in t.items():
            if key == "rule":
                if not isinstance(val, list):
                    raise BadInput(f"{path}: {tier}.rule must be an array of tables ([[{tier}.rule]])")
                for i, r in enumerate(val):
                    where = f"{tier}.rule[{i}]"
                    extra = set(r) - {"scenes", "outputs", "units", "tolerance", "why"}
                    if extra:
                        raise BadInput(f"{path}: {where}: unknown key(s) {', '.join(sorted(extra))} (allowed: "
                                       "scenes, outputs, units, tolerance, why)")
                    if not isinstance(r.get("why"), str) or not r["why"].strip():
                        raise BadInput(f"{path}: {where}: a rule needs 'why' (the measurement that justifies it)")
                    rules[tier].append(Rule(
                        tier, i, _positive_float(r.get("tolerance"), f"{where}.tolerance", path), r["why"].strip(),
                        _str_list(r.get("scenes", "*"), f"{where}.scenes", path),
                        _str_list(r.get("outputs", "*"), f"{where}.outputs", path),
                        _str_list(r["units"], f"{where}.units", path) if "units" in r else None))
            else:
                by_unit[tier][key] = _positive_float(val, f"{tier}.{key}", path)
    return ToleranceTable(path, by_unit, rules)


# ---------------------------------------------------------------------------------------------
# results

@dataclass
class Finding:
    """One output over its tolerance."""
    scene: str
    output: str
    unit: str | None
    kind: str
    reaction_unique: bool | None
    max_abs: float
    t_max: float
    first_exceed: float | None
    tolerance: float
    source: str  # where the tolerance is stated
    tier: str
    cross_tolerance: float | None = None  # the cross-platform tolerance of the output (same tier only)

    def output_class(self) -> int:
        """0 position/angle/other, 1 unique reaction, 2 non-unique reaction (printing order)."""
        if self.kind != "reaction":
            return 0
        return 1 if self.reaction_unique else 2

    def describe(self) -> str:
        u = f" {self.unit}" if self.unit else ""
        what = self.kind
        if self.kind == "reaction" and self.reaction_unique is not None:
            what = ("reaction, unique" if self.reaction_unique else
                    "reaction NOT unique: compared for this fixed elimination")
        first = "" if self.first_exceed is None else f"; first over tolerance at t = {self.first_exceed:g} s"
        text = (f"{self.scene}: {self.output} ({self.unit or 'no unit'}, {what}) differs from the baseline by "
                f"{self.max_abs:.3g}{u} (largest at t = {self.t_max:g} s{first}); tolerance {self.tolerance:.3g}{u} "
                f"[{self.source}]")
        if self.cross_tolerance is not None and self.max_abs <= self.cross_tolerance:
            text += (f" -- below the cross-platform tolerance {self.cross_tolerance:.3g}{u}: as large as a change "
                     "of rounding alone; if the code change is intended, regenerate")
        return text


@dataclass
class SceneCheck:
    scene: str
    status: str  # ok, regression, input
    messages: list[str] = field(default_factory=list)
    findings: list[Finding] = field(default_factory=list)
    comparison: object = None  # overcon.tooling.compare.Comparison
    tier: str = ""
    seconds: float = 0.0
    bit_identical: bool = False


@dataclass
class Outcome:
    code: int
    checks: dict  # scene -> SceneCheck
    problems: list[str] = field(default_factory=list)  # bad input not tied to a run
    report: Path | None = None
    seconds: dict = field(default_factory=dict)

    def messages(self) -> list[str]:
        out = list(self.problems)
        for c in self.checks.values():
            out.extend(c.messages)
        return out


# ---------------------------------------------------------------------------------------------
# build, validate, run

def _build(names: list[str], scenes: dict[str, Path], fmu_dir: Path) -> tuple[dict[str, Path], dict[str, list[str]]]:
    """FMU per scene (pre-check verdicts go to the build log only); problems per scene."""
    from ..fmu.build import build_all

    log: list[str] = []
    fmu_dir.mkdir(parents=True, exist_ok=True)
    _, results = build_all([scenes[n] for n in names], fmu_dir, allow_nonunique=True, refs=False,
                           validate=False, echo=log.append, echo_err=log.append)
    (fmu_dir / "build.log").write_text("\n".join(log) + "\n", encoding="utf-8")
    by_file = {str(scenes[n]): n for n in names}
    fmus, problems = {}, {}
    for r in results:
        n = by_file.get(r.source)
        if n is None:
            continue
        if r.status == "built":
            fmus[n] = r.fmu
        else:
            problems[n] = [f"{n}: build {r.status}: " + "; ".join(r.messages)]
    return fmus, problems


def _validate(fmu: Path) -> list[str]:
    from fmpy.validation import validate_fmu

    return [str(p) for p in validate_fmu(str(fmu))]


def _run(jobs_list, out_dir: Path, jobs: int) -> dict:
    """jobs_list: [(FmuInfo, Experiment)], longest first. Returns model -> (csv, seconds inside
    simulate_fmu) or the error text.
    One ``run_fmus`` call per FMU so that a failure stays with its scene."""
    from . import InputError, SimulationFailed
    from .run import run_fmus

    out_dir.mkdir(parents=True, exist_ok=True)

    def one(item):
        info, ex = item
        csv = out_dir / f"{info.model}.csv"
        csv.unlink(missing_ok=True)
        try:
            r = run_fmus([info], out_dir, jobs=1, progress=False, echo=lambda s: None,
                         experiments={info.model: ex})
            return info.model, (r[0].csv, r[0].sim_seconds)
        except (SimulationFailed, InputError) as exc:
            return info.model, str(exc)

    with ThreadPoolExecutor(max(1, min(jobs, len(jobs_list) or 1))) as pool:
        return dict(pool.map(one, jobs_list))


def _experiment(start: float, stop: float, step: float):
    from .run import Experiment

    return Experiment(float(start), float(stop), float(step))


def _check_baseline_grid(ref, opt: dict, csv_path: Path) -> None:
    start, stop, step = opt["StartTime"], opt["StopTime"], opt["StepSize"]
    if not (math.isfinite(step) and step > 0 and stop > start):
        raise BadInput(f"{csv_path.with_suffix('.opt')}: StartTime/StopTime/StepSize {start}/{stop}/{step} invalid")
    n = int(round((stop - start) / step))
    grid = start + step * np.arange(n + 1)
    if len(ref.time) != len(grid) or not np.allclose(ref.time, grid, rtol=0, atol=1e-9 * step):
        raise BadInput(f"{csv_path}: its time column ({len(ref.time)} points, t = {ref.time[0]:g}..{ref.time[-1]:g} s) "
                       f"is not the grid of its .opt (t = {start:g}..{stop:g} s every {step:g} s): regenerate it")


# ---------------------------------------------------------------------------------------------
# comparison

def compare_scene(scene: str, info, result, ref, ref_path: Path, table: ToleranceTable, tier: str) -> SceneCheck:
    """``compare_reference`` (library reference mode: every common output decides), then the
    per-output tolerances of ``table`` for ``tier`` and the reaction-uniqueness marks."""
    from .compare import compare_reference

    c = compare_reference(info, result, ref, ref_path, tolerance=1.0)  # tolerances replaced below
    ref_s, res_s = c.series
    check = SceneCheck(scene, "ok", comparison=c, tier=tier)
    meta = {o.name: o for o in info.outputs}
    for d in c.diffs:
        o = meta.get(d.name)
        tol, source = table.lookup(tier, scene, d.name, d.unit)
        dev = np.abs(res_s.values[d.name] - ref_s.values[d.name])
        if not np.all(np.isfinite(res_s.values[d.name])):
            dev = np.where(np.isfinite(dev), dev, np.inf)
        d.max_abs = float(np.max(dev))
        d.tolerance = tol
        over = np.nonzero(dev > tol)[0]
        d.first_exceed = float(ref_s.time[over[0]]) if len(over) else None
        if d.kind == "reaction" and o is not None:
            d.reaction_unique = info.reaction_unique.get(o.joint)
        if not d.within:
            cross = table.lookup("cross_platform", scene, d.name, d.unit)[0] if tier == "same_platform" else None
            check.findings.append(Finding(scene, d.name, d.unit, d.kind, d.reaction_unique, d.max_abs,
                                          float(ref_s.time[int(np.argmax(dev))]), d.first_exceed, tol, source,
                                          tier, cross))
    check.bit_identical = all(d.max_abs == 0.0 for d in c.diffs)
    check.findings.sort(key=lambda f: (f.output_class(), -(f.max_abs / f.tolerance)))
    return check


def _ok_line(check: SceneCheck) -> str:
    c = check.comparison
    n_nonunique = sum(1 for d in c.diffs if d.kind == "reaction" and d.reaction_unique is False)
    nu = f"; {n_nonunique} of them non-unique reactions, compared too" if n_nonunique else ""
    if check.bit_identical:
        how = "bit-identical"
    else:
        w = max(c.diffs, key=lambda d: d.max_abs / d.tolerance)
        how = (f"largest difference {w.max_abs:.2g} {w.unit or ''} in {w.name} = "
               f"{w.max_abs / w.tolerance:.2g} of its tolerance")
    return (f"ok   {check.scene}: {len(c.diffs)} outputs within tolerance ({check.tier}{nu}), {how} "
            f"[{check.seconds:.1f} s]")


def _report(outcome: Outcome, out: Path, title: str) -> Path:
    from .report import console_table

    lines = [f"# {title}", ""]
    if outcome.problems:
        lines += ["## Bad input", ""] + [f"- {p}" for p in outcome.problems] + [""]
    lines += ["## Scenes", "", "| scene | result | tier | outputs | seconds |", "|---|---|---|---|---|"]
    for c in outcome.checks.values():
        n = len(c.comparison.diffs) if c.comparison is not None else 0
        res = {"ok": "ok" + (" (bit-identical)" if c.bit_identical else ""), "regression": "**REGRESSION**",
               "input": "**bad input**"}[c.status]
        lines.append(f"| {c.scene} | {res} | {c.tier or '—'} | {n} | {c.seconds:.1f} |")
    lines.append("")
    for c in outcome.checks.values():
        lines += [f"## {c.scene}", ""]
        lines += [f"- {m}" for m in (c.messages if c.status != "ok" else [])]
        if c.comparison is not None:
            lines += ["", "```", console_table(c.comparison), "```", ""]
    p = out / "report.md"
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p


# ---------------------------------------------------------------------------------------------
# the check

@dataclass
class _Regress:
    """One regression check's settings and its growing :class:`Outcome` (the stages below share it)."""

    mechanisms: Path
    baselines: Path
    out: Path
    jobs: int
    tier: str | None
    echo: object
    outcome: Outcome
    table: ToleranceTable | None = None
    scenes: dict = field(default_factory=dict)  # all scenes found: name -> scene file
    provenance: dict = field(default_factory=dict)
    here: str = ""

    def bad(self, msg: str) -> None:
        self.outcome.problems.append(msg)
        self.echo(f"BAD INPUT {msg}")

    def fail(self, check: SceneCheck, status: str, msg: str, label: str) -> None:
        check.status = status
        check.messages.append(msg)
        self.echo(f"{label} {msg}")


def regress(scenes: list[str] | None = None, *, mechanisms=DEFAULT_MECHANISMS, baselines=DEFAULT_BASELINES,
            tolerances=DEFAULT_TOLERANCES, out=DEFAULT_OUT, jobs: int | None = None, tier: str | None = None,
            echo=_echo) -> Outcome:
    """Build, validate, run and compare the selected scenes (all when None) against their
    baselines; every message goes through ``echo``. ``tier`` forces a tolerance tier (default: per
    scene from the platform fingerprint). Never raises for bad input: see ``Outcome.code``.
    Stages: inputs, baselines present, build and validate, run and compare, summary."""
    t0 = time.perf_counter()
    r = _Regress(Path(mechanisms), Path(baselines), Path(out), jobs or os.cpu_count() or 2, tier, echo,
                 Outcome(EXIT_OK, {}))
    names = _regress_inputs(r, scenes, tolerance_file(tolerances))
    if names is None:
        return r.outcome
    ready = _baselines_present(r, names, full_set=not scenes)
    t_build = time.perf_counter()
    fmus, build_problems = _build(ready, r.scenes, r.out / "fmus") if ready else ({}, {})
    todo = [item for item in (_prepare_scene(r, n, fmus, build_problems) for n in ready) if item is not None]
    t_build = time.perf_counter() - t_build
    t_run = time.perf_counter()
    todo.sort(key=lambda x: (-(x[4].stop - x[4].start), -len(x[1].friction)))  # longest first
    csvs = _run([(x[1], x[4]) for x in todo], r.out / "results", r.jobs) if todo else {}
    t_run = time.perf_counter() - t_run
    for item in todo:
        _compare_run(r, item, csvs[item[1].model])
    r.outcome.seconds = {"build_validate": t_build, "run_compare": t_run, "total": time.perf_counter() - t0}
    _regress_summary(r)
    return r.outcome


def _regress_inputs(r: _Regress, scenes, tolerances: Path) -> list[str] | None:
    """Tolerances, scenes, the selection and the provenance; None (exit 2) if one is unreadable."""
    try:
        r.table = load_tolerances(tolerances)
        r.scenes, problems = discover_scenes(r.mechanisms)
        names = select_scenes(r.scenes, scenes)
        r.provenance = load_provenance(r.baselines)
    except BadInput as exc:
        r.bad(str(exc))
        r.outcome.code = EXIT_INPUT
        return None
    for p in problems:
        r.bad(p)
    if not r.scenes and not problems:
        r.bad(f"{r.mechanisms}: no scene files (*.toml with a [scene] table)")
    r.here = fingerprint_id(platform_fingerprint())
    return names


def _baselines_present(r: _Regress, names: list[str], full_set: bool) -> list[str]:
    """The scenes of ``names`` that have a baseline (a missing one is reported at once, before any
    build); for the full set, every baseline must belong to a scene."""
    ready: list[str] = []
    for n in names:
        csv, opt = baseline_files(r.baselines, n)
        lacking = [p.name for p in (csv, opt) if not p.is_file()]
        if not lacking:
            ready.append(n)
            continue
        check = SceneCheck(n, "input")
        msg = (f"{n}: no baseline ({', '.join(_rel(r.baselines / x) for x in lacking)} missing): scene "
               f"{_rel(r.scenes[n])} has never been baselined; create it deliberately with\n"
               f"    {regenerate_command([n], r.mechanisms, r.baselines, _table_path(r))}\n"
               f"  then review and commit {_rel(r.baselines)}/{n}_ref.csv, {n}_ref.opt and {PROVENANCE}")
        check.messages.append(msg)
        r.outcome.checks[n] = check
        r.echo(f"MISSING BASELINE {msg}")
    if full_set:
        for f in sorted(r.baselines.glob("*_ref.csv")):
            n = f.name[: -len("_ref.csv")]
            if n not in r.scenes:
                r.bad(f"{_rel(f)}: baseline of scene {n}, which is not in {_rel(r.mechanisms)} (renamed or removed?): "
                      f"delete {n}_ref.csv/{n}_ref.opt (git rm) or restore the scene")
    return ready


def _prepare_scene(r: _Regress, n: str, fmus: dict, build_problems: dict):
    """One built scene: its FMU validated, its baseline read and checked against the FMU's outputs
    and tolerance, its tier chosen. Returns (scene, FmuInfo, baseline, baseline csv, experiment)
    to run, or None (the problem is in its check)."""
    from . import InputError
    from .fmus import inspect_fmu
    from .run import read_series

    check = r.outcome.checks.setdefault(n, SceneCheck(n, "ok"))
    if n in build_problems:
        check.status = "input"
        check.messages += build_problems[n]
        r.echo("BAD INPUT " + "\n  ".join(build_problems[n]))
        return None
    problems_v = _validate(fmus[n])
    if problems_v:
        r.fail(check, "regression", f"{n}: fmpy validate found {len(problems_v)} problem(s) in {fmus[n].name}: "
               + "; ".join(problems_v), "REGRESSION")
        return None
    csv, opt_path = baseline_files(r.baselines, n)
    try:
        opt = read_opt(opt_path)
        ref = read_series(csv)
        _check_baseline_grid(ref, opt, csv)
        info = inspect_fmu(fmus[n])
    except (BadInput, InputError) as exc:
        r.fail(check, "input", f"{n}: {exc}", "BAD INPUT")
        return None
    new = [o for o in info.output_names if o not in ref.values]
    gone = [o for o in ref.names if o not in info.output_names]
    if new or gone:
        parts = ([f"outputs not in the baseline: {', '.join(new)}"] if new else []) + \
                ([f"baseline outputs the FMU no longer has: {', '.join(gone)}"] if gone else [])
        r.fail(check, "regression", f"{n}: the FMU's outputs changed ({'; '.join(parts)}); if intended, "
               f"regenerate: {regenerate_command([n], r.mechanisms, r.baselines, _table_path(r))}", "REGRESSION")
    if "RelTol" in opt and info.tolerance is not None and not math.isclose(opt["RelTol"], info.tolerance):
        check.messages.append(f"{n}: note: the FMU's solver tolerance is {info.tolerance:g}, the baseline's "
                              f"RelTol {opt['RelTol']:g}")
        r.echo(check.messages[-1])
    prov = r.provenance["scenes"].get(n, {})
    check.tier = r.tier or ("same_platform" if prov.get("platform") == r.here else "cross_platform")
    return n, info, ref, csv, _experiment(opt["StartTime"], opt["StopTime"], opt["StepSize"])


def _compare_run(r: _Regress, item, got) -> None:
    """One scene's run (its CSV and seconds, or the failure text) compared with its baseline."""
    from . import InputError
    from .run import read_series

    n, info, ref, csv, ex = item
    check = r.outcome.checks[n]
    if isinstance(got, str):
        r.fail(check, "regression", f"{n}: the simulation failed (the baseline ran to t = {ex.stop:g} s): {got}",
               "REGRESSION")
        return
    got, check.seconds = got
    try:
        res = read_series(got)
        cmp = compare_scene(n, info, res, ref, csv, r.table, check.tier)
    except (BadInput, InputError) as exc:
        r.fail(check, "input", f"{n}: {exc}", "BAD INPUT")
        return
    check.comparison, check.findings, check.bit_identical = cmp.comparison, cmp.findings, cmp.bit_identical
    if check.findings:
        _report_findings(r, check)
    elif check.status == "ok":
        r.echo(_ok_line(check))


def _report_findings(r: _Regress, check: SceneCheck) -> None:
    """A scene's outputs over tolerance: every one into its messages, at most
    MAX_LINES_PER_CLASS per output class echoed (positions first, then unique, then non-unique
    reactions)."""
    check.status = "regression"
    shown = 0
    per_class: dict[int, int] = {}
    for f in check.findings:
        check.messages.append(f.describe())
        k = f.output_class()
        per_class[k] = per_class.get(k, 0) + 1
        if per_class[k] <= MAX_LINES_PER_CLASS:
            r.echo("REGRESSION " + check.messages[-1])
            shown += 1
    if len(check.findings) > shown:
        r.echo(f"REGRESSION {check.scene}: ... and {len(check.findings) - shown} more output(s) over tolerance "
               f"(all in {_rel(r.out / 'report.md')})")


def _regress_summary(r: _Regress) -> None:
    """The exit code, the report and the summary lines."""
    outcome, echo = r.outcome, r.echo
    statuses = [c.status for c in outcome.checks.values()]
    if outcome.problems or "input" in statuses:
        outcome.code = EXIT_INPUT
    elif "regression" in statuses:
        outcome.code = EXIT_REGRESSION
    outcome.report = _report(outcome, r.out, "overcon regression check")
    n_ok = statuses.count("ok")
    n_reg = statuses.count("regression")
    n_bad = statuses.count("input") + len(outcome.problems)
    tiers = sorted({c.tier for c in outcome.checks.values() if c.tier})
    echo(f"regress: {n_ok} scene(s) match their baselines, {n_reg} regression(s), {n_bad} bad input(s) "
         f"[tolerance tier: {', '.join(tiers) or '—'}; platform {r.here}]; build+validate "
         f"{outcome.seconds['build_validate']:.1f} s, runs {outcome.seconds['run_compare']:.1f} s "
         f"({r.jobs} process(es)), total {outcome.seconds['total']:.1f} s; report {_rel(outcome.report)}")
    if outcome.code == EXIT_REGRESSION:
        echo("regress: FAILED. If the change is intended, regenerate deliberately: "
             + regenerate_command(sorted(n for n, c in outcome.checks.items() if c.status == "regression"),
                                  r.mechanisms, r.baselines, _table_path(r)))


# ---------------------------------------------------------------------------------------------
# regeneration (deliberate, by hand)

def regenerate(scenes: list[str] | None = None, *, mechanisms=DEFAULT_MECHANISMS, baselines=DEFAULT_BASELINES,
               out=DEFAULT_OUT, jobs: int | None = None, stop_time: float | None = None,
               step: float | None = None, tolerances=DEFAULT_TOLERANCES, echo=_echo) -> Outcome:
    """Write the baselines of the selected scenes (all when None); see the module docstring. A
    scene with an output that the tolerance table (``tolerances``, as in :func:`regress`) has no
    tolerance for in some tier gets no baseline (exit 2): every later check of it would fail."""
    t0 = time.perf_counter()
    mechanisms, baselines, out = Path(mechanisms), Path(baselines), Path(out)
    jobs = jobs or os.cpu_count() or 2
    outcome = Outcome(EXIT_OK, {})
    for v, flag in ((stop_time, "--stop-time"), (step, "--step")):
        if v is not None and not (math.isfinite(v) and v > 0):
            outcome.problems.append(f"{flag} {v!r}: must be a positive finite number")
    try:
        all_scenes, problems = discover_scenes(mechanisms)
        names = select_scenes(all_scenes, scenes)
        provenance = load_provenance(baselines)
        table = load_tolerances(tolerance_file(tolerances))
    except BadInput as exc:
        outcome.problems.append(str(exc))
        problems, names = [], []
    outcome.problems += problems
    if outcome.problems:
        for p in outcome.problems:
            echo(f"BAD INPUT {p}")
        outcome.code = EXIT_INPUT
        return outcome
    fmus, build_problems = _build(names, all_scenes, out / "fmus")
    todo = [x for x in (_regenerate_plan(outcome, n, fmus, build_problems, baselines, stop_time, step, table)
                        for n in names) if x is not None]
    for c in outcome.checks.values():
        for m in c.messages:
            echo(("BAD INPUT " if c.status == "input" else "FAILED ") + m)
    todo.sort(key=lambda x: (-(x[2].stop - x[2].start), -len(x[1].friction)))
    csvs = _run([(x[1], x[2]) for x in todo], out / "results", jobs) if todo else {}
    fid = _write_baselines(outcome, todo, csvs, baselines, provenance, echo)
    save_provenance(baselines, provenance)
    statuses = [c.status for c in outcome.checks.values()]
    outcome.code = EXIT_INPUT if "input" in statuses else EXIT_REGRESSION if "regression" in statuses else EXIT_OK
    outcome.seconds = {"total": time.perf_counter() - t0}
    echo(f"regenerate: {statuses.count('ok')} baseline(s) written to {_rel(baselines)} in "
         f"{outcome.seconds['total']:.1f} s (platform {fid}); review the changes above and `git diff "
         f"--stat {_rel(baselines)}` before committing")
    return outcome


def _regenerate_plan(outcome: Outcome, n: str, fmus: dict, build_problems: dict, baselines: Path,
                     stop_time: float | None, step: float | None, table: ToleranceTable):
    """(scene, FmuInfo, Experiment) to run for a new baseline, or None (the reason in its check)."""
    from . import InputError
    from .fmus import inspect_fmu

    check = outcome.checks[n] = SceneCheck(n, "ok")
    if n in build_problems:
        check.status, check.messages = "input", build_problems[n]
        return None
    problems_v = _validate(fmus[n])
    if problems_v:
        check.status = "regression"
        check.messages.append(f"{n}: fmpy validate found problems, baseline NOT written: " + "; ".join(problems_v))
        return None
    csv, opt_path = baseline_files(baselines, n)
    try:
        info = inspect_fmu(fmus[n])
        old = read_opt(opt_path) if opt_path.is_file() else {}
    except (BadInput, InputError) as exc:
        check.status = "input"
        check.messages.append(f"{n}: {exc}")
        return None
    for o in info.outputs:
        for tier in TIERS:
            try:
                table.lookup(tier, n, o.name, o.unit)
            except BadInput as exc:
                check.status = "input"
                check.messages.append(f"{n}: baseline NOT written: {exc}")
    if check.status == "input":
        return None
    start = info.start
    stop = stop_time if stop_time is not None else old.get("StopTime", info.stop)
    h = step if step is not None else old.get("StepSize", BASELINE_STEP)
    if stop <= start:
        check.status = "input"
        check.messages.append(f"{n}: stop time {stop:g} s is not after the start time {start:g} s")
        return None
    return n, info, _experiment(start, stop, h)


def _write_baselines(outcome: Outcome, todo, csvs, baselines: Path, provenance: dict, echo) -> str:
    """Copy each finished run to its baseline (with its .opt and provenance); returns the
    platform's fingerprint id."""
    fp = platform_fingerprint()
    fid = fingerprint_id(fp)
    baselines.mkdir(parents=True, exist_ok=True)
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    for n, info, ex in todo:
        check = outcome.checks[n]
        got = csvs[info.model]
        if isinstance(got, str):
            check.status = "regression"
            check.messages.append(f"{n}: the simulation failed, baseline NOT written: {got}")
            echo("FAILED " + check.messages[-1])
            continue
        got = got[0]
        csv, opt_path = baseline_files(baselines, n)
        change = _baseline_change(csv, got, ex, info) if csv.is_file() else "new baseline"
        shutil.copyfile(got, csv)
        write_opt(opt_path, ex.start, ex.stop, ex.step, info.tolerance)
        provenance["platforms"][fid] = fp
        provenance["scenes"][n] = {"platform": fid, "generated": now, "fmu_guid": info.path and _guid(info.path),
                                   "stop_time": ex.stop, "step": ex.step}
        check.messages.append(f"{n}: wrote {_rel(csv)} ({csv.stat().st_size // 1024} KiB, t = {ex.start:g}..{ex.stop:g} s "
                              f"every {ex.step:g} s): {change}")
        echo(check.messages[-1])
    return fid


def _baseline_change(csv: Path, got: Path, ex, info) -> str:
    """How far the new run moved from the old baseline, in words."""
    from . import InputError
    from .run import read_series

    try:
        old, new = read_series(csv), read_series(got)
    except InputError:
        return "replaced (the old file was unreadable)"
    if not (len(old.time) == len(new.time) and np.allclose(old.time, new.time, rtol=0, atol=1e-9 * ex.step)):
        return "replaced (different grid)"
    common = [x for x in new.names if x in old.values]
    diffs = {x: float(np.max(np.abs(new.values[x] - old.values[x]))) for x in common}
    units = {o.name: o.unit for o in info.outputs}
    if not diffs or max(diffs.values()) == 0.0:
        change = "unchanged (bit-identical)"
    else:
        w = max(diffs, key=diffs.get)
        change = f"changed: largest {diffs[w]:.3g} {units.get(w) or ''} in {w}"
        for u in ("m", "rad", "N", "N.m"):
            du = [d for x, d in diffs.items() if units.get(x) == u]
            if du:
                change += f"; max {max(du):.3g} {u}"
    added = [x for x in new.names if x not in old.values]
    if added:
        change += f"; new outputs {', '.join(added)}"
    return change


def _guid(fmu: Path) -> str:
    import zipfile

    try:
        with zipfile.ZipFile(fmu) as zf:
            return json.loads(zf.read("resources/overcon_fmu.json")).get("guid", "")
    except (KeyError, ValueError, OSError, zipfile.BadZipFile):
        return ""




# ---------------------------------------------------------------------------------------------
# JUnit XML (what GitHub, GitLab and Jenkins display)

def write_junit(outcome: Outcome, path, *, suite: str = "overcon regress") -> Path:
    """Write ``outcome`` as JUnit XML: one ``testcase`` per scene (classname ``overcon.regress``,
    its run's seconds), with a ``failure`` for a regression (message: the scene and its outputs
    over tolerance; text: every finding) and an ``error`` for bad input; bad input not tied to a
    scene (an orphan baseline, an unreadable file) is one more test case, ``(input)``, in error."""
    from xml.etree import ElementTree as ET

    cases = []
    for c in outcome.checks.values():
        case = ET.Element("testcase", classname="overcon.regress", name=c.scene, time=f"{c.seconds:.3f}")
        if c.status == "regression":
            outputs = ", ".join(f.output for f in c.findings) or "see the text"
            el = ET.SubElement(case, "failure", type="regression",
                               message=f"{c.scene}: differs from its baseline in {outputs}")
            el.text = "\n".join(c.messages)
        elif c.status == "input":
            el = ET.SubElement(case, "error", type="bad input", message=(c.messages or ["bad input"])[0][:500])
            el.text = "\n".join(c.messages)
        cases.append(case)
    if outcome.problems:
        case = ET.Element("testcase", classname="overcon.regress", name="(input)", time="0")
        el = ET.SubElement(case, "error", type="bad input", message=outcome.problems[0][:500])
        el.text = "\n".join(outcome.problems)
        cases.append(case)
    failures = sum(1 for c in cases if c.find("failure") is not None)
    errors = sum(1 for c in cases if c.find("error") is not None)
    total = f"{outcome.seconds.get('total', 0.0):.3f}"
    attrs = dict(name=suite, tests=str(len(cases)), failures=str(failures), errors=str(errors), time=total)
    root = ET.Element("testsuites", **attrs)
    ts = ET.SubElement(root, "testsuite", **attrs)
    ts.extend(cases)
    ET.indent(root)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path
