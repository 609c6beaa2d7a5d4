"""``fmpy.simulate_fmu`` with the FMU's log recorded, without fmpy's logging proxy.

``fmpy.simulate_fmu(..., logger=f)`` (and ``instantiate_fmu``) wraps ``f`` in a ctypes callback
and hands it to fmpy's native logging proxy (fmpy/logging: ``addLoggerProxy``), which keeps it in
one static pointer after the run. Once the run's FMU object is collected the callback is freed,
and the next FMU that logs through fmpy's default callbacks (which all go through that proxy)
calls freed memory: a segmentation fault in whichever test comes next. Here the FMU is
instantiated with the caller's own ``fmi2CallbackFunctions`` (test_fmu.Logs), which the proxy
never sees, and freed before the caller's records go away."""
from __future__ import annotations

import shutil
from pathlib import Path

import fmpy
from fmpy.fmi2 import FMU2Slave


def simulate_logged(fmu: Path, logs, *, debug_logging: bool = False, **kw):
    """``fmpy.simulate_fmu(fmu, **kw)`` for an FMI 2.0 co-simulation FMU, its log going to
    ``logs`` (a test_fmu.Logs: records of (status, category, message); messages are the FMU's
    format strings, so a % reads %%). ``debug_logging`` is the instance's loggingOn. Whatever
    simulate_fmu raises is raised after the instance is freed; ``logs`` keeps what was logged."""
    md = fmpy.read_model_description(str(fmu))
    unzipdir = fmpy.extract(str(fmu))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName=Path(fmu).stem)
    try:
        slave.instantiate(callbacks=logs.callbacks, loggingOn=debug_logging)
        try:
            return fmpy.simulate_fmu(unzipdir, model_description=md, fmu_instance=slave, **kw)
        finally:
            slave.freeInstance()
    finally:
        shutil.rmtree(unzipdir, ignore_errors=True)
