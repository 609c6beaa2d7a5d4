"""Model Exchange against co-simulation on the paper's scenes with friction (C runtime, FMI 3.0):
builds them (``overcon build --runtime c --fmi 3``, both kinds) into a temporary directory, runs each
through fmpy as co-simulation (the FMU's dopri5) and as Model Exchange (fmpy's CVode), both at
tolerance 1e-9, and prints the wall time of each run and the largest difference of the x, y, z
positions (m). tests/test_fmi3_me.py asserts the bound 1e-6 m; this prints the figures.

    python benchmarks/me_vs_cs.py [--mechanisms DIR]
"""
import argparse
import tempfile
import time
from pathlib import Path

import fmpy
import numpy as np

from overcon.fmu.build import build_all


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mechanisms", default="mechanisms", help="directory of the paper's scenes")
    args = p.parse_args()
    scenes = [s for s in sorted(Path(args.mechanisms).glob("*_wo*.toml")) if "_none_" not in s.stem]
    with tempfile.TemporaryDirectory() as tmp:
        code, built = build_all([str(s) for s in scenes], tmp, refs=False, validate=False, runtime="c", fmi=3,
                                allow_nonunique=True, echo=lambda s: None)
        assert code == 0, code
        worst = 0.0
        for r in built:
            md = fmpy.read_model_description(str(r.fmu))
            pos = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Float64"
                   and not v.dimensions and v.name.rsplit(".", 1)[1] in ("x", "y", "z")]
            t0 = time.perf_counter()
            cs = fmpy.simulate_fmu(str(r.fmu), fmi_type="CoSimulation", relative_tolerance=1e-9, output=pos)
            t1 = time.perf_counter()
            me = fmpy.simulate_fmu(str(r.fmu), fmi_type="ModelExchange", relative_tolerance=1e-9, output=pos)
            t2 = time.perf_counter()
            d = max(float(np.max(np.abs(cs[n] - me[n]))) for n in pos)
            worst = max(worst, d)
            print(f"{r.name:20s} co-simulation {t1 - t0:6.2f} s  Model Exchange {t2 - t1:6.2f} s  "
                  f"largest position difference {d:.3g} m", flush=True)
        print(f"largest over {len(built)} scenes: {worst:.3g} m")


if __name__ == "__main__":
    main()
