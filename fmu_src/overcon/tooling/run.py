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
import dataclasses
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

from ..outfiles import atomic, atomic_path
from ..params import MAX_OUTPUT_POINTS, check_param
from . import InputError, SimulationFailed
from .fmus import FmuInfo, interface, type_name
from .inputs import InputTable, check_interpolation, read_input_table, write_input_table

RESULT_TAG = "OVERCON-RESULT "
ALONG_SUFFIX = ".along.csv"  # <model>.along.csv: the discrete uniqueness outputs (module docstring)
PROGRESS_EVERY = 1.0  # s between progress lines of one FMU


@dataclass(frozen=True)
class Experiment:
    """Run settings: times (s), the output interval ``step`` (s) and FMU parameters to set
    (``start_values``: name/value pairs, e.g. the lockstep grid of :mod:`overcon.verdict`), the
    input table given to fmpy's ``input=`` (``--input``, :mod:`overcon.tooling.inputs`; None: the
    inputs keep their start values) and how the inputs move within a communication step
    (``interpolation``: "hold", or "linear" with fmpy's ``set_input_derivatives``)."""

    start: float
    stop: float
    step: float
    start_values: tuple = ()
    input_table: InputTable | None = None
    interpolation: str = "hold"

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


def with_inputs(info: FmuInfo, ex: Experiment, table_path=None, interpolation: str = "hold") -> Experiment:
    """``ex`` with the ``--input`` table ``table_path`` read for ``info``'s Real inputs (every one a
    column, no other column; :func:`overcon.tooling.inputs.read_input_table`) and the
    ``--input-interpolation``. :class:`InputError` naming the FMU and the table for a bad table,
    an FMU without inputs, an input also given a start value (``--set``, ``--param``: the table
    would override it), and ``linear`` for an FMU that cannot interpolate inputs (fmpy sets
    input derivatives through ``fmi2SetRealInputDerivatives`` only: FMI 2.0 co-simulation with
    ``canInterpolateInputs="true"``). Without a table, ``ex`` unchanged ("linear" refused: there
    is nothing to interpolate)."""
    check_interpolation(interpolation)
    if table_path is None:
        if interpolation != "hold":
            raise InputError(f"--input-interpolation {interpolation}: given without an --input table")
        return ex
    names = info.real_inputs
    if not names:
        raise InputError(f"{info.path}: --input {table_path}: the FMU has no Real input variable to set")
    try:
        table = read_input_table(table_path, names)
    except InputError as exc:
        raise InputError(f"{info.path}: {exc}") from exc
    clash = [n for n, _ in ex.start_values if n in table.values]
    if clash:
        raise InputError(f"{info.path}: the input {clash[0]} has a start value (--set/--param) and a column in "
                         f"{table_path}: the table sets it at every step; give it in one place")
    if interpolation == "linear" and not info.can_interpolate_inputs:
        why = ("an FMI 3.0 FMU (fmpy sets input derivatives for FMI 2.0 only)" if not info.fmi_version.startswith("2")
               else "its co-simulation interface does not declare canInterpolateInputs=\"true\" (or it has none)")
        raise InputError(f"{info.path}: --input-interpolation linear: the FMU cannot take input derivatives: "
                         f"{why}; use --input-interpolation hold")
    return dataclasses.replace(ex, input_table=table, interpolation=interpolation)


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
    """The ``--set`` values typed for ``info``'s parameters (and inputs: their start values, the
    value they keep when no --input table sets them); :class:`InputError` naming the FMU and
    the parameter when it has no such parameter, the value does not fit its type, or (an overcon
    FMU) the value is outside the parameter's rule in :mod:`overcon.params` (the same rule the FMU
    applies, so the run is refused before anything starts rather than failing in it; another
    tool's FMU checks its ranges itself)."""
    out = {}
    for name, text in settings.items():
        typ = info.parameters.get(name) or info.inputs.get(name)  # an input's start value: set like a parameter
        if typ == "Enumeration":  # an item's name or its value
            items = info.enumerations.get(name, {})
            value = items.get(text, int(text) if text.lstrip("-").isdigit() else None)
            if value not in items.values():
                raise InputError(f"{info.path}: --set {name}={text}: not one of {name}'s items "
                                 f"({', '.join(f'{k} ({v})' for k, v in items.items()) or 'none listed'})")
            out[name] = value
            continue
        if typ not in _CONVERT:
            known = ", ".join(sorted(info.parameters)[:12]) or "none"
            raise InputError(f"{info.path}: --set {name}: no such parameter or input (parameters: {known}"
                             f"{', ...' if len(info.parameters) > 12 else ''}; inputs: "
                             f"{', '.join(info.inputs) or 'none'})")
        try:
            out[name] = _CONVERT[typ](text)
        except (ValueError, KeyError) as exc:
            raise InputError(f"{info.path}: --set {name}={text}: not a valid {typ} value") from exc
        if name in info.inputs:  # an input's start: any finite value (the host's to choose)
            if isinstance(out[name], float) and not math.isfinite(out[name]):
                raise InputError(f"{info.path}: --set {name}={text}: an input's start value must be finite")
            continue
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
def _instance(fmu, logger, unzip_dir=None):
    """(path for simulate_fmu, model description, FMU instance or None, a function returning
    ``solver.stable_step`` or None). An FMU file is unzipped here, under the archive limits
    (:func:`overcon.tooling.fmus.extract`), into ``unzip_dir`` (made and removed by the caller) or a
    temporary directory removed on every way out (success, failure, Ctrl-C). An FMU with that
    variable is instantiated here, so that after a failed run the variable can still be read from
    the instance (as data, not from the log's prose); any other FMU is left to simulate_fmu."""
    import fmpy

    from .fmus import extract

    tmp = None
    instance = None
    try:
        if Path(fmu).is_dir():
            where = str(fmu)
        else:
            if unzip_dir is None:
                unzip_dir = tmp = tempfile.mkdtemp(prefix="overcon-run-")
            where = str(extract(fmu, unzip_dir))
        md = fmpy.read_model_description(where)
        vr = next((v.valueReference for v in md.modelVariables if v.name == STABLE_STEP), None)
        if vr is None:
            yield where, None, None, lambda: None
            return
        instance = fmpy.instantiate_fmu(where, md, interface(md), debug_logging=True, logger=logger)
        get = instance.getFloat64 if md.fmiVersion.startswith("3") else instance.getReal

        def stable_step():
            try:
                value = float(get([vr])[0])
            except Exception:  # noqa: BLE001 -- the instance may be unusable after the failure
                return None
            return value if value > 0.0 else None

        yield where, md, instance, stable_step
    finally:
        if instance is not None:
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


