"""The singularity watch's cost with a given build of the core: bare kernel.Run of the N-four-bar
(N = 2, 10, 40, ``singular = "pass"``, 20 s, tolerance 1e-7) and spatial_MN_wo5 (10 s), best of 3
runs each: wall time, the watch's time (ovk_sim_info ``watch_time``) and share, steps, singular
positions passed, capped estimates. Run it twice, with the installed core and with another build,
to compare two versions of the watch in one session (docs/benchmarks.md, "The watch without
masses"):

    git archive <commit> fmu_src/overcon/core | tar -x -C /tmp/old
    gcc -O2 -ffp-contract=off -fno-fast-math -std=c11 -shared -fPIC -o /tmp/libold.so \\
        /tmp/old/fmu_src/overcon/core/*.c -lm
    python benchmarks/watch_core.py /tmp/libold.so
    python benchmarks/watch_core.py                      # the installed core

The other build must have the installed one's ABI (overcon.kernel.ABI)."""
from __future__ import annotations

import importlib.util
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str]) -> None:
    from overcon import kernel
    if argv:
        kernel.LIBRARY = Path(argv[0])  # before the first use: library() loads it
    from overcon import scene as scene_mod
    from overcon.checks import compile_checked

    spec = importlib.util.spec_from_file_location("nfourbar", ROOT / "mechanisms" / "examples" / "nfourbar.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    tmp = Path(tempfile.mkdtemp())
    cases = []
    for n in (2, 10, 40):
        _, path = mod.write(n, tmp / f"n{n}", stop_time=20.0, tolerance=1e-7, singular="pass")
        cases.append((f"N-four-bar N = {n}, 20 s", scene_mod.as_scene(scene_mod.load(path)), 20.0))
    cases.append(("spatial_MN_wo5, 10 s",
                  scene_mod.as_scene(scene_mod.load(ROOT / "mechanisms" / "spatial_MN_wo5.toml"), stop_time=10.0), 10.0))
    print(f"core: {kernel.LIBRARY}")
    print("| run | wall (s) | watch (s) | share | steps | singular passed | capped |")
    print("|---|---|---|---|---|---|---|")
    for name, sc, stop in cases:
        model = compile_checked(sc)
        best = None
        for _ in range(3):
            run = kernel.Run(model, sc.solver)
            run.advance(stop)
            if best is None or run.info["wall_time"] < best["wall_time"]:
                best = run.info
        print(f"| {name} | {best['wall_time']:.3f} | {best['watch_time']:.3f} | "
              f"{best['watch_time'] / best['wall_time']:.0%} | {best['nsteps']:.0f} | {best['singular_passed']:.0f} | "
              f"{best['watch_capped']:.0f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
