"""The FMU's entry into Python (overcon.fmu.boot): the reason fmi2Instantiate gives when the slave
cannot be imported names a fix that works where the FMU runs."""
from __future__ import annotations

import sys

import pytest

from overcon.fmu import boot


def _without_slave(monkeypatch):
    monkeypatch.setitem(sys.modules, "overcon.fmu.slave", None)  # the import fails as without numpy
    monkeypatch.setattr(sys, "path", list(sys.path))


def test_python_host_without_numpy_is_told_to_install_there(monkeypatch, tmp_path):
    _without_slave(monkeypatch)
    (tmp_path / "overcon_python.txt").write_text("python=/x/bin/python\nversion=3.99\nlibpython=/x/lib/libpython3.99.so\n")
    with pytest.raises(ImportError, match=r"runs inside this host's own Python \(\d+\.\d+\.\d+.*\), which lacks numpy "
                       r"or scipy: install them there \(python -m pip install numpy scipy\)\. The Python recorded at "
                       r"build time \(version 3\.99\) lends its packages only to a host of the same version; "
                       r"OVERCON_PYTHON has no effect in a host that already runs Python"):
        boot.instantiate("inst", "guid", str(tmp_path), 0, 0, 0, "")


def test_interpreter_started_by_the_fmu_points_to_overcon_python(monkeypatch, tmp_path):
    _without_slave(monkeypatch)
    with pytest.raises(ImportError, match=r"the FMU needs numpy and scipy in the interpreter it started \(Python "
                       r".*\); set OVERCON_PYTHON to a Python executable that has them") as info:
        boot.instantiate("inst", "guid", str(tmp_path), 0, 0, 0, str(tmp_path / "site"))
    assert "has no effect" not in str(info.value)
