"""One sweep run, as a Dask task on a worker: the FMU unpacked once per worker, run with fmpy in a
child process."""
from __future__ import annotations

import dataclasses
import io
import os
import shutil
import tempfile
import threading
import zipfile
from pathlib import Path

from .. import InputError, SimulationFailed
from ..fmus import FmuInfo
from ..run import Experiment, read_series, run_one

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
    ``{"status": reason, "stable_step": s or None}`` (the FMU's logged reason, one line; the stable
    step rk4 named, as data, when it refused a step as unstable)."""
    unpacked = _unpacked(data, sha)
    with tempfile.TemporaryDirectory(prefix="overcon-sweep-run-") as tmp:
        try:
            r = run_one(dataclasses.replace(info, path=unpacked), ex, Path(tmp) / "run.csv", False, None,
                        label=info.model)
            s = read_series(r.csv)
        except (SimulationFailed, InputError) as exc:
            return {"status": _one_line(str(exc).replace(str(unpacked), str(info.path))),
                    "stable_step": getattr(exc, "stable_step", None)}
    return {"status": "ok", "wall": r.wall_seconds, "time": s.time,
            "values": {n: s.values[n] for n in info.output_names}}
