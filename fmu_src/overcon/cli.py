"""Command line: ``overcon check | simulate | figures | build | run | compare | reproduce | sweep |
converge | regress | schema | draw | animate``. This module parses the arguments and reports; the
work is done by the library. :func:`build_parser` is the one argument parser (the documentation's
CLI reference is generated from it).

Exit codes: 0 success (``check``: no friction on a non-unique reaction); 1 ``check`` found
friction on a joint whose reaction is not unique (or the three tests disagree); 2 invalid input
(file, field or flag at fault is named); 3 the simulation failed (time and cause are named, also
when the work budget ``--max-steps``/``--max-wall-time`` ran out); 130 interrupted (Ctrl-C).

Solver flags of ``simulate`` (``--tolerance``, ``--step``, ``--max-step``, ``--output-interval``,
``--method``, ``--kernel``) override the scene's [solver] table and are checked by the one rules table
:mod:`overcon.params` (envelope and bounded-work relations), reported with the flag's name.
"""
from __future__ import annotations

import argparse
import os
import json
import sys
import time

from .argtypes import count as _jobs
from .simulate import MAX_STEPS, MAX_WALL_TIME
from .spec import KERNELS, METHODS, SINGULAR
from .verdict import LOCKSTEP_STEP

EXIT_OK, EXIT_NONUNIQUE, EXIT_INPUT, EXIT_RUNTIME = 0, 1, 2, 3
EXIT_INTERRUPTED = 130  # Ctrl-C (SIGINT), as a shell reports it
EXIT_BROKEN_PIPE = 141  # the output pipe was closed by its reader (SIGPIPE, as a shell reports it)


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
                   help="1-based paper equation indices and/or joint names (all their equations) to eliminate, or auto (pivoted QR)")
    p.add_argument("--stop-time", type=float, metavar="T", help="stop time (s)")


DESCRIPTION = ("Overconstrained rigid mechanisms with Coulomb joint friction: pre-check whether the simulated "
               "motion is unique (Fraczek & Wojtyra 2011), simulate it, export it as an FMI FMU, and compare the "
               "motions a simulator's choice of eliminated equations gives.")
EPILOG = ("Start with: overcon check FILE. Exit codes: 0 ok; 1 a verdict to look at (friction on a non-unique "
          "reaction, a mismatch, a regression); 2 bad input; 3 a simulation failed; 130 interrupted. "
          "overcon COMMAND --help shows a command's flags; the documentation is in docs/ (README.md).")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``overcon`` command (every sub-command and flag)."""
    from . import __version__

    parser = _Parser(prog="overcon", description=DESCRIPTION, epilog=EPILOG)
    parser.add_argument("--version", action="version", version=f"overcon {__version__}",
                        help="print the version of overcon and exit")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser, metavar="COMMAND")
    c = sub.add_parser("check", help="reaction-uniqueness pre-check of a mechanism or scene")
    _scene_flags(c)
    c.add_argument("--json", action="store_true", help="print the report as JSON")
    c.add_argument("--methods", choices=("auto", "svd", "all"), default="auto",
                   help="svd: the one-factorisation test, one SVD of the Jacobian; all: also the rank comparison "
                        "and QR tests as a cross-check (two SVDs per joint); auto (default): all up to 50 joints, "
                        "svd above")
    c.add_argument("--along", type=_positive, metavar="T",
                   help="also run the scene to T s and repeat the one-factorisation test at every output point: "
                        "where the rank or a friction joint's uniqueness differs from t = 0")
    s = sub.add_parser("simulate", help="integrate a scene (or a bare mechanism) in process, write CSV")
    _scene_flags(s)
    s.add_argument("--out", required=True, metavar="OUT.csv", help="CSV file: time, then the outputs")
    s.add_argument("--tolerance", type=_number, metavar="TOL",
                   help=f"accuracy target, rtol = atol of the adaptive methods ({_range('solver.tolerance')})")
    s.add_argument("--method", choices=METHODS, help="integrator")
    s.add_argument("--kernel", choices=KERNELS,
                   help="auto or c: the compiled core (every run uses it); numpy: a deprecated alias that warns and "
                        "runs the core")
    s.add_argument("--singular", choices=SINGULAR,
                   help="at a singular position of the mechanism: stop (default; exit 3) or pass (augmented "
                        "Lagrangian with projections, compiled kernel; a 'singular' event is recorded)")
    s.add_argument("--step", type=_number, metavar="H", help=f"rk4 step ({_range('solver.step')})")
    s.add_argument("--max-step", type=_number, metavar="H",
                   help=f"largest step of the adaptive methods ({_range('solver.max_step')})")
    s.add_argument("--output-interval", type=_number, metavar="DT",
                   help=f"output grid interval ({_range('solver.output_interval')})")
    s.add_argument("--events", metavar="EVENTS.csv",
                   help="also write the run's events (time, kind, detail): singular positions, eliminations "
                        "chosen again, the stop")
    s.add_argument("--input", metavar="INPUTS.csv",
                   help="input table: a time column and one column per scene input ([[inputs]] name), set at every "
                        "output point as a co-simulation host sets an FMU's inputs")
    s.add_argument("--input-interpolation", choices=("hold", "linear"), default="hold",
                   help="hold (default): each input held over each output interval (co-simulation); linear: linear "
                        "inside it (the FMU when the host sets input derivatives)")
    s.add_argument("--friction-outputs", metavar="all|none|J1,J2",
                   help="friction force outputs <joint>.friction (overrides the scene's outputs.friction)")
    s.add_argument("--max-steps", type=_jobs, metavar="N",
                   help=f"work budget: internal steps (default {MAX_STEPS:.0e})")
    s.add_argument("--max-wall-time", type=_positive, metavar="S",
                   help=f"work budget: wall time in seconds (default {MAX_WALL_TIME:g})")
    fg = sub.add_parser("figures", help="run the paper's scene groups in process and plot Figs. 3-5, 7-9 (PNG)")
    fg.add_argument("--mechanisms", default="mechanisms", help="directory with the scene files (default: mechanisms)")
    fg.add_argument("--out", default="figures", help="output directory for the PNG files (default: figures)")
    fg.add_argument("--tolerance", type=float, metavar="TOL", help="override the scenes' solver tolerance")
    from .fmu.build import add_arguments as _build_arguments

    _build_arguments(sub.add_parser(
        "build", help="build one FMU per scene file (FMI 2.0 or 3.0, co-simulation and/or Model Exchange; pre-check "
                      "first; same as build_fmu.py)"))
    _tooling_parsers(sub)
    return parser


def _number(text: str) -> float:
    """Any float (its range is checked by overcon.params, naming the flag)."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None


