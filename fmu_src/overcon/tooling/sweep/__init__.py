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

Inputs
------
``--input TABLE`` gives every run the same input table (:mod:`overcon.tooling.inputs`, through
fmpy's ``input=``; ``--input-interpolation linear`` with input derivatives); ``sweep.json``
records its path and SHA-256 and ``--resume`` refuses a table that changed. An input's start value
is swept like a parameter (``--param motor=0:20:5``: a constant input per run), unless the table
sets that input. An overcon FMU with inputs refuses rk4, the lockstep method: sweep it with
``--lockstep-step 0``.

Results and faults
------------------
``DIR/sweep.csv`` is written by the client only, one row per run, appended as soon as every
elimination of a group has finished one parameter set (so a set is written whole). Each row has a
``key`` (scene and parameter set); a key already in the file is never written again. A worker that
dies has its tasks rerun by Dask (up to ``distributed.scheduler.allowed-failures`` times; then the
row records ``KilledWorker``); a task the scheduler cancels (its worker died holding the
scattered FMU) is submitted again, the FMU scattered again, twice at most (then the row records
the cancellation). Ctrl-C cancels the remaining tasks and keeps the rows written;
``overcon sweep --resume DIR`` reads ``DIR/sweep.json`` (the sweep's definition), rebuilds or
re-reads the FMUs, refuses to continue if an FMU's GUID changed, and runs only the parameter sets
not in ``sweep.csv`` (runs of a set that was not complete at the interruption are run again).
After the runs: ``DIR/sweep.png`` (the measure against each swept numeric parameter, per group,
log scale) and, when pyarrow is installed, ``DIR/sweep.parquet`` (the same rows).

Modules: :mod:`.grid` (parameter sets), :mod:`.inputs` (the FMUs), :mod:`.worker` (one run, a Dask
task), :mod:`.rows` (sweep.csv and the summary), :mod:`.define` (sweep.json, new or resumed),
:mod:`.execute` (the Dask run), :mod:`.plots` (sweep.png, sweep.parquet).
"""
from __future__ import annotations

from .define import prepare
from .execute import EXIT_INTERRUPTED, SweepOutcome, _experiment, run
from .grid import ParamSpec, grid, params_key, parse_param, row_key, set_ids
from .inputs import LOCKSTEP_FIXED, SweepFmu, _load_fmu, value_problem
from .plots import ZERO_FLOOR, plot, write_parquet
from .rows import (CSV_NAME, FIXED_COLUMNS, JSON_NAME, PARQUET_NAME, PNG_NAME, RowWriter, Sweep, _set_rows, read_rows,
                   summary)
from .worker import run_task
from ..run import Experiment

__all__ = ["prepare", "run", "EXIT_INTERRUPTED", "SweepOutcome", "ParamSpec", "grid", "params_key", "parse_param",
           "row_key", "set_ids", "LOCKSTEP_FIXED", "SweepFmu", "value_problem", "ZERO_FLOOR", "plot", "write_parquet",
           "CSV_NAME", "FIXED_COLUMNS", "JSON_NAME", "PARQUET_NAME", "PNG_NAME", "RowWriter", "Sweep", "read_rows",
           "summary", "run_task", "Experiment", "_experiment", "_load_fmu", "_set_rows"]