def _write_along(path: Path, result, names: list[str], held: dict | None = None, step: float = 0.0,
                 start: float = 0.0) -> None:
    """The along file (module docstring): ``result``'s rows of ``names`` as integers, then, when
    ``held`` (name -> value after a failure) is given, one row at the last time + ``step`` (at
    ``start`` when the run failed before its first output point: every time in the file is finite)."""
    rows = [[float(r["time"])] + [int(r[n]) for n in names] for r in result]
    if held is not None:
        t = rows[-1][0] + step if rows else float(start)
        rows.append([t] + [int(held[n]) for n in names])
    with atomic(path, "w", encoding="utf-8") as f:
        f.write(",".join(f'"{n}"' for n in ["time", *names]) + "\n")
        for r in rows:
            f.write(",".join([repr(r[0]), *map(str, r[1:])]) + "\n")


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


@contextlib.contextmanager
def _input_derivatives_buffers():
    """fmpy's input derivatives for any number of inputs. fmpy (0.3.32: ``fmpy.simulation.Input``)
    sizes the buffer of the derivatives it passes to ``fmi2SetRealInputDerivatives`` for exactly 9
    inputs, so ``set_input_derivatives=True`` fails with "Can only assign sequence of same size"
    for any other count. For the duration of a run, ``simulate_fmu`` builds its ``Input`` from a
    subclass that sizes each buffer to its inputs (nothing else changes); a fixed fmpy already
    sizes them so and is left alone."""
    import fmpy.simulation as sim

    base = sim.Input

    class Input(base):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            if getattr(self, "t", None) is None:
                return
            self.continuous = [info._replace(derivatives=(info.derivatives._type_ * len(info.vrs))())
                               if len(info.derivatives) != len(info.vrs) else info for info in self.continuous]

    sim.Input = Input
    try:
        yield
    finally:
        sim.Input = base


