"""Hot-path benchmark of the right-hand side (dynamics.evaluate via simulate.Simulation._rhs).

Runs four paper scenes (planar 0-4 s, spatial 0-10 s, dopri5, tolerance 1e-8) and prints a Markdown
table: wall time of the whole run (median of ``--repeat`` runs), right-hand-side evaluations, wall time
per evaluation, time spent inside ``Simulation._rhs`` per evaluation (median), friction iterations
per evaluation. The wall time also contains the output points (one extra evaluation and the
reactions each) and the singularity monitor (one SVD per step).

    python benchmarks/hot_path.py [--repeat 3] [--mechanisms mechanisms] [--save runs.npz]

``--save`` stores each scene's output matrix (positions, reactions) for comparison between versions.
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from overcon import scene as scene_mod
from overcon.checks import compile_checked
from overcon import simulate
from overcon.simulate import run

SCENES = (("planar_none_wo4", 4.0), ("planar_f45_wo4", 4.0),
          ("spatial_none_wo5", 10.0), ("spatial_MN_wo5", 10.0))


class _RhsTimer:
    """Wraps Simulation._rhs to accumulate the time spent in right-hand-side evaluations."""

    def __init__(self):
        self.total = 0.0
        self._orig = simulate.Simulation._rhs

    def __enter__(self):
        orig, timer = self._orig, self

        def timed(sim, t, y):
            t0 = time.perf_counter()
            try:
                return orig(sim, t, y)
            finally:
                timer.total += time.perf_counter() - t0

        simulate.Simulation._rhs = timed
        return self

    def __exit__(self, *exc):
        simulate.Simulation._rhs = self._orig


def bench(path: Path, stop: float, repeat: int):
    spec = scene_mod.as_scene(scene_mod.load(path), stop_time=stop, tolerance=1e-8, source=str(path))
    model = compile_checked(spec)
    walls, rhs, res = [], [], None
    for _ in range(repeat):
        with _RhsTimer() as timer:
            t0 = time.perf_counter()
            res = run(model, spec.solver, stop_time=stop)
            walls.append(time.perf_counter() - t0)
        rhs.append(timer.total)
    return statistics.median(walls), statistics.median(rhs), res


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--mechanisms", default=str(Path(__file__).resolve().parent.parent / "mechanisms"))
    ap.add_argument("--save", help="write the output matrices to this .npz file")
    args = ap.parse_args(argv)
    saved = {}
    print("| scene | t (s) | wall (s) | evaluations | wall ms/eval | rhs ms/eval | friction it./eval |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, stop in SCENES:
        wall, rhs, res = bench(Path(args.mechanisms) / f"{name}.toml", stop, args.repeat)
        ev = res.evaluations
        print(f"| {name} | 0-{stop:g} | {wall:.3f} | {ev} | {1e3 * wall / ev:.4f} | {1e3 * rhs / ev:.4f} | "
              f"{res.friction_iterations / ev:.2f} |", flush=True)
        saved[name] = res.values
    if args.save:
        np.savez(args.save, **saved)


if __name__ == "__main__":
    main()
