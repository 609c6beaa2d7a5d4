"""FMUs that travel (docs/platforms.md): the binaries an FMU carries, read from their bytes and run.

Default run (no cross-compiler needed): the installed FMU binaries export the FMI functions alone
and need nothing newer than glibc 2.17 (read by overcon.fmu.binfmt and, where binutils is
installed, by ``objdump -T`` too), the core library keeps its ``ovk_*`` entry points, an FMU
carries its sources, ``--platforms`` without the extra or with a bad name is exit 2.

``-m platforms`` (``.ci/run``'s platforms stage; skipped otherwise, and skipped when zig, wine or
qemu is missing unless ``OVERCON_PLATFORMS_REQUIRED=1``, which ``.ci/run`` sets): planar_f45_wo4
and spatial_MN_wo5 built with ``--platforms all`` for FMI 2.0 and 3.0; fmpy validates them; every
binary of every platform exports the FMI functions alone (ELF and PE also read by objdump), Linux
ones need at most glibc 2.17, macOS ones are Mach-O of the right architecture importing libSystem
alone (they cannot run here); the win64 binaries run under wine and the aarch64-linux one under
qemu-aarch64 in the C hosts (tests/c_host) cross-compiled with the same zig, to the scenes' stop
times, their positions within 1e-7 m of the native Linux run; an FMU whose binaries were removed,
compiled from its sources by ``fmpy.build.build_platform_binary``, gives the shipped binary's
results to 1e-9; the per-platform binaries are cached (a second build compiles nothing).
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from overcon.fmu import binfmt
from overcon.fmu import build as build_mod
from overcon.fmu import platforms as P

ROOT = Path(__file__).resolve().parent.parent
MECH = ROOT / "mechanisms"
HOSTS = ROOT / "tests" / "c_host"
SCENES = ("planar_f45_wo4", "spatial_MN_wo5")
REQUIRED = os.environ.get("OVERCON_PLATFORMS_REQUIRED") == "1"
LINUX_X86 = sys.platform.startswith("linux") and P._native_or_none() == P.PLATFORMS["linux64"]


def need(ok: bool, what: str) -> None:
    """Skip (fail under OVERCON_PLATFORMS_REQUIRED=1) when a tool of these tests is missing."""
    if not ok:
        if REQUIRED:
            pytest.fail(f"OVERCON_PLATFORMS_REQUIRED=1 but {what} is missing (.ci/run installs it)")
        pytest.skip(f"needs {what}")


def objdump_dynamic(path: Path) -> tuple[list[str], set[str]]:
    """(defined exported names, GLIBC versions) from ``objdump -T``."""
    out = subprocess.run(["objdump", "-T", str(path)], capture_output=True, text=True, check=True).stdout
    exports, versions = [], set(re.findall(r"\((GLIBC_[0-9.]+)\)", out))
    for line in out.splitlines():
        parts = line.split()
        if len(parts) >= 6 and parts[2] in ("DF", "DO") and "*UND*" not in line:
            exports.append(parts[-1])
    return sorted(exports), versions


def objdump_pe_exports(path: Path) -> list[str]:
    """The names of a DLL's export table, from ``objdump -p``."""
    out = subprocess.run(["objdump", "-p", str(path)], capture_output=True, text=True, check=True).stdout
    table = out.split("[Ordinal/Name Pointer] Table", 1)[1].split("\n\n", 1)[0]
    return sorted(m.group(1) for m in re.finditer(r"\]\s+(\w+)\s*$", table, re.M))


# ---------------------------------------------------------------------------------------------
# default run: the installed binaries, the FMU's sources, bad input

