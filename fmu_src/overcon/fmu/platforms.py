"""The platforms an FMU's binaries are built for (``overcon build --platforms``), and the binaries
themselves: compiled once per platform, FMI version and overcon version, and cached.

Platforms (:data:`PLATFORMS`; ``all`` is every one; ``native`` is this machine's, the default):

============== ============= ================ ============================ ============
name           FMI 2.0 folder FMI 3.0 folder  compiler target (zig)         file
============== ============= ================ ============================ ============
linux64        linux64       x86_64-linux     x86_64-linux-gnu.2.17         .so
aarch64-linux  (none)        aarch64-linux    aarch64-linux-gnu.2.17        .so
win64          win64         x86_64-windows   x86_64-windows-gnu            .dll
darwin64       darwin64      x86_64-darwin    x86_64-macos                  .dylib
aarch64-darwin (none)        aarch64-darwin   aarch64-macos                 .dylib
============== ============= ================ ============================ ============

FMI 2.0 names only linux64, win64 and darwin64 among these (it has no folder for 64-bit ARM): an
FMI 2.0 FMU asked for aarch64-linux or aarch64-darwin carries the others, and the build says which
were left out (:func:`folders`).

Where a binary comes from (:func:`binary`): the platform of this machine is the binary compiled
when the package was installed (setup.py, with this machine's C compiler, and with the same
flags, exports and glibc pins: :data:`CFLAGS`, :data:`FMU_FLAGS`); every other platform is
cross-compiled with zig (the PyPI wheel ``ziglang``, the extra ``overcon[platforms]``), from the
same C files (:func:`source_files`) and flags. Without zig, asking for another platform is bad
input (:class:`PlatformsUnavailable`, exit 2 of ``overcon build``, naming the extra).

Every binary exports the FMI functions alone (``-fvisibility=hidden -DOVK_FMU_BINARY``; on ELF
the version script ``native/exports.map``; on Windows ``__declspec(dllexport)`` of the FMI
functions only, so the DLL needs no .def file) and Linux binaries need nothing newer than glibc
2.17 (zig links against glibc 2.17's symbols; a native build on a newer glibc binds libm's exp,
pow and hypot to their first versions: ``-DOVK_GLIBC_PINS``, core/libm_pins.h). :func:`check` reads each compiled
binary (:mod:`overcon.fmu.binfmt`) and refuses one that breaks a rule (wrong architecture, another
export, a newer glibc, another library), so a toolchain that changed cannot fill the cache with a
bad binary.

The cache (:func:`cache_dir`): ``$OVERCON_CACHE_DIR``, else ``$XDG_CACHE_HOME/overcon``, else
``~/.cache/overcon`` (Linux), ``~/Library/Caches/overcon`` (macOS), ``%LOCALAPPDATA%\\overcon``
(Windows); binaries in its ``binaries/`` folder, named ``<platform>-fmi<N>-<key>.<ext>``, the key
a SHA-256 (:func:`cache_key`) over everything that makes the bytes: the overcon version, the
compiler (zig's version), the target, the flags, and the names and bytes of every C file and
header compiled in. Changing any of these makes a new key, so a stale binary is never used (old
files are left; deleting the folder is always safe). A binary is written under a temporary name
and renamed, so concurrent builds never see half a file.
"""
from __future__ import annotations

import dataclasses
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

NATIVE_DIR = Path(__file__).resolve().parent / "native"
CORE_DIR = Path(__file__).resolve().parent.parent / "core"
EXPORTS_MAP = NATIVE_DIR / "exports.map"

CFLAGS = ["-O2", "-ffp-contract=off", "-fno-fast-math", "-std=c11", "-Wall", "-Wextra", "-Werror"]
"""The flags of every compilation of the core (setup.py uses these): no fused multiply-add, no
reassociation, so the results do not depend on the CPU's FMA support."""
FMU_FLAGS = ["-fvisibility=hidden", "-DOVK_FMU_BINARY", "-DOVK_GLIBC_PINS"]
"""Added for an FMU binary: every symbol internal but the FMI functions (FMU_EXPORT); on glibc,
libm's exp, pow and hypot bound to their first versions (core/libm_pins.h)."""