def _range(name: str) -> str:
    from .params import rule_of

    return rule_of(name).range_text()


def _positive(text: str) -> float:
    try:
        val = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (val > 0 and val < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text}")
    return val


def _archive_flags(p) -> None:
    """The limits of an FMU archive (overcon.tooling.fmus.archive_limits; docs/untrusted-input.md)."""
    from .tooling.fmus import MAX_UNZIPPED_FILES, MAX_UNZIPPED_MB
    p.add_argument("--max-unzipped-mb", type=_positive, metavar="MB",
                   help=f"refuse an FMU whose files unzip to more than MB MiB (default {MAX_UNZIPPED_MB})")
    p.add_argument("--max-unzipped-files", type=_jobs, metavar="N",
                   help=f"refuse an FMU archive of more than N files (default {MAX_UNZIPPED_FILES})")


def _use_archive_flags(args) -> None:
    """The flags' limits, for this process and (through the environment) its worker processes."""
    from .tooling.fmus import LIMIT_ENV
    if getattr(args, "max_unzipped_mb", None):
        os.environ[LIMIT_ENV[0]] = repr(float(args.max_unzipped_mb))
    if getattr(args, "max_unzipped_files", None):
        os.environ[LIMIT_ENV[1]] = str(int(args.max_unzipped_files))


def _tooling_parsers(sub) -> None:
    """``run``, ``compare``, ``reproduce``: fmpy drives the FMUs (overcon.tooling)."""
    r = sub.add_parser("run", help="simulate FMUs with fmpy, one CSV per FMU")
    r.add_argument("fmus", nargs="+", metavar="FMU", help="FMU files or directories of them")
    r.add_argument("--stop-time", type=_positive, metavar="T", help="stop time (s; default: the FMU's DefaultExperiment)")
    r.add_argument("--step", type=_positive, metavar="S",
                   help="output interval = communication step (s; default: the FMU's DefaultExperiment stepSize)")
    r.add_argument("--out", default="results", metavar="DIR", help="directory for <model>.csv (default: results)")
    r.add_argument("--jobs", type=_jobs, default=2, metavar="N", help="FMUs run in parallel processes (default 2)")
    r.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    _input_flags(r)
    _archive_flags(r)
    c = sub.add_parser("compare", help="run FMUs of a scene group (or one FMU and a reference CSV) and compare "
                                       "them: uniqueness verdict next to the pre-check's prediction")
    c.add_argument("fmus", nargs="+", metavar="FMU", help="FMU files or directories of them; grouped by their "
                                                          "scene's group (FMUs of other tools: one group)")
    c.add_argument("--group", metavar="NAME", help="compare only this group (e.g. planar_f45)")
    c.add_argument("--one-group", action="store_true",
                   help="compare all FMUs given as one group, whatever their scene groups")
    c.add_argument("--ref", metavar="CSV", help="reference result (FMI cross-check CSV) to compare one FMU against")
    c.add_argument("--tolerance", type=_positive, metavar="TOL",
                   help="absolute tolerance for every output (default: derived per output from the FMUs' "
                        "solver tolerance and the output's scale)")
    c.add_argument("--stop-time", type=_positive, metavar="T", help="stop time (s; default: DefaultExperiment, "
                                                                  "or the reference's last time)")
    c.add_argument("--step", type=_positive, metavar="S", help="output interval (s; default: DefaultExperiment "
                                                             "stepSize, or the reference's spacing)")
    c.add_argument("--out", default="comparison", metavar="DIR",
                   help="directory for the CSVs, report.md and PNGs (default: comparison)")
    c.add_argument("--plot", default="worst", metavar="worst|all|NAME,...",
                   help="outputs plotted per group (default: the deciding output with the largest difference)")
    c.add_argument("--jobs", type=_jobs, default=2, metavar="N", help="FMUs run in parallel processes (default 2)")
    c.add_argument("--lockstep-step", type=float, default=LOCKSTEP_STEP, metavar="H", help=LOCKSTEP_HELP)
    c.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    _input_flags(c)
    _archive_flags(c)
    p = sub.add_parser("reproduce", help="the main job: build the paper's FMUs, pre-check, run with fmpy, compare "
                                         "every group, write report.md with the verdicts and Figs. 3-5, 7-9")
    p.add_argument("--out", default="reproduce", metavar="DIR", help="output directory (default: reproduce)")
    p.add_argument("--mechanisms", default="mechanisms", metavar="DIR",
                   help="directory with the scene files (default: mechanisms)")
    p.add_argument("--jobs", type=_jobs, default=2, metavar="N", help="FMUs run in parallel processes (default 2)")
    p.add_argument("--stop-time", type=_positive, metavar="T", help="shorter runs (s; default: the scenes' stop times)")
    p.add_argument("--lockstep-step", type=float, default=LOCKSTEP_STEP, metavar="H", help=LOCKSTEP_HELP)
    p.add_argument("--fmi", type=int, choices=(2, 3), default=2,
                   help="FMI version of the paper scenes' FMUs: 2 (default) or 3 (FMI 3.0, the C runtime)")
    _sweep_parser(sub)
    _converge_parser(sub)
    _regress_parser(sub)
    _schema_parser(sub)
    _draw_parsers(sub)