def _check_fmu_archive(fmu: str | Path) -> None:
    """The archive limits of the zipped FMU ``fmu``, before fmpy reads anything of it."""
    import zipfile

    from .fmus import check_archive
    with zipfile.ZipFile(fmu) as zf:
        check_archive(Path(fmu), zf)


def _message_logger(messages: list[str]):
    """An fmpy logger that appends each warning, discard, error or fatal message of the FMU to
    ``messages`` ("ERROR: text")."""
    def logger(*args):  # FMI 2.0: (env, instance, status, category, message); FMI 3.0: (env, status, ...)
        status, message = args[-3], args[-1]
        if status >= 1:  # warning, discard, error, fatal
            text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
            messages.append(["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"][min(status, 5)] + ": " + text)

    return logger


def _step_callback(recorder: list, label: str, start: float, stop: float, t0: float, progress: bool):
    """fmpy's ``step_finished``: keeps its recorder in ``recorder[0]`` and, with ``progress``,
    prints a progress line to stderr at most every :data:`PROGRESS_EVERY` s (``t0``: the run's
    start on ``time.perf_counter``)."""
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

    return step_finished


def _reached_stop(fmu, result, start: float, stop: float, messages: list[str]) -> float:
    """The last time of fmpy's ``result`` (``start`` when it is empty); :class:`SimulationFailed`
    when it ends before ``stop``, with the FMU's last logged ``messages``."""
    last_time = float(result["time"][-1]) if len(result) else start
    if last_time < stop - 1e-9 * max(1.0, abs(stop)):
        why = "; ".join(messages[-3:]) or "no reason logged"
        raise SimulationFailed(f"{fmu}: the simulation stopped at t = {last_time:g} s, before the stop "
                               f"time {stop:g} s: {why}")
    return last_time


def simulate(fmu: str | Path, csv: str | Path, *, start: float, stop: float, step: float,
             outputs: list[str], progress: bool = True, label: str = "", start_values: dict | None = None,
             along: bool = False, input_table: InputTable | None = None, interpolation: str = "hold",
             unzip_dir: str | None = None) -> dict:
    """One ``fmpy.simulate_fmu`` run; writes ``csv`` (and with ``along`` the along file, module
    docstring). ``input_table`` goes to fmpy's ``input=`` (its structured array), with
    ``set_input_derivatives`` when ``interpolation`` is "linear" (:mod:`overcon.tooling.inputs`).
    Returns {rows, sim_seconds, last_time}. Progress lines (``label: 42% ...``) go to
    stderr at most every :data:`PROGRESS_EVERY` s."""
    import fmpy
    from fmpy.util import write_csv

    label = label or Path(fmu).stem
    along_file = along_path(csv)
    along_file.unlink(missing_ok=True)  # never a stale one from an earlier run
    if not Path(fmu).is_dir():
        _check_fmu_archive(fmu)
    discrete = along_outputs(fmpy.read_model_description(str(fmu), validate=False)) if along else []
    recorder = [None]  # fmpy's recorder, for the points before a failure
    messages: list[str] = []
    logger = _message_logger(messages)
    t0 = time.perf_counter()
    # progress lines on a terminal only: a CI log or a pipe gets the result lines alone (overcon.progress)
    from ..progress import _terminal

    step_finished = _step_callback(recorder, label, start, stop, t0, progress and _terminal())
    kw = dict(start_time=start, stop_time=stop, output_interval=step, output=list(outputs) + discrete,
              step_finished=step_finished, start_values=dict(start_values or {}))
    if input_table is not None:
        kw.update(input=input_table.structured(), set_input_derivatives=check_interpolation(interpolation) == "linear")
    stable = None
    try:
        with _instance(fmu, logger, unzip_dir) as (where, md, instance, stable_step), _input_derivatives_buffers():
            try:
                result = fmpy.simulate_fmu(where, model_description=md, fmu_instance=instance, **kw) \
                    if instance is not None else fmpy.simulate_fmu(where, logger=logger, debug_logging=True, **kw)
            except Exception:
                stable = stable_step()
                held = _held(instance, md, discrete)
                if held is not None:  # else no file: its last row would not be the stop's
                    with contextlib.suppress(Exception):  # the failure is what the caller reports
                        done = recorder[0].result() if recorder[0] is not None else []
                        _write_along(along_file, done, discrete, held, step, start)
                raise
    except Exception as exc:
        why = "; ".join(messages[-3:])
        raise SimulationFailed(f"{fmu}: fmpy.simulate_fmu failed: {type(exc).__name__}: {exc}"
                               + (f" (FMU log: {why})" if why else ""), stable_step=stable) from exc
    finally:
        _release_logging_proxy()
    sim_seconds = time.perf_counter() - t0
    last_time = _reached_stop(fmu, result, start, stop, messages)
    csv = Path(csv)
    csv.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(csv) as part:
        write_csv(str(part), result, columns=list(outputs))
    if discrete:
        _write_along(along_file, result, discrete)
    return {"rows": len(result), "sim_seconds": sim_seconds, "last_time": last_time}


