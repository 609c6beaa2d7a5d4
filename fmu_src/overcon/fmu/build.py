"""Build one FMU per scene file, with overcon's own C binary (no Python in the FMU).

:func:`build_all` is the library function behind ``python build_fmu.py`` and ``overcon build``.
For each scene file (files with a ``[scene]`` table; mechanism files are skipped) it runs the
pre-check and prints its verdict; a scene with friction on a joint whose reaction is not unique is
refused (the pre-check's reasons are printed) unless ``allow_nonunique``. Each FMU
``<out>/<scene name>.fmu`` is self-contained::

    modelDescription.xml              overcon.fmu.description (validated with fmpy after writing)
    binaries/<platform>/<scene>.so    the FMI layer over the core (native/fmu_*.c with fmi2_*.c or
                                      fmi3_*.c, and core/*.c), compiled once at the package
                                      installation (setup.py): :data:`C_RUNTIME_LIBRARY`,
                                      :data:`C_RUNTIME_LIBRARY3`, copied; C11 and libm, no libpython;
                                      with ``platforms`` (``--platforms``) one folder per platform,
                                      the others cross-compiled once and cached (overcon.fmu.platforms)
    sources/core/*.c, *.h             the C sources of that binary (source FMU: a tool compiles it
    sources/fmu/native/*.c, *.h       for a platform not shipped): listed in FMI 2.0's <SourceFiles>,
    sources/buildDescription.xml      FMI 3.0's build description (with -DOVK_FMU_BINARY)
    resources/overcon_model.bin       the packed model, output plan, variables and parameter rules
                                      (overcon.fmu.cmodel, its format versioned)
    resources/overcon_fmu.json        GUID, scene path, pre-check verdicts and warnings, binary facts
    resources/overcon_facts.json      the versioned facts the tooling reads (overcon.fmu.facts)
    resources/scene/...               the scene file and its mechanism file (for the reader; the
                                      binary reads only the model file)

The binary does not depend on the scene, so building needs no C compiler: the package installation
compiled it. It covers every scene that can be integrated (:func:`overcon.kernel.support`:
every joint type, both rotations, every load, the friction laws ``regularised`` and ``stribeck``,
any number of friction joints, every redundancy method, ``solver.singular`` "stop" and "pass",
every integrator: dopri5, dop853, rk4 and radau). A scene with the friction law ``coulomb``
(discontinuous at v = 0: for analysis only, refused for integration as by ``overcon simulate``) is
refused as invalid input (exit 2), as is any scene the C runtime would not cover, naming why:
there is no other runtime to fall back on.

``runtime`` (``overcon build --runtime``): ``c``; ``python``, the runtime that embedded the
building Python in the FMU until it was retired, is a deprecated alias that says so on stderr and
builds the C runtime (the exit codes are those of the build).

FMI version and kind (``fmi``, ``kind``; ``overcon build --fmi 2|3 --kind cs|me|both``, default FMI
2.0 and both): co-simulation, Model Exchange (the continuous states y = [q, h] and their
derivatives: :mod:`overcon.fmu.variables`, ``native/fmu_me.c``) or both, as FMI 2.0
(``binaries/linux64``, :data:`C_RUNTIME_LIBRARY`) or FMI 3.0 (``binaries/x86_64-linux``,
:data:`C_RUNTIME_LIBRARY3`). Model Exchange does not carry the energy outputs (their work ledger
integrates over the run's own steps): a scene with energy outputs is built for co-simulation only
under the default kind (said in the build output) and refused (exit 2) under an explicit ``--kind
me|both``.

The GUID is a SHA-256 over the scene file, the mechanism file, the overcon source (Python) and the
binaries (each with its folder), so rebuilding unchanged inputs gives the same GUID and the same
bytes.

Platforms (``platforms``; ``overcon build --platforms LIST``, default ``native``): the FMU carries a
binary for each platform of the list (:mod:`overcon.fmu.platforms`: linux64, aarch64-linux, win64,
darwin64, aarch64-darwin, or all), under the folder names of its FMI version; FMI 2.0 has none for
the aarch64 platforms, which it leaves out (said in the build output). This machine's binary is the
installed one; the others are cross-compiled by zig (``pip install 'overcon[platforms]'``) once per
platform, FMI version and overcon version, and cached, before the first FMU is written. Without
zig, or for an unknown name, the build is refused (exit 2) naming the fix. docs/platforms.md.

Compatibility information (FMI cross-check convention) next to each FMU, unless ``refs=False``:
``<scene>_ref.csv`` (time and every Real output, simulated through ``fmpy.simulate_fmu`` at the
default experiment) and ``<scene>_ref.opt`` (StartTime, StopTime, StepSize, RelTol). A reference
run that fails or ends before the stop time writes neither (and removes stale ones) and names
the scene, the time reached and the FMU's logged reason.

Exit codes of :func:`main`: 0 all built, 1 some scene refused by the pre-check, 2 invalid input or
a build that failed, 3 a reference simulation failed (worst wins: 2 > 3 > 1).
"""
from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import hashlib
import json
import os
import platform
import posixpath
import shutil
import sys
import tempfile
import time
import tomllib
import uuid
import zipfile
from pathlib import Path

