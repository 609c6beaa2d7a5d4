"""BLAS threads in a run: the same in-process run with BLAS's own thread count and with one
thread (overcon.cli.single_threaded_blas), side by side, repeated alternately.

    python benchmarks/blas_threads.py [SCENE ...]

Default scenes: the paper's spatial_MN_wo5 and a planar parallelogram of 20 cranks (40 joints,
generated). Prints per scene the median wall time of ``overcon.simulate.run`` of each setting
and their ratio; the figures go to docs/benchmarks.md ("BLAS threads") by hand.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from threadpoolctl import threadpool_info  # noqa: E402

from overcon import scene  # noqa: E402
from overcon.checks import compile_checked  # noqa: E402
from overcon.cli import single_threaded_blas  # noqa: E402
from overcon.simulate import run  # noqa: E402


def scenes(tmp: Path, given: list[str]) -> list[Path]:
    if given:
        return [Path(p) for p in given]
    from test_precheck_methods import parallelogram
    parallelogram(20, tmp / "parallelogram20.toml")
    (tmp / "parallelogram20_scene.toml").write_text(
        '[scene]\nname = "parallelogram20"\nmechanism = "parallelogram20.toml"\nfriction = []\n'
        'eliminate = "auto"\nstop_time = 1.0\n')
    return [ROOT / "mechanisms" / "spatial_MN_wo5.toml", tmp / "parallelogram20_scene.toml"]


def timed(model, solver, limit: bool) -> float:
    t = time.perf_counter()
    if limit:
        with single_threaded_blas():
            run(model, solver)
    else:
        run(model, solver)
    return time.perf_counter() - t


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", help="scene files (default: spatial_MN_wo5 and a parallelogram of 20 cranks)")
    argv = ap.parse_args(argv).scenes
    threads = sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})
    print(f"BLAS threads by default: {threads}")
    with tempfile.TemporaryDirectory() as tmp:
        for path in scenes(Path(tmp), argv):
            spec = scene.load(path)
            model = compile_checked(scene.as_scene(spec))
            own, one = [], []
            for _ in range(5):
                own.append(timed(model, spec.solver, False))
                one.append(timed(model, spec.solver, True))
            a, b = statistics.median(own), statistics.median(one)
            print(f"{path.name}: BLAS's own threads {a:.3f} s, one thread {b:.3f} s, ratio {a / b:.1f}x "
                  f"(median of 5 each, alternating)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