def _converge_parser(sub) -> None:
    """``converge``: the rigid limit of a compliant scene (overcon.converge)."""
    v = sub.add_parser("converge", help="run a compliant scene over a range of stiffnesses: convergence, measured "
                                        "order, the limit against the rigid eliminations (converge.csv, converge.png)")
    v.add_argument("file", help="scene TOML file with redundancy = \"compliant\"")
    v.add_argument("--stiffness", required=True, metavar="START:STOP:COUNT",
                   help="COUNT log-spaced stiffnesses k (N/m), e.g. 1e4:1e10:7. At k every compliant joint's "
                        "stiffnesses (translational and rotational, every axis) are multiplied by k/k0 and its "
                        "dampings by sqrt(k/k0), k0 the scene's largest translational stiffness: ratios and damping "
                        "ratios stay the scene's")
    v.add_argument("--accuracy", type=_number, default=1e-6, metavar="M",
                   help="position accuracy (m) for the 'stiffness enough' answer (default 1e-6)")
    v.add_argument("--stop-time", type=_number, metavar="T", help="stop time (s; default: the scene's)")
    v.add_argument("--out", required=True, metavar="DIR", help="directory for converge.csv and converge.png")


def _regress_parser(sub) -> None:
    """``regress``: scene FMUs against committed baselines (overcon.tooling.regress)."""
    from .tooling.regress import BASELINE_STEP, DEFAULT_BASELINES, DEFAULT_OUT, DEFAULT_TOLERANCES, TIERS

    g = sub.add_parser("regress", help="regression check: build every scene of a directory as an FMU, run it and "
                                       "compare every output with its committed baseline (exit 1 on a difference)",
                       description="Build, validate (fmpy), run and compare every scene of DIR with its baseline "
                                   "<baselines>/<scene>_ref.csv; --regenerate writes the baselines instead.",
                       epilog="Exit codes: 0 every scene matches; 1 a regression (scene, output, difference and "
                              "tolerance named); 2 bad input or a missing baseline (with the command that creates it).")
    g.add_argument("dir", nargs="?", default="mechanisms", metavar="DIR",
                   help="directory of the scene files, searched recursively (default: mechanisms)")
    g.add_argument("--baselines", default=str(DEFAULT_BASELINES), metavar="DIR",
                   help=f"directory of the baselines <scene>_ref.csv/.opt and provenance.json (default: {DEFAULT_BASELINES})")
    g.add_argument("--tolerances", default=str(DEFAULT_TOLERANCES), metavar="FILE",
                   help=f"tolerance table (default: {DEFAULT_TOLERANCES} if it exists, else the package's per-unit "
                        "defaults); --regenerate refuses a scene with an output it has no tolerance for")
    g.add_argument("--scenes", nargs="+", metavar="NAME", help="scene names or shell globs (default: every scene)")
    g.add_argument("--out", default=str(DEFAULT_OUT), metavar="DIR",
                   help=f"work directory: FMUs, result CSVs, report.md (default: {DEFAULT_OUT})")
    g.add_argument("--junit", metavar="FILE", help="also write the result as JUnit XML, one test case per scene")
    g.add_argument("--jobs", type=_jobs, metavar="N", help="FMUs run in parallel processes (default: CPU count)")
    g.add_argument("--tier", choices=TIERS, help="force a tolerance tier (default: same_platform where the "
                                                 "platform fingerprint equals the baseline's, else cross_platform)")
    g.add_argument("--regenerate", action="store_true",
                   help="write the baselines instead of checking them (deliberately, by hand; never in CI)")
    g.add_argument("--stop-time", type=_positive, metavar="T",
                   help="with --regenerate: stop time of the new baselines (default: the old one, else the FMU's)")
    g.add_argument("--step", type=_positive, metavar="S",
                   help=f"with --regenerate: output interval (default: the old one, else {BASELINE_STEP} s)")
    g.add_argument("--fingerprint", action="store_true", help="print this platform's fingerprint (JSON) and exit")


