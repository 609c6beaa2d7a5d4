"""Simulate FMUs with ``fmpy.simulate_fmu`` and exchange results as FMI cross-check CSV files.

Each FMU runs in its own worker process (``python -m overcon.tooling.run``), at most ``jobs`` at a
time. Reasons: the runs are independent and CPU bound (2 processes halve the wall time on 2
cores), and an FMU is foreign native code: FMUs of other tools may crash the process that loads
them (pythonfmu 0.7's wrapper, for one, corrupts the heap at exit about 1 exit in 6), and fmpy
keeps a pointer to the last ``logger`` callback after ``simulate_fmu`` returns. A worker writes
its CSV, reports on stdout and leaves with ``os._exit``, so no such crash reaches the overcon
process or changes an exit code.

Grid: the output interval of ``simulate_fmu`` is the step (default: the FMU's DefaultExperiment
stepSize), the stop time defaults to the FMU's DefaultExperiment stopTime. Outputs are the FMU's
Real outputs; the CSV (``<model>.csv``: quoted header ``"time"`` + output names, comma separated,
shortest round-trip ``repr`` of every value, i.e. full double precision) is written with
``fmpy.util.write_csv`` and read back with ``fmpy.util.read_csv``.

A run that raises, or whose last output time is before the stop time (fmpy ends a co-simulation
quietly when the FMU discards a step), is a :class:`SimulationFailed` carrying the FMU's logged
reason.

Uniqueness along the motion (``along=True``: the runs of ``compare`` and ``reproduce``): an FMU
that publishes the discrete outputs ``rank`` (Integer), ``motion_unique`` and
``<joint>.reaction_unique`` (Boolean, :func:`along_outputs`) has them recorded at every output
point into ``<model>.along.csv`` beside ``<model>.csv`` (``"time"``, then those columns as
integers, Booleans as 0/1). Decided: a file of their own, so that ``<model>.csv`` keeps exactly
its Real columns: ``fmpy.util.read_csv`` (and :func:`read_series`) cannot read fmpy's ``True``
and ``False`` literals, so Boolean columns in it would break its readers. A run that fails still
writes that file when the FMU instance can still be read: the points before the failure, then one
row at the end of the failed communication step with the values the FMU holds after the failure
(its verdicts at the instant the run stopped). ``overcon run`` does not record them (its files
are unchanged)."""
from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import subprocess
import tempfile
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..params import MAX_OUTPUT_POINTS, check_param
from . import InputError, SimulationFailed
from .fmus import FmuInfo, interface, type_name

RESULT_TAG = "OVERCON-RESULT "
ALONG_SUFFIX = ".along.csv"  # <model>.along.csv: the discrete uniqueness outputs (module docstring)
PROGRESS_EVERY = 1.0  # s between progress lines of one FMU


@dataclass(frozen=True)
class Experiment:
    """Run settings: times (s), the output interval ``step`` (s) and FMU parameters to set
    (``start_values``: name/value pairs, e.g. the lockstep grid of :mod:`overcon.verdict`)."""

    start: float
    stop: float
    step: float
    start_values: tuple = ()

    def n_points(self) -> int:
        return int(round((self.stop - self.start) / self.step)) + 1


def experiment(info: FmuInfo, *, stop_time: float | None = None, step: float | None = None) -> Experiment:
    """The run settings of ``info``: command-line values over the FMU's DefaultExperiment."""
    stop = info.stop if stop_time is None else float(stop_time)
    if not (math.isfinite(stop) and stop > info.start):
        raise InputError(f"{info.path}: stop time {stop!r} must be finite and after the start time {info.start!r}")
    h = step if step is not None else info.step
    if h is None:
        h = (stop - info.start) / 500.0
    h = float(h)
    if not (math.isfinite(h) and h > 0):
        raise InputError(f"{info.path}: step {h!r} must be a positive finite number")
    n = (stop - info.start) / h + 1
    if not n <= MAX_OUTPUT_POINTS:
        raise InputError(f"{info.path}: step {h:g} s from {info.start:g} to {stop:g} s gives {n:.3g} output points; "
                         f"at most {MAX_OUTPUT_POINTS:.0e} (each is one fmi2DoStep and one CSV row): use a larger "
                         "--step or a shorter --stop-time")
    return Experiment(info.start, stop, h)


