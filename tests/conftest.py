"""Markers (registered in pyproject.toml): ``integration`` tests build or run FMUs (``-m "not
integration"`` is the quick run of everything else); ``stress`` tests repeat a check many times and
are skipped unless selected by name in ``-m`` (``.ci/run`` runs ``-m stress``); so are ``platforms``
tests (cross-compiled FMUs run under wine and qemu: ``.ci/run`` runs ``-m platforms``)."""
from __future__ import annotations

import pytest


def pytest_collection_modifyitems(config, items):
    for marker in ("stress", "platforms"):
        if marker in (config.getoption("markexpr") or ""):
            continue
        skip = pytest.mark.skip(reason=f"{marker} test: run with -m {marker} (.ci/run does)")
        for item in items:
            if item.get_closest_marker(marker) is not None:
                item.add_marker(skip)
