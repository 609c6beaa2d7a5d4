"""The two FMU runtimes side by side: ``overcon build --runtime python`` (the FMU embeds Python and
runs overcon.simulate over the compiled core) against ``--runtime c`` (the FMI layer and the
integrators in C, no Python), measured as a user runs them.

    python benchmarks/fmu_runtime.py              # ~1 min on the 2-core reference machine
    python benchmarks/fmu_runtime.py --repeat 5

For each scene both FMUs are built into a temporary directory; each run is ``fmpy.simulate_fmu``
over the scene's default experiment at its output interval, in a fresh process (so the Python FMU
pays its start: the interpreter, numpy, scipy, compiling the scene), and the wall time printed is
the median of ``--repeat`` runs of the whole subprocess, and of the simulate_fmu call alone. The
largest difference between the two results (every output) is printed too. Figures are printed,
never asserted.
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENES = ["mechanisms/planar_f45_wo4.toml", "mechanisms/spatial_MN_wo5.toml",
          "mechanisms/examples/door_h1_wo_hinge2.toml", "mechanisms/examples/fourbar_A_wo3_4_5.toml"]

RUN = r'''
import sys, time, numpy as np, fmpy
t0 = time.perf_counter()
res = fmpy.simulate_fmu(sys.argv[1], output_interval=float(sys.argv[2]))
print(time.perf_counter() - t0)
np.save(sys.argv[3], np.column_stack([res[n] for n in res.dtype.names]))
'''


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    import numpy as np

    from overcon import scene as scene_mod
    from overcon.fmu.build import build_all

    print("| scene | runtime | process (s) | simulate_fmu (s) | max |difference| |")
    print("|---|---|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for rel in SCENES:
            spec = scene_mod.load(ROOT / rel)
            out = {}
            for runtime in ("python", "c"):
                d = Path(tmp) / runtime
                code, res = build_all([str(ROOT / rel)], d, refs=False, allow_nonunique=True, runtime=runtime,
                                      echo=lambda s: None, echo_err=lambda s: None)
                assert code in (0, 1) and res[0].fmu, res[0].messages
                walls, calls = [], []
                for _ in range(args.repeat):
                    t0 = time.perf_counter()
                    proc = subprocess.run([sys.executable, "-c", RUN, str(res[0].fmu), repr(spec.solver.output_interval),
                                           str(d / "r.npy")], capture_output=True, text=True, check=True)
                    walls.append(time.perf_counter() - t0)
                    calls.append(float(proc.stdout.split()[-1]))
                out[runtime] = np.load(d / "r.npy")
                diff = "" if runtime == "python" else f"{np.max(np.abs(out['c'] - out['python'])):.1e}"
                print(f"| {spec.name} | {runtime} | {statistics.median(walls):.2f} | {statistics.median(calls):.3f} "
                      f"| {diff} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
