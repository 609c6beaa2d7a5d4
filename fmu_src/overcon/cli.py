"""Command line: ``overcon check`` and ``overcon simulate`` (argument parsing only; the work is
done by the library).

Exit codes: 0 success (``check``: no friction on a non-unique reaction); 1 ``check`` found
friction on a joint whose reaction is not unique (or the three tests disagree); 2 invalid input
(file, field or flag at fault is named); 3 the simulation failed (time and cause are named).
"""
from __future__ import annotations

import argparse
import json
import sys
import time

EXIT_OK, EXIT_NONUNIQUE, EXIT_INPUT, EXIT_RUNTIME = 0, 1, 2, 3


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse exits 2 on bad flags, as we do for bad input
        self.print_usage(sys.stderr)
        print(f"overcon: error: {message}", file=sys.stderr)
        raise SystemExit(EXIT_INPUT)


def _scene_flags(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="mechanism or scene TOML file")
    p.add_argument("--friction", metavar="J1,J2|none",
                   help="joints with friction switched on (overrides the scene), e.g. joint4,joint5 or none")
    p.add_argument("--eliminate", metavar="K1,K2|auto",
                   help="1-based paper equation indices to eliminate, or auto (pivoted QR)")
    p.add_argument("--stop-time", type=float, metavar="T", help="stop time (s)")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="overcon", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    c = sub.add_parser("check", help="reaction-uniqueness pre-check of a mechanism or scene")
    _scene_flags(c)
    c.add_argument("--json", action="store_true", help="print the report as JSON")
    s = sub.add_parser("simulate", help="integrate a scene (or a bare mechanism) in process, write CSV")
    _scene_flags(s)
    s.add_argument("--out", required=True, metavar="OUT.csv", help="CSV file: time, then the outputs")
    s.add_argument("--tolerance", type=float, metavar="TOL", help="accuracy target (rtol = atol of dopri5)")
    s.add_argument("--method", choices=("dopri5", "rk4"), help="integrator")
    s.add_argument("--step", type=float, help="rk4 step (s)")
    s.add_argument("--output-interval", type=float, help="output grid interval (s)")
    fg = sub.add_parser("figures", help="run the paper's scene groups in process and plot Figs. 3-5, 7-9 (PNG)")
    fg.add_argument("--mechanisms", default="mechanisms", help="directory with the scene files (default: mechanisms)")
    fg.add_argument("--out", default="figures", help="output directory for the PNG files (default: figures)")
    fg.add_argument("--tolerance", type=float, metavar="TOL", help="override the scenes' solver tolerance")
    from .fmu.build import add_arguments as _build_arguments

    _build_arguments(sub.add_parser(
        "build", help="build one FMI 2.0 co-simulation FMU per scene file (pre-check first; same as build_fmu.py)"))
    return parser


def _load(args):
    """Scene with the command-line overrides applied, compiled. Raises SceneError/ModelError."""
    from . import scene as scene_mod
    from .model import compile_model

    spec = scene_mod.load(args.file)
    overrides = dict(
        friction=None if args.friction is None else scene_mod.parse_joint_list(args.friction),
        eliminate=None if args.eliminate is None else scene_mod.parse_eliminate(args.eliminate),
        stop_time=args.stop_time, tolerance=getattr(args, "tolerance", None), source=args.file)
    spec = scene_mod.as_scene(spec, **overrides)
    return compile_model(spec)


def _input_error(exc) -> int:
    print(f"overcon: {exc}", file=sys.stderr)
    return EXIT_INPUT


def cmd_check(args) -> int:
    from .precheck import format_table, precheck

    model = _load(args)
    report = precheck(model, args.file)
    print(json.dumps(report, indent=2) if args.json else format_table(report))
    return EXIT_NONUNIQUE if report["friction_on_nonunique"] or not report["methods_agree"] else EXIT_OK


def cmd_simulate(args) -> int:
    from .simulate import SimulationError, run, write_csv

    for flag in ("tolerance", "step", "output_interval"):
        val = getattr(args, flag)
        if val is not None and not (val > 0 and val < float("inf")):
            raise ValueError(f"--{flag.replace('_', '-')}: must be a positive finite number, got {val}")
    model = _load(args)
    start = time.perf_counter()
    try:
        res = run(model, output_interval=args.output_interval, method=args.method, step=args.step,
                  tolerance=args.tolerance)
    except SimulationError as exc:
        print(f"overcon: {args.file}: {exc}", file=sys.stderr)
        return EXIT_RUNTIME
    wall = time.perf_counter() - start
    write_csv(res, args.out)
    print(f"{args.out}: {len(res.time)} rows x {len(res.names)} outputs, t = {res.time[0]:g}..{res.time[-1]:g} s; "
          f"eliminated {', '.join('Phi%d' % i for i in model.eliminated) or 'none'} ({model.elimination_mode}); "
          f"{res.steps} steps, {res.evaluations} evaluations, {res.friction_iterations} friction iterations; "
          f"max constraint drift {res.max_drift:.3g}; wall {wall:.2f} s")
    if res.stiff_steps:
        print(f"note: {res.stiff_steps} steps were limited by stability (stiff: friction sticking inside the "
              "regularisation band); a larger v_reg or a looser tolerance is cheaper")
    return EXIT_OK


def cmd_figures(args) -> int:
    from pathlib import Path

    from .paper import make_figures
    from .simulate import SimulationError

    start = time.perf_counter()
    try:
        make_figures(Path(args.mechanisms), Path(args.out), tolerance=args.tolerance)
    except SimulationError as exc:
        print(f"overcon: {exc}", file=sys.stderr)
        return EXIT_RUNTIME
    print(f"figures written to {args.out}/ in {time.perf_counter() - start:.1f} s")
    return EXIT_OK


def cmd_build(args) -> int:
    from .fmu.build import run_args

    return run_args(args)


def main(argv=None) -> int:
    from .model import ModelError
    from .scene import SceneError
    from .simulate import InconsistentInitialState

    args = build_parser().parse_args(argv)
    handler = {"check": cmd_check, "simulate": cmd_simulate, "figures": cmd_figures,
               "build": cmd_build}[args.command]
    try:
        return handler(args)
    except SceneError as exc:  # already names file and field
        return _input_error(exc)
    except (ModelError, InconsistentInitialState, ValueError, OSError) as exc:
        return _input_error(f"{getattr(args, 'file', '')}: {exc}")


if __name__ == "__main__":
    sys.exit(main())