from .. import kernel as kernel_mod
from ..argtypes import count as _jobs
from .. import scene as scene_mod
from ..model import ModelError
from ..checks import compile_checked
from ..precheck import PrecheckResult, precheck
from ..spec import SceneSpec
from ..precheck import friction_warnings
from . import cmodel, description, facts, platforms as platforms_mod, variables

EXIT_OK, EXIT_NONUNIQUE, EXIT_INPUT, EXIT_RUNTIME = 0, 1, 2, 3
PACKAGE_DIR = Path(__file__).resolve().parent.parent
FORMAT_VERSION = "overcon-fmu-3"  # bump when the FMU layout changes (enters the GUID): 3 added sources/
RUNTIMES = ("c", "python")
"""The accepted values of ``--runtime``: ``python`` is a deprecated alias of ``c`` (module docstring)."""
FMI_VERSIONS = (2, 3)
KINDS = ("cs", "me", "both")
C_RUNTIME_LIBRARY = Path(__file__).resolve().parent / "native" / f"libovercon_fmi2{kernel_mod._shared_suffix()}"
"""The binary of the FMI 2.0 FMUs without Python, compiled by the package installation (setup.py)."""
C_RUNTIME_LIBRARY3 = Path(__file__).resolve().parent / "native" / f"libovercon_fmi3{kernel_mod._shared_suffix()}"
"""The binary of the FMI 3.0 FMUs (without Python), compiled by the package installation (setup.py)."""
_DATE = (1980, 1, 1, 0, 0, 0)  # fixed zip timestamps: reproducible FMU bytes


@dataclasses.dataclass
class BuildResult:
    source: str
    status: str  # "built", "refused", "skipped", "invalid", "failed"
    name: str = ""
    fmu: Path | None = None
    guid: str = ""
    motion_unique: bool | None = None
    messages: list[str] = dataclasses.field(default_factory=list)
    seconds: float = 0.0
    ref_status: str = ""  # "", "written", "failed"


# ---------------------------------------------------------------------------------------------
# inputs

def _source_files() -> list[tuple[str, bytes]]:
    """(relative posix path, bytes) of the overcon package's Python source, sorted."""
    files = []
    for f in sorted(PACKAGE_DIR.rglob("*.py")):
        if "__pycache__" in f.parts:
            continue
        files.append((f.relative_to(PACKAGE_DIR).as_posix(), f.read_bytes()))
    return files


class BuildError(RuntimeError):
    """The FMU binary is not at hand here (a source tree never installed, an unknown platform)."""


def _fmi_platform() -> tuple[str, str]:
    bits = "64" if sys.maxsize > 2**32 else "32"
    if sys.platform.startswith("linux"):
        return f"linux{bits}", "so"
    if sys.platform == "darwin":
        return f"darwin{bits}", "dylib"
    raise BuildError(f"the FMU binary (dlopen, POSIX) is built on Linux and macOS only, not on {sys.platform}")


def c_runtime_library(fmi: int = 2) -> bytes:
    """The FMU binary for FMI ``fmi`` (:data:`C_RUNTIME_LIBRARY`,
    :data:`C_RUNTIME_LIBRARY3`). Raises :class:`BuildError` naming the fix when it is missing (a
    source tree that was never built)."""
    path = C_RUNTIME_LIBRARY3 if fmi == 3 else C_RUNTIME_LIBRARY
    try:
        return path.read_bytes()
    except OSError as exc:
        raise BuildError(f"the FMU binary {path} cannot be read ({exc.strerror or exc}): "
                         "run `pip install -e .` in the project directory, which compiles it") from exc


def _fmi3_platform() -> str:
    """FMI 3.0's platform tuple of this machine (binaries/<tuple>)."""
    arch = {"x86_64": "x86_64", "amd64": "x86_64", "aarch64": "aarch64", "arm64": "aarch64"}.get(
        platform.machine().lower(), platform.machine().lower())
    if sys.platform.startswith("linux"):
        return f"{arch}-linux"
    if sys.platform == "darwin":
        return f"{arch}-darwin"
    raise BuildError(f"the FMU binary (dlopen, POSIX) is built on Linux and macOS only, not on {sys.platform}")


def _overcon_version() -> str:
    try:
        from importlib.metadata import version  # noqa: PLC0415

        return version("overcon")
    except Exception:  # not installed as a distribution (e.g. run from a source tree)
        return "0+unknown"


