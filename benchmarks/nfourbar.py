"""The N-four-bar (mechanisms/examples/nfourbar.py) up to its first flat position: the cost of a
run and of the singularity watch as N grows.

    python benchmarks/nfourbar.py [N ...]        (default: 2 10 40 100)

For each N, the scene is run in process (one BLAS thread) from 0 to 0.70 s, just before the
first flat position (about 0.714 s), at tolerance 1e-9; printed side by side: steps,
right-hand-side evaluations, the run's wall time, the time spent in the watch
(overcon.watch.SingularityMonitor.check, measured by wrapping it) and its share, and the wall
time per evaluation. The figures go to docs/benchmarks.md ("The N-four-bar") by hand.
"""
from __future__ import annotations

import importlib.util
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

from overcon import scene  # noqa: E402
from overcon import watch  # noqa: E402
from overcon.checks import compile_checked  # noqa: E402
from overcon.cli import single_threaded_blas  # noqa: E402
from overcon.simulate import run  # noqa: E402


def _generator():
    spec = importlib.util.spec_from_file_location("nfourbar", ROOT / "mechanisms" / "examples" / "nfourbar.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def measure(n: int, tmp: Path) -> dict:
    _, path = _generator().write(n, tmp / f"n{n}", stop_time=0.70, tolerance=1e-9)
    spec = scene.as_scene(scene.load(path))
    model = compile_checked(spec)
    spent = [0.0]
    check = watch.SingularityMonitor.check

    def timed(self, *a, **kw):
        start = time.perf_counter()
        try:
            return check(self, *a, **kw)
        finally:
            spent[0] += time.perf_counter() - start

    watch.SingularityMonitor.check = timed
    try:
        with single_threaded_blas():
            start = time.perf_counter()
            res = run(model, spec.solver)
            wall = time.perf_counter() - start
    finally:
        watch.SingularityMonitor.check = check
    return {"N": n, "coordinates": model.nh, "equations": model.m, "steps": res.steps, "evaluations": res.evaluations,
            "wall": wall, "watch": spent[0], "note": res.kernel_note.split(" (")[0]}


def main(argv: list[str]) -> int:
    ns = [int(a) for a in argv] or [2, 10, 40, 100]
    print(f"{'N':>4} {'coords':>6} {'eqs':>5} {'steps':>6} {'evals':>6} {'wall s':>8} {'watch s':>8} "
          f"{'watch %':>7} {'us/eval':>8}  right-hand side")
    with tempfile.TemporaryDirectory() as tmp:
        for n in ns:
            r = measure(n, Path(tmp))
            per_eval = (r["wall"] - r["watch"]) / r["evaluations"] * 1e6
            print(f"{r['N']:>4} {r['coordinates']:>6} {r['equations']:>5} {r['steps']:>6} {r['evaluations']:>6} "
                  f"{r['wall']:>8.3f} {r['watch']:>8.3f} {100 * r['watch'] / r['wall']:>6.0f}% {per_eval:>8.1f}  "
                  f"{r['note']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
