"""Cost of the uniqueness along the motion (core/unique.c through overcon.kernel.Kernel.unique):
one evaluation of the whole Jacobian's rank and every joint's verdict at q0, against one
evaluation of Eq. 18, per mechanism. Prints the figures docs/howto/singular.md quotes.

    python benchmarks/uniqueness_along.py [--repeat N]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from overcon import kernel, scene
from overcon.checks import compile_checked

ROOT = Path(__file__).resolve().parents[1]
SCENES = ("mechanisms/planar_f45_wo4.toml", "mechanisms/examples/fourbar_A_wo3_4_5.toml",
          "tests/data/bricard/bricard_wo2.toml", "mechanisms/spatial_MN_wo5.toml")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=50)
    args = ap.parse_args()
    lib, reason = kernel.library()
    if lib is None:
        raise SystemExit(reason)
    for name in SCENES:
        spec = scene.as_scene(scene.load(ROOT / name))
        model = compile_checked(spec)
        k = kernel.Kernel(lib, model, spec.solver)
        y = np.concatenate([model.q0, model.h0])
        k.unique(y)
        t = time.perf_counter()
        for _ in range(args.repeat):
            k.unique(y)
        unique = (time.perf_counter() - t) / args.repeat
        t = time.perf_counter()
        for _ in range(args.repeat):
            k.evaluate(0.0, y)
        evaluation = (time.perf_counter() - t) / args.repeat
        print(f"{Path(name).stem}: {model.m} equations, {model.nh} velocities: uniqueness {unique * 1e3:.3f} ms, "
              f"one evaluation of Eq. 18 {evaluation * 1e6:.1f} us")


if __name__ == "__main__":
    main()