def _scene_layout(scene_path: Path, mech_ref: str) -> tuple[str, str]:
    """Zip paths of the scene and mechanism files under resources/, keeping the scene's relative
    ``mechanism`` path valid (a path starting with ``..`` puts the scene in sub-folders)."""
    if posixpath.isabs(mech_ref) or os.path.isabs(mech_ref):
        raise ValueError(f"scene.mechanism {mech_ref!r} is an absolute path: the FMU could not carry "
                         "it; give it relative to the scene file")
    parts = posixpath.normpath(mech_ref.replace("\\", "/")).split("/")
    up = 0
    while up < len(parts) and parts[up] == "..":
        up += 1
    scene_dir = "/".join(["scene"] + ["d"] * up)
    return f"{scene_dir}/{scene_path.name}", "/".join(["scene"] + parts[up:])


# ---------------------------------------------------------------------------------------------
# one FMU

def _bad_efforts(report: PrecheckResult) -> list[str]:
    """The drivers whose effort the pre-check finds not unique (its "effort not unique" problems)."""
    return [d for d in report.drivers if any(p.startswith(f"effort not unique: driver {d}:") for p in report.problems)]


def _prescribed(report: PrecheckResult) -> bool:
    """The drivers prescribe the whole motion (DOF 0): the elimination can change efforts and
    reactions, not the motion (as :func:`overcon.precheck.motion_verdict` says)."""
    return bool(report.drivers) and report.dof == 0


def _verdict(report: PrecheckResult) -> str:
    """The build's one-line pre-check summary; with drivers, their efforts' verdict too, in the
    words of ``check`` (a prescribed motion is unique while its efforts may not be)."""
    bad_efforts = _bad_efforts(report)
    effort = ""
    if report.drivers:
        effort = (f", effort NOT UNIQUE (driver {', '.join(bad_efforts)})" if bad_efforts else ", effort UNIQUE")
    if _prescribed(report):
        fr = ", ".join(report.friction)
        reactions = (f"reaction of {', '.join(report.friction_on_nonunique)} NOT unique"
                     if report.friction_on_nonunique else "reactions unique")
        head = f"friction in {fr}: {reactions}, " if report.friction else "no friction: "
        return f"{head}motion prescribed by the drivers (unique){effort}"
    if not report.friction:
        return "no friction: motion unique" + effort
    fr = ", ".join(report.friction)
    if report.motion_unique:
        return f"friction in {fr}: reactions unique, motion UNIQUE{effort}"
    bad = ", ".join(report.friction_on_nonunique) or fr
    return f"friction in {fr}: friction on non-unique reaction(s) of {bad}, motion NOT UNIQUE{effort}"


def _refusal(path: Path, report: PrecheckResult) -> str:
    """Why ``build`` refuses friction on a non-unique reaction: the motion depends on the
    eliminated equations, or under a prescribed motion (drivers, DOF 0) the drivers' efforts."""
    head = (f"{path}: refused: friction on a joint whose reaction is not unique "
            f"({', '.join(report.friction_on_nonunique)}); ")
    if _prescribed(report):
        drivers = ", ".join(_bad_efforts(report) or report.drivers)
        why = (f"the motion is prescribed by the drivers, but the effort of driver {drivers} would depend on the "
               "eliminated equations (effort NOT UNIQUE)")
    else:
        why = "the simulated motion would depend on the eliminated equations"
    return head + why + " (--allow-nonunique builds it anyway)"


def _zip_write(zf: zipfile.ZipFile, name: str, data: bytes, mode: int = 0o644) -> None:
    info = zipfile.ZipInfo(name, date_time=_DATE)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = mode << 16
    zf.writestr(info, data)


class _NotBuilt(Exception):
    """A scene whose FMU is not built: its status ("skipped", "invalid", "refused", "failed") and
    messages for the :class:`BuildResult`."""

    def __init__(self, status: str, *messages: str):
        super().__init__(status)
        self.status, self.messages = status, messages


def build_scene(path: Path, out_dir: Path, *, allow_nonunique: bool = False, validate: bool = True,
                echo=print, sources=None, runtime: str = "c", fmi: int = 2, kind: str | None = None,
                binaries=None) -> BuildResult:
    """Build the FMU of one scene file (see the module docstring); never raises for bad input.
    ``runtime``: one of :data:`RUNTIMES`, every one building the C runtime (:func:`build_all` says
    that ``python`` is deprecated); ``kind`` None: the default (both); ``binaries``: (binaries/
    folder, file extension, bytes) of every platform the FMU carries (:func:`platform_binaries`),
    None for this machine's alone."""
    if runtime not in RUNTIMES:
        raise ValueError(f"runtime {runtime!r}: one of {', '.join(RUNTIMES)}")
    t0 = time.perf_counter()
    res = BuildResult(source=str(path), status="invalid")
    try:
        spec, model = _load_scene(path)
        res.name = spec.name
        report = _precheck_scene(path, spec, model, allow_nonunique, echo)
        res.motion_unique = bool(report.motion_unique)
        if report.friction_on_nonunique and not allow_nonunique:
            raise _NotBuilt("refused", _refusal(path, report))
        kinds = _kinds(spec, model, fmi, kind, echo)
        fmu, guid, table = _write_fmu(path, out_dir, spec, model, report, sources=sources, validate=validate,
                                      fmi=fmi, kinds=kinds, binaries=binaries)
    except _NotBuilt as exc:
        res.status = exc.status
        res.messages.extend(exc.messages)
        res.seconds = time.perf_counter() - t0
        return res
    res.fmu, res.guid, res.status = fmu, guid, "built"
    res.seconds = time.perf_counter() - t0
    n_out = len(model.output_names())
    n_par = sum(v.causality == "parameter" for v in table)
    echo(f"{spec.name}: built {fmu} ({n_out} outputs, {n_par} parameters, "
         f"{fmu.stat().st_size // 1024} KiB, runtime c) in {res.seconds:.2f} s")
    return res


