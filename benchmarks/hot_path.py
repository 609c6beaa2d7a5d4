"""Hot path of an in-process run (overcon.simulate.Simulation over the core's run, core/sim.c).

Runs four paper scenes (planar 0-4 s, spatial 0-10 s, dopri5, tolerance 1e-8) with outputs at the
scene's interval, as ``overcon.simulate.run`` does (the whole grid inside the core, core/sim_out.c), and prints a Markdown table: wall time of the
whole run (median of ``--repeat`` runs), right-hand-side evaluations, wall time per evaluation, the
core's time inside ``Simulation.advance`` per evaluation (``info["wall_time"]``: the integration,
its evaluations and the singularity watch, without the output points), the watch's share of that
(``info["watch_time"]``), friction iterations per evaluation. The rest of the wall time is the
output points (one evaluation of Eq. 18 and the reactions each, computed in the core) and the Python around the run.

    python benchmarks/hot_path.py [--repeat 3] [--mechanisms mechanisms] [--save runs.npz]
    python benchmarks/hot_path.py --door [--repeat 20]     the door at 1 ms output (``door``)

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
from overcon.simulate import Simulation, output_grid

SCENES = (("planar_none_wo4", 4.0), ("planar_f45_wo4", 4.0),
          ("spatial_none_wo5", 10.0), ("spatial_MN_wo5", 10.0))


def bench(path: Path, stop: float, repeat: int):
    """(median wall s, median core s inside advance, median watch s, the last run's Simulation,
    its output matrix)."""
    spec = scene_mod.as_scene(scene_mod.load(path), stop_time=stop, tolerance=1e-8, source=str(path))
    model = compile_checked(spec)
    grid = output_grid(spec.start_time, stop, spec.solver.output_interval)
    walls, core, watch, sim, values = [], [], [], None, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        sim = Simulation(model, spec.solver)
        values, _, stop = sim.grid(grid)  # the whole output grid inside the core, as run() does
        if stop is not None:
            raise stop
        walls.append(time.perf_counter() - t0)
        core.append(sim.info["wall_time"])
        watch.append(sim.info["watch_time"])
    return statistics.median(walls), statistics.median(core), statistics.median(watch), sim, values


def door(repeat: int) -> None:
    """``--door``: the frictionless door (examples/door_none_wo_hinge2.toml), 2 s, dop853 at 1e-5,
    outputs every 1 ms, in process: the best of ``repeat`` runs of ``overcon.simulate.run`` (the
    model compiled once, outside the time), with the scene's outputs (positions and both hinges'
    reactions) and with the positions only, and the integration alone (one output point)."""
    import dataclasses

    from overcon.simulate import run
    path = Path(__file__).resolve().parent.parent / "mechanisms" / "examples" / "door_none_wo_hinge2.toml"
    spec = scene_mod.load(path)
    spec = dataclasses.replace(spec, solver=dataclasses.replace(spec.solver, method="dop853", tolerance=1e-5,
                                                               output_interval=1e-3))
    print("| door, 2 s, dop853 1e-5 | outputs | output points | best of runs (s) | us per output point |")
    print("|---|---:|---:|---:|---:|")
    for label, positions_only, interval in (("scene's outputs", False, 1e-3), ("positions only", True, 1e-3),
                                            ("integration alone", True, 2.0)):
        s = dataclasses.replace(spec, reactions=(), friction_outputs=()) if positions_only else spec
        model = compile_checked(s)
        best = float("inf")
        for _ in range(repeat):
            t0 = time.perf_counter()
            res = run(model, s.solver, output_interval=interval)
            best = min(best, time.perf_counter() - t0)
        print(f"| {label} | {res.values.shape[1]} | {len(res.time)} | {best:.4f} | {1e6 * best / len(res.time):.2f} |")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--door", action="store_true", help="only the door at 1 ms output (issue 40's goal)")
    ap.add_argument("--mechanisms", default=str(Path(__file__).resolve().parent.parent / "mechanisms"))
    ap.add_argument("--save", help="write the output matrices to this .npz file")
    args = ap.parse_args(argv)
    if args.door:
        return door(args.repeat)
    saved = {}
    print("| scene | t (s) | wall (s) | evaluations | wall ms/eval | core ms/eval (advance) | watch share | "
          "friction it./eval |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, stop in SCENES:
        wall, core, watch, sim, values = bench(Path(args.mechanisms) / f"{name}.toml", stop, args.repeat)
        ev = sim.evaluations
        print(f"| {name} | 0-{stop:g} | {wall:.3f} | {ev} | {1e3 * wall / ev:.4f} | {1e3 * core / ev:.4f} | "
              f"{watch / core:.0%} | {sim.friction_iterations / ev:.2f} |", flush=True)
        saved[name] = values
    if args.save:
        np.savez(args.save, **saved)


if __name__ == "__main__":
    main()
