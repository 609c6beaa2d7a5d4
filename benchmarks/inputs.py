"""What FMU inputs cost, measured as a user runs the FMUs (``fmpy.simulate_fmu`` in this process,
FMI 2.0 co-simulation, C runtime). Figures are printed, never asserted (docs/benchmarks.md,
"FMU inputs").

    python benchmarks/inputs.py --door [--repeat 3] [--intervals]
    python benchmarks/inputs.py --paper --base DIR [--repeat 3] [--scenes NAME ...]

``--door``: the door of the coupling example (mechanisms/examples/coupling/door_motor.toml: motor
input on hinge1, friction in hinge1, hinge sensors) over 0-2 s at 1 ms communication steps, against
the same scene without its ``[[inputs]]`` table (everything else equal), built into a temporary
directory. Rows: the FMU without inputs; with the input left at its start value (no table); with
a constant table equal to the start value through ``input=`` (fmpy sets the same value at every
point: its cost without a change of the input); with a ramp from 0 to 20 N·m, held; with the
ramp and input derivatives (``set_input_derivatives``, linear). Median wall time of ``--repeat`` calls of
``simulate_fmu`` (the FMU extracted once), alternating the variants.

``--paper``: every paper scene's FMU (mechanisms/*_wo*.toml, their default experiments) built by
this tree and by the tree at DIR (e.g. a checkout of the commit before inputs, with its C core
compiled: ``git archive 76d28d9 | tar -x -C DIR && cd DIR && python setup.py build_ext
--inplace``), each run through ``simulate_fmu``, alternating old and new, median of ``--repeat``.
DIR's FMUs are built in a child process with DIR/fmu_src first on the path.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import fmpy
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DOOR = ROOT / "mechanisms" / "examples" / "coupling" / "door_motor.toml"


def _build(scenes, out: Path, src: Path | None = None) -> dict[str, Path]:
    """Build ``scenes`` (co-simulation, FMI 2.0) into ``out`` with this tree or, ``src`` given, with
    the overcon package found in ``src`` (a child process); returns model name -> FMU path."""
    code = ("import json, sys\nfrom overcon.fmu.build import build_all\n"
            "c, r = build_all(sys.argv[2:], sys.argv[1], refs=False, validate=False, allow_nonunique=True, kind='cs',"
            " echo=lambda s: None)\nprint(json.dumps({x.name: str(x.fmu) for x in r if x.status == 'built'}))\n")
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = str(src)
    proc = subprocess.run([sys.executable, "-c", code, str(out), *map(str, scenes)], capture_output=True, text=True,
                          env=env, timeout=1200, cwd=str(src or ROOT))
    if proc.returncode != 0:
        raise SystemExit(f"build failed: {proc.stderr[-2000:]}")
    return {k: Path(v) for k, v in json.loads(proc.stdout.strip().splitlines()[-1]).items()}


def _timed(path: str, **kw) -> float:
    t0 = time.perf_counter()
    fmpy.simulate_fmu(path, **kw)
    return time.perf_counter() - t0


def door(repeat: int, intervals: bool = False) -> None:
    from overcon.tooling.inputs import InputTable
    from overcon.tooling.run import _input_derivatives_buffers

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        text = DOOR.read_text()
        start = text.index("[[inputs]]")
        plain = text[:start] + text[text.index("[outputs]"):]
        (tmp / "plain").mkdir()
        (tmp / "plain" / "door_motor.toml").write_text(plain.replace('mechanism = "../door.toml"',
                                                                     'mechanism = "door.toml"'))
        (tmp / "plain" / "door.toml").write_text((DOOR.parent.parent / "door.toml").read_text())
        with_in = _build([DOOR], tmp / "in")["coupled_door"]
        without = _build([tmp / "plain" / "door_motor.toml"], tmp / "out")["coupled_door"]
        d_in, d_out = fmpy.extract(str(with_in)), fmpy.extract(str(without))
        ramp = InputTable(np.array([0.0, 2.0]), {"motor": np.array([0.0, 20.0])}).structured()
        zero = InputTable(np.array([0.0, 2.0]), {"motor": np.array([0.0, 0.0])}).structured()
        kw = dict(stop_time=2.0, output_interval=1e-3)
        variants = {
            "without inputs (the same scene, no [[inputs]])": lambda: _timed(d_out, **kw),
            "with the input at its start value (no table)": lambda: _timed(d_in, **kw),
            "with a constant table (0 N·m, the start value), held (input=)": lambda: _timed(d_in, input=zero, **kw),
            "with a ramp table (0 to 20 N·m), held (input=)": lambda: _timed(d_in, input=ramp, **kw),
            "with the ramp table, linear (input=, set_input_derivatives)": lambda: _timed(
                d_in, input=ramp, set_input_derivatives=True, **kw),
        }
        times = {k: [] for k in variants}
        with _input_derivatives_buffers():  # fmpy 0.3.32's buffer for 9 inputs (overcon.tooling.run)
            for _ in range(repeat):
                for k, f in variants.items():
                    times[k].append(f())
        if intervals:  # the FMU without inputs against the one with its input unset, per communication step
            print(f"door, 0-2 s, without inputs / with the input unset, median of {repeat}\n")
            print("| communication step (s) | without (s) | with (s) | ratio |")
            print("|---:|---:|---:|---:|")
            for dt in (1e-3, 1e-2, 1e-1):
                a, b = [], []
                for _ in range(repeat):
                    a.append(_timed(d_out, stop_time=2.0, output_interval=dt))
                    b.append(_timed(d_in, stop_time=2.0, output_interval=dt))
                ma, mb = statistics.median(a), statistics.median(b)
                print(f"| {dt:g} | {ma:.3f} | {mb:.3f} | {mb / ma:.2f} |")
            print()
        base = statistics.median(times[next(iter(variants))])
        print(f"door, 0-2 s, 2000 communication points (1 ms), fmpy.simulate_fmu, median of {repeat}\n")
        print("| FMU | wall (s) | ratio |")
        print("|---|---:|---:|")
        for k, v in times.items():
            m = statistics.median(v)
            print(f"| {k} | {m:.3f} | {m / base:.2f} |")


def paper(repeat: int, base_src: Path, only=None) -> None:
    scenes = [s for s in sorted((ROOT / "mechanisms").glob("*_wo*.toml")) if not only or s.stem in only]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        new = _build(scenes, tmp / "new")
        old = _build(scenes, tmp / "old", src=base_src / "fmu_src")
        print(f"every paper scene's FMU, its default experiment, fmpy.simulate_fmu, median of {repeat} "
              f"(old: {base_src})\n")
        print("| scene | old (s) | new (s) | new / old |")
        print("|---|---:|---:|---:|")
        ratios = []
        for name in sorted(new):
            d_new, d_old = fmpy.extract(str(new[name])), fmpy.extract(str(old[name]))
            t_new, t_old = [], []
            for _ in range(repeat):
                t_old.append(_timed(d_old))
                t_new.append(_timed(d_new))
            a, b = statistics.median(t_old), statistics.median(t_new)
            ratios.append(b / a)
            print(f"| {name} | {a:.3f} | {b:.3f} | {b / a:.2f} |")
        print(f"\nratio new / old: median {statistics.median(ratios):.2f}, range {min(ratios):.2f}..{max(ratios):.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--door", action="store_true")
    ap.add_argument("--intervals", action="store_true", help="--door: also the ratio at 1, 10 and 100 ms steps")
    ap.add_argument("--paper", action="store_true")
    ap.add_argument("--base", type=Path, help="--paper: the tree of the commit to compare with (C core compiled)")
    ap.add_argument("--scenes", nargs="+", metavar="NAME", help="--paper: only these scenes (e.g. spatial_MN_wo9)")
    args = ap.parse_args(argv)
    if args.door:
        door(args.repeat, args.intervals)
    if args.paper:
        if args.base is None:
            ap.error("--paper needs --base DIR")
        paper(args.repeat, args.base, args.scenes)
    if not (args.door or args.paper):
        ap.error("give --door and/or --paper")
    return 0


if __name__ == "__main__":
    sys.exit(main())