def _kinds(spec: SceneSpec, model, fmi: int, kind: str | None, echo) -> tuple[str, ...]:
    """The interface kinds the FMU offers ("cs", "me"), or :class:`_NotBuilt` ("invalid") for a kind
    the scene cannot have (module docstring)."""
    wanted = ("cs", "me") if kind in (None, "both") else (kind,)
    if "me" in wanted and model.energy_outputs:
        if kind is not None:
            raise _NotBuilt("invalid", f"{spec.name}: --kind {kind} refused: Model Exchange does not carry the "
                                       "energy outputs ([outputs] energy = true; their work ledger integrates over "
                                       "the run's own steps): use --kind cs")
        echo(f"{spec.name}: co-simulation only (Model Exchange does not carry the energy outputs)")
        return ("cs",)
    return wanted


def _load_scene(path: Path):
    """(scene, admitted model) of a scene file; :class:`_NotBuilt` for a mechanism file (skipped),
    an invalid scene, or solver settings the FMU could never start with."""
    kind = scene_mod.is_scene_file(path)
    if kind is False:
        raise _NotBuilt("skipped", f"{path}: mechanism file, skipped")
    try:
        spec = scene_mod.load(path)
        if not isinstance(spec, SceneSpec):
            raise _NotBuilt("skipped", f"{path}: mechanism file, skipped")
        model = compile_checked(spec)
    except scene_mod.SceneError as exc:
        raise _NotBuilt("invalid", *(str(p) for p in exc.problems)) from exc
    except (ModelError, kernel_mod.KernelUnavailable, ValueError, OSError) as exc:
        raise _NotBuilt("invalid", f"{path}: {exc}") from exc
    for c in model.joints:  # the FMU integrates: the law overcon simulate refuses for integration
        if c.law is not None and c.law.name == "coulomb":
            raise _NotBuilt("invalid", f"{path}: joint {c.name}: friction law 'coulomb' (paper Fig. 1 variant A, "
                                       "mu sign(v)) is discontinuous at v = 0: for analysis only, not for "
                                       "integration, so no FMU; use 'regularised'")
    why = kernel_mod.support(model)  # the FMU's binary is the core: its coverage is the core's
    if why is not None:
        raise _NotBuilt("invalid", f"{path}: the compiled core cannot run this scene: {why}")
    return spec, model


def _precheck_scene(path: Path, spec: SceneSpec, model, allow_nonunique: bool, echo) -> PrecheckResult:
    report = precheck(model, str(path))
    echo(f"{spec.name}: pre-check: {_verdict(report)}")
    for problem in report.problems:
        echo(f"{spec.name}:   {problem}")
    return report


def _digest(parts, sources) -> str:
    """SHA-256 (hex) over ``parts`` (bytes) and the (relative path, bytes) ``sources``, each
    length-prefixed: the GUID's and the package name's source."""
    h = hashlib.sha256()
    for part in parts:
        h.update(len(part).to_bytes(8, "little") + part)
    for rel, data in sources:
        h.update(len(rel).to_bytes(8, "little") + rel.encode() + len(data).to_bytes(8, "little") + data)
    return h.hexdigest()


def _finish(path: Path, tmp: Path, fmu: Path, validate: bool) -> None:
    """Validate the written ``tmp`` (fmpy's checks of modelDescription.xml) when asked, then move
    it to ``fmu``; a problem removes it and refuses the build, naming the scene ``path``."""
    if validate:
        from fmpy.validation import validate_fmu  # noqa: PLC0415

        problems = validate_fmu(str(tmp))
        if problems:
            tmp.unlink()
            raise _NotBuilt("failed", *(f"{path}: modelDescription.xml: {p}" for p in problems))
    os.replace(tmp, fmu)


