"""The FMUs (``overcon build``: the FMI layer, the integrators and the model's evaluation in C, no
Python in the FMU), measured as a user runs them.

    python benchmarks/fmu_runtime.py              # ~15 s on the 2-core reference machine
    python benchmarks/fmu_runtime.py --repeat 5
    python benchmarks/fmu_runtime.py --overhead   # the C FMU's cost per doStep against an empty C FMU
    python benchmarks/fmu_runtime.py --examples   # the example scenes through fmpy, C runtime (~20 s)

For each scene the FMU is built into a temporary directory; each run is ``fmpy.simulate_fmu``
over the scene's default experiment at its output interval, in a fresh process (loading fmpy and
the FMU included), and the wall time printed is the median of ``--repeat`` runs of the whole
subprocess, and of the simulate_fmu call alone, with the rows written. Figures are printed, never
asserted.

``--overhead``: the FMI overhead per communication point of a C-runtime FMU against the smallest
FMU a host can run (``benchmarks/empty_fmu/empty_fmi2.c``, compiled here with ``cc`` with as many
Real, Integer and Boolean outputs as ours, and a doStep that only advances time). Our FMU is
``planar_none_wo4`` declaring positions only (so a communication point costs one dense-output
reading, no evaluation); both run in this process through ``fmpy.simulate_fmu`` (extracted once)
over 0-4 s with 4000 and 400 communication points, alternating, medians of ``--repeat`` runs; the
cost per point is the slope between the two, so the integration itself (the same whatever the
grid: the integrator takes its own steps) drops out.

``--examples``: each example scene (its default experiment, 1 ms output interval) through
``fmpy.simulate_fmu`` in this process with the C runtime, the wall time of the call (median of
``--repeat``).
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
print(len(res), time.perf_counter() - t0)
'''


EMPTY_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="empty" guid="{{00000000-0000-0000-0000-000000000000}}"
  generationTool="benchmarks/fmu_runtime.py" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="empty" canHandleVariableCommunicationStepSize="true"/>
  <DefaultExperiment startTime="0" stopTime="4"/>
  <ModelVariables>
{variables}
  </ModelVariables>
  <ModelStructure><Outputs>
{outputs}
  </Outputs></ModelStructure>
</fmiModelDescription>
"""


def build_empty(tmp: Path, n_real: int, n_int: int, n_bool: int) -> Path:
    """The empty C FMU (module docstring), extracted in ``tmp/empty``: its directory."""
    import shutil

    from overcon.fmu.build import _fmi_platform

    cc = shutil.which("cc")
    if cc is None:
        raise SystemExit("--overhead needs a C compiler (cc) for the empty FMU")
    d = tmp / "empty"
    plat = _fmi_platform()[0]
    (d / "binaries" / plat).mkdir(parents=True)
    subprocess.run([cc, "-O2", "-shared", "-fPIC", "-std=c11", "-Wall", "-Wextra", "-Werror", f"-DN_OUT={n_real}",
                    f"-DN_INT={n_int}", f"-DN_BOOL={n_bool}", "-o", str(d / "binaries" / plat / "empty.so"),
                    str(ROOT / "benchmarks" / "empty_fmu" / "empty_fmi2.c")], check=True)
    rows = [("Real", i) for i in range(n_real)] + [("Integer", i) for i in range(n_int)] + \
        [("Boolean", i) for i in range(n_bool)]
    variables = "\n".join(f'    <ScalarVariable name="{t[0].lower()}{i}" valueReference="{i}" causality="output" '
                          f'variability="{"continuous" if t == "Real" else "discrete"}"><{t}/></ScalarVariable>'
                          for t, i in rows)
    outputs = "\n".join(f'    <Unknown index="{k + 1}"/>' for k in range(len(rows)))
    (d / "modelDescription.xml").write_text(EMPTY_MD.format(variables=variables, outputs=outputs))
    return d