def parse_settings(texts) -> dict[str, str]:
    """``["solver.method=radau", "joint4.mu=0.2"]`` (``--set``) -> {name: text}; :class:`InputError`
    naming the bad item."""
    out: dict[str, str] = {}
    for text in texts or ():
        name, sep, value = str(text).partition("=")
        name, value = name.strip(), value.strip()
        if not sep or not name or not value:
            raise InputError(f"--set {text!r}: expected NAME=VALUE, e.g. --set solver.method=radau")
        if name in out:
            raise InputError(f"--set {name}: given twice")
        out[name] = value
    return out


_CONVERT = {"Real": float, "Integer": int, "String": str,
            "Boolean": lambda v: {"true": True, "1": True, "false": False, "0": False}[v.lower()]}


def start_values_for(info: FmuInfo, settings: dict[str, str]) -> dict:
    """The ``--set`` values typed for ``info``'s parameters; :class:`InputError` naming the FMU and
    the parameter when it has no such parameter, the value does not fit its type, or (an overcon
    FMU) the value is outside the parameter's rule in :mod:`overcon.params` (the same rule the FMU
    applies, so the run is refused before anything starts rather than failing in it; another
    tool's FMU checks its ranges itself)."""
    out = {}
    for name, text in settings.items():
        typ = info.parameters.get(name)
        if typ not in _CONVERT:
            known = ", ".join(sorted(info.parameters)[:12]) or "none"
            raise InputError(f"{info.path}: --set {name}: no such parameter (parameters: {known}"
                             f"{', ...' if len(info.parameters) > 12 else ''})")
        try:
            out[name] = _CONVERT[typ](text)
        except (ValueError, KeyError) as exc:
            raise InputError(f"{info.path}: --set {name}={text}: not a valid {typ} value") from exc
        if info.motion_unique is not None:  # an overcon FMU: its parameters obey overcon.params
            try:
                reason = check_param(name, out[name])
            except KeyError:  # a parameter without a rule (none today)
                reason = None
            if reason is not None:
                raise InputError(f"{info.path}: --set {name}={text}: {reason}")
    return out


@dataclass
class Series:
    """A result: ``time`` (k,) and ``values`` name -> (k,) arrays, in file/FMU order."""

    time: np.ndarray
    values: dict

    @property
    def names(self) -> list[str]:
        return list(self.values)


@dataclass
class RunResult:
    info: FmuInfo
    csv: Path
    rows: int
    sim_seconds: float  # inside simulate_fmu
    wall_seconds: float  # the worker process, start to end
    series: Series | None = None


# ---------------------------------------------------------------------------------------------
# in process (the worker's body)

STABLE_STEP = "solver.stable_step"
"""The overcon FMU's variable that holds, after a failed fmi2DoStep, the stable step rk4 named."""


@contextlib.contextmanager
def _instance(fmu, logger):
    """(path for simulate_fmu, model description, FMU instance or None, a function returning
    ``solver.stable_step`` or None). An FMU with that variable is extracted and instantiated here,
    so that after a failed run the variable can still be read from the instance (as data, not
    from the log's prose); any other FMU is left to simulate_fmu."""
    import fmpy

    md = fmpy.read_model_description(str(fmu))
    vr = next((v.valueReference for v in md.modelVariables if v.name == STABLE_STEP), None)
    if vr is None:
        yield str(fmu), None, None, lambda: None
        return
    tmp = None if Path(fmu).is_dir() else tempfile.mkdtemp(prefix="overcon-run-")
    where = str(fmu) if tmp is None else fmpy.extract(str(fmu), tmp)
    instance = fmpy.instantiate_fmu(where, md, interface(md), debug_logging=True, logger=logger)
    get = instance.getFloat64 if md.fmiVersion.startswith("3") else instance.getReal

    def stable_step():
        try:
            value = float(get([vr])[0])
        except Exception:  # noqa: BLE001 -- the instance may be unusable after the failure
            return None
        return value if value > 0.0 else None

    try:
        yield where, md, instance, stable_step
    finally:
        instance.freeInstance()
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)