def _write_fmu(path: Path, out_dir: Path, spec: SceneSpec, model, report: PrecheckResult, *, sources,
               validate: bool, fmi: int = 2, kinds=("cs", "me"), binaries=None):
    """Write ``<out_dir>/<scene>.fmu`` (module docstring) through a ``.fmu.part`` file, validated
    with fmpy unless ``validate`` is false. Returns (FMU path, GUID, variable table);
    :class:`_NotBuilt` ("failed") naming the scene file otherwise."""
    try:
        mech_ref = tomllib.loads(path.read_text(encoding="utf-8"))["scene"]["mechanism"]
        scene_zip, mech_zip = _scene_layout(path, mech_ref)
        scene_bytes, mech_bytes = path.read_bytes(), (path.parent / mech_ref).read_bytes()
        sources = _source_files() if sources is None else sources
        plat, ext = _fmi_platform()
        if fmi == 3:
            plat = _fmi3_platform()
        if binaries is None:
            binaries = [(plat, ext, c_runtime_library(fmi))]
        c_files = c_sources(fmi)
        digest = _digest((FORMAT_VERSION.encode(), b"runtime c",
                          *(f"{folder}.{e}".encode() + b"\0" + data for folder, e, data in binaries),
                          scene_zip.encode(), scene_bytes, mech_zip.encode(), mech_bytes)
                         + ((f"fmi {fmi} kinds {','.join(kinds)}".encode(),) if (fmi, kinds) != (2, ("cs",)) else ()),
                         sources)
        guid = "{" + str(uuid.UUID(digest[:32])) + "}"
        table = variables.table(model, spec.solver, report.reaction_unique, bool(report.motion_unique), report.rank,
                                states="me" in kinds, fmi3=fmi == 3)
        overcon_version = _overcon_version()
        xml = description.model_description(
            spec, table, guid=guid, version=overcon_version, fmi=fmi, kinds=kinds,
            generation_tool=f"overcon {overcon_version} build_fmu (C runtime: the compiled core, no Python)",
            source_files=[rel for rel, _ in c_files if rel.endswith(".c")] if fmi == 2 else ())
        warnings = [(1, text) for text in friction_warnings(model)]
        model_bin = cmodel.model_file(model, spec.solver, table, guid, warnings)
        manifest = {"scene": scene_zip, "guid": guid, "runtime": "c", "model_identifier": spec.name,
                    "reaction_unique": report.reaction_unique, "motion_unique": bool(report.motion_unique),
                    "precheck_problems": list(report.problems), "precheck_warnings": list(report.warnings),
                    "fmi_version": fmi, "kinds": list(kinds),
                    "binary": {"platform": plat,
                               "library": (C_RUNTIME_LIBRARY3 if fmi == 3 else C_RUNTIME_LIBRARY).name,
                               "source": f"overcon/core, overcon/fmu/native/fmu_*.c, fmi{fmi}_*.c"},
                    "platforms": [folder for folder, _, _ in binaries],
                    "model_file": {"path": "resources/overcon_model.bin", "format": cmodel.FORMAT}}
        out_dir.mkdir(parents=True, exist_ok=True)
        fmu = out_dir / f"{spec.name}.fmu"
        tmp = fmu.with_suffix(".fmu.part")
        try:  # the .part removed on any way out but the rename (Ctrl-C included: overcon.outfiles)
            with zipfile.ZipFile(tmp, "w") as zf:
                _zip_write(zf, "modelDescription.xml", xml)
                for folder, e, data in binaries:
                    _zip_write(zf, f"binaries/{folder}/{spec.name}.{e}", data, 0o755)
                for rel, data in c_files:
                    _zip_write(zf, f"sources/{rel}", data)
                if fmi == 3:
                    _zip_write(zf, "sources/buildDescription.xml", build_description(spec.name, c_files))
                _zip_write(zf, "resources/overcon_model.bin", model_bin)
                _zip_write(zf, "resources/overcon_fmu.json", json.dumps(manifest, indent=1).encode())
                _zip_write(zf, facts.PATH, facts.encode(facts.record(spec, model, report)))
                _zip_write(zf, f"resources/{scene_zip}", scene_bytes)
                _zip_write(zf, f"resources/{mech_zip}", mech_bytes)
            _finish(path, tmp, fmu, validate)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
    except BuildError as exc:
        raise _NotBuilt("failed", f"{path}: build failed: {exc}") from exc
    except (OSError, ValueError, KeyError, RuntimeError) as exc:
        raise _NotBuilt("failed", f"{path}: build failed: {type(exc).__name__}: {exc}") from exc
    return fmu, guid, table


def c_sources(fmi: int) -> list[tuple[str, bytes]]:
    """(path under sources/, bytes) of the C files and headers of the FMU binary of FMI ``fmi``
    (overcon.fmu.platforms.source_files)."""
    return [(rel, f.read_bytes()) for rel, f in platforms_mod.source_files(fmi)]


