"""overcon: overconstrained rigid multibody mechanisms with Coulomb joint friction.

The public Python API is what ``__all__`` names (defined in :mod:`overcon.api`, imported on first
use so that ``import overcon`` stays cheap); every other module is internal.
"""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("overcon")
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["load", "check", "simulate_scene", "build", "run", "compare", "regress",
           "SceneError", "SimulationError", "InputError", "SimulationFailed", "PrecheckResult", "Result",
           "MechanismSpec", "SceneSpec", "__version__"]


def __getattr__(name: str):
    if name in __all__:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'overcon' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
