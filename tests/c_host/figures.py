#!/usr/bin/env python3
"""Figures quoted in docs/reference/fmu.md: wall time of one fmi2DoStep(0, 1e6) under the default work
budget, of the C host (fmu_host.c) per process from an empty environment, and the FMI overhead per
communication point through fmpy (20000 points of 1e-5 s, minus the same run in process: kernel.Run's
advance and its outputs' table per point, two ctypes calls as fmpy makes two FMI calls).

    python tests/c_host/figures.py [--runs N] [SCENE ...]     (default: planar_none_wo4 planar_f45_wo4)

Builds the FMUs into a temporary folder, prints one line per figure; no assertion (timings vary
with load).
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import fmpy
from fmpy.fmi2 import FMU2Slave

from overcon.fmu.build import build_all

ROOT = Path(__file__).resolve().parents[2]


def huge_step(unz: str) -> str:
    md = fmpy.read_model_description(unz)
    s = FMU2Slave(guid=md.guid, unzipDirectory=unz, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="budget")
    s.instantiate(loggingOn=False)
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    t0 = time.perf_counter()
    try:
        s.doStep(0.0, 1e6)
        outcome = "completed"
    except Exception as exc:  # the budget ends it with fmi2Error
        outcome = str(exc)
    return f"{md.coSimulation.modelIdentifier}: fmi2DoStep(0, 1e6) {outcome} after {time.perf_counter() - t0:.1f} s"


def overhead(unz: str, scene: str, n: int = 20000, h: float = 1e-5) -> str:
    from overcon import kernel
    from overcon import scene as scene_mod
    from overcon.checks import compile_checked, watch_rows

    md = fmpy.read_model_description(unz)
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    s = FMU2Slave(guid=md.guid, unzipDirectory=unz, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="overhead")
    s.instantiate(loggingOn=False)
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    t0, t = time.perf_counter(), 0.0
    for k in range(n):
        t_next = (k + 1) * h
        s.doStep(t, t_next - t)
        s.getReal(outs)
        t = t_next
    fmu = time.perf_counter() - t0
    s.terminate()
    s.freeInstance()
    spec = scene_mod.load(ROOT / "mechanisms" / f"{scene}.toml")
    model = compile_checked(spec)
    run = kernel.Run(model, spec.solver, watch=watch_rows(model))
    t0 = time.perf_counter()
    for k in range(n):
        t_next = (k + 1) * h
        run.outputs(t_next, run.advance(t_next))
    engine = time.perf_counter() - t0
    return (f"{scene}: {len(outs)} outputs, {fmu / n * 1e6:.1f} us per communication point through fmpy, "
            f"{engine / n * 1e6:.1f} us in process (kernel.Run): FMI overhead {(fmu - engine) / n * 1e6:.1f} us")


def host_runs(host: Path, unz: str, runs: int) -> str:
    md = fmpy.read_model_description(unz)
    outs = [f"{v.valueReference}:{v.name}" for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    args = [str(host), "-q", unz, md.coSimulation.modelIdentifier, md.guid, "0.0", "0.05", "0.01", "1e-9", *outs]
    t0 = time.perf_counter()
    ok = sum(subprocess.run(args, capture_output=True, env={}).returncode == 0 for _ in range(runs))
    per = (time.perf_counter() - t0) / runs
    return f"{md.coSimulation.modelIdentifier}: C host from an empty environment, {ok}/{runs} exit 0, {per:.2f} s per process"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=["planar_none_wo4", "planar_f45_wo4"])
    p.add_argument("--runs", type=int, default=10)
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        code, _ = build_all([str(ROOT / "mechanisms" / f"{s}.toml") for s in a.scenes], tmp, refs=False,
                            echo=lambda s: None)
        if code:
            return code
        host = tmp / "fmu_host"
        subprocess.run([shutil.which("cc") or "cc", "-O2", "-o", str(host), str(ROOT / "tests" / "c_host" / "fmu_host.c"),
                        "-ldl", "-lm"], check=True)
        for s in a.scenes:
            unz = fmpy.extract(str(tmp / f"{s}.fmu"), str(tmp / f"unz_{s}"))
            print(host_runs(host, unz, a.runs), flush=True)
            print(huge_step(unz), flush=True)
            print(overhead(unz, s), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