def build_description(model_identifier: str, c_files) -> bytes:
    """FMI 3.0's sources/buildDescription.xml: the C files of ``c_files`` (C11), compiled with
    OVK_FMU_BINARY defined (the FMI functions alone exported under GCC and Clang) and linked with
    libm."""
    import xml.etree.ElementTree as ET  # noqa: PLC0415

    root = ET.Element("fmiBuildDescription", {"fmiVersion": "3.0"})
    bc = ET.SubElement(root, "BuildConfiguration", {"modelIdentifier": model_identifier})
    sfs = ET.SubElement(bc, "SourceFileSet", {"language": "C11"})
    for rel, _ in c_files:
        if rel.endswith(".c"):
            ET.SubElement(sfs, "SourceFile", {"name": rel})
    ET.SubElement(sfs, "PreprocessorDefinition", {
        "name": "OVK_FMU_BINARY", "value": "1",
        "description": "the core's entry points stay internal: the binary exports the FMI functions alone"})
    ET.SubElement(bc, "Library", {"name": "m", "description": "the C math library (libm)"})
    ET.indent(root)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n").encode()


def platform_binaries(platforms: str, fmi: int, echo=print) -> list[tuple[str, str, bytes]]:
    """(binaries/ folder, extension, bytes) of every platform of the ``--platforms`` list
    ``platforms`` that FMI ``fmi`` names (overcon.fmu.platforms: this machine's is the installed
    binary, checked; the others cross-compiled once and cached); the platforms FMI 2.0 has no
    folder for are left out, said through ``echo``. Raises
    :class:`overcon.fmu.platforms.PlatformsUnavailable` (bad input, exit 2) or
    :class:`overcon.fmu.platforms.PlatformBuildError` / :class:`BuildError`."""
    chosen = platforms_mod.parse(platforms)
    kept, left = platforms_mod.folders(chosen, fmi)
    if left:
        echo(f"build: FMI {fmi}.0 names no binaries folder for {', '.join(p.name for p in left)}: left out "
             f"(FMI 3.0 carries them: --fmi 3)")
    if not kept:
        raise platforms_mod.PlatformsUnavailable(f"--platforms {platforms}: none of these has an FMI {fmi}.0 "
                                                 "binaries folder")
    platforms_mod.require_cross(kept)
    version = _overcon_version()
    out = []
    for p in kept:
        data = platforms_mod.binary(p, fmi, version, native_binary=lambda: c_runtime_library(fmi), echo=echo)
        platforms_mod.check(p, fmi, data)
        out.append((p.folder(fmi), p.ext, data))
    return out


# ---------------------------------------------------------------------------------------------
# compatibility information

class ReferenceRunFailed(RuntimeError):
    """The reference simulation stopped before the default experiment's stop time."""


def write_reference(fmu: Path) -> tuple[Path, Path]:
    """Simulate ``fmu`` with fmpy at its default experiment; write ``<id>_ref.csv`` (time and
    every Real output, FMI cross-check CSV: quoted header, comma separated, full precision) and
    ``<id>_ref.opt`` next to it. A run that fails or ends before the stop time raises
    :class:`ReferenceRunFailed` naming the model, the time reached and the FMU's logged reason,
    and leaves no (stale) reference files. FMI 3.0 (scalar Float64 outputs) and Model-Exchange-only
    FMUs (fmpy's CVode at the default experiment's tolerance) are run by fmpy's own instantiation;
    their logged reasons come from fmpy's exception (fmpy keeps an FMI 3.0 instance's logger alive
    with the instance, so the caveat of _reference_callbacks does not apply)."""
    import fmpy  # noqa: PLC0415
    from fmpy.fmi2 import FMU2Slave  # noqa: PLC0415
    from fmpy.util import write_csv  # noqa: PLC0415

    md = fmpy.read_model_description(str(fmu))
    ex = md.defaultExperiment
    start, stop, step = float(ex.startTime), float(ex.stopTime), float(ex.stepSize)
    names = [v.name for v in md.modelVariables if v.causality == "output" and v.type in ("Real", "Float64")
             and not getattr(v, "dimensions", None)]
    fmi2_cs = md.fmiVersion == "2.0" and md.coSimulation is not None
    stem = (md.coSimulation or md.modelExchange).modelIdentifier
    csv_path, opt_path = fmu.parent / f"{stem}_ref.csv", fmu.parent / f"{stem}_ref.opt"
    for stale in (csv_path, opt_path):
        stale.unlink(missing_ok=True)
    messages = _reference_messages()
    messages.clear()
    unzipdir = tempfile.mkdtemp(prefix=f"{stem}_ref_")
    reached, failure = start, ""
    try:
        fmpy.extract(str(fmu), unzipdir)
        if fmi2_cs:
            instance = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=stem, instanceName=stem)
            instance.instantiate(callbacks=_reference_callbacks(), loggingOn=False)
            try:
                result = fmpy.simulate_fmu(unzipdir, output=names, output_interval=step, fmu_instance=instance)
            finally:
                instance.freeInstance()
        else:
            result = fmpy.simulate_fmu(unzipdir, output=names, output_interval=step)
        reached = float(result["time"][-1]) if len(result) else start
    except Exception as exc:  # fmpy raises on fmi2Error
        failure = f"{type(exc).__name__}: {exc}"
        reached = None
    finally:
        shutil.rmtree(unzipdir, ignore_errors=True)
    if failure or reached < stop - 1e-9 * max(1.0, abs(stop)):
        reason = "; ".join(messages) or failure or "no reason logged by the FMU"
        at = "" if reached is None else f" at t = {reached!r} s"
        raise ReferenceRunFailed(f"the reference run of {stem} (default experiment {start!r} to {stop!r} s) "
                                 f"stopped{at}: {reason}")
    from ..outfiles import atomic_path, write_text_atomic  # noqa: PLC0415
    with atomic_path(csv_path) as part:
        write_csv(str(part), result)
    write_text_atomic(opt_path, f"StartTime, {start!r}\nStopTime, {stop!r}\n"
                      f"StepSize, {step!r}\nRelTol, {float(ex.tolerance)!r}\n")
    return csv_path, opt_path


