"""The pre-check at scale: ``overcon check`` of generated linkages, and the analysis alone, with
the one factorisation (:func:`overcon.analysis._factorise`: peeled coloops, decoupled blocks,
one dense SVD per block) against one dense SVD of the whole Jacobian (the former test's
factorisation), side by side where the dense SVD ends in reasonable time.

    python benchmarks/precheck_scale.py [--quick]

Everything runs in process with one BLAS thread (overcon.cli.single_threaded_blas). Per mechanism:
coordinates n, equations m, the peeled columns and the largest block left; then wall seconds and,
for check and analysis, this process's CPU seconds (``time.process_time``: what other jobs on a
loaded machine change least), medians of 3 runs (1 run above 20 s), of
  check      ``overcon.cli.main(["check", FILE, "--json", "--friction", "none"])``: loading,
             compiling (the elimination's rank and independent columns), the Jacobian, the
             analysis, the report;
  analysis   ``overcon.analysis.analyse(J, groups, methods="svd")`` on the Jacobian at q0;
  dense      ``equilibrate`` plus one dense SVD of the whole J (``_svd_full``): the
             factorisation the analysis ran before, without its per-joint work (a lower bound
             of the former analysis' time), or "-" where min(n, m) > 2500 (minutes).
The figures go to docs/benchmarks.md ("Pre-check at scale") and the README by hand.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import numpy as np  # noqa: E402

from overcon import analysis, kernel, scene  # noqa: E402
from overcon.checks import compile_checked  # noqa: E402
from overcon.cli import main, single_threaded_blas  # noqa: E402
from overcon.precheck import joint_groups  # noqa: E402

DENSE_LIMIT = 2500


def cases(tmp: Path, quick: bool) -> list[tuple[str, Path]]:
    from test_precheck_methods import linkage, parallelogram
    from test_robust import chain
    out = [("parallelogram 99 cranks (198 joints)", parallelogram(99, tmp / "p99.toml"))]
    for n in ([100, 1000] if quick else [100, 200, 500, 1000]):
        out.append((f"planar chain {n} bodies", chain(n, tmp / f"chain{n}.toml")))
    rng = np.random.default_rng
    out.append(("planar tree 980 bodies + 20 loops", linkage(rng(1), "planar", "loops", 980, tmp / "l1000.toml", 20)))
    out.append(("spatial tree 990 bodies + 10 loops", linkage(rng(2), "spatial", "loops", 990, tmp / "s1000.toml", 10)))
    if not quick:
        out.append(("spatial chain 500 bodies", linkage(rng(3), "spatial", "chain", 500, tmp / "sc500.toml")))
        out.append(("parallelogram 250 cranks (500 joints)", parallelogram(250, tmp / "p250.toml")))
        out.append(("parallelogram 500 cranks (1000 joints)", parallelogram(500, tmp / "p500.toml")))
    return out


def timed(fn, repeat: int = 3) -> tuple[float, float]:
    """Median wall and CPU seconds of ``fn()``."""
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        if wall[-1] > 20.0:
            break
    return statistics.median(wall), statistics.median(cpu)


def check(path: Path) -> None:
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["check", str(path), "--json", "--friction", "none"])
    if code not in (0, 1):
        raise RuntimeError(f"overcon check {path}: exit {code}")


def main_(quick: bool) -> None:
    with tempfile.TemporaryDirectory() as tmp, single_threaded_blas():
        print(f"{'mechanism':<40} {'n':>5} {'m':>5} {'peeled':>6} {'block':>11} {'check s':>8} {'(cpu)':>7} "
              f"{'analysis s':>10} {'(cpu)':>7} {'dense s':>8}")
        for label, path in cases(Path(tmp), quick):
            model = compile_checked(scene.as_scene(scene.load(path)))
            J = kernel.jacobian(model, model.q0).T  # Phi_h^T at q0: (n_h coordinates, m equations)
            groups = joint_groups(model)
            f = analysis._factorise(analysis.equilibrate(J)[0], analysis.DEFAULT_RTOL)
            block = max(((len(r), len(c)) for r, c in f.blocks), default=(0, 0))
            t_check = timed(lambda: check(path))
            t_an = timed(lambda: analysis.analyse(J, groups, methods="svd"))
            if min(J.shape) <= DENSE_LIMIT:
                t_dense = f"{timed(lambda: analysis._svd_full(analysis.equilibrate(J)[0]))[0]:8.3f}"
            else:
                t_dense = f"{'-':>8}"
            print(f"{label:<40} {J.shape[0]:>5} {J.shape[1]:>5} {len(f.peeled):>6} "
                  f"{f'{block[0]}x{block[1]}':>11} {t_check[0]:8.3f} {t_check[1]:7.3f} {t_an[0]:10.3f} "
                  f"{t_an[1]:7.3f} {t_dense}", flush=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer and smaller mechanisms (chains of 100 and 1000 "
                    "bodies, the parallelogram of 99 cranks, the two trees with loops)")
    main_(ap.parse_args().quick)