def cmd_regress(args) -> int:
    from .tooling import regress as rg

    if args.fingerprint:
        fp = rg.platform_fingerprint()
        print(json.dumps({"id": rg.fingerprint_id(fp), **fp}, indent=1))
        return EXIT_OK
    if args.regenerate:
        if args.junit:
            return _input_error("--junit: only for the check (--regenerate writes baselines, it checks nothing)")
        return rg.regenerate(args.scenes, mechanisms=args.dir, baselines=args.baselines, out=args.out,
                             jobs=args.jobs, stop_time=args.stop_time, step=args.step,
                             tolerances=args.tolerances).code
    if args.stop_time is not None or args.step is not None:
        return _input_error("--stop-time/--step only with --regenerate (the check runs on each baseline's grid)")
    out = rg.regress(args.scenes, mechanisms=args.dir, baselines=args.baselines, tolerances=args.tolerances,
                     out=args.out, jobs=args.jobs, tier=args.tier)
    if args.junit:
        print(f"regress: JUnit XML {rg.write_junit(out, args.junit)}")
    return out.code


def _schema_parser(sub) -> None:
    """``schema``: the JSON Schema of the file formats (overcon.schema)."""
    m = sub.add_parser("schema", help="print the JSON Schema of mechanism or scene files (for editors: taplo, "
                                      "Even Better TOML)",
                       description="Print the JSON Schema (draft-07) of a file format, generated from the rules "
                                   "the validator uses. any: either file, told apart by its [scene] table.")
    m.add_argument("kind", choices=("mechanism", "scene", "any"), help="which file format")
    m.add_argument("--out", metavar="FILE", help="write the schema to FILE instead of printing it")


def _draw_parsers(sub) -> None:
    """``draw`` and ``animate``: pictures of a mechanism and of a run (overcon.draw)."""
    d = sub.add_parser("draw", help="draw a mechanism (bodies, joints with their axes, guides, ground, names) at "
                                    "q0 or at a time of a run, as PNG or SVG",
                       description="Draw the mechanism of a mechanism or scene file: planar as one view, spatial "
                                   "as three orthographic views and an isometric one.")
    d.add_argument("file", metavar="SCENE_OR_MECHANISM", help="mechanism or scene TOML file")
    d.add_argument("--out", required=True, metavar="FILE.png|svg", help="picture to write")
    d.add_argument("--csv", metavar="RUN.csv", help="a run of the scene (overcon simulate or run): draw it at --at")
    d.add_argument("--at", type=_number, metavar="T", help="time (s) in the run: its output point nearest T "
                                                           "(default: the first)")
    d.add_argument("--dpi", type=_jobs, default=120, metavar="N", help="PNG resolution (default 120)")
    a = sub.add_parser("animate", help="animate a run of a scene (GIF, or MP4 with ffmpeg)",
                       description="Draw every frame of a run (at most --frames output points, evenly spread) "
                                   "and write them as an animation.")
    a.add_argument("csv", metavar="RUN.csv", help="the run's CSV (overcon simulate or overcon run)")
    a.add_argument("--scene", required=True, metavar="S", help="the scene (or mechanism) file of the run")
    a.add_argument("--out", required=True, metavar="FILE.gif|mp4", help="animation to write")
    a.add_argument("--fps", type=_jobs, default=20, metavar="N", help="frames per second (default 20)")
    a.add_argument("--frames", type=_jobs, default=120, metavar="N", help="at most N frames (default 120)")
    a.add_argument("--dpi", type=_jobs, default=80, metavar="N", help="resolution (default 80)")


def cmd_draw(args) -> int:
    from .draw import DrawError, draw

    try:
        out, what = draw(args.file, args.out, csv_path=args.csv, at=args.at, dpi=args.dpi)
    except DrawError as exc:
        return _input_error(exc)
    if "not in the run" in what:
        print(f"overcon: warning: {what.split('(', 1)[1].rstrip(')')}", file=sys.stderr)
    print(f"wrote {out} ({what})")
    return EXIT_OK


def cmd_animate(args) -> int:
    from .draw import DrawError, animate

    try:
        out, frames, held = animate(args.csv, args.scene, args.out, fps=args.fps, max_frames=args.frames,
                                    dpi=args.dpi)
    except DrawError as exc:
        return _input_error(exc)
    if held:
        print(f"overcon: warning: {', '.join(held)} not in the run: drawn at q0", file=sys.stderr)
    print(f"wrote {out} ({frames} frames at {args.fps} per second)")
    return EXIT_OK


def cmd_schema(args) -> int:
    from .schema import text

    doc = text(args.kind)
    if args.out is None:
        sys.stdout.write(doc)
        return EXIT_OK
    try:
        with open(args.out, "w", encoding="utf-8") as f:
            f.write(doc)
    except OSError as exc:
        return _input_error(f"--out {args.out}: {exc.strerror or exc}")
    print(f"wrote {args.out}")
    return EXIT_OK


def cmd_converge(args) -> int:
    from pathlib import Path

    from . import converge as cv

    out = Path(args.out)
    try:
        ks = cv.parse_range(args.stiffness)
        if out.exists() and not out.is_dir():
            raise cv.ConvergeInputError(f"--out {args.out}: exists and is not a directory")
        print(f"{args.file}: {len(ks)} stiffnesses {ks[0]:.3g}..{ks[-1]:.3g} N/m")
        with single_threaded_blas():
            study = cv.converge(Path(args.file), ks, accuracy=args.accuracy, stop_time=args.stop_time)
    except cv.ConvergeInputError as exc:
        return _input_error(exc)
    except cv.ConvergeRunError as exc:
        print(f"overcon: {exc}", file=sys.stderr)
        return EXIT_RUNTIME
    out.mkdir(parents=True, exist_ok=True)
    for line in cv.summary(study):
        print(line)
    print(f"wrote {cv.write_table(study, out / 'converge.csv')} and "
          f"{cv.write_plot(study, out / 'converge.png', Path(args.file).stem)}")
    return EXIT_OK