_REFERENCE_LOG: list[str] = []
_REFERENCE_CALLBACKS = []


def _reference_messages() -> list[str]:
    return _REFERENCE_LOG


def _reference_callbacks():
    """fmi2CallbackFunctions collecting discard/error/fatal messages into :data:`_REFERENCE_LOG`,
    made once and kept for the life of the process. (``fmpy.simulate_fmu(logger=...)`` is not
    used: fmpy's logging proxy keeps that logger in a global after the run, and the next FMU that
    logs through fmpy's default callbacks calls the freed function: a segmentation fault.)"""
    if not _REFERENCE_CALLBACKS:
        import fmpy  # noqa: PLC0415
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,  # noqa: PLC0415
                               fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)

        def logger(env, instance, status, category, message):
            if status >= 2:  # the message is a printf format without arguments
                _REFERENCE_LOG.append((message or b"").decode("utf-8", "replace").replace("%%", "%"))

        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(logger)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
        _REFERENCE_CALLBACKS.extend([cb, logger])
    return _REFERENCE_CALLBACKS[0]


def _reference_job(fmu: str) -> tuple[str, str, float]:
    t0 = time.perf_counter()
    try:
        write_reference(Path(fmu))
    except ReferenceRunFailed as exc:  # reported by the parent
        return fmu, str(exc), time.perf_counter() - t0
    except Exception as exc:
        return fmu, f"{type(exc).__name__}: {exc}", time.perf_counter() - t0
    return fmu, "", time.perf_counter() - t0


# ---------------------------------------------------------------------------------------------
# many FMUs

def build_all(paths, out_dir, *, allow_nonunique: bool = False, refs: bool = True,
              validate: bool = True, jobs: int | None = None, echo=None, echo_err=None,
              runtime: str = "c", fmi: int = 2, kind: str | None = None,
              platforms: str = "native") -> tuple[int, list[BuildResult]]:
    """Build every scene in ``paths`` (files or directories) into ``out_dir``; print progress with
    ``echo`` (problems with ``echo_err``). ``runtime``: "c", or "python", a deprecated alias of it
    (said through ``echo_err``; module docstring); ``fmi`` 2 or 3 and ``kind`` "cs", "me", "both"
    or None (the default: both; module docstring); ``platforms``: the ``--platforms`` list
    (:func:`platform_binaries`; every binary is made before the first FMU). Returns (exit code,
    results)."""
    if runtime not in RUNTIMES:
        raise ValueError(f"runtime {runtime!r}: one of {', '.join(RUNTIMES)}")
    if fmi not in FMI_VERSIONS or kind not in (None, *KINDS):
        raise ValueError(f"fmi {fmi!r}, kind {kind!r}: fmi one of {FMI_VERSIONS}, kind one of {KINDS}")
    echo = echo or (lambda s: print(s, flush=True))
    echo_err = echo_err or (lambda s: print(s, file=sys.stderr, flush=True))
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    files = scene_mod.toml_files(paths)
    results: list[BuildResult] = []
    if not files:
        echo_err("build: no scene files given")
        return EXIT_INPUT, results
    if runtime == "python":
        echo_err("build: WARNING: --runtime python is deprecated: the FMU that embedded Python is retired, and "
                 "this builds the C runtime (no Python in the FMU), as --runtime c does")
    try:
        binaries = None if platforms == "native" else platform_binaries(platforms, fmi, echo)
    except platforms_mod.PlatformsUnavailable as exc:
        echo_err(f"build: {exc}")
        return EXIT_INPUT, results
    except (platforms_mod.PlatformBuildError, BuildError, OSError) as exc:
        echo_err(f"build: the binaries of --platforms {platforms} failed: {exc}")
        return EXIT_INPUT, results
    sources = _source_files()
    names: dict[str, str] = {}
    for f in files:
        r = build_scene(f, out_dir, allow_nonunique=allow_nonunique, validate=validate, echo=echo,
                        sources=sources, runtime=runtime, fmi=fmi, kind=kind, binaries=binaries)
        if r.status == "built" and r.name in names:
            r.status = "failed"
            r.messages.append(f"{f}: scene name {r.name} already built from {names[r.name]} "
                              f"(the FMU {r.fmu} was overwritten)")
        if r.status == "built":
            names[r.name] = str(f)
        for m in r.messages:
            (echo if r.status == "skipped" else echo_err)(m)
        results.append(r)
    t_build = time.perf_counter() - t0
    built = [r for r in results if r.status == "built"]
    t_ref = 0.0
    if refs and built:
        t1 = time.perf_counter()
        _write_references(built, jobs, echo, echo_err)
        t_ref = time.perf_counter() - t1
    counts = {s: sum(r.status == s for r in results) for s in ("built", "refused", "skipped", "invalid", "failed")}
    ref_failed = sum(r.ref_status == "failed" for r in results)
    summary = (f"build: {counts['built']} FMU(s) built, {counts['refused']} refused by the pre-check, "
               f"{counts['invalid'] + counts['failed']} failed, "
               + (f"{ref_failed} reference run(s) failed, " if refs and built else "")
               + f"{counts['skipped']} mechanism file(s) skipped; FMUs built in {t_build:.2f} s")
    if refs and built:
        summary += f", reference results in {t_ref:.1f} s"
    echo(summary + f" (total {time.perf_counter() - t0:.1f} s)")
    if counts["invalid"] or counts["failed"]:
        return EXIT_INPUT, results
    if ref_failed:
        return EXIT_RUNTIME, results
    return (EXIT_NONUNIQUE if counts["refused"] else EXIT_OK), results


