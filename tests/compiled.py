"""Test helper: a cache of models compiled from generated mechanism files, for the joint tests'
random configurations (not on the constraint manifold: derivatives only, so the initial state is
not checked)."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from overcon.model import Model
from overcon.checks import compile_checked
from overcon.scene import as_scene, load


def compiled_models(tmp: Path, write: Callable[[Path, str, int], Path]) -> Callable[[str, int], Model]:
    """``get(jtype, seed)``: the model of the file ``write(tmp, jtype, seed)`` writes, compiled once."""
    cache: dict[tuple[str, int], Model] = {}

    def get(jtype: str, seed: int) -> Model:
        if (jtype, seed) not in cache:
            cache[jtype, seed] = compile_checked(as_scene(load(write(tmp, jtype, seed))), check_initial=False)
        return cache[jtype, seed]

    return get
