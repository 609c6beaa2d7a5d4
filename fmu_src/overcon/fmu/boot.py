"""Entry point of the FMU binary (``native/overcon_fmi2.c``) into Python: imported by
``fmi2Instantiate`` with ``resources/`` on ``sys.path``. Standard library only at import time,
because in an interpreter the binary started itself numpy and scipy become importable only after
:func:`add_site_dirs`. The binary also hands over the addresses of its C functions the slave calls
back: the log function and the registration of the published values (the outputs fmi2GetReal
and fmi2GetBoolean answer without entering Python; see :mod:`overcon.fmu.slave`)."""
from __future__ import annotations

import importlib.util
import os
import site
import sys
from pathlib import Path

from . import pyinfo


def add_site_dirs(dirs: list[str]) -> None:
    """Add the recorded interpreter's site-packages (``.pth`` files processed) in front of
    ``sys.path``, as in that interpreter (a virtual environment's packages before the base
    installation's)."""
    before = list(sys.path)
    for d in dirs:
        site.addsitedir(d)
    added = [p for p in sys.path if p not in before]
    sys.path[:] = added + before


def _missing() -> list[str]:
    return [m for m in pyinfo.NEEDED if importlib.util.find_spec(m) is None]


def _borrow_recorded_site_dirs(resources: str) -> None:
    """A host interpreter (fmpy, libcosimpy, ...) without numpy or scipy: append the recorded
    interpreter's site-packages to sys.path (after the host's own entries), if that interpreter
    has the same Python version (compiled extension modules are version specific)."""
    path = Path(resources) / "overcon_python.txt"
    facts = pyinfo.parse(path.read_text(encoding="utf-8")) if path.is_file() else {}
    here = "{}.{}".format(*sys.version_info[:2])
    if facts.get("version") == [here]:
        for d in facts.get("site", []):
            if d not in sys.path:
                site.addsitedir(d)


def missing_packages_message(exc: Exception, *, joined_host: bool, resources: str) -> str:
    """The reason fmi2Instantiate gives when the slave cannot be imported (numpy or scipy
    missing). The advice depends on whose interpreter the FMU runs in: ``OVERCON_PYTHON`` chooses
    the interpreter only in a host process without Python; in a Python host (``joined_host``) the
    FMU runs in the host's own interpreter, so the packages must be installed there, or the
    recorded interpreter's lent, which works for its Python version only."""
    here = f"{sys.version.split()[0]} at {sys.executable or '(unknown executable)'}"
    if not joined_host:
        return (f"{exc}: the FMU needs numpy and scipy in the interpreter it started (Python {here}); set "
                "OVERCON_PYTHON to a Python executable that has them")
    path = Path(resources) / "overcon_python.txt"
    facts = pyinfo.parse(path.read_text(encoding="utf-8")) if path.is_file() else {}
    recorded = ".".join(facts.get("version", [])) or "unknown"
    return (f"{exc}: the FMU runs inside this host's own Python ({here}), which lacks numpy or scipy: "
            f"install them there (python -m pip install numpy scipy). The Python recorded at build time "
            f"(version {recorded}) lends its packages only to a host of the same version; OVERCON_PYTHON "
            "has no effect in a host that already runs Python")


def instantiate(instance_name: str, guid: str, resources: str, log_address: int, component: int,
                logging_on: int, site_dirs: str, publish_address: int = 0):
    """Called by fmi2Instantiate; returns the slave (an exception is logged by the binary and
    fmi2Instantiate returns NULL). ``site_dirs``: newline-separated folders, given only when the
    binary initialised the interpreter. ``publish_address``: the binary's ``register_published``
    (0: a binary without published values)."""
    if site_dirs:
        # an interpreter the FMU started itself: its BLAS has not started yet, and one thread suits the
        # small matrices of a run (overcon.cli.single_threaded_blas); the host's own setting wins
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(var, "1")
        add_site_dirs([d for d in site_dirs.split("\n") if d])
    elif _missing():
        _borrow_recorded_site_dirs(resources)
    if not getattr(sys, "argv", None):
        sys.argv = [""]  # an embedded interpreter has none; some libraries read sys.argv[0]
    try:
        from .slave import instantiate as make
    except ImportError as exc:
        raise ImportError(missing_packages_message(exc, joined_host=not site_dirs, resources=resources)) from exc
    return make(instance_name, guid, resources, log_address, component, bool(logging_on), publish_address)