@pytest.mark.parametrize("fmi", [2, 3])
def test_installed_fmu_binary_exports_fmi_alone_and_needs_glibc_217(fmi):
    path = build_mod.C_RUNTIME_LIBRARY3 if fmi == 3 else build_mod.C_RUNTIME_LIBRARY
    facts = binfmt.inspect(path.read_bytes())
    assert facts.exports and all(e.startswith(f"fmi{fmi}") for e in facts.exports), facts.exports
    assert f"fmi{fmi}DoStep" in facts.exports
    if facts.format == "elf":
        assert facts.glibc_max() <= (2, 17), facts.versions
        if shutil.which("objdump"):
            exports, versions = objdump_dynamic(path)
            assert exports == facts.exports  # the reader and binutils agree
            assert max(tuple(map(int, v[6:].split("."))) for v in versions) <= (2, 17), versions
    P.check(P.native(), fmi, path.read_bytes())  # the rule the build applies


def test_core_library_keeps_its_entry_points():
    """libovercore (ctypes, overcon.kernel) is no FMU binary: its ovk_* functions stay exported."""
    from overcon.kernel import LIBRARY  # noqa: PLC0415

    exports = binfmt.inspect(LIBRARY.read_bytes()).exports
    assert "ovk_abi" in exports and len([e for e in exports if e.startswith("ovk_")]) >= 20


def test_check_refuses_a_binary_that_exports_more(tmp_path):
    from overcon.kernel import LIBRARY  # noqa: PLC0415

    with pytest.raises(P.PlatformBuildError, match="exports ovk_"):
        P.check(P.native(), 2, LIBRARY.read_bytes())


def test_binfmt_refuses_what_is_no_library():
    with pytest.raises(binfmt.BinaryFormatError):
        binfmt.inspect(b"#!/bin/sh\n")
    with pytest.raises(binfmt.BinaryFormatError):
        binfmt.inspect(b"\x7fELF\x02\x01" + b"\0" * 30)  # truncated


@pytest.mark.integration
@pytest.mark.parametrize("fmi", [2, 3])
def test_fmu_carries_its_sources(tmp_path, fmi):
    code, res = build_mod.build_all([str(MECH / "planar_f45_wo4.toml")], tmp_path, refs=False, fmi=fmi,
                                    echo=lambda s: None, echo_err=lambda s: None)
    assert code == 0
    import fmpy  # noqa: PLC0415

    fmu = res[0].fmu
    names = zipfile.ZipFile(fmu).namelist()
    c_files = sorted(n[len("sources/"):] for n in names if n.startswith("sources/") and n.endswith(".c"))
    assert "core/sim.c" in c_files and f"fmu/native/fmi{fmi}_core.c" in c_files
    assert not [c for c in c_files if c.startswith(f"fmu/native/fmi{5 - fmi}_")]  # the other version's layer
    assert "sources/core/core.h" in names and "sources/fmu/native/fmu_common.h" in names
    md = fmpy.read_model_description(str(fmu))  # FMI 3.0: reads and validates buildDescription.xml
    assert sorted(md.buildConfigurations[0].sourceFileSets[0].sourceFiles) == c_files
    xml = zipfile.ZipFile(fmu).read("modelDescription.xml").decode()
    assert 'needsExecutionTool="true"' not in xml and 'needsExecutionTool="false"' in xml
    if fmi == 3:
        assert "sources/buildDescription.xml" in names
        assert md.buildConfigurations[0].sourceFileSets[0].language == "C11"


def test_platforms_without_the_extra_is_exit_2(tmp_path, monkeypatch):
    monkeypatch.setattr(P, "zig_command", lambda: None)
    other = "win64" if P._native_or_none() != P.PLATFORMS["win64"] else "linux64"
    said = []
    code, _ = build_mod.build_all([str(MECH / "planar_f45_wo4.toml")], tmp_path, refs=False, platforms=other,
                                  echo=said.append, echo_err=said.append)
    assert code == build_mod.EXIT_INPUT
    assert any("overcon[platforms]" in s and other in s for s in said), said
    assert not list(tmp_path.glob("*.fmu"))


def test_platforms_bad_name_is_exit_2_through_the_cli(tmp_path, capsys):
    from overcon.cli import main  # noqa: PLC0415

    code = main(["build", str(MECH / "planar_f45_wo4.toml"), "--out", str(tmp_path), "--no-ref",
                 "--platforms", "linux64,amiga"])
    assert code == 2
    assert "'amiga'" in capsys.readouterr().err