@dataclasses.dataclass(frozen=True)
class Platform:
    name: str          # the --platforms name
    fmi2: str | None   # binaries/<folder> of FMI 2.0 (None: the standard names none)
    fmi3: str          # binaries/<folder> of FMI 3.0
    zig: str           # zig's -target
    ext: str           # the binary's file extension, without the dot
    fmt: str           # binfmt's format: elf, pe, macho
    arch: str          # binfmt's architecture

    def folder(self, fmi: int) -> str | None:
        return self.fmi3 if fmi == 3 else self.fmi2


PLATFORMS = {p.name: p for p in (
    Platform("linux64", "linux64", "x86_64-linux", "x86_64-linux-gnu.2.17", "so", "elf", "x86_64"),
    Platform("aarch64-linux", None, "aarch64-linux", "aarch64-linux-gnu.2.17", "so", "elf", "aarch64"),
    Platform("win64", "win64", "x86_64-windows", "x86_64-windows-gnu", "dll", "pe", "x86_64"),
    Platform("darwin64", "darwin64", "x86_64-darwin", "x86_64-macos", "dylib", "macho", "x86_64"),
    Platform("aarch64-darwin", None, "aarch64-darwin", "aarch64-macos", "dylib", "macho", "aarch64"),
)}
"""Every platform an FMU can carry (module docstring)."""
CHOICES = ("native", *PLATFORMS, "all")
EXTRA = "pip install 'overcon[platforms]'"
GLIBC_MAX = (2, 17)
"""The newest glibc a Linux binary may need."""
MACHO_LINKER_SYMBOLS = {"_mh_dylib_header", "__dso_handle"}
"""Symbols every Mach-O dylib's linker defines (the image header, the DSO handle): not overcon's."""


class PlatformsUnavailable(ValueError):
    """A --platforms list that cannot be built here: an unknown name, or another platform than
    this machine's without the cross-compiler (the message names the extra)."""


class PlatformBuildError(RuntimeError):
    """A cross-compilation that failed, or a binary that breaks a rule (:func:`check`)."""


def native() -> Platform:
    """This machine's platform (the binary setup.py compiled)."""
    import platform as _platform  # noqa: PLC0415

    arch = {"x86_64": "x86_64", "amd64": "x86_64", "aarch64": "aarch64", "arm64": "aarch64"}.get(
        _platform.machine().lower(), _platform.machine().lower())
    system = "linux" if sys.platform.startswith("linux") else "darwin" if sys.platform == "darwin" \
        else "windows" if sys.platform == "win32" else sys.platform
    for p in PLATFORMS.values():
        if p.fmi3 == f"{arch}-{system}":
            return p
    raise PlatformsUnavailable(f"this machine ({arch}, {system}) is none of the platforms {', '.join(PLATFORMS)}")


def parse(text: str) -> list[Platform]:
    """The platforms of a --platforms list (comma separated names of :data:`CHOICES`), in the
    order of :data:`PLATFORMS`, each once. :class:`PlatformsUnavailable` for an unknown or
    empty name."""
    names = [t.strip() for t in str(text).split(",")]
    bad = [n for n in names if n not in CHOICES]
    if bad or not names:
        raise PlatformsUnavailable(f"--platforms {text!r}: unknown platform(s) {', '.join(map(repr, bad))}; "
                                   f"choose among {', '.join(CHOICES)} (comma separated)")
    wanted = set()
    for n in names:
        wanted |= set(PLATFORMS) if n == "all" else {native().name} if n == "native" else {n}
    return [p for p in PLATFORMS.values() if p.name in wanted]


def folders(platforms: list[Platform], fmi: int) -> tuple[list[Platform], list[Platform]]:
    """(the platforms an FMU of FMI ``fmi`` carries, those its standard has no folder for)."""
    return ([p for p in platforms if p.folder(fmi)], [p for p in platforms if not p.folder(fmi)])


def zig_command() -> list[str] | None:
    """The zig compiler of the ``ziglang`` wheel (``python -m ziglang``), None when not installed."""
    import importlib.util  # noqa: PLC0415

    if importlib.util.find_spec("ziglang") is None:
        return None
    return [sys.executable, "-m", "ziglang"]