def _sweep_parser(sub) -> None:
    """``sweep``: parameter grids of FMUs on Dask (overcon.tooling.sweep)."""
    w = sub.add_parser("sweep", help="run a grid (or random samples) of FMU parameters on Dask and measure how much "
                                     "the eliminations of each scene group disagree (sweep.csv, sweep.png)")
    w.add_argument("inputs", nargs="*", metavar="SCENE_OR_FMU",
                   help="scene files (TOML, built to FMUs first), FMU files or directories of FMUs")
    w.add_argument("--param", action="append", default=[], metavar="NAME=V1,V2,...|NAME=lo:hi:n",
                   help="an FMU parameter and its values (repeatable; full-factorial grid), e.g. joint1.mu=0:0.02:5")
    w.add_argument("--samples", type=_jobs, metavar="N",
                   help="N random parameter sets instead of the full grid (ranges given as lo:hi, uniform)")
    w.add_argument("--seed", type=int, metavar="S", help="random seed of --samples (default 0)")
    w.add_argument("--scheduler", metavar="ADDRESS",
                   help="a running Dask scheduler, e.g. tcp://host:8786 (default: a local cluster)")
    w.add_argument("--workers", type=_jobs, metavar="N",
                   help="worker processes of the local cluster (default 2; not with --scheduler)")
    w.add_argument("--stop-time", type=_positive, metavar="T", help="stop time (s; default: the FMUs' DefaultExperiment)")
    w.add_argument("--lockstep-step", type=float, default=LOCKSTEP_STEP, metavar="H",
                   help="rk4 step (s) of the runs, identical for every elimination (default 0.005); 0: the FMUs' "
                        "own solver settings (then solver.tolerance can be swept; no verdict)")
    w.add_argument("--out", metavar="DIR", help="directory for sweep.csv, sweep.json, sweep.png (and fmus/)")
    w.add_argument("--resume", metavar="DIR", help="continue the sweep in DIR (runs only the missing rows)")
    _input_flags(w)


def _input_flags(p: argparse.ArgumentParser) -> None:
    """``--input`` and ``--input-interpolation`` of run, compare and sweep (overcon.tooling.inputs)."""
    p.add_argument("--input", dest="input_table", metavar="INPUTS.csv",
                   help="values of the FMUs' inputs over time: a CSV with a time column (s) and one column per "
                        "input (every Real input of the FMU, no other); linear between rows, the first/last row's "
                        "value before/after them; given to fmpy's input= (docs/coupling.md)")
    p.add_argument("--input-interpolation", choices=("hold", "linear"), default="hold",
                   help="hold (default): each input held over each communication step at its value at the step's "
                        "start (FMI co-simulation); linear: the host also sets the input's derivative "
                        "(fmi2SetRealInputDerivatives: FMI 2.0 FMUs with canInterpolateInputs)")


SET_HELP = ("set an FMU parameter in every run (repeatable), e.g. --set solver.method=radau --set joint4.mu=0.2, "
            "or an input's start value (--set motor=2.5: the input keeps it when no --input table sets it); "
            "the lockstep runs keep their own solver.method and solver.step")
LOCKSTEP_HELP = ("fixed step (s) of the lockstep runs that decide the verdict: every elimination of a group is also "
                 "run with rk4 on this grid (default 0.005; 0: no lockstep runs, verdict from the adaptive runs)")


def _lockstep(args):
    return None if args.lockstep_step == 0 else args.lockstep_step


def _load(args):
    """(scene with the command-line overrides applied, its compiled model). Raises
    SceneError/ModelError."""
    from . import scene as scene_mod
    from .checks import compile_checked

    spec = scene_mod.load(args.file)
    solver = {key: getattr(args, key) for key in SOLVER_FLAGS if getattr(args, key, None) is not None}
    overrides = dict(
        friction=None if args.friction is None else scene_mod.parse_joint_list(args.friction),
        eliminate=None if args.eliminate is None else scene_mod.parse_eliminate(args.eliminate),
        stop_time=args.stop_time, solver=solver, friction_outputs=getattr(args, "friction_outputs", None),
        source=args.file)
    spec = scene_mod.as_scene(spec, **overrides)
    return spec, compile_checked(spec, eliminate_field="scene.eliminate" if args.eliminate is None else "--eliminate")


SOLVER_FLAGS = ("method", "tolerance", "step", "max_step", "output_interval", "kernel", "singular")
"""``simulate`` flags that override the scene's [solver] table (checked by overcon.params)."""


def _input_error(exc, args=None) -> int:
    """Exit 2 with the reason on stderr; ``check --json`` also prints ``{"file", "error"}`` on
    stdout, so that a script parsing the JSON gets a document for bad input too."""
    print(f"overcon: {exc}", file=sys.stderr)
    if args is not None and getattr(args, "json", False):
        doc = {"file": getattr(args, "file", ""), "error": str(exc)}
        doc.update(getattr(exc, "details", None) or {})  # e.g. a refused elimination's valid ones
        print(json.dumps(doc, indent=2))
    return EXIT_INPUT


