"""The pre-check at scale: ``overcon check`` of generated linkages, from the command line and in
process, and the analysis alone, with the one factorisation (:func:`overcon.analysis._factorise`:
peeled coloops, decoupled blocks, one dense SVD per block or, for a block with hub rows, one
small SVD per part and one of the hub rows) against one dense SVD of the whole Jacobian (the
first test's factorisation), side by side where the dense SVD ends in reasonable time.

    python benchmarks/precheck_scale.py [--quick] [--only SUBSTRING ...]

Per mechanism: coordinates n, equations m, the peeled columns, the largest block left and how
it was factorised (``dense``: its SVD; ``hubs``: through its hub rows); then wall seconds and,
where said, CPU seconds (what other jobs on a loaded machine change least), medians of 3 runs
(1 run above 20 s), of
  cli        ``python -m overcon.cli check FILE --json --friction none`` in a fresh process
             (the user's figure: starting Python and importing included); CPU: the child's
             user + system time;
  check      ``overcon.cli.main(["check", FILE, "--json", "--friction", "none"])`` in process:
             loading, compiling, admitting (q0 on the constraints, the elimination chosen from
             the factorisation), the analysis, the report; CPU ``time.process_time``;
  analysis   ``overcon.analysis.analyse(J, groups, methods="svd")`` on the Jacobian at q0, one
             BLAS thread (``overcon.cli.single_threaded_blas``, as ``check`` runs);
  dense      ``equilibrate`` plus one dense SVD of the whole J (``_svd_full``), one BLAS thread:
             the factorisation of the first test, without its per-joint work, or "-" where
             min(n, m) > 2500 (minutes).
The code measured is the ``overcon`` this Python imports: ``PYTHONPATH=OTHER/fmu_src`` measures
another checkout (with its compiled core). The figures go to docs/benchmarks.md ("Pre-check at
scale") and docs/reference/bounds.md by hand.

    python benchmarks/precheck_scale.py --large [--against OTHER] [--repeat 3]

The issue-40 sizes instead (docs/limits.md, docs/benchmarks.md "Memory and limits at scale"): a
planar chain of 10,000 bodies and a coupler on 999 parallel cranks (1000 bodies, 1998 joints),
``overcon check FILE --json --friction none`` in a fresh process: wall and CPU seconds (medians)
and the child's peak resident size (its own ``ru_maxrss``, from ``wait4``). ``--against OTHER``
runs the checkout at OTHER (``PYTHONPATH=OTHER/fmu_src``, its core compiled in place: ``python
setup.py build_ext --inplace`` there) interleaved with this one, run by run, and says whether
the two JSON reports are identical. ``--stages`` adds where the CPU time of ``check`` goes for
the chain, stage by stage in a fresh process per checkout (``time.process_time``, one BLAS
thread): the pre-scan of the text, ``tomllib``, the rest of ``scene.load`` (the validation),
compiling, admitting (Phi_h at q0, the one factorisation, the elimination's pick), the
pre-check's analysis and report, and the JSON text. ``--run`` adds the child of
tests/test_sparse_scale.py (the 10,000-body chain checked, then run 1 s by ``Simulation``) per
checkout: wall seconds of its check and of its run, and its peak resident size (VmHWM) after
the check and at the end.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import numpy as np  # noqa: E402

from overcon import analysis, kernel, scene  # noqa: E402
from overcon.checks import compile_checked  # noqa: E402
from overcon.cli import main, single_threaded_blas  # noqa: E402
from overcon.precheck import joint_groups  # noqa: E402

DENSE_LIMIT = 2500


def cases(tmp: Path, quick: bool) -> list[tuple[str, Path]]:
    from test_precheck_methods import linkage, parallelogram
    from test_robust import chain
    out = [("parallelogram 99 cranks (198 joints)", parallelogram(99, tmp / "p99.toml"))]
    for n in ([100, 1000] if quick else [100, 200, 500, 1000]):
        out.append((f"planar chain {n} bodies", chain(n, tmp / f"chain{n}.toml")))
    rng = np.random.default_rng
    out.append(("planar tree 980 bodies + 20 loops", linkage(rng(1), "planar", "loops", 980, tmp / "l1000.toml", 20)))
    out.append(("spatial tree 990 bodies + 10 loops", linkage(rng(2), "spatial", "loops", 990, tmp / "s1000.toml", 10)))
    if not quick:
        out.append(("spatial chain 500 bodies", linkage(rng(3), "spatial", "chain", 500, tmp / "sc500.toml")))
        out.append(("parallelogram 250 cranks (500 joints)", parallelogram(250, tmp / "p250.toml")))
    out.append(("parallelogram 500 cranks (1000 joints)", parallelogram(500, tmp / "p500.toml")))
    return out


def timed(fn, repeat: int = 3) -> tuple[float, float]:
    """Median wall and CPU seconds of ``fn()``."""
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        if wall[-1] > 20.0:
            break
    return statistics.median(wall), statistics.median(cpu)


def cli(path: Path, repeat: int = 3) -> tuple[float, float]:
    """Median wall and CPU (user + system) seconds of ``overcon check`` in a fresh process."""
    wall, cpu = [], []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "overcon.cli", "check", str(path), "--json", "--friction", "none"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=os.environ.copy())
        wall.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
        if done.returncode not in (0, 1):
            raise RuntimeError(f"overcon check {path}: exit {done.returncode}: {done.stderr.decode()[-500:]}")
        if wall[-1] > 20.0:
            break
    return statistics.median(wall), statistics.median(cpu)


def check(path: Path) -> None:
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["check", str(path), "--json", "--friction", "none"])
    if code not in (0, 1):
        raise RuntimeError(f"overcon check {path}: exit {code}")


def largest_block(A: np.ndarray) -> str:
    """The largest block left after peeling (rows x columns) and how it is factorised."""
    f = analysis._factorise(A, analysis.DEFAULT_RTOL)
    if not f.blocks:
        return f"{len(f.peeled)} 0x0 -"
    rows, cols = max(f.blocks, key=lambda b: len(b[0]) * len(b[1]))
    how = "dense"
    if getattr(analysis, "_hub", None) is not None and f.route == "blocks":
        rr, cc = np.nonzero(A)
        rows_of, cols_of = analysis._pattern(rr, cc, *A.shape)
        live = np.zeros(A.shape[1], bool)
        live[list(cols)] = True
        if analysis._hub(A, rows, cols, rows_of, cols_of, live) is not None:
            how = "hubs"
    return f"{len(f.peeled)} {len(rows)}x{len(cols)} {how}"


def main_(quick: bool, only: list[str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        print(f"{'mechanism':<40} {'n':>5} {'m':>5} {'peeled':>6} {'block':>9} {'how':>5} {'cli s':>7} {'(cpu)':>7} "
              f"{'check s':>8} {'(cpu)':>7} {'analysis s':>10} {'(cpu)':>7} {'dense s':>8}", flush=True)
        for label, path in cases(Path(tmp), quick):
            if only and not any(o in label for o in only):
                continue
            with single_threaded_blas():
                model = compile_checked(scene.as_scene(scene.load(path)))
                J = kernel.jacobian(model, model.q0).T  # Phi_h^T at q0: (n_h coordinates, m equations)
                groups = joint_groups(model)
                peeled, block, how = largest_block(analysis.equilibrate(J)[0]).split()
            t_cli = cli(path)
            t_check = timed(lambda: check(path))
            with single_threaded_blas():
                t_an = timed(lambda: analysis.analyse(J, groups, methods="svd"))
                if min(J.shape) <= DENSE_LIMIT:
                    t_dense = f"{timed(lambda: analysis._svd_full(analysis.equilibrate(J)[0]))[0]:8.3f}"
                else:
                    t_dense = f"{'-':>8}"
            print(f"{label:<40} {J.shape[0]:>5} {J.shape[1]:>5} {peeled:>6} {block:>9} {how:>5} {t_cli[0]:7.3f} "
                  f"{t_cli[1]:7.3f} {t_check[0]:8.3f} {t_check[1]:7.3f} {t_an[0]:10.3f} {t_an[1]:7.3f} {t_dense}",
                  flush=True)


class _Child(subprocess.Popen):
    """A Popen that keeps the child's own rusage (wait4), not the sum over all children
    (CPython's Popen reaps its child in ``_try_wait``; another Python leaves the figures NaN)."""

    cpu = peak_mb = float("nan")

    def _try_wait(self, wait_flags):
        pid, status, usage = os.wait4(self.pid, wait_flags)
        if pid:
            self.cpu = usage.ru_utime + usage.ru_stime
            self.peak_mb = usage.ru_maxrss / 1024
        return pid, status


def stages(path: str) -> None:
    """Print {stage: CPU seconds} of ``check`` of ``path`` (JSON, one line): see the docstring."""
    import json
    import tomllib
    from overcon.checks import admit
    from overcon.model import compile_model
    from overcon.precheck import precheck

    out = {}

    def run(name, fn):
        c0 = time.process_time()
        res = fn()
        out[name] = time.process_time() - c0
        return res

    with single_threaded_blas():
        text = Path(path).read_text()
        run("pre-scan", lambda: scene.toml_prescan(text))
        run("tomllib", lambda: tomllib.loads(text))
        spec = run("load", lambda: scene.load(path))
        out["validation"] = out.pop("load") - out["pre-scan"] - out["tomllib"]
        model = run("compile", lambda: compile_model(scene.as_scene(spec, friction=())))
        model = run("admit", lambda: admit(model))
        report = run("pre-check", lambda: precheck(model, path))
        run("JSON text", lambda: json.dumps(report.to_json(), indent=2))
    print(json.dumps(out))


def check_and_run(env: dict) -> dict:
    """The child of tests/test_sparse_scale.py, timed: {check s, peak MB after it, run s, peak MB}."""
    import json
    import test_sparse_scale
    with tempfile.TemporaryDirectory() as tmp:
        code = test_sparse_scale.CHILD.format(tests=str(ROOT / "tests"), tmp=tmp)
        code = code.replace("report = io.StringIO()", "import time\nt0 = time.perf_counter()\nreport = io.StringIO()")
        code = code.replace('(out / "check.json")', 'check_s, check_mb = time.perf_counter() - t0, peak_kb() / 1024\n'
                            '(out / "check.json")', 1)
        code += 'print(json.dumps({"check s": check_s, "check MB": check_mb, "run s": sim.info["wall_time"], ' \
                '"peak MB": peak_kb() / 1024}))\n'
        done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def large(against: str | None, repeat: int, with_stages: bool = False, with_run: bool = False) -> None:
    from test_precheck_methods import linkage
    from test_robust import chain
    codes = [("this", os.environ.copy())]
    if against:
        env = os.environ.copy()
        env["PYTHONPATH"] = str(Path(against).resolve() / "fmu_src")
        codes.append(("other", env))
    with tempfile.TemporaryDirectory() as tmp:
        cases = [("planar chain 10,000 bodies", chain(10_000, Path(tmp) / "chain10000.toml")),
                 ("coupler on 999 parallel cranks", linkage(np.random.default_rng(1000), "planar", "cranks", 1000,
                                                            Path(tmp) / "cranks.toml"))]
        print(f"{'mechanism':<32} {'code':<6} {'wall s':>7} {'cpu s':>7} {'peak MB':>8}", flush=True)
        for label, path in cases:
            runs: dict = {name: [] for name, _ in codes}
            outs: dict = {}
            for _ in range(repeat):
                for name, env in codes:  # interleaved: the machine's load falls on both alike
                    t0 = time.perf_counter()
                    child = _Child([sys.executable, "-m", "overcon.cli", "check", str(path), "--json", "--friction",
                                    "none"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
                    out, err = child.communicate()
                    if child.returncode not in (0, 1):
                        raise RuntimeError(f"{name}: overcon check {path}: exit {child.returncode}: "
                                           f"{err.decode()[-500:]}")
                    runs[name].append((time.perf_counter() - t0, child.cpu, child.peak_mb))
                    outs[name] = out
            for name, _ in codes:
                wall, cpu, peak = (statistics.median(r[k] for r in runs[name]) for k in range(3))
                print(f"{label:<32} {name:<6} {wall:7.2f} {cpu:7.2f} {peak:8.0f}", flush=True)
            if against:
                print(f"{label:<32} reports identical: {outs['this'] == outs['other']}", flush=True)
        if with_stages:
            import json
            got = {}
            for name, env in codes:
                child = subprocess.run([sys.executable, __file__, "--stages-of", str(cases[0][1])], env=env,
                                       capture_output=True, text=True, check=True)
                got[name] = json.loads(child.stdout.strip().splitlines()[-1])
            print(f"\nCPU seconds of check of the {cases[0][0]}, by stage:")
            print(f"{'stage':<14}" + "".join(f" {name:>7}" for name, _ in codes))
            for key in got["this"]:
                print(f"{key:<14}" + "".join(f" {got[name].get(key, float('nan')):7.3f}" for name, _ in codes))
            print(f"{'total':<14}" + "".join(f" {sum(got[name].values()):7.3f}" for name, _ in codes))
        if with_run:
            print(f"\ncheck, then Simulation 1 s, of the {cases[0][0]} (tests/test_sparse_scale.py's child):")
            for name, env in codes:
                got = check_and_run(env)
                print(f"{name:<6} " + "  ".join(f"{k} {v:.2f}" for k, v in got.items()), flush=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer and smaller mechanisms (chains of 100 and 1000 "
                    "bodies, the parallelograms of 99 and 500 cranks, the two trees with loops)")
    ap.add_argument("--only", nargs="*", default=[], metavar="SUBSTRING",
                    help="only the mechanisms whose label contains one of these")
    ap.add_argument("--large", action="store_true", help="the 10,000-body chain and the 999 parallel cranks "
                    "(issue 40), from the command line, with peak memory")
    ap.add_argument("--against", metavar="OTHER", help="with --large: also the checkout at OTHER, interleaved")
    ap.add_argument("--repeat", type=int, default=3, help="with --large: runs per mechanism and checkout (median)")
    ap.add_argument("--stages", action="store_true", help="with --large: the chain's check stage by stage")
    ap.add_argument("--run", action="store_true", help="with --large: the chain checked and run 1 s, in the "
                    "child of tests/test_sparse_scale.py")
    ap.add_argument("--stages-of", metavar="FILE", help=argparse.SUPPRESS)  # the child of --stages
    args = ap.parse_args()
    if args.stages_of:
        stages(args.stages_of)
    elif args.large:
        large(args.against, args.repeat, args.stages, args.run)
    else:
        main_(args.quick, args.only)
