"""Progress bars for the commands that run for more than a few seconds (``reproduce``, ``compare``,
``run``, ``regress``, ``sweep``, ``converge``, a long ``simulate``), with tqdm.

Decided: a bar is drawn only when stderr is a terminal (tqdm's ``disable=None``), so CI logs and
pipes get none; it appears only once a task has run for :data:`DELAY` seconds (short runs stay
as they were), goes to stderr and is removed when done (``leave=False``), so what the commands
print on stdout is unchanged. Without tqdm installed (it is a dependency) nothing is drawn.
"""
from __future__ import annotations

import sys

DELAY = 2.0  # s before a bar appears


class _Quiet:
    """The bar's interface, doing nothing (not a terminal, or no tqdm)."""

    n = 0

    def update(self, n=1) -> None:
        self.n += n

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass


def bar(total, desc: str, unit: str = "it", **kw):
    """A tqdm bar on stderr when it is a terminal, else a quiet stand-in; use as a context."""
    if not _terminal():
        return _Quiet()
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover -- tqdm is a dependency
        return _Quiet()
    return tqdm(total=total, desc=desc, unit=unit, delay=DELAY, leave=False, file=sys.stderr, dynamic_ncols=True,
                **kw)


def _terminal() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False