def cmd_check(args) -> int:
    from .precheck import format_table, precheck

    with single_threaded_blas():  # the factorisations: BLAS threads cost 3x here (docs/benchmarks.md)
        spec, model = _load(args)  # refuses an inconsistent q0/h0 (exit 2), as simulate and build do
        from .kernel import refusal
        why = refusal(model, spec.solver)
        if why is not None:
            return _input_error(f"{args.file}: the compiled core cannot run this scene: {why}", args)
        report = precheck(model, args.file, args.methods)
    path = None if args.along is None else _along(args, spec, model)
    if isinstance(path, int):
        return path
    if args.json:
        doc = report.to_json()
        if path is not None:
            doc["along"] = path.to_json()
        print(json.dumps(doc, indent=2))
    else:
        print(format_table(report))
        if path is not None:
            from .along import format_along
            print(format_along(path))
    nonunique = report.friction_on_nonunique or (path is not None and path.friction_on_nonunique)
    return EXIT_NONUNIQUE if nonunique or not report.methods_agree else EXIT_OK


def _along(args, spec, model):
    """``check --along T``: the :class:`overcon.along.AlongReport`, or exit 2 for a bad T."""
    from .along import along
    try:
        with single_threaded_blas():
            return along(model, spec.solver, args.along)
    except ValueError as exc:
        return _input_error(f"{args.file}: {exc}", args)


def cmd_simulate(args) -> int:
    from pathlib import Path

    from .simulate import SimulationError, run, write_csv

    from .precheck import precheck, run_warnings

    from .outfiles import check_outputs

    outputs = {"--out": args.out, "--events": args.events}
    why = check_outputs(outputs, {"scene file": args.file, "--input": args.input})
    if why:
        return _input_error(why)
    spec, model = _load(args)
    mechanism = getattr(spec.mechanism, "source", None)
    why = check_outputs(outputs, {"scene file": args.file, "mechanism file": mechanism, "--input": args.input})
    if why:
        return _input_error(why)
    for w in run_warnings(precheck(model, args.file)):
        print(f"overcon: warning: {w}", file=sys.stderr)
    from .kernel import refusal
    from .simulate import NUMPY_DEPRECATED
    if spec.solver.kernel == "numpy":
        where = "--kernel numpy" if args.kernel else f"{args.file}: solver.kernel = 'numpy'"
        print(f"overcon: warning: {where}: {NUMPY_DEPRECATED}", file=sys.stderr)
    why = refusal(model, spec.solver, here=True)  # a core that cannot run here: bad input, not a failed run
    if why is not None:
        return _input_error(f"{args.file}: the compiled core cannot run this scene: {why}")
    table = None
    if getattr(args, "input", None):
        from .tooling import InputError
        from .tooling.inputs import read_input_table
        try:
            table = read_input_table(args.input, [u.name for u in model.inputs])
        except InputError as exc:
            return _input_error(f"--input {exc}")
    start = time.perf_counter()
    try:
        from .progress import bar

        span = spec.stop_time - spec.start_time
        with single_threaded_blas(), bar(span, "simulate", "s", bar_format="{l_bar}{bar}| t = {n:.3g}/{total:g} s") \
                as shown:
            res = run(model, spec.solver, max_steps=args.max_steps or MAX_STEPS,
                      max_wall_time=args.max_wall_time or MAX_WALL_TIME, inputs=table,
                      input_interpolation=args.input_interpolation,
                      progress=lambda t: shown.update(t - spec.start_time - shown.n))
    except SimulationError as exc:
        return _failed_run(args, model, spec, exc, time.perf_counter() - start)
    wall = time.perf_counter() - start
    try:
        write_csv(res, args.out)
        _write_events(args, res)
    except OSError as exc:
        return _input_error(f"--out {args.out}: cannot write: {exc.strerror or exc}")
    print(_run_stats(args.out, model, res, wall))
    if res.stiff_steps:
        print(f"note: {res.stiff_steps} steps were limited by stability (stiff: friction sticking inside the "
              "regularisation band); a larger v_reg or a looser tolerance is cheaper")
    return EXIT_OK


def _write_events(args, res) -> None:
    """``--events``: the run's events as CSV (overcon.simulate.write_events)."""
    if args.events:
        from .simulate import write_events
        write_events(res.events, args.events)


def _events_note(res) -> str:
    """'; events: 1 elimination-reselected at t = 0.2 s' (nothing without events)."""
    if not res.events:
        return ""
    shown = ", ".join(f"{kind} at t = {t:.6g} s" for t, kind, _ in res.events[:5])
    more = f" and {len(res.events) - 5} more" if len(res.events) > 5 else ""
    return f"; events: {shown}{more}"


def _run_stats(out, model, res, wall: float) -> str:
    """The line ``simulate`` prints after a run (also after a failed one, for the rows it kept)."""
    span = f"t = {res.time[0]:g}..{res.time[-1]:g} s" if len(res.time) else "no output point"
    return (f"{out}: {len(res.time)} rows x {len(res.names)} outputs, {span}; "
            f"eliminated {', '.join('Phi%d' % i for i in model.eliminated) or 'none'} ({model.elimination_mode}); "
            f"{res.steps} steps, {res.evaluations} evaluations, {res.friction_iterations} friction iterations; "
            f"max constraint drift {res.max_drift:.3g}; wall {wall:.2f} s; {res.kernel_note}"
            + _events_note(res))


