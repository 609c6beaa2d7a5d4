"""The N-four-bar (benchmark A02 of the multibody benchmark library; mechanisms/examples/nfourbar.py)
over the benchmark's 20 s with ``[solver] singular = "pass"`` (the augmented Lagrangian solve and
projections of core/kkt_al.c and core/project.c): its error, its wall time and the cost of an
evaluation as N grows.

    python benchmarks/nfourbar.py [N ...] [--stop-time T] [--tolerance TOL] [--methods M ...]
                                  [--c-max N] [--plot docs/nfourbar_cost.png]
                                            (default: 2 10 40 100, 20 s, tolerance 1e-9, dop853 and
                                            dopri5, C runs up to N = 10)
    python benchmarks/nfourbar.py --watch [N ...] [--stop-time T] [--scenes]
                                            the C runs only, with their watch's share
    python benchmarks/nfourbar.py --q0-cost [N ...] [--repeat R]
                                            the core's evaluation at q0 only, both acceleration solves
    python benchmarks/nfourbar.py --error-table [N ...] [--methods M ...] [--tolerances TOL ...]
                                  [--max-step S]
                                            B0's error over the run against the tolerance (default
                                            N = 2, dop853 and dopri5, 1e-6 ... 1e-12, the scene's
                                            max_step 0.05 s)

For each N and method (``--methods``, default dop853 then dopri5: one line each, so that the two
stand side by side in one run; the scene's own method is dopri5, the default of every scene, and
benchmarks/peers.py runs dop853) the scene (tolerance 1e-9 or --tolerance) is run in process (one BLAS thread) through
``overcon.simulate.Simulation`` (``overcon simulate``'s path: the core's run, core/sim.c, behind
the Python interface) and, up to ``--c-max``, as a bare ``kernel.Run`` (the same run without the
Python wrapper: its wall time, and its states compared with the Simulation's), printed side by side:
  - the benchmark's measure, the x coordinate of B0 (the first coupler's left end, the first
    crank's top: crank0.x + 0.5 cos(crank0.phi), m) every 0.01 s, against the tight-tolerance run:
    the parallelogram branch reduced to its one coordinate (every crank at phi, the couplers
    translating: I phi'' = -g c cos(phi), I = (N + 1)/3 + N kg m^2, c = (N + 1)/2 + N kg m) by
    DOP853 at 1e-13, which is the motion of the benchmark's branch itself (B0's x = cos phi);
    also, for N <= 10, the whole model in process at tolerance 1e-12 against the same reference;
  - the singular events (20 flat positions in 20 s), steps, evaluations, the max drift;
  - wall times: the in-process run, its watch (core/watch.c, watch_eig.c: ``watch_time`` of
    ovk_sim_info) and, within the watch, the uniqueness along the motion (core/unique.c,
    ``along_time``), and the bare C run with its watch; the projections (core/project.c) have no
    timer of their own in the core and are not reported;
  - the cost of one evaluation of the right-hand side in the core alone (kernel.Kernel.evaluate
    at 200 states of the run, microseconds; the AL's banded factorisation is O(N) here, and the
    assembly of Phi_h writes each row's two bodies' blocks only, O(N) too).
``--watch``: only the C runs, one line per N (wall time, the watch's and the uniqueness's seconds
and share of it, steps, singular positions passed, estimates of r that hit their iteration bound),
and with ``--scenes`` the same for spatial_MN_wo5 and the four examples of docs/examples.md over
10 s (kernel.Run, in process).
``--q0-cost``: microseconds per evaluation of the core alone at the initial state, in the
eliminated form (``[solver] singular = "stop"``: S = J_R M^-1 J_R^T in band order and its banded
Cholesky factor, core/kkt.c) and in the augmented Lagrangian form (``"pass"``, core/kkt_al.c),
one line per N: the best of 5 rounds of R evaluations (default 300), so that a busy machine's
slower rounds do not count. The main table prints the same two figures (``elim q0``, ``AL q0``).
``--error-table``: for each N, method and tolerance, the in-process run's error of B0's x against
the exact branch (max over the 0.01 s grid), its wall time, steps and evaluations: what a user gets
for a tolerance through the singular positions (docs/benchmarks.md, "Error against tolerance").
``--max-step 1`` lets the tolerance alone set the steps (at the scene's 0.05 s, dop853's steps at
1e-6 and 1e-7 are all 0.05 s, and the two runs are the same).
``--plot``: the core's cost per evaluation and the in-process run's wall time per evaluation
against N, log-log, with slopes 1 and 3 for reference. The figures go to docs/benchmarks.md
("The N-four-bar") by hand.
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import math
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[1]

from overcon import kernel  # noqa: E402
from overcon import scene  # noqa: E402
from overcon.checks import compile_checked, watch_rows  # noqa: E402
from overcon.cli import single_threaded_blas  # noqa: E402
from overcon.simulate import Simulation  # noqa: E402

G = 9.81


def _generator():
    spec = importlib.util.spec_from_file_location("nfourbar", ROOT / "mechanisms" / "examples" / "nfourbar.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def reference_x(n: int, times: np.ndarray) -> np.ndarray:
    """B0's x (m) on the parallelogram branch at ``times`` (the module docstring's 1-DOF motion)."""
    inertia, moment = (n + 1) / 3 + n, (n + 1) / 2 + n
    sol = solve_ivp(lambda t, y: [y[1], -G * moment * math.cos(y[0]) / inertia], (0.0, float(times[-1])),
                    [math.pi / 2, -1.0], t_eval=times, rtol=1e-13, atol=1e-13, method="DOP853")
    return np.cos(sol.y[0])


def _b0_x(model, y: np.ndarray) -> float:
    b = model.body_names.index("crank0")
    return float(y[3 * b] + 0.5 * math.cos(y[3 * b + 2]))


def in_process(model, solver, times: np.ndarray) -> dict:
    """The run through overcon.simulate.Simulation (the core's run), its watch's wall times from
    the core's counters."""
    with single_threaded_blas():
        start = time.perf_counter()
        sim = Simulation(model, solver)
        states = [sim.advance(float(t)) for t in times]
        wall = time.perf_counter() - start
    info = sim.info
    return {"x": np.array([_b0_x(model, y) for y in states]), "wall": wall, "steps": sim.steps,
            "evaluations": sim.evaluations, "drift": sim.max_drift,
            "singular": sum(1 for e in sim.events if e[1] == "singular"), "watch": info["watch_time"],
            "along": info["along_time"], "states": states}


def c_run(model, solver, times: np.ndarray, b0: bool = True) -> dict:
    start = time.perf_counter()
    run = kernel.Run(model, solver, watch=watch_rows(model))
    states = [run.advance(float(t)) for t in times]
    wall = time.perf_counter() - start
    info = run.info
    return {"x": np.array([_b0_x(model, y) for y in states]) if b0 else None, "wall": wall,
            "evaluations": info["evaluations"],
            "singular": int(info["singular_passed"]), "drift": info["max_drift"], "states": states,
            "watch": info["watch_time"], "along": info["along_time"], "steps": int(info["nsteps"]),
            "capped": int(info["watch_capped"])}


SCENES = ("mechanisms/spatial_MN_wo5.toml", "mechanisms/examples/door_h1_wo_hinge2.toml",
          "mechanisms/examples/fourbar_A_wo3_4_5.toml", "mechanisms/examples/loop_D_wo_A2.toml",
          "mechanisms/examples/carriage_guide_wo_rod.toml")


def _watch_line(label: str, c: dict) -> str:
    return (f"{label:>34} {c['wall']:>8.3f} {c['watch']:>8.3f} {c['watch'] / c['wall']:>6.0%} {c['along']:>8.3f} "
            f"{c['steps']:>6} {c['singular']:>4} {c['capped']:>6}")


def watch_table(ns: list[int], stop: float, scenes: bool, tolerance: float = 1e-9) -> None:
    """The C runs alone: wall time and the watch's share (``--watch``)."""
    print(f"{'run':>34} {'wall s':>8} {'watch s':>8} {'share':>6} {'along s':>8} {'steps':>6} {'sing':>4} "
          f"{'capped':>6}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in ns:
            _, path = _generator().write(n, Path(tmp) / f"n{n}", stop_time=stop, tolerance=tolerance, singular="pass")
            spec = scene.as_scene(scene.load(path))
            c = c_run(compile_checked(spec), spec.solver, np.array([stop]))
            print(_watch_line(f"N-four-bar N = {n}, {stop:g} s", c), flush=True)
    for name in SCENES if scenes else ():
        spec = scene.as_scene(scene.load(ROOT / name))
        end = 10.0
        c = c_run(compile_checked(spec), spec.solver, np.array([end]), b0=False)
        print(_watch_line(f"{Path(name).stem}, {end:g} s", c), flush=True)


def eval_cost(model, solver, states) -> float:
    """Microseconds per evaluation of the core alone at up to 200 states of the run."""
    k = kernel.Kernel(kernel.library()[0], model, solver)
    picks = states[:: max(1, len(states) // 200)][:200]
    start = time.perf_counter()
    for y in picks:
        k.evaluate(0.0, y)
    return (time.perf_counter() - start) / len(picks) * 1e6


def q0_cost(n: int, tmp: Path, singular: str, repeat: int = 300, rounds: int = 5) -> float:
    """Microseconds per evaluation of the core alone at the N-four-bar's initial state with
    ``[solver] singular = singular`` ("stop": the eliminated form, "pass": the AL): the best of
    ``rounds`` rounds of ``repeat`` evaluations."""
    _, path = _generator().write(n, tmp / f"q0_{singular}_{n}", singular=singular)
    spec = scene.as_scene(scene.load(path))
    model = compile_checked(spec)
    k = kernel.Kernel(kernel.library()[0], model, spec.solver)
    y0 = np.concatenate([model.q0, model.h0])
    if k.evaluate(0.0, y0) is None:
        raise RuntimeError(f"N = {n}, singular = {singular!r}: the core refused q0: {k.last_message}")
    best = math.inf
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(repeat):
            k.evaluate(0.0, y0)
        best = min(best, (time.perf_counter() - start) / repeat * 1e6)
    return best


def q0_table(ns: list[int], repeat: int) -> None:
    """``--q0-cost``: the core's evaluation at q0 in both forms, one line per N."""
    print(f"{'N':>4} {'coords':>6} {'eqs':>5} {'elim us':>9} {'AL us':>9} {'elim/AL':>7}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in ns:
            elim, al = q0_cost(n, Path(tmp), "stop", repeat), q0_cost(n, Path(tmp), "pass", repeat)
            print(f"{n:>4} {3 * (2 * n + 1):>6} {2 * (3 * n + 1):>5} {elim:>9.1f} {al:>9.1f} {elim / al:>7.2f}",
                  flush=True)


def measure(n: int, tmp: Path, stop: float, c_max: int, tolerance: float = 1e-9, method: str = "dop853") -> dict:
    _, path = _generator().write(n, tmp / f"n{n}_{method}", stop_time=stop, tolerance=tolerance, singular="pass")
    spec = scene.as_scene(scene.load(path))
    model = compile_checked(spec)
    solver = dataclasses.replace(spec.solver, method=method)
    times = np.round(np.arange(1, int(round(stop / 0.01)) + 1) * 0.01, 10)
    ref = reference_x(n, times)
    py = in_process(model, solver, times)
    c = c_run(model, solver, times) if n <= c_max else None
    tight = None
    if n <= 10:
        tight = in_process(model, dataclasses.replace(solver, tolerance=1e-12), times)
    return {"N": n, "method": method, "coords": model.nh, "eqs": model.m, "py": py, "c": c,
            "err_py": float(np.max(np.abs(py["x"] - ref))),
            "err_c": None if c is None else float(np.max(np.abs(c["x"] - ref))),
            "dy_c": None if c is None else float(max(np.max(np.abs(a - b)) for a, b in zip(py["states"], c["states"]))),
            "err_tight": None if tight is None else float(np.max(np.abs(tight["x"] - ref))),
            "us_eval": eval_cost(model, solver, py["states"]),
            "us_elim_q0": q0_cost(n, tmp, "stop"), "us_al_q0": q0_cost(n, tmp, "pass")}


def error_table(ns: list[int], methods: list[str], tolerances: list[float], stop: float,
                max_step: float | None = None) -> None:
    """``--error-table``: B0's error against the tolerance, one line per N, method and tolerance
    (max_step: the solver's, None for the scene's)."""
    print(f"{'N':>4} {'method':>7} {'tolerance':>9} {'error m':>9} {'wall s':>7} {'steps':>6} {'evals':>6} {'sing':>4}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in ns:
            _, path = _generator().write(n, Path(tmp) / f"e{n}", stop_time=stop, singular="pass")
            spec = scene.as_scene(scene.load(path))
            model = compile_checked(spec)
            times = np.round(np.arange(1, int(round(stop / 0.01)) + 1) * 0.01, 10)
            ref = reference_x(n, times)
            for method in methods:
                for tol in tolerances:
                    solver = dataclasses.replace(spec.solver, method=method, tolerance=tol)
                    if max_step is not None:
                        solver = dataclasses.replace(solver, max_step=max_step)
                    try:
                        r = in_process(model, solver, times)
                    except Exception as exc:  # a run that stopped is reported as such, not as a figure
                        print(f"{n:>4} {method:>7} {tol:>9.4g} stopped: {exc}", flush=True)
                        continue
                    err = float(np.max(np.abs(r["x"] - ref)))
                    print(f"{n:>4} {method:>7} {tol:>9.4g} {err:>9.2e} {r['wall']:>7.3f} {r['steps']:>6} "
                          f"{r['evaluations']:>6} {r['singular']:>4}", flush=True)


def plot(rows: list[dict], path: Path, stop: float, tolerance: float) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    first = [r for r in rows if r["method"] == rows[0]["method"]]
    ns = np.array([r["N"] for r in first], float)
    core = np.array([r["us_eval"] for r in first])
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.loglog(ns, core, "o-", label="core evaluation (AL, banded)")
    for method, marker in zip(dict.fromkeys(r["method"] for r in rows), "sD^v"):
        mine = [r for r in rows if r["method"] == method]
        ax.loglog([r["N"] for r in mine], [r["py"]["wall"] / r["py"]["evaluations"] * 1e6 for r in mine],
                  marker + "-", label=f"in-process run, {method}: wall / evaluations (with the watch)")
    for slope, style in ((1, ":"), (3, "--")):
        ax.loglog(ns, core[0] * (ns / ns[0]) ** slope, "k" + style, lw=0.8, label=f"slope {slope}")
    ax.set_xlabel("N (loops)")
    ax.set_ylabel("microseconds per evaluation")
    ax.set_title(f"N-four-bar, singular = \"pass\", 0-{stop:g} s, tolerance {tolerance:g}")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", lw=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"plot: {path}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("n", type=int, nargs="*", help="N (default 2 10 40 100; --error-table: 2)")
    ap.add_argument("--stop-time", type=float, default=20.0)
    ap.add_argument("--tolerance", type=float, default=1e-9,
                    help="the runs' tolerance (default 1e-9; the 1e-12 column stays at 1e-12)")
    ap.add_argument("--c-max", type=int, default=10,
                    help="largest N also run as a bare kernel.Run beside the Simulation (default 10)")
    ap.add_argument("--plot", type=Path)
    ap.add_argument("--watch", action="store_true", help="only the C runs, with the watch's share")
    ap.add_argument("--scenes", action="store_true", help="with --watch: also spatial_MN_wo5 and the examples")
    ap.add_argument("--q0-cost", action="store_true",
                    help="only the core's evaluation at q0, eliminated form and AL (microseconds)")
    ap.add_argument("--repeat", type=int, default=300, help="with --q0-cost: evaluations per round (default 300)")
    ap.add_argument("--error-table", action="store_true",
                    help="B0's error against the tolerance (default N = 2; --methods, --tolerances)")
    ap.add_argument("--methods", nargs="+", default=["dop853", "dopri5"],
                    help="the integrators, one line each in the main table and the error table (default dop853 dopri5)")
    ap.add_argument("--tolerances", type=float, nargs="+", default=[1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12])
    ap.add_argument("--max-step", type=float, help="with --error-table: the solver's max_step (s; default the scene's)")
    args = ap.parse_args(argv)
    if args.error_table:
        error_table(args.n or [2], args.methods, args.tolerances, args.stop_time, args.max_step)
        return 0
    args.n = args.n or [2, 10, 40, 100]
    if args.q0_cost:
        q0_table(args.n, args.repeat)
        return 0
    if args.watch:
        watch_table(args.n, args.stop_time, args.scenes, args.tolerance)
        return 0
    print(f"{'N':>4} {'method':>7} {'coords':>6} {'eqs':>5} {'sing':>4} {'steps':>6} {'evals':>6} {'drift':>8} {'err py m':>9} "
          f"{'err C m':>9} {'|dy| C':>8} {'err 1e-12':>9} {'py s':>7} {'watch s':>7} {'along s':>7} {'C s':>7} "
          f"{'C watch':>7} "
          f"{'us/eval':>8} {'py us/ev':>8} {'elim q0':>8} {'AL q0':>8}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n, method in ((n, method) for n in args.n for method in args.methods):
            r = measure(n, Path(tmp), args.stop_time, args.c_max, args.tolerance, method)
            rows.append(r)
            py, c = r["py"], r["c"]
            tight = "" if r["err_tight"] is None else f"{r['err_tight']:.2e}"
            err_c = "" if c is None else f"{r['err_c']:.2e}"
            dy_c = "" if c is None else f"{r['dy_c']:.1e}"
            c_wall = "" if c is None else f"{c['wall']:.2f}"
            c_watch = "" if c is None else f"{c['watch']:.2f}"
            print(f"{n:>4} {method:>7} {r['coords']:>6} {r['eqs']:>5} {py['singular']:>4} {py['steps']:>6} {py['evaluations']:>6} "
                  f"{py['drift']:>8.1e} {r['err_py']:>9.2e} {err_c:>9} {dy_c:>8} {tight:>9} {py['wall']:>7.2f} "
                  f"{py['watch']:>7.2f} {py['along']:>7.2f} {c_wall:>7} {c_watch:>7} {r['us_eval']:>8.1f} "
                  f"{py['wall'] / py['evaluations'] * 1e6:>8.1f} {r['us_elim_q0']:>8.1f} {r['us_al_q0']:>8.1f}",
                  flush=True)
    if args.plot:
        plot(rows, args.plot, args.stop_time, args.tolerance)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
