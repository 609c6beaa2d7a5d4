"""Compiles overcon's C core (fmu_src/overcon/core/*.c) into overcon/core/libovercore.<so|dylib|dll>
when the package is installed (``pip install .``, ``pip install -e .``), and the binary of the FMUs
that run without Python (the core and the FMI layer fmu_src/overcon/fmu/native/fmu_*.c, fmi2_*.c) into
overcon/fmu/native/libovercon_fmi2.<so|dylib|dll> (FMI 2.0) and, from the same shared files fmu_*.c with
the FMI 3.0 layer fmi3_*.c, libovercon_fmi3.<so|dylib|dll>, which ``overcon build`` copies into such an FMU;
everything else about the package is in pyproject.toml.

The core is a plain C library (C11 and libm, no Python API), loaded through ctypes by
overcon.kernel and copied into every FMU by ``overcon build``. So it is declared as an Extension
(the wheel is platform-specific, an editable install builds it in place, the sdist carries its
sources) but compiled by :class:`BuildCore` with exactly the core's flags (:data:`CFLAGS`) and
none of the interpreter's own build flags (sysconfig's ``-O3 -g``, rpaths, libpython), and named
without a CPython tag: the same bytes work for every interpreter and outside Python.

Compiler: ``$CC``, else the compiler this Python was built with (sysconfig ``CC``) when it is on
PATH, else ``cc``;
it must take gcc-style flags (gcc, clang). ``CFLAGS`` from the environment is not used: the flags
are part of the numbers (``-ffp-contract=off -fno-fast-math``: no fused multiply-add, no
reassociation, so the results do not depend on the CPU's FMA support).
"""
import importlib.util
import os
import shlex
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.errors import CompileError

CORE = Path("fmu_src") / "overcon" / "core"
SOURCES = sorted(str(p.as_posix()) for p in CORE.glob("*.c"))
HEADERS = sorted(str(p.as_posix()) for p in CORE.glob("*.h"))
FMI = Path("fmu_src") / "overcon" / "fmu" / "native"
FMI_COMMON = sorted(str(p.as_posix()) for p in FMI.glob("fmu_*.c"))
FMI_SOURCES = FMI_COMMON + sorted(str(p.as_posix()) for p in FMI.glob("fmi2_*.c"))
FMI3_SOURCES = FMI_COMMON + sorted(str(p.as_posix()) for p in FMI.glob("fmi3_*.c"))
FMI_HEADERS = sorted(str(p.as_posix()) for p in FMI.glob("*.h"))
_spec = importlib.util.spec_from_file_location("_overcon_platforms", Path("fmu_src") / "overcon" / "fmu" / "platforms.py")
PLATFORMS = sys.modules[_spec.name] = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(PLATFORMS)  # stdlib only at import: the flags shared with the cross-compiled binaries
CFLAGS = PLATFORMS.CFLAGS
FMU_FLAGS = PLATFORMS.FMU_FLAGS  # an FMU binary exports the FMI functions alone
SHARED = ["-shared", "-fPIC"]
LIBS = ["-lm"]


def shared_suffix() -> str:
    return ".dll" if sys.platform == "win32" else ".dylib" if sys.platform == "darwin" else ".so"


def compiler() -> list:
    """``$CC``; else the compiler Python was built with, when it is on PATH; else ``cc``."""
    if os.environ.get("CC"):
        return shlex.split(os.environ["CC"])
    built_with = shlex.split(sysconfig.get_config_var("CC") or "")
    return built_with if built_with and shutil.which(built_with[0]) else ["cc"]


class BuildCore(build_ext):
    """build_ext for the core: one shared library, compiled and linked in one command."""

    def get_ext_filename(self, fullname):
        return os.path.join(*fullname.split(".")) + shared_suffix()

    def get_export_symbols(self, ext):
        return []  # a plain C library: no PyInit_ function

    def build_extension(self, ext):
        out = Path(self.get_ext_fullpath(ext.name))
        out.parent.mkdir(parents=True, exist_ok=True)
        cc = compiler()
        if not cc or shutil.which(cc[0]) is None:
            raise CompileError(f"overcon's C core needs a C compiler: {' '.join(cc) or 'cc'} not found "
                               "(install gcc or clang, or set CC)")
        fmu = []
        if ext.name.startswith("overcon.fmu."):
            fmu = list(FMU_FLAGS)
            if sys.platform.startswith("linux"):
                fmu.append(f"-Wl,--version-script={PLATFORMS.EXPORTS_MAP}")
        cmd = [*cc, *CFLAGS, *fmu, *SHARED, "-o", str(out), *ext.sources, *LIBS]
        print(shlex.join(cmd))
        run = subprocess.run(cmd, capture_output=True, text=True)
        if run.returncode != 0:
            said = (run.stderr.strip() or run.stdout.strip())[-4000:] or "no output"
            raise CompileError(f"compiling overcon's C core failed ({shlex.join(cmd)}): exit status "
                               f"{run.returncode}:\n{said}")


setup(
    ext_modules=[Extension("overcon.core.libovercore", sources=SOURCES, depends=HEADERS),
                 Extension("overcon.fmu.native.libovercon_fmi2", sources=SOURCES + FMI_SOURCES,
                           depends=HEADERS + FMI_HEADERS + [str(PLATFORMS.EXPORTS_MAP)]),
                 Extension("overcon.fmu.native.libovercon_fmi3", sources=SOURCES + FMI3_SOURCES,
                           depends=HEADERS + FMI_HEADERS + [str(PLATFORMS.EXPORTS_MAP)])],
    cmdclass={"build_ext": BuildCore},
)
