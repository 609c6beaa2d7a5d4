"""The compliant door (mechanisms/examples/compliant_door_h1_wo_hinge2.toml: two compliant hinges,
friction in hinge1) at a high stiffness through fmpy, as issue 24 measures it: 2 s simulated,
``fmpy.simulate_fmu`` at the scene's output interval.

    python benchmarks/compliant_door.py                    # k = 1e9 N/m, ~1 min on the 2-core machine
    python benchmarks/compliant_door.py --stiffness 1e8 1e9

At stiffness k every compliant value is scaled by overcon.converge's rule (stiffnesses by k / k0,
dampings by sqrt(k / k0), k0 = 1e8 N/m the file's), written as a scene file next to a copy of the
mechanism. The FMU is built once (``overcon build``: no Python in it) and run with each integrator
it has (solver.method set through fmpy's start values); a run that stops prints its reason. The
reference is the FMU's run with radau (the scene's method; its own row shows 0). Printed per
run: wall time of simulate_fmu (median of --repeat), and the largest position difference from
the reference (m). With ``--energy`` the scene has ``[outputs] energy = true`` and the table adds
the energy balance: the drift of kinetic + potential + dissipated - applied over the run (J) and
that drift relative to the kinetic+potential scale (max |kinetic| + max |potential|), issue 24's
goal of 1e-6. ``--methods`` limits the C runtime's integrators. Figures are printed, never asserted.

    python benchmarks/compliant_door.py --energy --methods radau
"""
from __future__ import annotations

import argparse
import math
import re
import statistics
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "mechanisms" / "examples"
K0 = 1e8  # N/m: the stiffness of the file's hinges


def scaled_files(tmp: Path, k: float, energy: bool = False) -> Path:
    """The scene and its mechanism at stiffness k (module docstring); the scene's path."""
    mech = (EXAMPLES / "compliant_door.toml").read_text()
    s, r = k / K0, math.sqrt(k / K0)

    def scale(m, factor):
        return f"{m.group(1)}{float(m.group(2)) * factor!r}"
    mech = re.sub(r"^((?:rotational_)?stiffness = )([0-9.e+-]+)", lambda m: scale(m, s), mech, flags=re.M)
    mech = re.sub(r"^((?:rotational_)?damping = )([0-9.e+-]+)", lambda m: scale(m, r), mech, flags=re.M)
    d = tmp / f"k{k:.0e}"
    d.mkdir()
    (d / "compliant_door.toml").write_text(mech)
    scene = d / "compliant_door_h1_wo_hinge2.toml"
    text = (EXAMPLES / "compliant_door_h1_wo_hinge2.toml").read_text()
    if energy:
        text = text.replace('friction = "all"\n', 'friction = "all"\nenergy = true\n')
    scene.write_text(text)
    return scene


def balance(out) -> str:
    """The energy columns of the table for one run's outputs (module docstring)."""
    e = {k: out[f"energy.{k}"] for k in ("kinetic", "potential", "dissipated", "applied")}
    bal = e["kinetic"] + e["potential"] + e["dissipated"] - e["applied"]
    drift = float(max(abs(bal - bal[0])))
    scale = float(max(abs(e["kinetic"])) + max(abs(e["potential"])))
    return f" {drift:.2e} | {drift / scale:.2e} |"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stiffness", type=float, nargs="+", default=[1e9])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--energy", action="store_true", help="energy outputs on, and their balance printed")
    ap.add_argument("--methods", nargs="+", help="the C runtime's integrators to run (default: all but rk4)")
    args = ap.parse_args(argv)
    import fmpy
    import numpy as np

    from overcon.fmu.build import build_all
    from overcon.kernel import C_METHODS

    extra = (" balance drift (J) | relative |", "---:|---:|") if args.energy else ("", "")
    print("| k (N/m) | runtime | method | simulate_fmu (s) | max position difference from radau (m) | stopped |"
          + extra[0])
    print("|---:|---|---|---:|---:|---|" + extra[1])
    with tempfile.TemporaryDirectory() as tmp:
        for k in args.stiffness:
            scene = scaled_files(Path(tmp), k, args.energy)
            code, res = build_all([str(scene)], Path(tmp) / f"c{k:.0e}", refs=False, echo=lambda s: None,
                                  echo_err=lambda s: None)
            assert code == 0 and res[0].fmu, res[0].messages
            fmus = {"c": str(res[0].fmu)}
            ref = fmpy.simulate_fmu(fmus["c"], start_values={"solver.method": "radau"})
            cols = [n for n in ref.dtype.names if n.startswith("door.")]
            runs = [("c", m) for m in args.methods or C_METHODS if m != "rk4"]
            for runtime, method in runs:
                walls, stopped, out = [], "", None
                for _ in range(args.repeat):
                    t0 = time.perf_counter()
                    try:
                        out = fmpy.simulate_fmu(fmus[runtime], start_values={"solver.method": method})
                    except Exception as exc:  # noqa: BLE001 - printed, the benchmark goes on
                        stopped = str(exc).splitlines()[0][:120]
                    walls.append(time.perf_counter() - t0)
                diff = max(float(np.max(np.abs(out[c] - ref[c]))) for c in cols) if out is not None and \
                    len(out) == len(ref) else float("nan")
                shown = " |" * 2 if args.energy else ""
                if args.energy and out is not None and not stopped:
                    shown = balance(out)
                print(f"| {k:.0e} | {runtime} | {method} | {statistics.median(walls):.3f} | {diff:.2e} | "
                      f"{stopped or 'no'} |{shown}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