def along_outputs(md) -> list[str]:
    """The discrete uniqueness outputs of the model description ``md`` (fmpy's): ``rank``,
    ``motion_unique`` (when discrete), then every discrete ``<joint>.reaction_unique`` in the
    model's order; [] for an FMU without the Integer output ``rank`` (built before they were
    judged along the motion, where they are constants, or another tool's)."""
    outs = {v.name: v for v in md.modelVariables if v.causality == "output" and v.variability == "discrete"}
    if "rank" not in outs or type_name(outs["rank"]) != "Integer":
        return []
    flags = [n for n, v in outs.items() if type_name(v) == "Boolean"]
    return ["rank"] + [n for n in flags if n == "motion_unique"] + [n for n in flags if n.endswith(".reaction_unique")]


def along_path(csv: str | Path) -> Path:
    """``<model>.along.csv`` beside the run's ``<model>.csv``."""
    csv = Path(csv)
    stem = csv.name[: -len(".csv")] if csv.name.endswith(".csv") else csv.name
    return csv.with_name(stem + ALONG_SUFFIX)


def _write_along(path: Path, result, names: list[str], held: dict | None = None, step: float = 0.0) -> None:
    """The along file (module docstring): ``result``'s rows of ``names`` as integers, then, when
    ``held`` (name -> value after a failure) is given, one row at the last time + ``step``."""
    rows = [[float(r["time"])] + [int(r[n]) for n in names] for r in result]
    if held is not None:
        t = rows[-1][0] + step if rows else float("nan")
        rows.append([t] + [int(held[n]) for n in names])
    part = path.with_name(path.name + ".part")
    with open(part, "w", encoding="utf-8") as f:
        f.write(",".join(f'"{n}"' for n in ["time", *names]) + "\n")
        for r in rows:
            f.write(",".join([repr(r[0]), *map(str, r[1:])]) + "\n")
    os.replace(part, path)


def _held(instance, md, names: list[str]) -> dict | None:
    """The values of ``names`` an FMU instance holds (after a failed step), or None when it cannot
    be read any more."""
    if instance is None or not names:
        return None
    var = {v.name: v for v in md.modelVariables}
    fmi3 = md.fmiVersion.startswith("3")
    try:
        out = {}
        for n in names:
            vr = [var[n].valueReference]
            if n == "rank":
                out[n] = (instance.getInt32 if fmi3 else instance.getInteger)(vr)[0]
            else:
                out[n] = bool(instance.getBoolean(vr)[0])
        return out
    except Exception:  # noqa: BLE001 -- the instance may be unusable after the failure
        return None


_PRINTER: list = []  # fmpy's printLogMessage as an fmi2 logger callback, made once, kept for the process


def _release_logging_proxy() -> None:
    """Point fmpy's native logging proxy back at fmpy's own printer, as fmpy left it at import.
    The proxy keeps the ctypes callback of the last ``logger`` given to ``instantiate_fmu`` or
    ``simulate_fmu`` (FMI 1.0 and 2.0) in one static pointer; that callback is freed with the run's
    FMU object, and the next FMU in the process that logs through fmpy's default callbacks would
    call freed memory (a segmentation fault). The worker leaves with ``os._exit`` right after its
    run; this keeps :func:`simulate` safe when called in process."""
    from ctypes import byref

    from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, printLogMessage
    try:
        from fmpy.logging import addLoggerProxy
    except (ImportError, OSError, AttributeError):  # no proxy library: fmpy installed no proxy either
        return
    if not _PRINTER:
        _PRINTER.append(fmi2CallbackLoggerTYPE(printLogMessage))
    callbacks = fmi2CallbackFunctions()  # read once by the proxy (it copies the logger's address)
    callbacks.logger = _PRINTER[0]
    addLoggerProxy(byref(callbacks))


