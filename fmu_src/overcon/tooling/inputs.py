"""Input tables: the values a host gives an FMU's inputs over time (``--input INPUTS.csv`` of
``overcon simulate``, ``run``, ``compare`` and ``sweep``).

File format
-----------
A CSV file (comma separated, UTF-8, header first; names may be quoted as in the FMI cross-check
format, ``"time","motor"``) with a ``time`` column (s) and one column per input, named by the
input's name (the scene's ``[[inputs]] name``, the FMU's input variable), values in the input's
unit (N or N·m). Every declared input has a column and every column is a declared input or
``time``; columns may come in any order. Each row has a value in every column; values are finite
numbers; times strictly increase. At least one row, at most :data:`MAX_ROWS` rows and
:data:`MAX_BYTES` bytes. Anything else is bad input (:class:`overcon.tooling.InputError`, a
``ValueError``: exit 2) naming the file, the column and the row (rows are numbered as in the file,
the header is row 1).

Semantics (what an input is at time t)
--------------------------------------
The table is a signal ``u(t)``: linear between consecutive rows; before the first row's time it
is the first row's value and after the last row's time the last row's value (held flat, never
extrapolated). This is exactly how fmpy's ``simulate_fmu(..., input=...)`` reads a table
(``fmpy.simulation.Input``: linear between rows, first/last row outside), so a table means the
same to overcon and to fmpy. Decided: no error for a run that starts before the first row or
ends after the last one; a table of one row is a constant input.

A co-simulation host sets an input at each communication point ``t_n`` (= each output point of
``overcon simulate``); over the step ``[t_n, t_n+1]`` the FMU then sees

- ``hold`` (the default, FMI co-simulation without input derivatives; what fmpy does without
  ``set_input_derivatives``): ``u(t_n)``, constant over the step;
- ``linear`` (the host sets first-order input derivatives, ``fmi2SetRealInputDerivatives``; fmpy
  with ``set_input_derivatives=True``): ``u(t_n) + u'(t_n) (t - t_n)``. The slope ``u'(t_n)`` is
  fmpy's, taken as it is so that a table means the same numbers to ``overcon simulate`` and to an
  FMU run through fmpy: the slope of the segment ``[t_i-1, t_i]`` with ``t_i-1 < t_n <= t_i`` (at a
  row, the segment that *ends* there), and 0 when ``t_n`` is at or before the first row or after
  the last. Consequences, decided with fmpy: the step that starts at the first row's time is held
  (a ramp meant to be linear from the start time needs a row before it, or rows on the
  communication grid where the first segment is flat); between rows on the communication grid
  the step ``[t_n, t_n+1]`` uses the slope of ``[t_n-1, t_n]``, so ``linear`` equals ``u(t)`` on
  the step only where the table is one straight segment across ``[t_n-1, t_n+1]``; the step that
  starts at the last row continues the last segment's slope (it is not flattened before the next
  communication point). ``linear`` is for tables sampled finer than, or lying along, the signal's
  straight pieces: a ramp of many steps is reproduced exactly, a bend costs one step of lag.

:meth:`InputTable.step` gives that pair (value at ``t_n``, slope over the step) for either mode:
the form a stepping engine needs; :meth:`InputTable.at` the signal ``u(t)`` itself, and
:meth:`InputTable.during` the value seen at ``t`` inside a step begun at ``t_n``.
"""
from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import InputError
from ..interpolation import INTERPOLATIONS  # noqa: F401  (re-exported: the tooling's name for it)
from ..interpolation import check_interpolation as _check_interpolation
MAX_ROWS = 1_000_000  # the output-point bound of a run (overcon.params.MAX_OUTPUT_POINTS)
MAX_BYTES = 256 * 1024 * 1024  # read whole into memory: bounded


