"""How a host's input table is read over a communication step: the names of the interpolation
modes and their check, ONE definition shared by the engine (:func:`overcon.simulate.run`) and the
tooling (:mod:`overcon.tooling.inputs`, whose module docstring defines what each mode means).

It sits in the vocabulary layer (tests/test_layers.py) so that the engine does not import the
tooling to check the name it is given."""
from __future__ import annotations

INTERPOLATIONS = ("hold", "linear")


def check_interpolation(interpolation: str, error: type[Exception] = ValueError) -> str:
    """``interpolation`` when it is one of :data:`INTERPOLATIONS`; else raises ``error`` (a
    ``ValueError`` by default; the tooling passes its ``InputError``) naming the bad value."""
    if interpolation not in INTERPOLATIONS:
        raise error(f"input interpolation {interpolation!r}: expected one of {', '.join(INTERPOLATIONS)}")
    return interpolation