@pytest.mark.skipif(not LINUX_X86, reason="the native platform here is linux64")
def test_fmi2_leaves_out_the_platforms_it_has_no_folder_for(tmp_path):
    said = []
    code, res = build_mod.build_all([str(MECH / "planar_f45_wo4.toml")], tmp_path, refs=False,
                                    platforms="linux64,aarch64-linux", echo=said.append, echo_err=said.append)
    assert code == 0, said
    assert any("left out" in s and "aarch64-linux" in s for s in said), said
    names = zipfile.ZipFile(res[0].fmu).namelist()
    assert [n for n in names if n.startswith("binaries/")] == ["binaries/linux64/planar_f45_wo4.so"]


def test_parse_and_folders():
    assert [p.name for p in P.parse("all")] == list(P.PLATFORMS)
    assert [p.name for p in P.parse("win64, linux64,win64")] == ["linux64", "win64"]
    kept, left = P.folders(P.parse("all"), 2)
    assert [p.folder(2) for p in kept] == ["linux64", "win64", "darwin64"]
    assert [p.name for p in left] == ["aarch64-linux", "aarch64-darwin"]
    assert [p.folder(3) for p in P.parse("all")] == ["x86_64-linux", "aarch64-linux", "x86_64-windows",
                                                       "x86_64-darwin", "aarch64-darwin"]
    with pytest.raises(P.PlatformsUnavailable):
        P.parse("")


def test_cache_key_follows_sources_and_flags(monkeypatch):
    monkeypatch.setattr(P, "zig_version", lambda: "0.0-test")
    p = P.PLATFORMS["win64"]
    key = P.cache_key(p, 2, "1.0")
    assert key == P.cache_key(p, 2, "1.0")
    assert key != P.cache_key(p, 3, "1.0") and key != P.cache_key(p, 2, "1.1")
    assert key != P.cache_key(P.PLATFORMS["darwin64"], 2, "1.0")
    monkeypatch.setattr(P, "CFLAGS", [*P.CFLAGS, "-DX"])
    assert P.cache_key(p, 2, "1.0") != key
    monkeypatch.undo()
    monkeypatch.setattr(P, "zig_version", lambda: "0.0-test")
    real = P.source_files(2)
    monkeypatch.setattr(P, "source_files", lambda fmi: real[:-1])
    assert P.cache_key(p, 2, "1.0") != key


# ---------------------------------------------------------------------------------------------
# -m platforms: every platform, built, read and run

def zig():
    need(P.zig_command() is not None, f"the zig compiler ({P.EXTRA})")
    return [*P.zig_command(), "cc"]


@pytest.fixture(scope="module")
def all_fmus(tmp_path_factory):
    """{fmi: {scene: FMU path}} built with --platforms all (binaries from the cache, compiled once)."""
    zig()
    out = {}
    for fmi in (2, 3):
        d = tmp_path_factory.mktemp(f"all{fmi}")
        said = []
        code, res = build_mod.build_all([str(MECH / f"{s}.toml") for s in SCENES], d, refs=False, fmi=fmi,
                                        platforms="all", echo=said.append, echo_err=said.append)
        assert code == 0, "\n".join(said)
        out[fmi] = {r.name: r.fmu for r in res}
    return out


@pytest.fixture(scope="module")
def unzipped(all_fmus, tmp_path_factory):
    import fmpy  # noqa: PLC0415

    return {(fmi, s): Path(fmpy.extract(str(f), str(tmp_path_factory.mktemp(f"u{fmi}_{s}"))))
            for fmi, fmus in all_fmus.items() for s, f in fmus.items()}


FOLDERS = {2: ["darwin64", "linux64", "win64"],
           3: ["aarch64-darwin", "aarch64-linux", "x86_64-darwin", "x86_64-linux", "x86_64-windows"]}