@dataclass(frozen=True, eq=False)
class InputTable:
    """An input table (module docstring): ``time`` (k,) strictly increasing, ``values`` input name
    -> (k,) array (in the caller's order of names), ``path`` the file it came from (for messages).
    Compared by identity (``eq=False``: arrays have no single truth value)."""

    time: np.ndarray
    values: dict
    path: str = ""

    @property
    def names(self) -> list[str]:
        return list(self.values)

    def structured(self) -> np.ndarray:
        """The table as fmpy's ``simulate_fmu(input=...)`` wants it: a structured array of dtype
        ``[('time', '<f8'), (name, '<f8'), ...]``, one record per row."""
        dtype = [("time", "<f8")] + [(n, "<f8") for n in self.values]
        out = np.empty(len(self.time), dtype=dtype)
        out["time"] = self.time
        for n, v in self.values.items():
            out[n] = v
        return out

    def at(self, t: float) -> dict:
        """The signal u(t): linear between rows, the first/last row's value outside them. The
        arithmetic is fmpy's (``w0 v0 + w1 v1``, ``w0 = (t1 - t) / (t1 - t0)``, ``w1 = 1 - w0``), so
        the value set at a communication point is the one fmpy sets, to the bit."""
        t = _finite_time(t)
        i = int(np.searchsorted(self.time, t, side="left"))
        if i == 0:
            return {n: float(v[0]) for n, v in self.values.items()}
        if i == len(self.time):
            return {n: float(v[-1]) for n, v in self.values.items()}
        t0, t1 = self.time[i - 1], self.time[i]
        w0 = (t1 - t) / (t1 - t0)
        w1 = 1.0 - w0
        return {n: float(w0 * v[i - 1] + w1 * v[i]) for n, v in self.values.items()}

    def slope(self, t: float) -> dict:
        """u'(t) as fmpy passes it as the first input derivative at a communication point t
        (module docstring): the slope of the segment [time[i-1], time[i]] with time[i-1] < t <=
        time[i]; 0 when t <= time[0] or t > time[-1] (fmpy.simulation.Input.interpolate)."""
        t = _finite_time(t)
        i = int(np.searchsorted(self.time, t, side="left"))
        if i == 0 or i == len(self.time):
            return {n: 0.0 for n in self.values}
        dt = self.time[i] - self.time[i - 1]
        return {n: float((v[i] - v[i - 1]) / dt) for n, v in self.values.items()}

    def step(self, t_n: float, interpolation: str = "hold") -> tuple[dict, dict]:
        """(value, slope) seen over a communication step starting at ``t_n``: the input at a time t
        of that step is ``value + slope * (t - t_n)``. ``hold``: (u(t_n), 0); ``linear``:
        (u(t_n), u'(t_n))."""
        mode = check_interpolation(interpolation)
        value = self.at(t_n)
        return value, (self.slope(t_n) if mode == "linear" else {n: 0.0 for n in self.values})

    def during(self, t: float, t_n: float, interpolation: str = "hold") -> dict:
        """The input at time ``t`` inside the communication step that began at ``t_n``
        (``t_n <= t``), as the FMU sees it (module docstring)."""
        value, slope = self.step(t_n, interpolation)
        return {n: value[n] + slope[n] * (float(t) - float(t_n)) for n in value}


def write_input_table(table: InputTable, path) -> Path:
    """Write ``table`` as an input table CSV (header ``"time","name",...``, every value as its
    shortest round-trip ``repr``: read back bit for bit by :func:`read_input_table`)."""
    path = Path(path)
    with open(path, "w", encoding="utf-8", newline="") as f:
        f.write(",".join(f'"{n}"' for n in ["time", *table.names]) + "\n")
        cols = [table.time, *table.values.values()]
        for r in range(len(table.time)):
            f.write(",".join(repr(float(c[r])) for c in cols) + "\n")
    return path


def check_interpolation(interpolation: str) -> str:
    """``interpolation`` when it is a known mode (:func:`overcon.interpolation.check_interpolation`),
    else :class:`overcon.tooling.InputError`: bad input, exit 2."""
    return _check_interpolation(interpolation, InputError)


