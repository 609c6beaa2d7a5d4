"""Running a sweep on Dask: the client (a scheduler's or a local cluster), the tasks, the rows
appended as groups finish."""
from __future__ import annotations

import dataclasses
import hashlib
import signal
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from ...verdict import LockstepGrid, lockstep_start_values
from .. import InputError
from ..run import Experiment
from .grid import row_key
from .inputs import SweepFmu, value_problem
from .plots import plot, write_parquet
from .rows import RowWriter, Sweep, _set_rows, read_rows, summary
from .worker import _one_line, run_task

EXIT_INTERRUPTED = 130


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


def _experiment(sw: Sweep, f: SweepFmu, values: dict, step: float | None = None) -> Experiment:
    """The run settings of ``f`` at the parameter set ``values``: on the lockstep grid of ``step``
    (default the sweep's) unless the sweep runs the FMUs' own settings."""
    step = sw.lockstep_step if step is None else step
    sv = dict(lockstep_start_values(step)) if sw.lockstep_step is not None else {}
    sv.update(values)
    return dataclasses.replace(sw.experiments[f.info.model], start_values=tuple(sv.items()))


class _Sets:
    """The results of the runs in flight, per (group, parameter set id), and per such pair the
    lockstep procedure (:class:`overcon.verdict.LockstepGrid`, the one compare and reproduce use)
    that decides whether a failed set is run again at a smaller step."""

    def __init__(self, sw: Sweep):
        self.sw = sw
        self.values = dict(sw.sets)
        self.pending: dict[tuple[str, str], dict] = {}  # (group, set id) -> model -> task result
        self.grids: dict[tuple[str, str], LockstepGrid] = {}

    def grid(self, g: str, pk: str) -> LockstepGrid | None:
        if self.sw.lockstep_step is None:
            return None
        return self.grids.setdefault((g, pk), LockstepGrid(self.sw.lockstep_step))

    def complete(self, g: str, pk: str) -> bool:
        return len(self.pending.get((g, pk), ())) == len(self.sw.groups[g])

    def retry(self, g: str, pk: str) -> bool:
        """The set's runs are complete; True (and its results dropped) when the lockstep procedure
        repeats them at a smaller step."""
        grid = self.grid(g, pk)
        failed = [r for r in self.pending[(g, pk)].values() if r["status"] != "ok"]
        if grid is None or not failed or not grid.retry([r.get("stable_step") for r in failed]):
            return False
        self.pending[(g, pk)] = {}
        return True

    def rows(self, g: str, pk: str) -> list[dict]:
        grid = self.grid(g, pk)
        return _set_rows(self.sw, g, pk, self.values[pk], self.pending.pop((g, pk)), grid)


def _queue(sw: Sweep, writer: RowWriter, sets: _Sets) -> tuple[list[tuple[str, SweepFmu, str]], int]:
    """The runs to do (group, FMU, set id) for the sets not yet in ``sweep.csv``; values the FMU's
    rule refuses are recorded without a run. Returns (runs, rows written)."""
    todo, written = [], 0
    for pk, values in sw.sets:
        for g, members in sw.groups.items():
            if all(row_key(f.info.model, pk) in writer.keys for f in members):
                continue
            results = sets.pending.setdefault((g, pk), {})
            for f in members:
                why = value_problem(f, values)
                if why:
                    results[f.info.model] = {"status": f"{why} (checked before running, by the FMU's parameter rule)"}
                else:
                    todo.append((g, f, pk))
            if sets.complete(g, pk):
                written += writer.write(sets.rows(g, pk))
    return todo, written


def run(sw: Sweep, *, client=None, scheduler: str | None = None, workers: int = 2, progress: bool = True,
        echo=print, on_rows=None) -> SweepOutcome:
    """Run the parameter sets of ``sw`` not yet in ``sweep.csv`` on Dask (``client``, else a
    connection to ``scheduler``, else a local cluster of ``workers`` processes); append rows per
    finished group and set; ``on_rows(rows, client)`` after each append (tests). Ctrl-C
    (KeyboardInterrupt) cancels the remaining tasks and returns with ``interrupted``."""
    t0 = time.perf_counter()
    writer = RowWriter(sw.csv, sw.columns)
    sets = _Sets(sw)
    before = len(writer.keys)
    interrupted, written = False, 0
    try:
        todo, written = _queue(sw, writer, sets)
        echo(f"== sweep: {len(sw.sets)} parameter set(s) x {sum(len(v) for v in sw.groups.values())} FMU(s); "
             f"{before} row(s) already in {sw.csv}, {len(writer.keys) - before} refused before running, "
             f"{len(todo)} run(s) to do; "
             + (f"lockstep runs (rk4, {sw.lockstep_step:g} s)" if sw.lockstep_step is not None
                else "the FMUs' own solver settings (no lockstep)"))
        if todo:
            more, interrupted = _execute(sw, todo, sets, writer, client, scheduler, workers, progress, echo, on_rows)
            written += more
    except KeyboardInterrupt:
        interrupted = True
    finally:
        writer.close()
    return _finish(sw, written, interrupted, t0, echo)


