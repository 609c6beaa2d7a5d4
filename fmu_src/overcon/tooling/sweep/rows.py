"""The rows of ``sweep.csv``: one per run, written per finished group and parameter set, and the
summary lines."""
from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

from .. import InputError
from ..compare import compare_group
from ..run import Series
from .grid import parse_param, row_key
from .inputs import SweepFmu

CSV_NAME, JSON_NAME, PNG_NAME, PARQUET_NAME = "sweep.csv", "sweep.json", "sweep.png", "sweep.parquet"

@dataclass
class Sweep:
    """A sweep's definition (``DIR/sweep.json``) and what it resolved to."""

    out_dir: Path
    definition: dict
    fmus: list[SweepFmu]
    groups: dict  # group -> [SweepFmu] (paper order)
    sets: list[tuple[str, dict]]  # (set id, parameter values), see set_ids
    experiments: dict  # model -> Experiment
    columns: list[str]
    lockstep_step: float | None

    @property
    def csv(self) -> Path:
        return self.out_dir / CSV_NAME


FIXED_COLUMNS = ("key", "scene", "group", "elimination", "sample", "status", "wall [s]", "max_diff [m]",
                 "max_diff [rad]", "max_diff_output", "verdict", "lockstep_step [s]")
"""The columns beside the parameters and the final outputs. ``lockstep_step [s]``: the step of the
lockstep runs of that set (the sweep's, or the smaller one :class:`overcon.verdict.LockstepGrid`
repeated them at); empty without lockstep."""


def _columns(param_names: list[str], fmus: list[SweepFmu]) -> list[str]:
    clash = [n for n in param_names if n in FIXED_COLUMNS or n.startswith("final ")]
    if clash:
        raise InputError(f"--param {clash[0]}: the name is also a column of sweep.csv; such a parameter cannot be swept")
    finals = []
    for f in fmus:
        for o in f.info.outputs:
            col = f"final {o.name} [{o.unit or '1'}]"
            if col not in finals:
                finals.append(col)
    return [*FIXED_COLUMNS[:5], *param_names, *FIXED_COLUMNS[5:], *finals]


def _fmt(x) -> str:
    if x is None:
        return ""
    if isinstance(x, float):
        return repr(x)
    return str(x)


def read_rows(path: Path) -> list[dict]:
    """The rows of a ``sweep.csv`` (strings)."""
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _set_rows(sw: Sweep, group: str, set_id: str, values: dict, results: dict, grid=None) -> list[dict]:
    """The rows of one group at one parameter set; ``results``: model -> task result; ``grid``:
    the set's :class:`overcon.verdict.LockstepGrid` (None without lockstep)."""
    members = sw.groups[group]
    ok = [f for f in members if results[f.info.model]["status"] == "ok"]
    diff_m = diff_rad = worst = verdict = None
    if len(ok) == len(members) and len(members) >= 2:
        series = [Series(results[f.info.model]["time"], results[f.info.model]["values"]) for f in members]
        infos = [f.info for f in members]
        lock = sw.lockstep_step is not None
        c = compare_group(group, infos, series, lockstep=series if lock else None,
                          lockstep_step=grid.step if grid is not None else sw.lockstep_step)
        by_unit = c.max_diff_by_unit()
        diff_m, diff_rad = by_unit.get("m"), by_unit.get("rad")
        w = c.worst()
        worst = w.name if w is not None else None
        verdict = c.verdict_text() if lock else None
    rows = []
    for f in members:
        res = results[f.info.model]
        row = {"key": row_key(f.info.model, set_id), "scene": f.info.model, "group": group,
               "sample": set_id[1:].split(" ", 1)[0] if set_id.startswith("#") else None,
               "elimination": f.info.label, **values, "status": res["status"], "wall [s]": res.get("wall"),
               "max_diff [m]": diff_m, "max_diff [rad]": diff_rad, "max_diff_output": worst, "verdict": verdict,
               "lockstep_step [s]": grid.step if grid is not None else None}
        if res["status"] == "ok":
            for o in f.info.outputs:
                row[f"final {o.name} [{o.unit or '1'}]"] = float(res["values"][o.name][-1])
        rows.append({c: _fmt(row.get(c)) for c in sw.columns})
    return rows