def _finite_time(t) -> float:
    t = float(t)
    if not math.isfinite(t):
        raise ValueError(f"input table evaluated at a non-finite time {t!r}")
    return t


def _clean(name: str) -> str:
    return name.strip().strip('"').strip()


def read_input_table(path, names) -> InputTable:
    """Read and check the input table ``path`` for the inputs ``names`` (the scene's or FMU's
    input names, in its order); :class:`InputError` naming the file, the column and the row for
    anything the module docstring does not allow."""
    path = Path(path)
    names = list(names)
    if not names:
        raise InputError(f"{path}: an input table was given but there are no inputs to set "
                         "(the scene declares no [[inputs]], the FMU no input variable)")
    try:
        size = os.path.getsize(path)
    except OSError as exc:
        raise InputError(f"{path}: cannot read the input table: {exc.strerror or exc}") from exc
    if size > MAX_BYTES:
        raise InputError(f"{path}: input table of {size} bytes, more than the {MAX_BYTES} allowed")
    try:
        text = path.read_text(encoding="utf-8-sig")  # -sig: a spreadsheet's byte-order mark is not a name
    except (OSError, UnicodeError) as exc:
        raise InputError(f"{path}: cannot read the input table as UTF-8 text: {exc}") from exc
    reader = csv.reader(io.StringIO(text), skipinitialspace=True, strict=True)
    try:
        rows = [(reader.line_num, r) for r in reader if any(c.strip() for c in r)]  # blank lines skipped
    except csv.Error as exc:
        raise InputError(f"{path}: row {reader.line_num}: not CSV: {exc}") from exc
    if not rows:
        raise InputError(f"{path}: empty input table (expected a header \"time\",{','.join(names)} and rows)")
    header_line, header = rows[0]
    cols = [_clean(c) for c in header]
    seen: dict[str, int] = {}
    for j, c in enumerate(cols):
        if c in seen:
            raise InputError(f"{path}: column {c!r} appears twice in the header (columns {seen[c] + 1} and {j + 1})")
        seen[c] = j
        if c != "time" and c not in names:
            raise InputError(f"{path}: column {c!r} (column {j + 1}) is not an input; the inputs are "
                             f"{', '.join(names)}")
    if "time" not in seen:
        raise InputError(f"{path}: no \"time\" column in the header (row {header_line})")
    missing = [n for n in names if n not in seen]
    if missing:
        raise InputError(f"{path}: no column for the input(s) {', '.join(missing)} (every input needs one)")
    data = rows[1:]
    if not data:
        raise InputError(f"{path}: the input table has a header but no rows")
    if len(data) > MAX_ROWS:
        raise InputError(f"{path}: {len(data)} rows, more than the {MAX_ROWS} allowed")
    table = np.empty((len(data), len(cols)))
    for r, (line, row) in enumerate(data):
        if len(row) != len(cols):
            raise InputError(f"{path}: row {line} has {len(row)} value(s), the header {len(cols)} columns")
        for j, cell in enumerate(row):
            try:
                x = float(cell)
            except ValueError:
                raise InputError(f"{path}: column {cols[j]!r}, row {line}: not a number: {cell.strip()!r}") from None
            if not math.isfinite(x):
                raise InputError(f"{path}: column {cols[j]!r}, row {line}: non-finite value {cell.strip()!r}")
            table[r, j] = x
    t = table[:, seen["time"]].copy()
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if bad.size:
        r = int(bad[0]) + 1
        raise InputError(f"{path}: column 'time', row {data[r][0]}: time {float(t[r])!r} does not increase "
                         f"(previous row {data[r - 1][0]}: {float(t[r - 1])!r}); times must strictly increase")
    values = {n: table[:, seen[n]].copy() for n in names}
    for a in (t, *values.values()):
        a.setflags(write=False)
    return InputTable(t, values, str(path))