def _worker(argv: list[str]) -> None:
    """``python -m overcon.tooling.run JSON``: run one FMU, print one result line, ``os._exit``."""
    job = json.loads(argv[0])
    try:
        table = read_input_table(job["input"], job["input_names"]) if job.get("input") else None
        out = simulate(job["fmu"], job["csv"], start=job["start"], stop=job["stop"], step=job["step"],
                       outputs=job["outputs"], progress=job["progress"], label=job["label"],
                       start_values=job.get("start_values"), along=job.get("along", False),
                       input_table=table, interpolation=job.get("interpolation", "hold"),
                       unzip_dir=job.get("unzip_dir"))
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
           "start_values": dict(ex.start_values), "along": along, "interpolation": ex.interpolation}
    t0 = time.perf_counter()
    unzip_dir = job["unzip_dir"] = tempfile.mkdtemp(prefix="overcon-run-")  # removed here whatever the worker did
    try:
        with tempfile.TemporaryDirectory(prefix="overcon-input-") as tmp:
            if ex.input_table is not None:  # to the worker as a file (a table may exceed an argument's size)
                job["input"] = str(write_input_table(ex.input_table, Path(tmp) / "input.csv"))
                job["input_names"] = ex.input_table.names
            try:
                proc = subprocess.run([sys.executable, "-m", "overcon.tooling.run", json.dumps(job)],
                                      stdout=subprocess.PIPE, stderr=None, text=True, timeout=timeout,
                                      env=_worker_env())
            except subprocess.TimeoutExpired as exc:
                raise SimulationFailed(f"{info.path}: no result within {timeout:g} s (killed)") from exc
    finally:
        shutil.rmtree(unzip_dir, ignore_errors=True)
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
        from ..progress import bar

        with bar(len(jobs), "FMU runs", "run") as shown, ThreadPoolExecutor(max(1, min(workers, len(jobs)))) as pool:
            for _ in pool.map(one, jobs):
                shown.update()
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
    row per time), validated as :data:`overcon.formats.CSV_FORMAT` (:func:`overcon.formats.read_csv_table`):
    :class:`InputError` naming the file (and the row and column) when it is missing or unreadable,
    has no ``time`` column first, a row with another number of columns than the header, a
    non-numeric or non-finite value, fewer than 2 rows, or times that do not increase."""
    from ..formats import SchemaError, read_csv_table

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such CSV file")
    try:
        names, rows = read_csv_table(path)
    except SchemaError as exc:
        raise InputError(str(exc)) from exc
    except OSError as exc:
        raise InputError(f"{path}: unreadable: {exc.strerror or exc}") from exc
    if len(rows) < 2:
        raise InputError(f"{path}: fewer than 2 rows")
    data = np.array(rows, dtype=float)
    return Series(data[:, 0].copy(), {n: data[:, k].copy() for k, n in enumerate(names) if k > 0})


if __name__ == "__main__":
    _worker(sys.argv[1:])