def require_cross(platforms: list[Platform]) -> None:
    """:class:`PlatformsUnavailable` naming the extra when a platform other than this machine's is
    asked for and zig is not installed."""
    others = [p.name for p in platforms if p != _native_or_none()]
    if others and zig_command() is None:
        raise PlatformsUnavailable(f"--platforms {','.join(others)}: cross-compiling needs the optional extra "
                                   f"'platforms' (the zig C compiler, PyPI's ziglang): {EXTRA}")


def _native_or_none() -> Platform | None:
    try:
        return native()
    except PlatformsUnavailable:
        return None


def source_files(fmi: int) -> list[tuple[str, Path]]:
    """The C files and headers of an FMU binary of FMI ``fmi``, as (path under the FMU's
    ``sources/``, file): the core (``core/``) and the FMI layer's shared files and version files
    (``fmu/native/``), the layout their ``#include "../../core/core.h"`` needs. Sorted."""
    layer = sorted(NATIVE_DIR.glob("fmu_*.c")) + sorted(NATIVE_DIR.glob(f"fmi{fmi}_*.c")) + \
        sorted(NATIVE_DIR.glob("*.h"))
    core = sorted(CORE_DIR.glob("*.c")) + sorted(CORE_DIR.glob("*.h"))
    return sorted([(f"core/{f.name}", f) for f in core] + [(f"fmu/native/{f.name}", f) for f in layer])


def compile_command(compiler: list[str], target: str | None, p: Platform, fmi: int, out: Path) -> list[str]:
    """The command compiling the binary of ``p`` for FMI ``fmi`` into ``out`` (``target``: zig's
    -target, None for a native compiler). Zig's binaries are stripped (``-s``: no debug
    information or local symbol table; it would triple a Linux binary's size)."""
    cmd = [*compiler, *(["-target", target, "-s"] if target else []), *CFLAGS, *FMU_FLAGS, "-shared"]
    if p.fmt != "pe":
        cmd.append("-fPIC")
    if p.fmt == "elf":
        cmd.append(f"-Wl,--version-script={EXPORTS_MAP}")
    srcs = [str(f) for rel, f in source_files(fmi) if rel.endswith(".c")]
    return [*cmd, "-o", str(out), *srcs, "-lm"]


def cache_dir() -> Path:
    """The folder of the cached binaries (module docstring)."""
    if os.environ.get("OVERCON_CACHE_DIR"):
        return Path(os.environ["OVERCON_CACHE_DIR"])
    if sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        return Path(os.environ["LOCALAPPDATA"]) / "overcon"
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "overcon"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "overcon"


_ZIG_VERSION: dict[str, str] = {}


def zig_version() -> str:
    if "v" not in _ZIG_VERSION:
        cmd = zig_command()
        if cmd is None:
            raise PlatformsUnavailable(f"the zig C compiler is not installed: {EXTRA}")
        run = subprocess.run([*cmd, "version"], capture_output=True, text=True)
        _ZIG_VERSION["v"] = run.stdout.strip() or f"unknown ({run.stderr.strip()[:200]})"
    return _ZIG_VERSION["v"]


def cache_key(p: Platform, fmi: int, overcon_version: str) -> str:
    """SHA-256 (hex, 20 digits) over what makes the bytes of the binary (module docstring)."""
    h = hashlib.sha256()
    flags = compile_command(["zig", "cc"], p.zig, p, fmi, Path("out"))
    for part in (f"overcon {overcon_version}", f"zig {zig_version()}", f"fmi {fmi}",
                 " ".join(f.replace(str(EXPORTS_MAP), "exports.map") for f in flags if not f.endswith(".c")),
                 EXPORTS_MAP.read_text(encoding="utf-8")):
        h.update(len(part).to_bytes(8, "little") + part.encode())
    for rel, f in source_files(fmi):
        data = f.read_bytes()
        h.update(len(rel).to_bytes(8, "little") + rel.encode() + len(data).to_bytes(8, "little") + data)
    return h.hexdigest()[:20]


_LOCK = threading.Lock()