class RowWriter:
    """Appends rows to ``sweep.csv`` (header first when new), never a key twice; flushed per set."""

    def __init__(self, path: Path, columns: list[str]):
        self.path = path
        self.columns = columns
        self.keys: set[str] = set()
        if path.is_file() and path.stat().st_size > 0:
            with open(path, newline="", encoding="utf-8") as fh:
                header = next(csv.reader(fh), [])
            if header != columns:
                raise InputError(f"{path}: its columns differ from this sweep's ({len(header)} against "
                                 f"{len(columns)}): not a sweep of this definition")
            self.keys = {r["key"] for r in read_rows(path)}
            self.fh = open(path, "a", newline="", encoding="utf-8")
            self.writer = csv.DictWriter(self.fh, columns)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            self.fh = open(path, "w", newline="", encoding="utf-8")
            self.writer = csv.DictWriter(self.fh, columns)
            self.writer.writeheader()
            self.fh.flush()

    def write(self, rows: list[dict]) -> int:
        new = [r for r in rows if r["key"] not in self.keys]
        for r in new:
            self.writer.writerow(r)
            self.keys.add(r["key"])
        self.fh.flush()
        os.fsync(self.fh.fileno())
        return len(new)

    def close(self) -> None:
        self.fh.close()


def overall(sw: Sweep, rows: list[dict]) -> str:
    """The first summary line: how many (group, parameter set) pairs were decided and how many
    failed, with each failure reason (the first run's, shortened) and its count."""
    sets: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        sets.setdefault((r["group"], r["key"].split(" ", 1)[1]), []).append(r)
    failed = {k: rs for k, rs in sets.items() if any(r["status"] != "ok" for r in rs)}
    decided = sum(1 for k, rs in sets.items() if k not in failed and rs[0]["verdict"])
    text = f"sweep: {len(sets)} (group, parameter set) pair(s): {decided} decided, {len(failed)} failed"
    if failed:
        why: dict[str, int] = {}
        for rs in failed.values():
            reason = next(r["status"] for r in rs if r["status"] != "ok")
            reason = reason if len(reason) <= 160 else reason[:157] + "..."
            why[reason] = why.get(reason, 0) + 1
        text += " (" + "; ".join(f"{n} x: {reason}" for reason, n in why.items()) + ")"
    return text


def summary(sw: Sweep, rows: list[dict]) -> list[str]:
    """One line per group: sets unique / not unique / without a measure, the range of
    ``max_diff [m]``; for a sweep of one numeric parameter also the largest value still unique and
    the smallest not unique (the question "above which value does the non-uniqueness matter?")."""
    names = [parse_param(t).name for t in sw.definition["params"]]
    lines = [overall(sw, rows)]
    for g in sw.groups:
        sets: dict[str, dict] = {}
        for r in rows:
            if r["group"] == g:
                sets.setdefault(r["key"].split(" ", 1)[1], r)
        if not sets:
            continue
        verdicts = [r["verdict"] for r in sets.values()]
        measured = [_number(r["max_diff [m]"]) for r in sets.values()]
        diffs = [d for d in measured if d is not None]
        text = (f"{g}: {len(sets)} parameter set(s): {verdicts.count('unique')} unique, "
                f"{verdicts.count('not unique')} not unique, {len(measured) - len(diffs)} without a measure "
                "(a run failed, or the group has one FMU)")
        if diffs:
            text += f"; max_diff {min(diffs):.2g} to {max(diffs):.2g} m"
        if len(names) == 1 and all(_number(r[names[0]]) is not None for r in sets.values()):
            x = names[0]
            uniq = [_number(r[x]) for r in sets.values() if r["verdict"] == "unique"]
            nonu = [_number(r[x]) for r in sets.values() if r["verdict"] == "not unique"]
            if uniq:
                text += f"; unique up to {x} = {max(uniq):g}"
            if nonu:
                text += f"; not unique from {x} = {min(nonu):g}"
        lines.append(text)
    return lines


def _number(text: str) -> float | None:
    try:
        return float(text) if text != "" else None
    except ValueError:
        return None
