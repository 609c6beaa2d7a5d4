"""The grid of a sweep: ``--param`` specifications, the full-factorial or sampled parameter
sets, their ids and the rows' keys (module docstring of :mod:`overcon.tooling.sweep`)."""
from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass

import numpy as np

from .. import InputError

@dataclass(frozen=True)
class ParamSpec:
    """One ``--param``: ``values`` (raw strings of a list) or a range ``lo``..``hi`` with ``n``
    points (``n`` None: a sampling range ``lo:hi``)."""

    name: str
    text: str
    values: tuple[str, ...] = ()
    lo: float | None = None
    hi: float | None = None
    n: int | None = None

    @property
    def is_range(self) -> bool:
        return self.lo is not None


def parse_param(text: str) -> ParamSpec:
    """``NAME=V1,V2,...`` or ``NAME=lo:hi:n`` (or ``NAME=lo:hi`` for ``--samples``);
    :class:`InputError` naming the ``--param`` at fault."""
    where = f"--param {text!r}"
    if "=" not in text:
        raise InputError(f"{where}: expected NAME=V1,V2,... or NAME=lo:hi:n")
    name, rhs = (s.strip() for s in text.split("=", 1))
    if not name:
        raise InputError(f"{where}: no parameter name before '='")
    if not rhs:
        raise InputError(f"{where}: no values after '='")
    if ":" in rhs:
        parts = rhs.split(":")
        if len(parts) not in (2, 3):
            raise InputError(f"{where}: a range is lo:hi:n (or lo:hi with --samples), got {rhs!r}")
        try:
            lo, hi = float(parts[0]), float(parts[1])
        except ValueError:
            raise InputError(f"{where}: range bounds must be numbers, got {parts[0]!r} and {parts[1]!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi)) or hi < lo:
            raise InputError(f"{where}: range bounds must be finite with lo <= hi, got {lo!r}:{hi!r}")
        n = None
        if len(parts) == 3:
            try:
                n = int(parts[2])
            except ValueError:
                raise InputError(f"{where}: n must be an integer, got {parts[2]!r}") from None
            if n < 1 or (n == 1 and lo != hi):
                raise InputError(f"{where}: n must be >= 2 (or 1 with lo = hi), got {n}")
        return ParamSpec(name, text, lo=lo, hi=hi, n=n)
    values = tuple(v.strip() for v in rhs.split(","))
    if any(not v for v in values):
        raise InputError(f"{where}: empty value in the list {rhs!r}")
    if len(set(values)) != len(values):
        raise InputError(f"{where}: a value is listed twice in {rhs!r}")
    return ParamSpec(name, text, values=values)


def _typed(spec: ParamSpec, raw: str, typ: str):
    where = f"--param {spec.text!r}"
    try:
        if typ == "Real":
            return float(raw)
        if typ == "Integer":
            return int(raw)
        if typ == "Boolean":
            low = raw.lower()
            if low not in ("true", "false", "1", "0"):
                raise ValueError(raw)
            return low in ("true", "1")
        return raw
    except ValueError:
        raise InputError(f"{where}: {raw!r} is not a valid {typ} value for {spec.name}") from None


def grid(specs: list[ParamSpec], types: dict[str, str], *, samples: int | None = None,
         seed: int | None = None) -> list[dict]:
    """The parameter sets: full factorial of ``specs`` (in the order given), or ``samples`` sets
    drawn with ``numpy.random.default_rng(seed)``. ``types``: FMU variable type per name."""
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise InputError(f"--param: {sorted({n for n in names if names.count(n) > 1})[0]} given twice")
    for s in specs:
        if s.is_range and types[s.name] != "Real":
            raise InputError(f"--param {s.text!r}: a range lo:hi needs a Real parameter; {s.name} is "
                             f"{types[s.name]}: list its values")
    if samples is None:
        axes = []
        for s in specs:
            if s.is_range and s.n is None:
                raise InputError(f"--param {s.text!r}: lo:hi is a sampling range (with --samples); give "
                                 "lo:hi:n for a grid of n values")
            if s.is_range:
                axes.append([float(v) for v in np.linspace(s.lo, s.hi, s.n)])
            else:
                axes.append([_typed(s, v, types[s.name]) for v in s.values])
        return [dict(zip(names, combo)) for combo in itertools.product(*axes)]
    if samples < 1:
        raise InputError(f"--samples {samples}: must be >= 1")
    rng = np.random.default_rng(0 if seed is None else seed)
    for s in specs:
        if s.is_range and s.n is not None:
            raise InputError(f"--param {s.text!r}: with --samples a range is lo:hi (drawn uniformly); "
                             "n has no meaning there")
    typed = {s.name: [_typed(s, v, types[s.name]) for v in s.values] for s in specs if not s.is_range}
    out = []
    for _ in range(samples):
        row = {}
        for s in specs:
            row[s.name] = float(rng.uniform(s.lo, s.hi)) if s.is_range else typed[s.name][int(rng.integers(len(s.values)))]
        out.append(row)
    return out


def params_key(values: dict) -> str:
    """Canonical text of a parameter set (sorted names, shortest round-trip floats)."""
    return json.dumps(dict(sorted(values.items())), separators=(",", ":"))


def set_ids(sets: list[dict], sampled: bool) -> list[str]:
    """The identity of each parameter set: its :func:`params_key`; for ``--samples`` prefixed by
    the sample number (``#3 {...}``), so that a set drawn twice is two samples (two rows per FMU),
    as a Monte-Carlo spread needs, never one row silently standing for both."""
    return [f"#{i} {params_key(v)}" if sampled else params_key(v) for i, v in enumerate(sets, start=1)]


def row_key(model: str, set_id: str) -> str:
    """The row's identity in ``sweep.csv``: scene (model identifier) and parameter set id."""
    return f"{model} {set_id}"