def binary(p: Platform, fmi: int, overcon_version: str, native_binary=None, echo=None) -> bytes:
    """The bytes of the FMU binary of platform ``p`` for FMI ``fmi``: ``native_binary()`` (the
    installed one) for this machine's platform, else the cached cross-compiled one, compiled now
    when missing (``echo`` told). Raises :class:`PlatformsUnavailable` (no zig) or
    :class:`PlatformBuildError`."""
    if native_binary is not None and p == _native_or_none():
        return native_binary()
    if zig_command() is None:
        raise PlatformsUnavailable(f"--platforms {p.name}: cross-compiling needs the optional extra 'platforms' "
                                   f"(the zig C compiler, PyPI's ziglang): {EXTRA}")
    path = cache_dir() / "binaries" / f"{p.name}-fmi{fmi}-{cache_key(p, fmi, overcon_version)}.{p.ext}"
    with _LOCK:
        if path.is_file():
            return path.read_bytes()
        if echo:
            echo(f"compiling the {p.name} binary (FMI {fmi}) with zig {zig_version()}, once: cached as {path}")
        data = compile_binary(p, fmi)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".part")
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o644)  # mkstemp's 0600: the cache may be shared by the users of one machine
        os.replace(tmp, path)
    return data


def compile_binary(p: Platform, fmi: int) -> bytes:
    """Cross-compile the binary of ``p`` for FMI ``fmi`` with zig (in a temporary folder: zig
    also writes an import library and debug files there) and :func:`check` it."""
    with tempfile.TemporaryDirectory(prefix="overcon_zig_") as tmp:
        out = Path(tmp) / f"overcon_fmi{fmi}.{p.ext}"
        cmd = compile_command([*zig_command(), "cc"], p.zig, p, fmi, out)
        run = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp)
        if run.returncode != 0 or not out.is_file():
            said = (run.stderr.strip() or run.stdout.strip())[-4000:] or "no output"
            raise PlatformBuildError(f"compiling the {p.name} binary (FMI {fmi}) failed: exit status "
                                     f"{run.returncode} of {' '.join(cmd[:8])} ...:\n{said}")
        data = out.read_bytes()
    check(p, fmi, data)
    return data


def check(p: Platform, fmi: int, data: bytes) -> None:
    """:class:`PlatformBuildError` unless ``data`` is a library of ``p``'s format and architecture
    that exports FMI ``fmi`` functions and nothing else (bar the Mach-O linker's own symbols),
    needs at most glibc 2.17 (ELF), and imports nothing but the C library (libc and libm on
    Linux; libSystem on macOS; KERNEL32 and the Universal C runtime on Windows)."""
    from .binfmt import BinaryFormatError, inspect  # noqa: PLC0415

    try:
        facts = inspect(data)
    except BinaryFormatError as exc:
        raise PlatformBuildError(f"the {p.name} binary (FMI {fmi}) cannot be read: {exc}") from exc
    problems = []
    if (facts.format, facts.arch) != (p.fmt, p.arch):
        problems.append(f"it is {facts.format} {facts.arch}, not {p.fmt} {p.arch}")
    exports = [e for e in facts.exports if not (p.fmt == "macho" and e in MACHO_LINKER_SYMBOLS)]
    other = [e for e in exports if not e.startswith(f"fmi{fmi}")]
    if other or not exports:
        problems.append(f"it exports {', '.join(other[:8]) or 'no FMI function'}"
                        + (f" (and {len(other) - 8} more)" if len(other) > 8 else "") + f" beside fmi{fmi}*")
    if facts.format == "elf" and facts.glibc_max() > GLIBC_MAX:
        problems.append(f"it needs GLIBC_{'.'.join(map(str, facts.glibc_max()))}, newer than 2.17")
    allowed = {"elf": lambda n: n in ("libc.so.6", "libm.so.6"),
               "macho": lambda n: n == "/usr/lib/libSystem.B.dylib",
               "pe": lambda n: n.lower() == "kernel32.dll" or n.lower().startswith("api-ms-win-crt-")}[facts.format] \
        if facts.format in ("elf", "macho", "pe") else (lambda n: False)
    if [n for n in facts.imports if not allowed(n)]:
        problems.append(f"it imports {', '.join(n for n in facts.imports if not allowed(n))}")
    if problems:
        raise PlatformBuildError(f"the {p.name} binary (FMI {fmi}) breaks the rules of an FMU binary: "
                                 + "; ".join(problems))