def _failed_run(args, model, spec, exc, wall: float) -> int:
    """A run that stopped (exit 3): the CSV keeps every output point computed before the stop,
    the stats are printed, then the reason, then where the file ends (decided: the file is written
    even when it has no data row, so a script always finds it)."""
    from .kernel import library_path
    from .simulate import write_csv
    note = f"right-hand side: compiled kernel ({library_path()})"
    partial = exc.partial
    if partial is not None:
        write_csv(partial, args.out)
        _write_events(args, partial)
        print(_run_stats(args.out, model, partial, wall))
    print(f"overcon: {args.file}: {exc} [{note}]", file=sys.stderr)
    if partial is not None:
        end = (f"ends early at t = {partial.time[-1]:.9g} s (its last output point before the stop)" if len(partial.time)
               else "has the header only (the run stopped before its first output point)")
        print(f"overcon: {args.out} {end}", file=sys.stderr)
    return EXIT_RUNTIME


def cmd_figures(args) -> int:
    from pathlib import Path

    from .paper import make_figures
    from .simulate import SimulationError

    start = time.perf_counter()
    try:
        with single_threaded_blas():
            make_figures(Path(args.mechanisms), Path(args.out), tolerance=args.tolerance)
    except SimulationError as exc:
        print(f"overcon: {exc}", file=sys.stderr)
        return EXIT_RUNTIME
    print(f"figures written to {args.out}/ in {time.perf_counter() - start:.1f} s")
    return EXIT_OK


def cmd_build(args) -> int:
    from .fmu.build import run_args

    return run_args(args)