@pytest.mark.platforms
@pytest.mark.parametrize("fmi", [2, 3])
def test_all_platforms_fmu_is_valid_and_complete(all_fmus, fmi):
    from fmpy.validation import validate_fmu  # noqa: PLC0415

    for scene, fmu in all_fmus[fmi].items():
        assert validate_fmu(str(fmu)) == []
        names = zipfile.ZipFile(fmu).namelist()
        folders = sorted({n.split("/")[1] for n in names if n.startswith("binaries/")})
        assert folders == FOLDERS[fmi]
        assert any(n.startswith("sources/core/") for n in names)


@pytest.mark.platforms
@pytest.mark.parametrize("fmi", [2, 3])
def test_every_binary_exports_fmi_alone(unzipped, fmi):
    by_folder = {p.folder(fmi): p for p in P.PLATFORMS.values() if p.folder(fmi)}
    root = unzipped[(fmi, "planar_f45_wo4")]
    for folder in FOLDERS[fmi]:
        p = by_folder[folder]
        path = root / "binaries" / folder / f"planar_f45_wo4.{p.ext}"
        facts = binfmt.inspect(path.read_bytes())
        assert (facts.format, facts.arch) == (p.fmt, p.arch)
        own = [e for e in facts.exports if not (p.fmt == "macho" and e in P.MACHO_LINKER_SYMBOLS)]
        assert f"fmi{fmi}DoStep" in own and all(e.startswith(f"fmi{fmi}") for e in own), own
        if p.fmt == "elf":
            assert facts.glibc_max() <= (2, 17), facts.versions
            assert set(facts.imports) <= {"libc.so.6", "libm.so.6"}
            if shutil.which("objdump"):
                exports, versions = objdump_dynamic(path)
                assert exports == facts.exports
                assert all(tuple(map(int, v[6:].split("."))) <= (2, 17) for v in versions), versions
        elif p.fmt == "pe":
            if shutil.which("objdump"):
                assert objdump_pe_exports(path) == facts.exports
            assert all(i.lower() == "kernel32.dll" or i.lower().startswith("api-ms-win-crt-") for i in facts.imports)
        else:  # macOS: read, not run (no macOS here)
            assert facts.imports == ["/usr/lib/libSystem.B.dylib"]


def host_exe(tmp_path_factory, name: str, source: str, target: str | None) -> Path:
    """A C host (tests/c_host) compiled for ``target`` with zig (None: this machine's cc)."""
    d = tmp_path_factory.mktemp(f"host_{name}")
    exe = d / name
    cmd = ([*zig(), "-target", target] if target else [shutil.which("cc") or "cc"]) + \
        ["-O2", "-Wall", "-Werror", "-o", str(exe), str(HOSTS / source)]
    if not target or "linux" in target:
        cmd += ["-ldl", "-lm"]
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=d, timeout=900)
    assert run.returncode == 0, run.stderr
    return exe


def positions(root: Path, every: bool = False):
    """(the position outputs (unit m; ``every``: every scalar Real output), the instantiation
    token, the default experiment)."""
    import fmpy  # noqa: PLC0415

    md = fmpy.read_model_description(str(root))
    pos = [v for v in md.modelVariables if v.causality == "output" and v.type in ("Real", "Float64")
           and (every or v.unit == "m") and not v.dimensions]
    ex = md.defaultExperiment
    token = md.guid if md.fmiVersion == "2.0" else md.instantiationToken
    return pos, token, ex