def simulate(fmu: str | Path, csv: str | Path, *, start: float, stop: float, step: float,
             outputs: list[str], progress: bool = True, label: str = "", start_values: dict | None = None,
             along: bool = False) -> dict:
    """One ``fmpy.simulate_fmu`` run; writes ``csv`` (and with ``along`` the along file, module
    docstring). Returns {rows, sim_seconds, last_time}. Progress lines (``label: 42% ...``) go to
    stderr at most every :data:`PROGRESS_EVERY` s."""
    import fmpy
    from fmpy.util import write_csv

    label = label or Path(fmu).stem
    along_file = along_path(csv)
    along_file.unlink(missing_ok=True)  # never a stale one from an earlier run
    discrete = along_outputs(fmpy.read_model_description(str(fmu), validate=False)) if along else []
    recorder = [None]  # fmpy's recorder, for the points before a failure
    messages: list[str] = []

    def logger(*args):  # FMI 2.0: (env, instance, status, category, message); FMI 3.0: (env, status, ...)
        status, message = args[-3], args[-1]
        if status >= 1:  # warning, discard, error, fatal
            text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
            messages.append(["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"][min(status, 5)] + ": " + text)

    t0 = time.perf_counter()
    last = [None]  # time of the last progress line (first: the first step, after instantiation)

    def step_finished(t, rec):
        recorder[0] = rec
        now = time.perf_counter()
        if last[0] is None:
            last[0] = now
        elif progress and now - last[0] >= PROGRESS_EVERY:
            last[0] = now
            pct = 100.0 * (t - start) / (stop - start)
            print(f"  {label}: {pct:5.1f}% (t = {t:.4g} of {stop:g} s, {now - t0:.0f} s)", file=sys.stderr, flush=True)
        return True

    kw = dict(start_time=start, stop_time=stop, output_interval=step, output=list(outputs) + discrete,
              step_finished=step_finished, start_values=dict(start_values or {}))
    stable = None
    try:
        with _instance(fmu, logger) as (where, md, instance, stable_step):
            try:
                result = fmpy.simulate_fmu(where, model_description=md, fmu_instance=instance, **kw) \
                    if instance is not None else fmpy.simulate_fmu(where, logger=logger, debug_logging=True, **kw)
            except Exception:
                stable = stable_step()
                held = _held(instance, md, discrete)
                if held is not None:  # else no file: its last row would not be the stop's
                    with contextlib.suppress(Exception):  # the failure is what the caller reports
                        done = recorder[0].result() if recorder[0] is not None else []
                        _write_along(along_file, done, discrete, held, step)
                raise
    except Exception as exc:
        why = "; ".join(messages[-3:])
        raise SimulationFailed(f"{fmu}: fmpy.simulate_fmu failed: {type(exc).__name__}: {exc}"
                               + (f" (FMU log: {why})" if why else ""), stable_step=stable) from exc
    finally:
        _release_logging_proxy()
    sim_seconds = time.perf_counter() - t0
    last_time = float(result["time"][-1]) if len(result) else start
    if last_time < stop - 1e-9 * max(1.0, abs(stop)):
        why = "; ".join(messages[-3:]) or "no reason logged"
        raise SimulationFailed(f"{fmu}: the simulation stopped at t = {last_time:g} s, before the stop "
                               f"time {stop:g} s: {why}")
    csv = Path(csv)
    csv.parent.mkdir(parents=True, exist_ok=True)
    part = csv.with_name(csv.name + ".part")
    write_csv(str(part), result, columns=list(outputs))
    os.replace(part, csv)
    if discrete:
        _write_along(along_file, result, discrete)
    return {"rows": len(result), "sim_seconds": sim_seconds, "last_time": last_time}