def measure_overhead(repeat: int) -> dict:
    """The cost per communication point of the C FMU and of the empty one (module docstring):
    ``ours_us``, ``empty_us`` (us per point), the walls per FMU and grid, and the output counts."""
    import re

    import fmpy

    from overcon.fmu.build import build_all

    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        text = (ROOT / "mechanisms" / "planar_none_wo4.toml").read_text()
        text = re.sub(r"(?m)^reactions = .*$", "reactions = []", text)
        scene = ROOT / "mechanisms" / "_overhead_planar_none_wo4.toml"
        scene.write_text(text)
        try:
            code, res = build_all([str(scene)], tmp / "ours", refs=False, runtime="c", echo=lambda s: None,
                                  echo_err=lambda s: None)
        finally:
            scene.unlink()
        assert code == 0 and res[0].fmu, res[0].messages
        ours = fmpy.extract(str(res[0].fmu), str(tmp / "unz"))
        md = fmpy.read_model_description(ours)
        counts = {t: sum(v.causality == "output" and v.type == t for v in md.modelVariables)
                  for t in ("Real", "Integer", "Boolean")}
        empty = str(build_empty(tmp, counts["Real"], counts["Integer"], counts["Boolean"]))
        md_empty = fmpy.read_model_description(empty)
        stop, walls = 4.0, {}
        for interval in (1e-3, 1e-2):
            for _ in range(repeat):
                for key, unz, m in (("ours", ours, md), ("empty", empty, md_empty)):
                    t0 = time.perf_counter()
                    fmpy.simulate_fmu(unz, stop_time=stop, output_interval=interval, model_description=m)
                    walls.setdefault((key, interval), []).append(time.perf_counter() - t0)
    med = {k: statistics.median(v) for k, v in walls.items()}
    n_hi, n_lo = round(stop / 1e-3), round(stop / 1e-2)
    per = {k: (med[(k, 1e-3)] - med[(k, 1e-2)]) / (n_hi - n_lo) for k in ("ours", "empty")}
    return {"ours_us": 1e6 * per["ours"], "empty_us": 1e6 * per["empty"], "walls": med, "n_hi": n_hi, "n_lo": n_lo,
            "stop": stop, "counts": counts, "repeat": repeat}


def overhead_table(o: dict) -> str:
    """Markdown lines of :func:`measure_overhead`'s figures."""
    c = o["counts"]
    lines = [f"outputs: {c['Real']} Real, {c['Integer']} Integer, {c['Boolean']} Boolean; {o['n_hi']} and "
             f"{o['n_lo']} communication points over 0-{o['stop']:g} s; medians of {o['repeat']}", "",
             f"| FMU | wall, {o['n_hi']} points (s) | wall, {o['n_lo']} points (s) | per point (us) |",
             "|---|---:|---:|---:|"]
    for k, name in (("ours", "overcon C runtime, planar_none_wo4 (positions)"), ("empty", "empty C FMU")):
        lines.append(f"| {name} | {o['walls'][(k, 1e-3)]:.3f} | {o['walls'][(k, 1e-2)]:.3f} | {o[k + '_us']:.1f} |")
    lines += ["", f"ratio per point: {o['ours_us'] / o['empty_us']:.2f}"]
    return "\n".join(lines)


def overhead(repeat: int) -> int:
    print(overhead_table(measure_overhead(repeat)))
    return 0


EXAMPLES = ["door_h1_wo_hinge2", "fourbar_A_wo3_4_5", "loop_D_wo_A2", "carriage_guide_wo_rod"]


def examples(repeat: int) -> int:
    """Print the C-runtime FMU of each example through fmpy at a 1 ms output interval."""
    import fmpy

    from overcon import scene as scene_mod
    from overcon.fmu.build import build_all

    print("| example | stop (s) | simulate_fmu, 1 ms output (s) |")
    print("|---|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for name in EXAMPLES:
            path = ROOT / "mechanisms" / "examples" / f"{name}.toml"
            spec = scene_mod.load(path)
            code, res = build_all([str(path)], Path(tmp) / name, refs=False, allow_nonunique=True, runtime="c",
                                  echo=lambda s: None, echo_err=lambda s: None)
            assert code in (0, 1) and res[0].fmu, res[0].messages
            unz = fmpy.extract(str(res[0].fmu), str(Path(tmp) / f"unz_{name}"))
            md = fmpy.read_model_description(unz)
            walls = []
            for _ in range(repeat):
                t0 = time.perf_counter()
                fmpy.simulate_fmu(unz, output_interval=1e-3, model_description=md)
                walls.append(time.perf_counter() - t0)
            print(f"| {name} | {spec.stop_time:g} | {statistics.median(walls):.3f} |", flush=True)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--overhead", action="store_true", help="the C FMU's cost per doStep against an empty C FMU")
    ap.add_argument("--examples", action="store_true", help="the example scenes through fmpy, C runtime")
    args = ap.parse_args(argv)
    if args.overhead:
        return overhead(args.repeat)
    if args.examples:
        return examples(args.repeat)
    from overcon import scene as scene_mod
    from overcon.fmu.build import build_all

    print("| scene | rows | process (s) | simulate_fmu (s) |")
    print("|---|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for rel in SCENES:
            spec = scene_mod.load(ROOT / rel)
            code, res = build_all([str(ROOT / rel)], Path(tmp), refs=False, allow_nonunique=True,
                                  echo=lambda s: None, echo_err=lambda s: None)
            assert code in (0, 1) and res[0].fmu, res[0].messages
            walls, calls, rows = [], [], 0
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                proc = subprocess.run([sys.executable, "-c", RUN, str(res[0].fmu), repr(spec.solver.output_interval)],
                                      capture_output=True, text=True, check=True)
                walls.append(time.perf_counter() - t0)
                rows, call = proc.stdout.split()[-2:]
                calls.append(float(call))
            print(f"| {spec.name} | {rows} | {statistics.median(walls):.2f} | {statistics.median(calls):.3f} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
