"""fmpy tooling: run FMUs, compare them, write reports (``overcon run``, ``compare``, ``reproduce``).

The FMUs are treated as black boxes driven by ``fmpy.simulate_fmu``; what overcon put into them
(scene file, pre-check verdicts) is read from their ``resources/`` and modelDescription only to
group, label and predict.

Modules: :mod:`.fmus` (inspect an FMU: experiment, outputs, scene, predictions),
:mod:`.run` (simulate FMUs in worker processes, CSV in and out), :mod:`.compare` (differences,
tolerances, verdicts), :mod:`.report` (Markdown and PNG), :mod:`.reproduce` (the main job),
:mod:`.sweep` (parameter sweeps on Dask), :mod:`.inputs` (the ``--input`` tables of FMU inputs),
:mod:`.cosim` (an overcon FMU in a system: the coupling example in libcosim).

Errors: :class:`InputError` (bad input: exit 2), :class:`SimulationFailed` (exit 3).
"""
from __future__ import annotations


class InputError(ValueError):
    """Bad input (missing or corrupt FMU, unreadable CSV, nothing to compare, mismatched grids);
    the message names the file."""


class SimulationFailed(RuntimeError):
    """An FMU simulation failed or stopped before its stop time; the message names the FMU, the
    time and the FMU's own reason where it logged one. ``stable_step`` (s): the FMU's variable
    ``solver.stable_step`` after the failure when rk4 refused a step as unstable (data for the
    lockstep comparison, :class:`overcon.verdict.LockstepGrid`), else None."""

    def __init__(self, message: str, stable_step: float | None = None):
        super().__init__(message)
        self.stable_step = stable_step