def _worker(argv: list[str]) -> None:
    """``python -m overcon.tooling.run JSON``: run one FMU, print one result line, ``os._exit``."""
    job = json.loads(argv[0])
    try:
        out = simulate(job["fmu"], job["csv"], start=job["start"], stop=job["stop"], step=job["step"],
                       outputs=job["outputs"], progress=job["progress"], label=job["label"],
                       start_values=job.get("start_values"), along=job.get("along", False))
        out["error"] = ""
    except SimulationFailed as exc:
        out = {"error": str(exc), "stable_step": exc.stable_step}
    except Exception as exc:  # noqa: BLE001 -- reported by the parent
        out = {"error": f"{job['fmu']}: {type(exc).__name__}: {exc}"}
    sys.stdout.write(RESULT_TAG + json.dumps(out) + "\n")
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)  # skip interpreter teardown: a foreign FMU may crash it (module docstring)


# ---------------------------------------------------------------------------------------------
# many FMUs, in worker processes

def _worker_env() -> dict:
    """One BLAS/OpenMP thread per worker (unless set): ``jobs`` workers on as many cores do not
    oversubscribe them."""
    env = dict(os.environ)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(var, "1")
    return env


def run_one(info: FmuInfo, ex: Experiment, csv: Path, progress: bool, timeout: float | None,
            label: str = "", along: bool = False) -> RunResult:
    """Run ``info.path`` (an FMU file or its unzipped directory) in one worker process into
    ``csv`` (``along``: and the along file, module docstring); :class:`SimulationFailed` with the
    FMU's logged reason. Used by :func:`run_jobs` and, one run per Dask task, by
    :mod:`overcon.tooling.sweep`."""
    job = {"fmu": str(info.path), "csv": str(csv), "start": ex.start, "stop": ex.stop, "step": ex.step,
           "outputs": info.output_names, "progress": progress, "label": label or info.model,
           "start_values": dict(ex.start_values), "along": along}
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-m", "overcon.tooling.run", json.dumps(job)],
                              stdout=subprocess.PIPE, stderr=None, text=True, timeout=timeout, env=_worker_env())
    except subprocess.TimeoutExpired as exc:
        raise SimulationFailed(f"{info.path}: no result within {timeout:g} s (killed)") from exc
    wall = time.perf_counter() - t0
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith(RESULT_TAG)]
    if not lines:
        raise SimulationFailed(f"{info.path}: the worker process ended with code {proc.returncode} "
                               "without a result (crashed while running the FMU?)")
    out = json.loads(lines[-1][len(RESULT_TAG):])
    if out["error"]:
        raise SimulationFailed(out["error"], stable_step=out.get("stable_step"))
    return RunResult(info, csv, out["rows"], out["sim_seconds"], wall)


@dataclass(frozen=True)
class Job:
    """One FMU run: ``key`` names it in the results (e.g. the model, or ``lockstep/<model>``)."""

    key: str
    info: FmuInfo
    experiment: Experiment
    csv: Path
    along: bool = False  # record the discrete uniqueness outputs too (module docstring)


def run_jobs(jobs: list[Job], *, workers: int = 2, progress: bool = True, timeout: float | None = None,
             echo=None, announce_failures: bool = True) -> tuple[dict[str, RunResult], dict[str, SimulationFailed]]:
    """Run every job (``workers`` processes at a time, in the order given) and return
    (results by key, failures by key: the reason and, as data, an unstable step's stable step):
    a failed run never stops the others. ``announce_failures``: say "<key>: FAILED (reason below)"
    as a run fails (False: the caller says what happens to it, e.g. a lockstep run repeated at a
    smaller step, :func:`overcon.tooling.pipeline.run_groups`)."""
    echo = echo or (lambda s: print(s, flush=True))
    results: dict[str, RunResult] = {}
    failures: dict[str, SimulationFailed] = {}

    def one(job: Job):
        ex = job.experiment
        try:
            r = run_one(job.info, ex, job.csv, progress, timeout, label=job.key, along=job.along)
        except SimulationFailed as exc:
            failures[job.key] = exc
            if announce_failures:
                echo(f"{job.key}: FAILED (reason below)")
            return
        results[job.key] = r
        echo(f"{job.key}: {r.rows} points, t = {ex.start:g}..{ex.stop:g} s every {ex.step:g} s -> {r.csv}; "
             f"wall {r.sim_seconds:.2f} s simulation, {r.wall_seconds:.2f} s process")

    if jobs:
        with ThreadPoolExecutor(max(1, min(workers, len(jobs)))) as pool:
            list(pool.map(one, jobs))
    return results, failures


