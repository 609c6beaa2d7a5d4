"""Every file a command writes, written whole or not at all (docs/untrusted-input.md, "Output files").

The convention, one for every command (simulate, run, compare, build, figures, reproduce, sweep,
converge): a file is written to ``<name>.part`` beside it and renamed over ``<name>`` only when it
is complete (:func:`atomic`). A command that fails or is interrupted (Ctrl-C, a full disk, a
killed worker) while writing removes its ``.part`` file: the old ``<name>`` is left as it was, or
there is none. A file that exists is therefore always complete. (The one file that holds less
than asked is documented as such: ``overcon simulate`` whose run stops writes the output points
computed before the stop and exits 3, saying where the file ends.)

And outputs never destroy inputs: :func:`check_outputs` refuses (exit 2) an output path that is
one of the command's input files or another output of the same command, or that exists and is not
a regular file (``/dev/full``, a directory), and a directory the command cannot write into, before
any work is done.
"""
from __future__ import annotations

import contextlib
import os
from pathlib import Path


def part_path(path) -> Path:
    path = Path(path)
    return path.with_name(path.name + ".part")


@contextlib.contextmanager
def atomic(path, mode: str = "w", **kw):
    """``open(<path>.part, mode)``; renamed over ``path`` when the block ends normally, removed when
    it raises (KeyboardInterrupt included)."""
    with atomic_path(path) as part, open(part, mode, **kw) as fh:
        yield fh


@contextlib.contextmanager
def atomic_path(path):
    """The ``.part`` path for a writer that takes a file name (matplotlib's savefig, zipfile):
    renamed over ``path`` when the block ends normally, removed when it raises."""
    part = part_path(path)
    try:
        yield part
        os.replace(part, path)
    except BaseException:
        with contextlib.suppress(OSError):
            part.unlink()
        raise


def write_text_atomic(path, text: str, encoding: str = "utf-8") -> None:
    """Path.write_text, whole or not at all."""
    with atomic(path, "w", encoding=encoding) as fh:
        fh.write(text)


def savefig_atomic(fig, path, **kw) -> None:
    """matplotlib's fig.savefig(path), whole or not at all (the format from path's suffix)."""
    path = Path(path)
    with atomic_path(path) as part:
        fig.savefig(part, format=path.suffix.lstrip(".") or "png", **kw)


def _same(a: Path, b: Path) -> bool:
    if a.resolve() == b.resolve():
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_outputs(outputs: dict[str, object], inputs: dict[str, object]) -> str | None:
    """Why the outputs (option -> path; None: not given) cannot be written, or None: an output
    equal to an input file or to another output, one that exists and is not a regular file, or
    whose directory is missing or not writable. Checked before any work."""
    given = {k: Path(v) for k, v in outputs.items() if v is not None}
    ins = {k: Path(v) for k, v in inputs.items() if v is not None}
    names = list(given)
    for i, k in enumerate(names):
        p = given[k]
        for j in names[:i]:
            if _same(p, given[j]):
                return f"{k} {p}: the same file as {j} {given[j]} (each output needs a file of its own)"
        for name, q in ins.items():
            if q.exists() and _same(p, q):
                return f"{k} {p}: is the input {name} {q} (refused: it would be overwritten)"
        if p.exists() and not p.is_file():
            return f"{k} {p}: " + ("is a directory (give a file name)" if p.is_dir() else "is not a regular file")
        parent = p.parent
        if not parent.is_dir():
            return f"{k} {p}: the directory {parent} does not exist"
        if not os.access(parent, os.W_OK | os.X_OK):
            return f"{k} {p}: the directory {parent} is not writable"
        if p.exists() and not os.access(p, os.W_OK):
            return f"{k} {p}: the file is not writable"
    return None


def check_out_dir(option: str, path, inputs: dict[str, object] | None = None) -> str | None:
    """Why the output directory ``path`` cannot be written, or None; checked before any simulation
    and without making it: an existing directory is probed with a file of its own, a missing one
    needs its nearest existing ancestor to be a writable directory."""
    d = Path(path)
    if d.exists() and not d.is_dir():
        return f"{option} {d}: not a directory"
    for name, q in (inputs or {}).items():
        if q is not None and Path(q).exists() and _same(d, Path(q)):
            return f"{option} {d}: is the input {name}"
    if d.is_dir():
        try:
            probe = d / f".overcon-write-probe-{os.getpid()}"
            probe.write_bytes(b"")
            probe.unlink()
        except OSError as exc:
            return f"{option} {d}: cannot write there ({exc.strerror or exc})"
        return None
    up = d.absolute().parent
    while not up.exists():
        up = up.parent
    if not up.is_dir():
        return f"{option} {d}: cannot write there ({up} is not a directory)"
    if not os.access(up, os.W_OK | os.X_OK):
        return f"{option} {d}: cannot write there ({up} is not writable)"
    return None


def check_input_outside(option: str, out_dir, input_option: str, table) -> str | None:
    """Why the input file ``table`` (``input_option``, None: not given) cannot be read by a command
    that writes into the directory ``out_dir`` (``option``), or None. A command writing a directory
    (run, compare, sweep) writes files named after its FMUs there and below (result and along CSVs,
    lockstep/, the report, figures, sweep tables): an input anywhere inside it could be overwritten,
    so it is refused before any work, whatever its name."""
    if table is None:
        return None
    t, d = Path(table), Path(out_dir)
    if not t.exists():
        return None  # the reader of the table says that it is missing
    if _same(d, t):
        return f"{option} {d}: is the input {input_option} {t} (refused: it would be overwritten)"
    try:
        t.resolve().relative_to(d.resolve())
    except ValueError:
        return None
    return (f"{input_option} {t}: is inside the output directory {option} {d}, whose files this command writes "
            "(refused: it could be overwritten); keep the input table outside it")
