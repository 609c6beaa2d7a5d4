"""Argument types shared by the command line (:mod:`overcon.cli`) and ``build_fmu.py``
(:mod:`overcon.fmu.build`): one parser of a count for every command, kept below both so that the
build never imports the command line."""
from __future__ import annotations

import argparse


def count(text: str) -> int:
    """An integer >= 1 (job counts, step budgets, sample counts); argparse reports the flag."""
    try:
        val = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if val < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text}")
    return val
