"""What the FMU binary needs to start a Python interpreter: its shared libpython, its home
(``sys.base_prefix``) and the site-packages that hold numpy and scipy.

Standard library only. :func:`text` gives ``key=value`` lines (``python``, ``version`` (major.minor),
``libpython``, ``home``, ``site`` repeated); the builder writes them for the building interpreter into the FMU's
``resources/overcon_python.txt``, and the FMU binary runs this file as a script with the
interpreter named by ``OVERCON_PYTHON`` (``python -I pyinfo.py``) to get the same lines for it.
"""
from __future__ import annotations

import importlib.util
import os
import site
import sys
import sysconfig

NEEDED = ("numpy", "scipy")


def libpython() -> tuple[str, bool]:
    """(path of the shared libpython, found). Not found (a Python built without
    ``--enable-shared``): the bare soname, left to the dynamic loader's search path."""
    v = sysconfig.get_config_var
    names = [n for n in (v("INSTSONAME"), v("LDLIBRARY")) if n and ".so" in n]
    dirs = [d for d in (v("LIBDIR"), os.path.join(v("LIBDIR") or "", v("MULTIARCH") or ""), v("LIBPL"),
                        os.path.join(sys.base_prefix, "lib")) if d]
    for name in names:
        for d in dirs:
            path = os.path.join(d, name)
            if os.path.isfile(path):
                return path, True
    return (names[0] if names else f"libpython{v('LDVERSION')}.so"), False


def site_dirs() -> list[str]:
    """The interpreter's site-packages, then any other folder numpy or scipy is imported from."""
    dirs = list(site.getsitepackages())
    if site.ENABLE_USER_SITE:
        dirs.append(site.getusersitepackages())
    for mod in NEEDED:
        spec = importlib.util.find_spec(mod)
        if spec is not None and spec.origin:
            d = os.path.dirname(os.path.dirname(os.path.abspath(spec.origin)))
            if d not in dirs:
                dirs.append(d)
    return [d for d in dirs if os.path.isdir(d)]


def parse(text: str) -> dict[str, list[str]]:
    """The lines of :func:`text` as {key: [values]}."""
    out: dict[str, list[str]] = {}
    for line in text.splitlines():
        key, sep, value = line.partition("=")
        if sep and not line.startswith("#"):
            out.setdefault(key, []).append(value)
    return out


def text() -> str:
    lib, _ = libpython()
    lines = [f"python={sys.executable}", "version={}.{}".format(*sys.version_info[:2]), f"libpython={lib}",
             f"home={sys.base_prefix}"]
    lines += [f"site={d}" for d in site_dirs()]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.stdout.write(text())