def check_unique_models(infos: list[FmuInfo], out_dir: Path) -> None:
    """:class:`InputError` for two FMUs with one model name (they would write one CSV)."""
    seen: dict[str, Path] = {}
    for info in infos:
        if info.model in seen:
            raise InputError(f"{info.path}: model {info.model} also given as {seen[info.model]}: "
                             f"both would write {Path(out_dir) / (info.model + '.csv')}")
        seen[info.model] = info.path


def run_fmus(infos: list[FmuInfo], out_dir, *, stop_time: float | None = None, step: float | None = None,
             jobs: int = 2, progress: bool = True, timeout: float | None = None, echo=None,
             experiments: dict | None = None) -> list[RunResult]:
    """Run every FMU (``jobs`` worker processes at a time) into ``out_dir/<model>.csv``; print one
    line per finished FMU with ``echo``. ``experiments`` (model -> :class:`Experiment`) overrides
    the per-FMU settings. Raises :class:`SimulationFailed` naming every failed FMU (after all
    ran), :class:`InputError` for two FMUs with one model name."""
    out_dir = Path(out_dir)
    check_unique_models(infos, out_dir)
    exps = experiments or {i.model: experiment(i, stop_time=stop_time, step=step) for i in infos}
    out_dir.mkdir(parents=True, exist_ok=True)
    results, failures = run_jobs([Job(i.model, i, exps[i.model], out_dir / f"{i.model}.csv") for i in infos],
                                 workers=jobs, progress=progress, timeout=timeout, echo=echo)
    if failures:
        raise SimulationFailed("\n".join(str(failures[i.model]) for i in infos if i.model in failures))
    return [results[i.model] for i in infos]


# ---------------------------------------------------------------------------------------------
# CSV in

def read_series(path) -> Series:
    """Read a result CSV (FMI cross-check rules: header with ``time`` first, comma separated, one
    row per time) with ``fmpy.util.read_csv``. :class:`InputError` naming the file when it is
    missing or unreadable, has no ``time`` column first, a non-numeric or non-finite value, fewer
    than 2 rows, or times that do not increase."""
    from fmpy.util import read_csv

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such CSV file")
    try:
        data = read_csv(str(path))
    except Exception as exc:  # noqa: BLE001 -- fmpy raises IndexError/ValueError/UnicodeError...
        raise InputError(f"{path}: unreadable CSV (FMI cross-check format expected: header "
                         f"\"time\",\"name\",..., then numbers): {type(exc).__name__}: {exc}") from exc
    names = list(data.dtype.names or ())
    if not names or names[0] != "time":
        raise InputError(f"{path}: the first column must be \"time\", got {names[:1]}")
    if len(data) < 2:
        raise InputError(f"{path}: fewer than 2 rows")
    t = np.asarray(data["time"], dtype=float)
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise InputError(f"{path}: the time column must be finite and strictly increasing")
    values = {}
    for n in names[1:]:
        col = np.asarray(data[n], dtype=float)
        if col.ndim != 1:
            continue  # array columns (not written by overcon) are not compared
        values[n] = col
    return Series(t, values)


if __name__ == "__main__":
    _worker(sys.argv[1:])