def run(cmd, root: Path, scene: str, fmi: int, timeout=900, every=False):
    pos, token, ex = positions(root, every)
    args = ["-q", str(root), scene, token, "0", repr(float(ex.stopTime)), repr(float(ex.stepSize)),
            repr(float(ex.tolerance)), *(f"{v.valueReference}:{v.name}" for v in pos)]
    proc = subprocess.run([*cmd, *args], capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"{cmd[0]} exit {proc.returncode}: {proc.stderr[-2000:]}"
    rows = np.array([[float(x) for x in line.split(",")] for line in proc.stdout.splitlines()[1:]])
    assert rows[-1, 0] == pytest.approx(float(ex.stopTime), abs=1e-9)  # ran to the stop time
    return rows


@pytest.fixture(scope="module")
def native_hosts(tmp_path_factory):
    need(LINUX_X86, "a Linux x86_64 machine (the native reference run)")
    return {2: host_exe(tmp_path_factory, "fmu_host", "fmu_host.c", None),
            3: host_exe(tmp_path_factory, "fmu_host3", "fmu_host3.c", None)}


@pytest.mark.platforms
@pytest.mark.parametrize("fmi", [2, 3])
def test_windows_binary_under_wine_agrees_with_native(unzipped, native_hosts, tmp_path_factory, fmi):
    wine = shutil.which("wine64") or shutil.which("wine")
    need(wine is not None, "wine (Debian's wine64)")
    exe = host_exe(tmp_path_factory, f"fmu_host{'3' if fmi == 3 else ''}.exe",
                   "fmu_host3.c" if fmi == 3 else "fmu_host.c", "x86_64-windows-gnu")
    os.environ.setdefault("WINEDEBUG", "-all")
    for scene in SCENES:
        root = unzipped[(fmi, scene)]
        ref = run([str(native_hosts[fmi])], root, scene, fmi)
        got = run([wine, str(exe)], root, scene, fmi)
        assert got.shape == ref.shape
        assert np.max(np.abs(got[:, 1:] - ref[:, 1:])) <= 1e-7, (scene, np.max(np.abs(got[:, 1:] - ref[:, 1:])))


@pytest.mark.platforms
def test_aarch64_binary_under_qemu_agrees_with_native(unzipped, native_hosts, tmp_path_factory):
    qemu = shutil.which("qemu-aarch64-static")
    need(qemu is not None and Path("/usr/aarch64-linux-gnu/lib").is_dir(),
         "qemu-aarch64-static and the aarch64 C library (Debian's qemu-user-static, libc6-arm64-cross)")
    exe = host_exe(tmp_path_factory, "fmu_host3_aarch64", "fmu_host3.c", "aarch64-linux-gnu.2.17")
    for scene in SCENES:
        root = unzipped[(3, scene)]
        ref = run([str(native_hosts[3])], root, scene, 3)
        got = run([qemu, "-L", "/usr/aarch64-linux-gnu", str(exe)], root, scene, 3)
        assert got.shape == ref.shape
        assert np.max(np.abs(got[:, 1:] - ref[:, 1:])) <= 1e-7, (scene, np.max(np.abs(got[:, 1:] - ref[:, 1:])))


@pytest.mark.platforms
@pytest.mark.parametrize("fmi", [2, 3])
def test_fmu_rebuilt_from_its_sources_by_fmpy_agrees(unzipped, native_hosts, tmp_path_factory, fmi):
    need(shutil.which("cmake") is not None, "cmake (fmpy.build compiles with it)")
    from fmpy.build import build_platform_binary  # noqa: PLC0415

    scene = "planar_f45_wo4"
    shipped = unzipped[(fmi, scene)]
    src = tmp_path_factory.mktemp(f"fromsrc{fmi}") / "fmu"
    shutil.copytree(shipped, src)
    shutil.rmtree(src / "binaries")
    proc = subprocess.run([sys.executable, "-c", "import sys; from fmpy.build import build_platform_binary as b; "
                           "b(sys.argv[1])", str(src)], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert build_platform_binary  # the API the issue names
    ref = run([str(native_hosts[fmi])], shipped, scene, fmi, every=True)
    got = run([str(native_hosts[fmi])], src, scene, fmi, every=True)
    assert got.shape == ref.shape and ref.shape[1] > 10
    assert np.all(np.abs(got - ref) <= 1e-9 * np.maximum(1.0, np.abs(ref)))


@pytest.mark.platforms
def test_second_build_compiles_nothing(all_fmus, tmp_path):
    said = []
    code, _ = build_mod.build_all([str(MECH / "planar_f45_wo4.toml")], tmp_path, refs=False, fmi=3,
                                  platforms="all", echo=said.append, echo_err=said.append)
    assert code == 0
    assert not [s for s in said if s.startswith("compiling")], said
