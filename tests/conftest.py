"""Markers (registered in pyproject.toml): ``integration`` tests build or run FMUs (``-m "not
integration"`` is the quick run of everything else); ``stress`` tests repeat a check many times and
are skipped unless selected by name in ``-m`` (``.ci/run`` runs ``-m stress``)."""
from __future__ import annotations

import pytest


def pytest_collection_modifyitems(config, items):
    if "stress" in (config.getoption("markexpr") or ""):
        return
    skip = pytest.mark.skip(reason="stress test: run with -m stress (.ci/run does)")
    for item in items:
        if item.get_closest_marker("stress") is not None:
            item.add_marker(skip)
