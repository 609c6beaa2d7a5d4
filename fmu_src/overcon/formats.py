"""The files the tooling reads, validated against a schema before use (docs/untrusted-input.md).

One schema per format, versioned, written as a JSON Schema (draft 2020-12) dict so that the same
document can be published and checked by any JSON Schema tool; the validator here is a small
hand-written one for the subset the schemas use (``type``, ``properties``, ``required``,
``additionalProperties``, ``items``, ``enum``, ``const``, ``anyOf``, ``minimum``, ``maximum``,
``maxItems``, ``maxLength``, ``maxProperties``). Decided: no dependency on the ``jsonschema``
package (it pulls in several packages, one compiled, for a few dozen lines of checks, and its
messages name a JSON path where ours name the file and the key as the rest of overcon does).

Before any schema, :func:`load_json` bounds what the parser itself may spend: the file's size,
the nesting depth (checked by a scan of the bytes before ``json.loads``, which would otherwise
raise RecursionError), and numbers (NaN, Infinity and overflowing literals such as ``1e999`` are
refused: JSON has no non-finite numbers). Every refusal is a :class:`SchemaError` (a ValueError)
naming the file and the key.

:func:`read_csv_table` is the CSV counterpart (format :data:`CSV_FORMAT`, the FMI cross-check
CSV): a header whose first name is ``time``, names unique, every row as many columns as the
header, every value a finite number, times strictly increasing; a refusal names the row and the
column.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

MAX_JSON_BYTES = 16 * 1024 * 1024  # a facts record is about 2 kB
MAX_JSON_DEPTH = 32
MAX_CSV_BYTES = 2 * 1024 ** 3
MAX_CSV_COLUMNS = 100_000
CSV_FORMAT = "overcon-csv/1"


class SchemaError(ValueError):
    """A file that does not match its format; the message names the file and the key (or row and column)."""


def _depth_exceeds(text: str, limit: int) -> bool:
    """Whether brackets (outside strings) nest deeper than limit: a linear scan, no recursion."""
    depth, in_str, esc = 0, False, False
    for ch in text:
        if in_str:
            if esc:
                esc = False
            elif ch == "\\":
                esc = True
            elif ch == '"':
                in_str = False
        elif ch == '"':
            in_str = True
        elif ch in "[{":
            depth += 1
            if depth > limit:
                return True
        elif ch in "]}":
            depth -= 1
    return False


def _finite_float(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise ValueError(f"number {text} is not finite")
    return x


def _no_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def load_json(data: bytes | str, where: str, *, max_bytes: int = MAX_JSON_BYTES, max_depth: int = MAX_JSON_DEPTH):
    """The JSON document of ``data`` (the bytes of the file ``where``), bounded before parsing."""
    if len(data) > max_bytes:
        raise SchemaError(f"{where}: {len(data)} bytes, more than the {max_bytes} a file of this format may have")
    try:
        text = data.decode("utf-8") if isinstance(data, bytes) else data
    except UnicodeDecodeError as exc:
        raise SchemaError(f"{where}: not UTF-8 text: {exc}") from exc
    if _depth_exceeds(text, max_depth):
        raise SchemaError(f"{where}: nested deeper than {max_depth} levels")
    try:
        return json.loads(text, parse_float=_finite_float, parse_constant=_no_constant)
    except ValueError as exc:
        raise SchemaError(f"{where} is not JSON: {exc}") from exc


_TYPES = {"object": dict, "array": list, "string": str, "boolean": bool, "null": type(None)}


def _type_ok(value, typ: str) -> bool:
    if typ == "integer":
        return isinstance(value, int) and not isinstance(value, bool)
    if typ == "number":
        return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    return isinstance(value, _TYPES[typ])


def _json_type(value) -> str:
    return {bool: "bool", dict: "object", list: "array", str: "str", type(None): "null"}.get(type(value),
                                                                                             type(value).__name__)


def _describe(value) -> str:
    text = json.dumps(value) if not isinstance(value, float) or math.isfinite(value) else repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def validate(value, schema: dict, where: str, key: str = "") -> None:
    """Raises :class:`SchemaError` ("<where>: key <key>: ...") at the first place value differs from schema."""
    at = f"{where}: key {key!r}" if key else where
    if "anyOf" in schema:
        errors = []
        for option in schema["anyOf"]:
            try:
                validate(value, option, where, key)
                break
            except SchemaError as exc:
                errors.append(str(exc).split(": ", 2)[-1])
        else:
            raise SchemaError(f"{at}: {_describe(value)} is none of: " + "; ".join(errors))
        return
    typ = schema.get("type")
    if typ is not None:
        types = typ if isinstance(typ, list) else [typ]
        if not any(_type_ok(value, t) for t in types):
            raise SchemaError(f"{at} has the wrong type ({_json_type(value)}), expected {' or '.join(types)}")
    if "const" in schema and value != schema["const"]:
        raise SchemaError(f"{at}: {_describe(value)}, expected {_describe(schema['const'])}")
    if "enum" in schema and value not in schema["enum"]:
        raise SchemaError(f"{at}: {_describe(value)} is not one of {', '.join(map(_describe, schema['enum']))}")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if "minimum" in schema and value < schema["minimum"]:
            raise SchemaError(f"{at}: {value!r} is below {schema['minimum']!r}")
        if "maximum" in schema and value > schema["maximum"]:
            raise SchemaError(f"{at}: {value!r} is above {schema['maximum']!r}")
    if isinstance(value, str) and len(value) > schema.get("maxLength", math.inf):
        raise SchemaError(f"{at}: a string of {len(value)} characters (at most {schema['maxLength']})")
    if isinstance(value, list):
        if len(value) > schema.get("maxItems", math.inf):
            raise SchemaError(f"{at}: {len(value)} items (at most {schema['maxItems']})")
        if "items" in schema:
            for i, item in enumerate(value):
                validate(item, schema["items"], where, f"{key}[{i}]")
    if isinstance(value, dict):
        if len(value) > schema.get("maxProperties", math.inf):
            raise SchemaError(f"{at}: {len(value)} keys (at most {schema['maxProperties']})")
        for name in schema.get("required", ()):
            if name not in value:
                raise SchemaError(f"{where}: key {(key + '.' if key else '') + name!r} missing")
        props = schema.get("properties", {})
        extra = schema.get("additionalProperties", True)
        for name, item in value.items():
            sub = f"{key}.{name}" if key else name
            if name in props:
                validate(item, props[name], where, sub)
            elif extra is False:
                raise SchemaError(f"{where}: key {sub!r} is not part of this format")
            elif isinstance(extra, dict):
                validate(item, extra, where, sub)


def read_csv_table(path, *, max_bytes: int = MAX_CSV_BYTES) -> tuple[list[str], list[list[float]]]:
    """The header and the rows of a result CSV (format :data:`CSV_FORMAT`, module docstring),
    checked; :class:`SchemaError` naming the file, the row (1 = the first data row) and the column."""
    path = Path(path)
    size = path.stat().st_size
    if size > max_bytes:
        raise SchemaError(f"{path}: {size} bytes, more than the {max_bytes} a result CSV may have")
    rows: list[list[float]] = []
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        try:
            header = next(reader, None)
            if not header:
                raise SchemaError(f"{path}: empty (a header \"time\",\"name\",... expected)")
            header = [h.strip() for h in header]
            if header[0] != "time":
                raise SchemaError(f"{path}: the first column must be \"time\", got {header[0]!r}")
            if len(header) > MAX_CSV_COLUMNS:
                raise SchemaError(f"{path}: {len(header)} columns (at most {MAX_CSV_COLUMNS})")
            seen = set()
            for name in header:
                if not name or name in seen:
                    raise SchemaError(f"{path}: header: column name {name!r} " + ("empty" if not name else "repeated"))
                seen.add(name)
            for n, cells in enumerate(reader, start=1):
                if not cells:
                    continue
                if len(cells) != len(header):
                    raise SchemaError(f"{path}: row {n} has {len(cells)} columns, the header has {len(header)}")
                row = []
                for name, cell in zip(header, cells):
                    try:
                        x = float(cell)
                    except ValueError:
                        raise SchemaError(f"{path}: row {n}, column {name!r}: {cell.strip()[:40]!r} is not a "
                                          "number") from None
                    if not math.isfinite(x):
                        raise SchemaError(f"{path}: row {n}, column {name!r}: {cell.strip()[:40]} is not finite")
                    row.append(x)
                if rows and not row[0] > rows[-1][0]:
                    raise SchemaError(f"{path}: row {n}, column 'time': {row[0]!r} does not increase "
                                      f"(the row before has {rows[-1][0]!r})")
                rows.append(row)
        except csv.Error as exc:
            raise SchemaError(f"{path}: not CSV: {exc}") from exc
        except UnicodeDecodeError as exc:
            raise SchemaError(f"{path}: not UTF-8 text: {exc}") from exc
    return header, rows