def _finish(sw: Sweep, written: int, interrupted: bool, t0: float, echo) -> SweepOutcome:
    rows = read_rows(sw.csv)
    failed = sum(r["status"] != "ok" for r in rows)
    out = SweepOutcome(sw.csv, len(rows), written, failed, interrupted, seconds=time.perf_counter() - t0)
    if rows:
        for line in summary(sw, rows):
            echo(line)
        out.png = plot(sw, rows)
        out.parquet = write_parquet(sw.csv)
    return out


def _execute(sw: Sweep, todo, sets: _Sets, writer: RowWriter, client, scheduler, workers, progress, echo,
             on_rows) -> tuple[int, bool]:
    """The runs ``todo`` on Dask; a set whose lockstep runs failed on an unstable step is run again
    at the step its grid names. Returns (rows written, interrupted)."""
    from distributed import as_completed

    own = client is None
    cluster = None
    if own:
        client, cluster = _start_client(scheduler, workers, echo)
    futures, written, interrupted = [], 0, False
    try:
        link = _dashboard(client)
        if link:
            echo(f"   dashboard: {link}")
        # hash=False: a key of its own per scatter. A content-hashed key is shared with any earlier
        # scatter of the same FMU on this scheduler (an earlier sweep of a shared client), whose
        # release can make the scheduler forget the data under the new tasks ("already forgotten")
        blobs = {f.info.model: client.scatter(f.data, broadcast=True, hash=False) for f in sw.fmus
                 if any(t[1] is f for t in todo)}
        meta = {}

        def submit(g, f, pk, attempt=0):
            grid = sets.grid(g, pk)
            ex = _experiment(sw, f, sets.values[pk], None if grid is None else grid.step)
            key = "overcon-sweep-" + hashlib.sha256(
                (f"{f.sha} {row_key(f.info.model, pk)} {ex.start_values} {attempt}").encode()).hexdigest()[:24]
            fut = client.submit(run_task, blobs[f.info.model], f.sha, f.info, ex, key=key, pure=False)
            meta[fut.key] = (g, f.info.model, pk)
            futures.append(fut)
            return fut

        ready = as_completed([submit(*t) for t in todo])
        bar = _progress_thread(futures, client) if progress else None
        lost: dict[tuple, int] = {}
        for fut in ready:
            g, model, pk = meta[fut.key]
            if _cancelled(fut) and lost.get((model, pk), 0) < LOST_RETRIES:
                # the scheduler dropped the task (its worker died with the scattered FMU):
                # scatter the FMU again and run the task again, instead of losing the row
                lost[(model, pk)] = lost.get((model, pk), 0) + 1
                f = next(x for x in sw.fmus if x.info.model == model)
                blobs[model] = client.scatter(f.data, broadcast=True, hash=False)
                ready.add(submit(g, f, pk, lost[(model, pk)]))
                continue
            written += _collect(sw, sets, writer, (g, model, pk), fut, echo, on_rows, client,
                                lambda g, pk: [ready.add(submit(g, f, pk)) for f in sw.groups[g]])
        if bar is not None:
            bar.join(timeout=5)
            print(file=sys.stdout, flush=True)
    except KeyboardInterrupt:
        interrupted = True
        client.cancel(futures)
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
    return written, interrupted


LOST_RETRIES = 2
"""Times a task the scheduler cancelled (its worker died, taking the scattered FMU with it) is
submitted again before its row records the cancellation."""


def _cancelled(fut) -> bool:
    """The task was cancelled by the scheduler (not failed by the run): status ``cancelled``, or a
    finished future whose outcome is a cancellation (``as_completed`` can hand a future over before
    its status reads ``cancelled``; its result then raises FutureCancelledError, a CancelledError,
    and the row was lost: seen once in the suite with a worker killed under load)."""
    from concurrent.futures import CancelledError

    if getattr(fut, "status", "") == "cancelled":
        return True
    try:
        return isinstance(fut.exception(), CancelledError)
    except CancelledError:
        return True
    except Exception:  # noqa: BLE001 -- any other outcome is the run's, recorded by _collect
        return False


def _collect(sw: Sweep, sets: _Sets, writer: RowWriter, where, fut, echo, on_rows, client, resubmit) -> int:
    """One finished task: its result recorded; a complete set is run again (``resubmit``) or
    written. Returns the rows written."""
    g, model, pk = where
    try:
        res = fut.result()
    except Exception as exc:  # noqa: BLE001 -- KilledWorker etc.: recorded in the row
        res = {"status": _one_line(f"{type(exc).__name__}: {exc}")}
    sets.pending[(g, pk)][model] = res
    if not sets.complete(g, pk):
        return 0
    if sets.retry(g, pk):
        echo(f"{g} {pk}: {sets.grid(g, pk).note}")
        resubmit(g, pk)
        return 0
    rows = sets.rows(g, pk)
    n = writer.write(rows)
    if on_rows is not None:
        on_rows(rows, client)
    return n


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
    """A tqdm bar over the runs on a terminal (overcon.progress: nothing in CI logs or pipes),
    advanced as tasks finish; the rows do not depend on it."""
    from distributed import as_completed

    from ...progress import bar as progress_bar

    def bar():
        try:
            with progress_bar(len(futures), "sweep", "run") as shown:
                for _ in as_completed(futures):
                    shown.update()
        except Exception:  # noqa: BLE001 -- the bar is cosmetic; the rows do not depend on it
            pass

    t = threading.Thread(target=bar, name="overcon-sweep-progress", daemon=True)
    t.start()
    return t


