"""Exact, safe serialization of an FMU state (fmi2SerializeFMUstate) to bytes.

The state is a tree of dicts (str keys), lists, tuples, NumPy arrays and scalars, floats, ints,
bools, strings and None (:meth:`overcon.simulate.Simulation.get_state` plus the slave's own
fields). It is written as UTF-8 JSON; arrays as base64 of their raw bytes (dtype and shape kept),
floats by ``repr`` (shortest round-trip text; inf and nan included), so decoding gives bit-identical
values. Unlike pickle, decoding untrusted bytes never executes code: anything that is not this
format raises :class:`ValueError`.
"""
from __future__ import annotations

import base64
import json

import numpy as np

MAGIC = "overcon-fmu-state/1"
_ALLOWED_DTYPES = {"float64", "float32", "int64", "int32", "bool"}


def _enc(x):
    if isinstance(x, np.ndarray):
        if x.dtype.name not in _ALLOWED_DTYPES:
            raise TypeError(f"cannot serialize an array of dtype {x.dtype}")
        a = np.ascontiguousarray(x)
        return {"__nd__": base64.b64encode(a.tobytes()).decode("ascii"), "dtype": a.dtype.str,
                "shape": list(a.shape)}
    if isinstance(x, np.generic):
        return _enc(x.item())
    if isinstance(x, dict):
        if not all(isinstance(k, str) for k in x):
            raise TypeError("state dict keys must be strings")
        if any(k.startswith("__") and k.endswith("__") for k in x):
            raise TypeError("state dict keys must not look like codec tags")
        return {k: _enc(v) for k, v in x.items()}
    if isinstance(x, tuple):
        return {"__tuple__": [_enc(v) for v in x]}
    if isinstance(x, list):
        return [_enc(v) for v in x]
    if x is None or isinstance(x, (bool, int, float, str)):
        return x
    raise TypeError(f"cannot serialize a {type(x).__name__} in an FMU state")


def _dec(x):
    if isinstance(x, dict):
        if "__nd__" in x:
            dtype = np.dtype(x["dtype"])
            if dtype.name not in _ALLOWED_DTYPES:
                raise ValueError(f"array dtype {dtype} not allowed")
            raw = base64.b64decode(x["__nd__"], validate=True)
            return np.frombuffer(raw, dtype=dtype).reshape(x["shape"]).copy()
        if "__tuple__" in x:
            return tuple(_dec(v) for v in x["__tuple__"])
        return {k: _dec(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_dec(v) for v in x]
    return x


def dumps(state) -> bytes:
    return json.dumps({"format": MAGIC, "state": _enc(state)}, allow_nan=True,
                      separators=(",", ":")).encode("utf-8")


def loads(data: bytes):
    try:
        doc = json.loads(bytes(data).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"not a serialized overcon FMU state: {exc}") from None
    if not isinstance(doc, dict) or doc.get("format") != MAGIC:
        raise ValueError(f"not a serialized overcon FMU state (format {MAGIC} expected)")
    try:
        return _dec(doc["state"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"corrupt serialized FMU state: {exc}") from None