def _write_references(built: list[BuildResult], jobs: int | None, echo, echo_err) -> None:
    """The compatibility files of every built FMU, in ``jobs`` processes (default: one per CPU);
    each result's ``ref_status`` set, each outcome printed."""
    n = max(1, min(jobs or os.cpu_count() or 1, len(built)))
    echo(f"reference results (fmpy.simulate_fmu at the default experiment, {n} process(es)) ...")
    by_fmu = {str(r.fmu): r for r in built}
    if n == 1:
        outcomes = map(_reference_job, by_fmu)
    else:
        import multiprocessing  # noqa: PLC0415

        pool = concurrent.futures.ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("spawn"))
        outcomes = pool.map(_reference_job, by_fmu)
    for fmu, err, secs in outcomes:
        r = by_fmu[fmu]
        if err:
            r.ref_status = "failed"
            echo_err(f"{r.name}: reference simulation failed: {err}")
        else:
            r.ref_status = "written"
            echo(f"{r.name}: wrote {r.name}_ref.csv and {r.name}_ref.opt ({secs:.1f} s)")
    if n > 1:
        pool.shutdown()


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("paths", nargs="+", metavar="PATH",
                   help="scene files or directories of them (mechanism files are skipped)")
    p.add_argument("--out", default="dist/fmus", metavar="DIR", help="output directory (default dist/fmus)")
    p.add_argument("--allow-nonunique", action="store_true",
                   help="also build scenes with friction on a joint whose reaction is not unique")
    p.add_argument("--no-ref", action="store_true",
                   help="skip the compatibility files <Model>_ref.csv/.opt (they need a full simulation)")
    p.add_argument("--no-validate", action="store_true", help="skip fmpy's validation of each FMU")
    p.add_argument("--jobs", type=_jobs, metavar="N",
                   help="processes for the reference simulations (default: number of CPUs)")
    p.add_argument("--runtime", choices=RUNTIMES, default="c",
                   help="c (default): the FMU runs the compiled core, without Python; python: deprecated alias "
                        "of c (warns on stderr)")
    p.add_argument("--fmi", type=int, choices=FMI_VERSIONS, default=2,
                   help="FMI version of the FMUs: 2 (FMI 2.0) or 3 (FMI 3.0) (default 2)")
    p.add_argument("--kind", choices=KINDS, default=None,
                   help="interfaces the FMU offers: cs (co-simulation), me (Model Exchange) or both (default both)")
    p.add_argument("--platforms", default="native", metavar="LIST",
                   help="the binaries the FMU carries, comma separated: native (default: this machine's), "
                        + ", ".join(platforms_mod.PLATFORMS) + " or all; other platforms than this machine's are "
                        f"cross-compiled once and cached (needs {platforms_mod.EXTRA}); FMI 2.0 leaves out "
                        "aarch64-linux and aarch64-darwin (docs/platforms.md)")



def run_args(args) -> int:
    code, _ = build_all(args.paths, args.out, allow_nonunique=args.allow_nonunique,
                        refs=not args.no_ref, validate=not args.no_validate, jobs=args.jobs,
                        runtime=getattr(args, "runtime", "c"), fmi=getattr(args, "fmi", 2),
                        kind=getattr(args, "kind", None), platforms=getattr(args, "platforms", "native"))
    return code


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="build_fmu.py",
        description="Build one FMU per scene file (pre-check first).")
    add_arguments(p)
    return run_args(p.parse_args(argv))