def _tooling_call(fn):
    """Exit 2 for bad input, 3 for a failed simulation (overcon.tooling errors name the file)."""
    from .tooling import InputError, SimulationFailed

    try:
        return fn()
    except InputError as exc:
        print(f"overcon: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except SimulationFailed as exc:
        print(f"overcon: simulation failed: {exc}", file=sys.stderr)
        return EXIT_RUNTIME


def cmd_run(args) -> int:
    from .tooling.pipeline import run_paths
    from .tooling.run import parse_settings

    from .outfiles import check_input_outside, check_out_dir
    from .tooling import InputError

    def go():
        start = time.perf_counter()
        _use_archive_flags(args)
        why = (check_out_dir("--out", args.out, {f"FMU {f}": f for f in args.fmus})
               or check_input_outside("--out", args.out, "--input", args.input_table))
        if why:
            raise InputError(why)
        res = run_paths(args.fmus, args.out, stop_time=args.stop_time, step=args.step, jobs=args.jobs,
                        settings=parse_settings(args.set), input_table=args.input_table,
                        interpolation=args.input_interpolation)
        print(f"{len(res)} FMU(s) run in {time.perf_counter() - start:.1f} s; CSVs in {args.out}/")
        return EXIT_OK

    return _tooling_call(go)


def cmd_compare(args) -> int:
    from .tooling.pipeline import compare_paths, compare_with_reference
    from .tooling.run import parse_settings

    from .outfiles import check_input_outside, check_out_dir
    from .tooling import InputError

    plots = args.plot if args.plot in ("worst", "all") else [n for n in args.plot.split(",") if n]

    def go():
        start = time.perf_counter()
        _use_archive_flags(args)
        why = (check_out_dir("--out", args.out, {**{f"FMU {f}": f for f in args.fmus}, "--ref": args.ref})
               or check_input_outside("--out", args.out, "--input", args.input_table))
        if why:
            raise InputError(why)
        if args.ref is not None:
            if len(args.fmus) != 1 or args.group:
                print("overcon: --ref compares exactly one FMU file against the CSV (no --group)", file=sys.stderr)
                return EXIT_INPUT
            if args.set:
                print("overcon: --set is for group comparisons; a reference comparison runs the FMU as it is",
                      file=sys.stderr)
                return EXIT_INPUT
            out = compare_with_reference(args.fmus[0], args.ref, args.out, tolerance=args.tolerance,
                                         stop_time=args.stop_time, step=args.step, plots=plots,
                                         input_table=args.input_table, interpolation=args.input_interpolation)
        else:
            out = compare_paths(args.fmus, args.out, group=args.group, one_group=args.one_group,
                                tolerance=args.tolerance, lockstep_step=_lockstep(args),
                                stop_time=args.stop_time, step=args.step, jobs=args.jobs, plots=plots,
                                settings=parse_settings(args.set), input_table=args.input_table,
                                interpolation=args.input_interpolation)
        print(f"report: {out.report} ({time.perf_counter() - start:.1f} s)")
        return _verdict_exit(out.comparisons)

    return _tooling_call(go)


def _verdict_exit(comparisons) -> int:
    """compare/reproduce: 3 a simulation failed, 2 a group was not compared (invalid), 1 a verdict
    differs from its prediction (or the reference), 0 otherwise; the reasons on stderr."""
    failed = [c for c in comparisons if c.run_failed]
    invalid = [c for c in comparisons if c.invalid]
    bad = [c.group for c in comparisons if not c.matches and c.failure is None]
    if failed:
        print("overcon: simulation failed for: " + "; ".join(
            f"{c.group} ({c.failure or 'adaptive runs: ' + c.adaptive_failure})" for c in failed), file=sys.stderr)
    if invalid:
        print("overcon: not compared (invalid group): " + "; ".join(c.failure for c in invalid), file=sys.stderr)
    if bad:
        print(f"overcon: verdict differs from the prediction (or the reference) for: {', '.join(bad)}",
              file=sys.stderr)
    return EXIT_RUNTIME if failed else EXIT_INPUT if invalid else EXIT_NONUNIQUE if bad else EXIT_OK


def cmd_reproduce(args) -> int:
    from .tooling.pipeline import reproduce

    def go():
        from .draw import draw

        out = reproduce(args.out, mechanisms=args.mechanisms, jobs=args.jobs, stop_time=args.stop_time,
                        lockstep_step=_lockstep(args), fmi=args.fmi, draw=lambda m, png: draw(m, png, dpi=90))
        failed = [c for c in out.comparisons if c.failure is not None]
        n_bad = sum(not c.matches for c in out.comparisons) - len(failed)
        print(f"\n{len(out.comparisons)} groups compared, "
              + ("every observed verdict equals its prediction" if not n_bad else f"{n_bad} MISMATCH(ES)")
              + (f", {len(failed)} FAILED (no verdict)" if failed else "")
              + f"; total wall time {out.seconds['total']:.1f} s")
        print(f"report: {out.report}  (figures: {', '.join(p.name for p in out.figures) or 'none'})")
        return _verdict_exit(out.comparisons)

    return _tooling_call(go)


def cmd_sweep(args) -> int:
    from .tooling import sweep

    def go():
        if (args.out is None) == (args.resume is None):
            print("overcon: sweep needs exactly one of --out DIR (a new sweep) and --resume DIR", file=sys.stderr)
            return EXIT_INPUT
        if args.scheduler is not None and args.workers is not None:
            print("overcon: --workers sizes the local cluster; with --scheduler the cluster's own workers run the "
                  "tasks (start more with dask worker)", file=sys.stderr)
            return EXIT_INPUT
        from .outfiles import check_input_outside
        why = check_input_outside("--resume" if args.out is None else "--out", args.resume or args.out,
                                  "--input", args.input_table)
        if why:
            print(f"overcon: {why}", file=sys.stderr)
            return EXIT_INPUT
        if args.resume is not None:
            if args.lockstep_step != LOCKSTEP_STEP:
                print("overcon: --resume continues the sweep as defined in DIR/sweep.json: no --lockstep-step",
                      file=sys.stderr)
                return EXIT_INPUT
            sw = sweep.prepare(args.resume, resume=True, inputs=args.inputs, params=args.param,
                               samples=args.samples, seed=args.seed, stop_time=args.stop_time,
                               input_table=args.input_table, interpolation=args.input_interpolation)
        else:
            sw = sweep.prepare(args.out, inputs=args.inputs, params=args.param, samples=args.samples,
                               seed=args.seed, stop_time=args.stop_time, lockstep_step=args.lockstep_step,
                               input_table=args.input_table, interpolation=args.input_interpolation)
        out = sweep.run(sw, scheduler=args.scheduler, workers=args.workers or 2)
        print(f"{out.rows} row(s) in {out.csv} ({out.written} new, {out.failed} not ok) in {out.seconds:.1f} s"
              + (f"; plot {out.png}" if out.png else "") + (f"; {out.parquet}" if out.parquet else ""))
        if out.interrupted:
            print(f"overcon: interrupted; the rows above are kept: continue with overcon sweep --resume {sw.out_dir}",
                  file=sys.stderr)
            return sweep.EXIT_INTERRUPTED
        return EXIT_OK

    return _tooling_call(go)


def single_threaded_blas():
    """A context in which BLAS runs one thread (threadpoolctl): a run's matrices have tens to
    hundreds of rows, where threads only add synchronisation, and on a loaded machine they cost
    more than the work (measured: docs/benchmarks.md, "BLAS threads"). The CLI owns its process,
    so it may set this; FMUs in other hosts leave the host's setting alone."""
    from threadpoolctl import threadpool_limits
    return threadpool_limits(limits=1, user_api="blas")


def main(argv=None) -> int:
    from .kernel import KernelUnavailable
    from .model import ModelError
    from .scene import SceneError
    from .simulate import InconsistentInitialState

    args = build_parser().parse_args(argv)
    handler = {"check": cmd_check, "simulate": cmd_simulate, "figures": cmd_figures,
               "build": cmd_build, "run": cmd_run, "compare": cmd_compare,
               "reproduce": cmd_reproduce, "sweep": cmd_sweep, "converge": cmd_converge,
               "regress": cmd_regress, "schema": cmd_schema, "draw": cmd_draw, "animate": cmd_animate}[args.command]
    try:
        code = handler(args)
        sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
        return code
    except BrokenPipeError:
        # the reader went away (e.g. | head): no more output, exit as a process killed by SIGPIPE
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except KeyboardInterrupt:
        print("overcon: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except SceneError as exc:  # already names file and field
        return _input_error(exc, args)
    except (ModelError, InconsistentInitialState, KernelUnavailable, ValueError, OSError) as exc:
        # KernelUnavailable: no compiled core to evaluate the scene with (its message names the fix)
        where = getattr(args, "file", None)
        if where and isinstance(exc, ModelError):
            return _input_error(ModelError(f"{where}: {exc}", exc.details), args)
        return _input_error(f"{where}: {exc}" if where else exc, args)


if __name__ == "__main__":
    sys.exit(main())
