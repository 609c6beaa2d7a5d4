"""Speed against accuracy, measured through fmpy as a user runs the FMUs (issue 6).

    python benchmarks/bench.py                 # ~35 s on the 2-core reference machine
    python benchmarks/bench.py --quick         # 1 repetition, short ladders (a smoke test, ~10 s)
    python benchmarks/bench.py --joints        # per joint type: one evaluation in the core, and the
                                               # example scenes in process (a few s; printed only)
    python benchmarks/bench.py --c-runtime     # C-runtime FMUs: FMI overhead per doStep against an empty
                                               # C FMU, the examples through fmpy (~20 s; printed only)
    python benchmarks/bench.py --integrators   # dop853 and radau in process: the core's run in C,
                                               # wall time and steps per method (printed only)

Prints Markdown tables and writes ``docs/benchmarks.md`` and ``docs/pareto.png`` (``--out DIR``
elsewhere). Figures are printed, never asserted.

What is measured
----------------
* Scenes (built once with :func:`overcon.fmu.build.build_all`, the default C runtime, into a temporary directory): the
  paper scenes ``planar_none_wo4`` (0-4 s), ``planar_f45_wo4`` (friction in joints 4, 5; 0-4 s)
  and ``spatial_MN_wo5`` (friction in M, N; 0-10 s) as shipped, and ``*_pos`` variants that
  declare the same positions and no reactions (what a user who needs only the motion builds).
* Each run is ``fmpy.simulate_fmu`` with a 1 ms output interval, the solver chosen by the FMU
  parameters ``solver.method`` / ``solver.tolerance`` / ``solver.step`` (start values); wall time is
  the median of ``--repeat`` runs of the whole call (instantiation to termination).
* RHS evaluations, steps, friction iterations and the constraint drift max |Phi| (at the step
  ends) come from the same run in process (:func:`run_stats`: ``overcon.kernel.Run``, which the C
  FMU runs bit for bit). Evaluations count the integration only; a scene with reaction outputs
  adds one evaluation of Eq. 18 per output point.
* Error: max over the output points and the length coordinates (``.x .y .z``, m) of the difference
  to a reference computed in process with dop853 at rtol = atol = 1e-13 on the same grid, checked
  against dop853 at 1e-11 (the difference, printed, bounds the reference's own error).
* FMI overhead per communication point: our FMU (planar_none_wo4, positions only) and an empty C
  FMU with the same outputs (``benchmarks/fmu_runtime.py --overhead``), each run with 4000 and 400
  points; overhead = the slope of the wall time over the number of points.
* Peer: if Exudyn is installed, the frictionless planar mechanism (planar_none_wo4: Phi4 removed,
  i.e. joint 2 without its rotation constraint) with Exudyn's default solver (generalized-alpha,
  fixed step), sensors recording the body positions every 1 ms, in the same process.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import os
import platform
import re
import shutil
import statistics
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
MECH = ROOT / "mechanisms"
INTERVAL = 1e-3

SCENES = {  # name: (source scene, stop time, positions only)
    "planar_none_wo4": ("planar_none_wo4", 4.0, False),
    "planar_none_wo4_pos": ("planar_none_wo4", 4.0, True),
    "planar_f45_wo4": ("planar_f45_wo4", 4.0, False),
    "planar_f45_wo4_pos": ("planar_f45_wo4", 4.0, True),
    "spatial_MN_wo5": ("spatial_MN_wo5", 10.0, False),
    "spatial_MN_wo5_pos": ("spatial_MN_wo5", 10.0, True),
    "planar_f145_wo6_pos": ("planar_f145_wo6", 4.0, True),
}
STIFF = "planar_f145_wo6_pos"  # mu = 1 in joints 1, 4, 5: sticking inside the regularisation band
STIFF_RUNS = [("dopri5", 1e-8), ("dop853", 1e-8), ("radau", 1e-6), ("radau", 1e-8)]

# ladders: (method, tolerance or rk4 step)
LADDERS = {
    "planar_none_wo4_pos": [("dopri5", 1e-6), ("dopri5", 1e-8), ("dopri5", 1e-10),
                            ("dop853", 1e-6), ("dop853", 1e-8), ("dop853", 1e-10),
                            ("rk4", 4e-3), ("rk4", 2e-3), ("rk4", 1e-3),
                            ("radau", 1e-6), ("radau", 1e-8)],
    "planar_f45_wo4_pos": [("dopri5", 1e-6), ("dopri5", 1e-7), ("dopri5", 1e-8), ("dopri5", 1e-9),
                           ("dop853", 1e-6), ("dop853", 1e-7), ("dop853", 1e-8), ("dop853", 1e-9),
                           ("rk4", 4e-3), ("rk4", 2e-3), ("rk4", 1e-3),
                           ("radau", 1e-6), ("radau", 1e-7), ("radau", 1e-8)],
    "spatial_MN_wo5_pos": [("dopri5", 1e-6), ("dopri5", 1e-7), ("dopri5", 1e-8), ("dopri5", 1e-9),
                           ("dop853", 1e-6), ("dop853", 1e-7), ("dop853", 1e-8),
                           ("rk4", 1e-2), ("rk4", 5e-3),
                           ("radau", 1e-6)],
}
QUICK = {
    "planar_none_wo4_pos": [("dopri5", 1e-8), ("dop853", 1e-8), ("rk4", 2e-3), ("radau", 1e-8)],
    "planar_f45_wo4_pos": [("dopri5", 1e-9), ("dop853", 1e-7), ("rk4", 2e-3), ("radau", 1e-7)],
    "spatial_MN_wo5_pos": [("dopri5", 1e-9), ("dop853", 1e-7)],
}
WHAT_IT_DECLARES = [("planar_none_wo4_pos", "frictionless, positions only"),
                    ("planar_none_wo4", "frictionless, positions + all reactions"),
                    ("planar_f45_wo4_pos", "friction 4, 5, positions only"),
                    ("planar_f45_wo4", "friction 4, 5, positions + all reactions"),
                    ("spatial_MN_wo5_pos", "friction M, N, positions only"),
                    ("spatial_MN_wo5", "friction M, N, positions + reactions G, H, M, N")]
DECLARE_SETTING = {"planar": ("dop853", 1e-7), "spatial": ("dop853", 1e-7)}
EXUDYN_STEPS = (1e-3, 5e-4, 2.5e-4, 1.25e-4)
TARGETS = {"planar_f45_wo4_pos": 0.15, "spatial_MN_wo5_pos": 0.5}  # s, positions to 1e-6 m (issue 14)
SHIPPED_TARGETS = {"planar_f45_wo4": 0.3, "spatial_MN_wo5": 1.0}  # s, the same as shipped (all declared outputs)
PEER_RATIO = 0.1  # overcon FMU / Exudyn wall time at matched accuracy, at every accuracy (issue 21)
OVERHEAD_RATIO = 1.2  # FMI overhead per doStep / an empty C FMU's (issue 21)
LIMIT_CASES = {"spatial_MN_wo5_pos": ("dopri5", 1e-9), "planar_f45_wo4_pos": ("dop853", 1e-7)}


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------ scenes

def make_scenes(tmp: Path) -> dict[str, Path]:
    """Scene files (as shipped, and _pos variants with ``reactions = []``) next to copies of the
    mechanism files."""
    for m in ("planar_sliders.toml", "spatial_parallelogram.toml"):
        shutil.copy(MECH / m, tmp / m)
    out = {}
    for name, (src, _stop, pos_only) in SCENES.items():
        text = (MECH / f"{src}.toml").read_text()
        if pos_only:
            text = re.sub(r'(?m)^name = "[^"]*"', f'name = "{name}"', text, count=1)
            text = re.sub(r"(?m)^reactions = .*$", "reactions = []", text)
        (tmp / f"{name}.toml").write_text(text)
        out[name] = tmp / f"{name}.toml"
    return out


# ------------------------------------------------------------------------------------ FMU runs

@dataclass
class FMU:
    name: str
    unz: Path
    md: object
    stop: float
    scene: Path  # the scene file it was built from (the in-process run that gives its statistics)
    outputs: list[str] = field(default_factory=list)


def load_fmu(path: Path, stop: float, tmp: Path, scene: Path) -> FMU:
    import fmpy

    unz = Path(fmpy.extract(str(path), str(tmp / f"unz_{path.stem}")))
    md = fmpy.read_model_description(str(unz))
    outs = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    return FMU(path.stem, unz, md, stop, scene, outs)


def run_stats(scene_path: Path, stop: float, sv: dict, adjust=None) -> dict:
    """The statistics of an FMU run, from the same run in process: the C FMU runs the core's
    ``kernel.Run`` (bit for bit: tests/test_fmu_c.py), so its steps, evaluations, friction
    iterations and drift are those of :class:`overcon.kernel.Run` with the scene's solver and the
    FMU parameters ``sv`` (``solver.*``); ``adjust(spec)`` changes the scene as other parameters
    do. ``t`` is where the run ended and ``stopped`` its reason ("" when it reached ``stop``)."""
    from overcon import kernel
    from overcon import scene as scene_mod
    from overcon.checks import compile_checked

    spec = scene_mod.load(scene_path)
    if adjust is not None:
        spec = adjust(spec)
    kw = {k.split(".", 1)[1]: v for k, v in sv.items() if k.startswith("solver.") and k != "solver.kernel"}
    run = kernel.Run(compile_checked(spec), replace(spec.solver, **kw))
    stopped = ""
    try:
        run.advance(stop)
    except kernel.RunStopped as e:
        stopped = str(e)
    i = run.info
    return {"evaluations": int(i["evaluations"]), "steps": int(i["nsteps"]), "its": i["friction_iterations"],
            "drift": i["max_drift"], "t": i["t"], "stopped": stopped}


def start_values(method: str, setting: float) -> dict:
    sv = {"solver.method": method}
    sv["solver.step" if method == "rk4" else "solver.tolerance"] = setting
    return sv


def fmu_run(fmu: FMU, sv: dict, interval: float = INTERVAL):
    import fmpy

    t0 = time.perf_counter()
    res = fmpy.simulate_fmu(str(fmu.unz), stop_time=fmu.stop, output_interval=interval, start_values=sv,
                            model_description=fmu.md)
    return time.perf_counter() - t0, res


def length_columns(names) -> list[str]:
    return [n for n in names if n.rsplit(".", 1)[1] in ("x", "y", "z")]


@dataclass
class Row:
    scene: str
    method: str
    setting: float
    wall: float
    walls: list
    evaluations: int
    steps: int
    fit_per_eval: float
    error: float
    drift: float
    note: str = ""

    @property
    def label(self) -> str:
        return f"h = {self.setting:g} s" if self.method == "rk4" else f"tol = {self.setting:g}"


def measure(fmu: FMU, method: str, setting: float, ref: np.ndarray | None, repeat: int) -> Row:
    sv = start_values(method, setting)
    walls, res = [], None
    for _ in range(repeat):
        wall, res = fmu_run(fmu, sv)
        walls.append(wall)
    err = np.nan
    if ref is not None:
        cols = length_columns(fmu.outputs)
        got = np.column_stack([res[c] for c in cols])
        assert got.shape == ref.shape, (got.shape, ref.shape)
        err = float(np.max(np.abs(got - ref)))
    st = run_stats(fmu.scene, fmu.stop, sv)
    ev = st["evaluations"]
    return Row(fmu.name, method, setting, statistics.median(walls), walls, ev, st["steps"],
               st["its"] / ev if ev else 0.0, err, st["drift"])


# ------------------------------------------------------------------------------------ references

def reference(scene_path: Path, stop: float):
    """Positions (length columns) on the 1 ms grid: dop853 at 1e-13, and its check at 1e-11."""
    from overcon import scene as scene_mod
    from overcon.checks import compile_checked
    from overcon.simulate import run

    spec = scene_mod.load(scene_path)
    model = compile_checked(spec)
    out = []
    for tol in (1e-13, 1e-11):
        r = run(model, spec.solver, stop_time=stop, output_interval=INTERVAL, method="dop853", tolerance=tol)
        out.append(np.column_stack([r.column(c) for c in length_columns(r.names)]))
    return out[0], float(np.max(np.abs(out[0] - out[1])))


# ------------------------------------------------------------------------------------ overhead

def overhead(repeat: int) -> dict:
    """The C FMU's cost per communication point against an empty C FMU with the same outputs
    (:func:`fmu_runtime.measure_overhead`)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import fmu_runtime

    return fmu_runtime.measure_overhead(repeat)


# ------------------------------------------------------------------------------------ stiff case

def stiff_rows(fmu: FMU, scene_path: Path, repeat: int) -> list[tuple[float, Row]]:
    """planar_f145_wo6 with mu = 1 in joints 1, 4, 5 and v_reg 1e-3 or 1e-6 (FMU parameters): the
    explicit methods end with fmi2Error (stiffness; the time and reason from the same run in
    process, :func:`run_stats`); radau against an in-process radau reference at 1e-11."""
    import dataclasses

    import fmpy
    from overcon import scene as scene_mod
    from overcon.checks import compile_checked
    from overcon.simulate import run

    rows = []
    for v_reg in (1e-3, 1e-6):
        params = {f"joint{j}.{p}": val for j in (1, 4, 5) for p, val in (("mu", 1.0), ("v_reg", v_reg))}

        def adjust(sc, v_reg=v_reg):
            return dataclasses.replace(sc, friction_params={k: dataclasses.replace(v, mu=1.0, v_reg=v_reg)
                                                            for k, v in sc.friction_params.items()})

        sc = adjust(scene_mod.load(scene_path))
        r = run(compile_checked(sc), sc.solver, stop_time=fmu.stop, output_interval=INTERVAL, method="radau", tolerance=1e-11)
        ref = np.column_stack([r.column(c) for c in length_columns(r.names)])
        for method, tol in STIFF_RUNS:
            sv = {**start_values(method, tol), **params}
            st = run_stats(scene_path, fmu.stop, start_values(method, tol), adjust)
            walls, err = [], np.nan
            for _ in range(1 if st["stopped"] else repeat):
                t0 = time.perf_counter()
                try:
                    res = fmpy.simulate_fmu(str(fmu.unz), stop_time=fmu.stop, output_interval=INTERVAL,
                                            start_values=sv, model_description=fmu.md)
                except Exception:  # fmpy raises on the fmi2Error of a run that stopped
                    res = None
                walls.append(time.perf_counter() - t0)
            if st["stopped"]:
                reason = st["stopped"].split("integration stopped: ")[-1].split(";")[0].split("(step")[0].strip()
                note = f"fmi2Error at t = {st['t']:.3g} s: {reason}"
            else:
                got = np.column_stack([res[c] for c in length_columns(fmu.outputs)])
                err = float(np.max(np.abs(got - ref)))
                note = f"completed 0-{fmu.stop:g} s"
            ev = max(1, st["evaluations"])
            rows.append((v_reg, Row(fmu.name, method, tol, statistics.median(walls), walls, st["evaluations"],
                                    st["steps"], st["its"] / ev, err, st["drift"], note=note)))
            log(f"stiff v_reg {v_reg:g} {method} {tol:g}: {rows[-1][1].wall:.3f} s {rows[-1][1].note}")
    return rows


# ------------------------------------------------------------------------------------ Exudyn peer

def exudyn_planar(h: float, stop: float = 4.0):
    """planar_none_wo4 in Exudyn (2D rigid bodies, default generalized-alpha solver, fixed step h);
    returns (wall time of SolveDynamic, positions x, y of slider1, slider2, link3, link4 per 1 ms)."""
    import exudyn as exu
    from exudyn.itemInterface import (LoadMassProportional, LoadTorqueVector, MarkerBodyMass, MarkerBodyRigid,
                                      NodeRigidBody2D, ObjectConnectorSpringDamper, ObjectGround,
                                      ObjectJointPrismatic2D, ObjectJointRevolute2D, ObjectRigidBody2D, SensorBody)

    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    mG = mbs.AddMarker(MarkerBodyRigid(bodyNumber=mbs.AddObject(ObjectGround()), localPosition=[0, 0, 0]))
    bodies = {}
    for name, q0 in (("slider1", (2, 0, 0)), ("slider2", (0, 2, 0)), ("link3", (2, 1, 0)), ("link4", (1, 2, 0))):
        node = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=list(q0), initialVelocities=[0, 0, 0]))
        b = mbs.AddObject(ObjectRigidBody2D(nodeNumber=node, physicsMass=3.0, physicsInertia=1.0))
        mbs.AddLoad(LoadMassProportional(markerNumber=mbs.AddMarker(MarkerBodyMass(bodyNumber=b)),
                                         loadVector=[0, -9.81, 0]))
        bodies[name] = b

    def mk(b, p):
        return mbs.AddMarker(MarkerBodyRigid(bodyNumber=bodies[b], localPosition=[p[0], p[1], 0]))

    s1, s2 = mk("slider1", (0, 0)), mk("slider2", (0, 0))
    r = 2 ** -0.5
    mbs.AddObject(ObjectJointPrismatic2D(markerNumbers=[mG, s1], axisMarker0=[1, 0, 0], normalMarker1=[0, 1, 0],
                                         constrainRotation=True))  # joint1: Phi1, Phi2
    mbs.AddObject(ObjectJointPrismatic2D(markerNumbers=[mG, s2], axisMarker0=[0, 1, 0], normalMarker1=[1, 0, 0],
                                         constrainRotation=False))  # joint2 without Phi4
    mbs.AddObject(ObjectJointPrismatic2D(markerNumbers=[s2, s1], axisMarker0=[r, -r, 0], normalMarker1=[r, r, 0],
                                         constrainRotation=True))  # joint3
    mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[s1, mk("link3", (0, -1))]))  # joint4
    mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[s2, mk("link4", (-1, 0))]))  # joint5
    mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[mk("link3", (0, 1)), mk("link4", (1, 0))]))  # joint6
    mbs.AddLoad(LoadTorqueVector(markerNumber=s1, loadVector=[0, 0, 10.0]))
    mbs.AddLoad(LoadTorqueVector(markerNumber=s2, loadVector=[0, 0, 30.0]))
    mbs.AddObject(ObjectConnectorSpringDamper(markerNumbers=[mG, s2], stiffness=30.0, damping=0.0, referenceLength=3.0))
    sensors = [mbs.AddSensor(SensorBody(bodyNumber=bodies[n], storeInternal=True, writeToFile=False,
                                        outputVariableType=exu.OutputVariableType.Position))
               for n in ("slider1", "slider2", "link3", "link4")]
    mbs.Assemble()
    ss = exu.SimulationSettings()
    ss.timeIntegration.numberOfSteps = int(round(stop / h))
    ss.timeIntegration.endTime = stop
    ss.timeIntegration.verboseMode = 0
    ss.solutionSettings.writeSolutionToFile = False
    ss.solutionSettings.sensorsWritePeriod = INTERVAL
    ss.displayComputationTime = False
    ss.displayStatistics = False
    t0 = time.perf_counter()
    mbs.SolveDynamic(ss)
    wall = time.perf_counter() - t0
    pos = np.column_stack([mbs.GetSensorStoredData(s)[:, 1:3] for s in sensors])
    return wall, pos


def exudyn_rows(ref: np.ndarray, repeat: int):
    try:
        import exudyn
    except ImportError:
        return None, "Exudyn is not installed (pip install exudyn): no peer rows"
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        for h in EXUDYN_STEPS:
            walls, pos = [], None
            for _ in range(repeat):
                wall, pos = exudyn_planar(h)
                walls.append(wall)
            err = float(np.max(np.abs(pos - ref))) if pos.shape == ref.shape else np.nan
            rows.append(Row("exudyn planar_none_wo4", f"Exudyn {exudyn.__version__} gen.-alpha", h,
                            statistics.median(walls), walls, int(round(4.0 / h)), int(round(4.0 / h)), 0.0, err,
                            np.nan, note="steps; wall of SolveDynamic only (no FMI)"))
    return rows, ""


# ------------------------------------------------------------------------------------ the limit

def limit_row(scene_path: Path, stop: float, method: str, tol: float) -> dict:
    """In process, one scene: the time of one right-hand-side evaluation in the core
    (:meth:`overcon.kernel.Kernel.evaluate`, one ctypes call) beside what the linear algebra alone
    costs with LAPACK at the same state: the Cholesky factorisation of S = J_R^T M^-1 J_R
    (dpotrf), the solve for lam0 and the multi-column solve for W (dpotrs), and per friction
    iteration the small Newton solve (dgetrf/dgetrs); numbers in us, each the best of 5 x 2000
    calls (``timeit``). The state is the end of the first accepted step after ``stop / 2`` of the
    run in C, the evaluation warm-started from the friction forces at the step before it (as a run
    warm-starts from its previous evaluation); the friction iterations per evaluation are the
    whole run's (:class:`overcon.kernel.Run`)."""
    import timeit

    from scipy.linalg.lapack import dgetrf, dgetrs, dpotrf, dpotrs

    from overcon import kernel
    from overcon import scene as scene_mod
    from overcon.checks import compile_checked, watch_rows

    spec = scene_mod.load(scene_path)
    model = compile_checked(spec)
    solver = replace(spec.solver, method=method, tolerance=tol)
    whole = kernel.Run(model, solver, watch=watch_rows(model))
    whole.advance(stop)
    info = whole.info
    mid = kernel.Run(model, solver, watch=watch_rows(model))
    mid.advance(stop / 2)
    y_before = mid.y
    mid.step()
    y, t = mid.y, mid.info["t"]
    k = kernel.Kernel(kernel.library()[0], model, solver, watch_rows(model))
    first = k.evaluate(stop / 2, y_before)
    if first is None:
        raise RuntimeError(f"{scene_path.name}: the core's evaluation at t = {stop / 2:g} s returned status "
                           f"{k.last_status}: {k.last_message}")
    qf = first[2]
    if k.evaluate(t, y, qf_guess=qf) is None:
        raise RuntimeError(f"{scene_path.name}: the core's evaluation at t = {t:g} s returned status "
                           f"{k.last_status}: {k.last_message}")
    JR = kernel.jacobian(model, y[: model.n])[model.retained].T
    MinvJ = model.Minv[:, None] * JR
    S = JR.T @ MinvJ
    c, _ = dpotrf(S)
    b = MinvJ.T @ np.ones(model.nh)
    B = np.ascontiguousarray(MinvJ.T[:, model.plan.friction_cols])
    nx = len(model.plan.friction_xrows)
    A = np.eye(nx) + 0.01 * np.ones((nx, nx))
    n = 2000

    def us(stmt):
        return 1e6 * min(timeit.repeat(stmt, number=n, repeat=5)) / n

    per_eval = us(lambda: k.evaluate(t, y, qf_guess=qf))
    factor = us(lambda: dpotrf(S))
    solves = us(lambda: dpotrs(c, b)) + us(lambda: dpotrs(c, B))
    lu, piv, _ = dgetrf(A)
    newton = us(lambda: dgetrf(A)) + us(lambda: dgetrs(lu, piv, np.ones(nx)))
    evaluations = int(info["evaluations"])
    its = info["friction_iterations"] / evaluations
    linalg = factor + solves + its * newton
    return {"scene": scene_path.stem, "method": method, "tol": tol, "size": S.shape[0], "nx": nx,
            "per_eval_us": per_eval, "evaluations": evaluations, "its": its,
            "factor_us": factor, "solves_us": solves, "newton_us": newton, "linalg_us": linalg,
            "ratio": per_eval / linalg}


# ------------------------------------------------------------------------------------ report

def fmt(x, spec=".2e"):
    return "-" if x is None or (isinstance(x, float) and not np.isfinite(x)) else format(x, spec)


def table(rows: list[Row], with_scene=False) -> str:
    head = ("| " + ("scene | " if with_scene else "") + "method | setting | wall (s), median | RHS evals | steps | "
            "friction it./eval | max pos. error (m) | max abs(Phi) |")
    sep = "|" + ("---|" if with_scene else "") + "---|---|---:|---:|---:|---:|---:|---:|"
    lines = [head, sep]
    for r in rows:
        lines.append("| " + (f"{r.scene} | " if with_scene else "") + f"{r.method} | {r.label} | {r.wall:.3f} | "
                     f"{r.evaluations} | {r.steps} | {r.fit_per_eval:.2f} | {fmt(r.error)} | {fmt(r.drift, '.1e')} |")
    return "\n".join(lines)


def fastest(rows, bound):
    ok = [r for r in rows if np.isfinite(r.error) and r.error <= bound]
    return min(ok, key=lambda r: r.wall) if ok else None


def pareto_plot(ladders: dict, exu: list | None, path: Path) -> None:
    import matplotlib
    import matplotlib.ticker
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    titles = {"planar_none_wo4_pos": "planar, frictionless, 0-4 s",
              "planar_f45_wo4_pos": "planar, friction in 4, 5, 0-4 s",
              "spatial_MN_wo5_pos": "spatial, friction in M, N, 0-10 s"}
    marks = {"dopri5": "o", "dop853": "s", "rk4": "^", "radau": "D"}
    fig, axes = plt.subplots(1, len(ladders), figsize=(5.2 * len(ladders), 4.4))
    for ax, (scene, rows) in zip(np.atleast_1d(axes), ladders.items()):
        for m, mk in marks.items():
            rs = sorted([r for r in rows if r.method == m and np.isfinite(r.error)], key=lambda r: r.wall)
            if rs:
                ax.loglog([r.wall for r in rs], [r.error for r in rs], mk + "-", label=m, alpha=0.85)
        pts = sorted([r for r in rows if np.isfinite(r.error)], key=lambda r: r.wall)
        front, best = [], np.inf
        for r in pts:
            if r.error < best:
                front.append(r)
                best = r.error
        ax.loglog([r.wall for r in front], [r.error for r in front], "k:", lw=2, label="Pareto front")
        if scene == "planar_none_wo4_pos" and exu:
            rs = [r for r in exu if np.isfinite(r.error)]
            ax.loglog([r.wall for r in rs], [r.error for r in rs], "x--", color="grey", label="Exudyn (no FMI)")
        ax.axhline(1e-6, color="r", lw=0.8)
        if scene in TARGETS:
            ax.axvline(TARGETS[scene], color="r", lw=0.8, ls="--")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        lo, hi = ax.get_xlim()
        ticks = [x for x in (0.1, 0.2, 0.5, 1, 2, 5, 10, 20) if lo <= x <= hi]
        ax.set_xticks(ticks, [f"{x:g}" for x in ticks])
        ax.set_title(titles[scene], fontsize=10)
        ax.set_xlabel("wall time through fmpy, 1 ms output (s)")
        ax.set_ylabel("max position error (m)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def machine() -> str:
    cpu = ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    import fmpy
    import numpy
    import scipy
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (f"{cpu or platform.processor()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
            f"numpy {numpy.__version__}, scipy {scipy.__version__}, fmpy {fmpy.__version__}; "
            f"load average at the end {load:.1f}")


# ------------------------------------------------------------------------------------ per joint type


def friction_keys(kind: str, jtype: str) -> tuple[str, ...]:
    """The friction size keys of a joint type (() without friction)."""
    from overcon.joints import TYPES, resolve

    return TYPES[resolve(kind, jtype)].friction_keys

JOINT_CASES = [("planar", "revolute", None), ("planar", "translational", None), ("spatial", "spherical", "euler_zxz"),
               ("spatial", "spherical", "quaternion")] + [
    ("spatial", t, r) for t in ("revolute", "prismatic", "cylindrical", "universal", "fixed")
    for r in ("euler_zxz", "quaternion")]
EXAMPLE_RUNS = ("door_h1_wo_hinge2", "fourbar_A_wo3_4_5", "loop_A1_wo_A2", "carriage_guide_wo_rod")


def chain_text(kind: str, jtype: str, rotation: str | None, friction: bool) -> str:
    """A chain of three bodies, each joined to the previous one (the first to the base) by a
    ``jtype`` joint, friction (regularised, mu 0.1) in every joint where the type has it. Spatial:
    every body in one orientation R0, the joints assembled at q0 (points coincide, axes parallel,
    a universal joint's cross axes perpendicular); planar: random geometry."""
    from overcon.kinematics import euler_R, euler_to_quat

    rng = np.random.default_rng(1)
    d = 2 if kind == "planar" else 3
    vec = (lambda k: ", ".join(f"{x:.6f}" for x in rng.uniform(-0.5, 0.5, k)))
    fmt3 = (lambda v: ", ".join(repeat_float(x) for x in v))
    lines = ["[mechanism]", f'name = "chain_{jtype}"', f'kind = "{kind}"',
             "gravity = [0.0, -9.81]" if d == 2 else "gravity = [0.0, 0.0, -9.81]"]
    if rotation:
        lines.append(f'rotation = "{rotation}"')
    angles0 = [0.3, 1.0, 0.5]
    R0 = euler_R(angles0)
    orient = euler_to_quat(angles0) if rotation == "quaternion" else angles0
    r = [np.array([0.3 * (b + 1), 0.1 * b, -0.2 * b]) for b in range(3)]
    for b in range(3):
        if d == 2:
            q0, inertia = f"{vec(2)}, {rng.uniform(-3, 3):.6f}", "1.0"
        else:
            q0, inertia = f"{fmt3(r[b])}, {fmt3(orient)}", "[1.0, 1.5, 2.0]"
        lines += ["[[bodies]]", f'name = "b{b}"', "mass = 1.0", f"inertia = {inertia}", f"q0 = [{q0}]"]
    a = np.array([0.2, 0.3, 0.9]) / np.linalg.norm([0.2, 0.3, 0.9])
    c = np.cross(a, [1.0, 0.0, 0.0])
    c /= np.linalg.norm(c)
    s_i = np.array([-0.15, 0.05, 0.0])
    for j in range(3):
        lines += ["[[joints]]", f'name = "J{j}"', f'type = "{jtype}"', f'body_i = "b{j}"',
                  f'body_j = "{"base" if j == 0 else f"b{j - 1}"}"']
        if jtype == "translational":
            lines += [f"s_A = [{vec(2)}]", f"s_B = [{vec(2)}]", f"v = [{vec(2)}]"]
        elif d == 2:
            lines += [f"s_i = [{vec(d)}]", f"s_j = [{vec(d)}]"]
        else:
            P = r[j] + R0 @ s_i
            s_j = P if j == 0 else R0.T @ (P - r[j - 1])
            lines += [f"s_i = [{fmt3(s_i)}]", f"s_j = [{fmt3(s_j)}]"]
            if jtype != "spherical":
                b_axis = c if jtype == "universal" else a
                lines += [f"axis_i = [{fmt3(a)}]", f"axis_j = [{fmt3(R0 @ b_axis if j == 0 else b_axis)}]"]
        if friction and friction_keys(kind, jtype):
            lines += ["[joints.friction]", 'law = "regularised"', "mu = 0.1", "v_reg = 1e-3"]
            lines += [f"{key} = 0.05" for key in friction_keys(kind, jtype)]
    return "\n".join(lines) + "\n"


def repeat_float(x) -> str:
    return repr(float(x))


def per_evaluation(model, solver, y, n: int) -> float:
    """Microseconds of one evaluation in the core (y' as the integrator asks for it,
    :meth:`overcon.kernel.Kernel.evaluate`, cold: no warm start), the best of 5 medians of n calls."""
    from overcon import kernel

    k, _note = kernel.select(model, solver)
    best = []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(n):
            k.evaluate(0.0, y)
        best.append((time.perf_counter() - t0) / n * 1e6)
    return min(best)


def joint_rows(n: int) -> list[tuple]:
    """Per joint type and rotation, with and without friction: (kind, type, rotation, friction,
    equations, core us), at a state near q0 with velocities (so friction slides)."""
    from overcon import scene as scene_mod
    from overcon.checks import compile_checked

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind, jtype, rotation in JOINT_CASES:
            for friction in (False, True):
                if friction and not friction_keys(kind, jtype):
                    continue
                path = Path(tmp) / "chain.toml"
                path.write_text(chain_text(kind, jtype, rotation, friction))
                spec = scene_mod.as_scene(scene_mod.load(path), friction=["J0", "J1", "J2"] if friction else [])
                model = compile_checked(spec, check_initial=False)
                y = np.concatenate([model.q0 + 0.001, model.h0 + 0.3])
                core = per_evaluation(model, spec.solver, y, n)
                rows.append((kind, jtype, rotation or "", friction, model.m, core))
                log(f"{kind} {jtype} {rotation or ''} friction={friction}: core {core:.1f} us")
    return rows


def example_runs(repeat: int) -> list[tuple]:
    """The example scenes (quaternions) integrated in process as shipped (``overcon simulate``'s
    path: overcon.simulate.run, the core's run): (scene, stop time s, wall s, steps, evaluations),
    the median wall time of ``repeat`` runs."""
    from overcon import scene as scene_mod
    from overcon.checks import compile_checked
    from overcon.simulate import run

    rows = []
    for name in EXAMPLE_RUNS:
        spec = scene_mod.as_scene(scene_mod.load(MECH / "examples" / f"{name}.toml"))
        model = compile_checked(spec)
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            res = run(model, spec.solver, stop_time=spec.stop_time)
            times.append(time.perf_counter() - t0)
        wall = statistics.median(times)
        rows.append((name, spec.stop_time, wall, res.steps, res.evaluations))
        log(f"{name}: {wall:.2f} s")
    return rows


def joints_report(rows, runs, n: int, repeat: int) -> str:
    out = ["## Per joint type: one evaluation in the compiled core (`python benchmarks/bench.py --joints`)", "",
           f"{machine()}. A chain of three bodies joined by three joints of the type (the first to the base), "
           "friction (regularised, mu 0.1) in all three where the type has it, at a state near q0 with "
           f"velocities; one evaluation = y' (Eq. 18 with the elimination, the friction solve from a cold start, "
           f"the rates), `overcon.kernel.Kernel.evaluate` (one ctypes call); best of 5 medians of {n} calls, "
           "in process (no FMI).", "",
           "| kind | joint | rotation | friction | equations | core (us) |",
           "|---|---|---|---|---:|---:|"]
    for kind, jtype, rot, fr, m, core in rows:
        out.append(f"| {kind} | {jtype} | {rot} | {'yes' if fr else 'no'} | {m} | {core:.1f} |")
    out += ["", f"The example scenes as shipped, integrated in process (`overcon simulate`'s path: "
            f"`overcon.simulate.run`, outputs at the scene's interval; median of {repeat}):",
            "", "| scene | stop (s) | wall (s) | steps | evaluations |",
            "|---|---:|---:|---:|---:|"]
    for name, stop, wall, steps, ev in runs:
        out.append(f"| {name} | {stop:g} | {wall:.3f} | {steps} | {ev} |")
    return "\n".join(out) + "\n"


def joints_main(repeat: int, quick: bool) -> int:
    n = 50 if quick else 300
    t0 = time.perf_counter()
    md = joints_report(joint_rows(n), example_runs(repeat), n, repeat)
    print(md)
    log(f"per joint type and examples: {time.perf_counter() - t0:.0f} s")
    return 0


# ------------------------------------------------------------------------------------ integrators

INTEGRATOR_RUNS = (("planar_f45_wo4", MECH / "planar_f45_wo4.toml", None, None),
                   ("planar_f145_wo6, mu 1, v_reg 1e-6 m/s", MECH / "planar_f145_wo6.toml", 1.0, (1.0, 1e-6)),
                   ("compliant_door_h1_wo_hinge2", MECH / "examples" / "compliant_door_h1_wo_hinge2.toml", 0.2, None))
"""(label, scene, stop time or None for the scene's, (mu, v_reg) for every friction joint or None): a
paper scene; the same mechanism sticking inside a tiny regularisation band (stiff: dop853 stops,
radau's case); a compliant example (stiff springs; its stop time shortened so dop853 does not crawl
for minutes)."""
INTEGRATOR_WALL = 60.0
"""s: the wall-time budget of one run (a run that spends it is reported as stopped, not timed)."""


def _timed_runs(make, stop: float, repeat: int):
    """(median wall time, the last run's (steps, final state)) of ``repeat`` runs; a run that stops
    or cannot run gives (None, that and its reason)."""
    times, last = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        try:
            steps, y = make(stop)
        except Exception as exc:  # the reason is printed in the table (stiff, budget, not covered)
            how = "not run" if type(exc).__name__ == "KernelUnavailable" else "stopped"
            return None, f"{how}: {str(exc).split(';')[0][:110]}"
        times.append(time.perf_counter() - t0)
        last = (steps, y)
    return statistics.median(times), last


def integrator_rows(repeat: int) -> list[tuple]:
    """Per scene and method (dop853, radau at the scene's tolerance): the whole run in C
    (overcon.kernel.Run: core/sim.c with core/integrate_rk.c or core/integrate_radau.c, what the C
    FMU and overcon.simulate run), to the stop time without outputs on the way: (label, stop s,
    method, tolerance, median wall s or None, (steps, final state) or the reason it stopped,
    evaluations)."""
    from overcon import kernel
    from overcon import scene as scene_mod
    from overcon.checks import compile_checked, watch_rows

    rows = []
    for label, path, stop, friction in INTEGRATOR_RUNS:
        spec = scene_mod.as_scene(scene_mod.load(path))
        stop = spec.stop_time if stop is None else stop
        if friction is not None:
            spec = replace(spec, friction_params={k: replace(v, mu=friction[0], v_reg=friction[1])
                                                  for k, v in spec.friction_params.items()})
        model = compile_checked(spec)
        for method in ("dop853", "radau"):
            solver = replace(spec.solver, method=method)
            evaluations = [0]

            def c_run(t, solver=solver):
                run = kernel.Run(model, solver, max_wall_time=INTEGRATOR_WALL, watch=watch_rows(model))
                y = run.advance(t)
                evaluations[0] = int(run.info["evaluations"])
                return int(run.info["nsteps"]), y

            c, c_last = _timed_runs(c_run, stop, repeat)
            rows.append((label, stop, method, solver.tolerance, c, c_last, evaluations[0]))
            log(f"{label} {method}: C run {c}")
    return rows


def integrators_report(rows, repeat: int) -> str:
    out = ["## dop853 and radau in process: the run in C (`python benchmarks/bench.py --integrators`)", "",
           f"{machine()}. Median wall time of {repeat} runs from the start to the stop time, no outputs on the way: "
           "overcon.kernel.Run (core/sim.c with core/integrate_rk.c or core/integrate_radau.c: what the C FMU "
           "and `overcon simulate` run). The comparison with the Python integrator loop was removed with that "
           "loop (the numpy path's retirement).", "",
           "| scene | stop (s) | method | tolerance | C run (s) | steps | evaluations |",
           "|---|---:|---|---:|---:|---:|---:|"]
    for label, stop, method, tol, c, c_last, ev in rows:
        if c is None:
            out.append(f"| {label} | {stop:g} | {method} | {tol:g} | {c_last} | | |")
        else:
            out.append(f"| {label} | {stop:g} | {method} | {tol:g} | {c:.3f} | {c_last[0]} | {ev} |")
    return "\n".join(out) + "\n"


def integrators_main(repeat: int) -> int:
    t0 = time.perf_counter()
    print(integrators_report(integrator_rows(repeat), repeat))
    log(f"integrators: {time.perf_counter() - t0:.0f} s")
    return 0


# ------------------------------------------------------------------------------------ main

KEEP_MARKER = "<!-- kept by bench.py"


def _kept_section(path: Path) -> str:
    """The hand-written end of an existing benchmarks.md, from the line holding KEEP_MARKER on."""
    if not path.is_file():
        return ""
    text = path.read_text()
    k = text.find(KEEP_MARKER)
    return "" if k < 0 else "\n" + text[k:]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs per setting (median wall time), default 3")
    ap.add_argument("--quick", action="store_true", help="1 repetition and short ladders (smoke test)")
    ap.add_argument("--out", default=str(ROOT / "docs"), help="where benchmarks.md and pareto.png go")
    ap.add_argument("--no-exudyn", action="store_true")
    ap.add_argument("--joints", action="store_true",
                    help="only the per-joint-type evaluation cost in the core and the example scenes in "
                         "process (printed, nothing written)")
    ap.add_argument("--c-runtime", action="store_true",
                    help="only the C-runtime FMUs: the FMI overhead per doStep against an empty C FMU, and the "
                         "example scenes through fmpy (benchmarks/fmu_runtime.py; printed, nothing written)")
    ap.add_argument("--integrators", action="store_true",
                    help="only dop853 and radau in process: the run in C (kernel.Run), wall time and steps "
                         "per method (printed, nothing written)")
    args = ap.parse_args(argv)
    repeat = 1 if args.quick else max(1, args.repeat)
    if args.joints:
        return joints_main(repeat, args.quick)
    if args.c_runtime:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        import fmu_runtime

        print("## FMI overhead per doStep: C runtime against an empty C FMU\n")
        fmu_runtime.overhead(repeat)
        print("\n## The examples through fmpy, C runtime\n")
        return fmu_runtime.examples(repeat)
    if args.integrators:
        return integrators_main(repeat)
    ladders_def = QUICK if args.quick else LADDERS
    t_start = time.perf_counter()
    from overcon.fmu.build import build_all

    tmp = Path(tempfile.mkdtemp(prefix="overcon_bench_"))
    try:
        paths = make_scenes(tmp)
        with contextlib.redirect_stdout(io.StringIO()):
            code, results = build_all([str(p) for p in paths.values()], tmp / "fmus", refs=False,
                                      allow_nonunique=True, echo=lambda s: None, echo_err=log)
        if code not in (0, 1):  # 1: the stiff example's motion is not unique (built anyway)
            log("build failed")
            return 2
        fmus = {n: load_fmu(tmp / "fmus" / f"{n}.fmu", SCENES[n][1], tmp, paths[n]) for n in SCENES}
        log(f"built {len(fmus)} FMUs in {time.perf_counter() - t_start:.1f} s")

        refs, ref_checks = {}, {}
        for n in ("planar_none_wo4_pos", "planar_f45_wo4_pos", "spatial_MN_wo5_pos"):
            t0 = time.perf_counter()
            refs[n], ref_checks[n] = reference(paths[n], SCENES[n][1])
            refs[n.removesuffix("_pos")] = refs[n]
            log(f"reference {n}: |dop853(1e-13) - dop853(1e-11)| = {ref_checks[n]:.1e} m "
                f"({time.perf_counter() - t0:.1f} s)")

        ladders: dict[str, list[Row]] = {}
        for n, settings in ladders_def.items():
            ladders[n] = []
            for method, setting in settings:
                r = measure(fmus[n], method, setting, refs[n], repeat)
                ladders[n].append(r)
                log(f"{n} {method} {setting:g}: {r.wall:.3f} s, {r.evaluations} evals, error {r.error:.2e}")

        declared = []
        for n, what in WHAT_IT_DECLARES:
            kind = "planar" if n.startswith("planar") else "spatial"
            method, setting = DECLARE_SETTING[kind]
            hit = [r for r in ladders.get(n, []) if (r.method, r.setting) == (method, setting)]
            r = hit[0] if hit else measure(fmus[n], method, setting, refs[n], repeat)
            declared.append((what, len(fmus[n].outputs), r))
            log(f"{n}: {r.wall:.3f} s")

        shipped = []
        for n, _limit in SHIPPED_TARGETS.items():
            f = fastest(ladders.get(n + "_pos", []), 1e-6)
            if f is None:
                continue
            hit = [r for _w, _o, r in declared if r.scene == n and (r.method, r.setting) == (f.method, f.setting)]
            r = hit[0] if hit else measure(fmus[n], f.method, f.setting, refs[n], repeat)
            shipped.append(r)
            log(f"{n} as shipped, {r.method} {r.label}: {r.wall:.3f} s")

        limits = []
        for n, (method, tol) in LIMIT_CASES.items():
            limits.append(limit_row(paths[n], SCENES[n][1], method, tol))
            log(f"limit {n}: {limits[-1]['per_eval_us']:.0f} us per evaluation, linear algebra "
                f"{limits[-1]['linalg_us']:.1f} us")

        stiff = [] if args.quick else stiff_rows(fmus[STIFF], paths[STIFF], repeat)

        ovh = overhead(repeat)
        log(f"FMI overhead per point: ours {ovh['ours_us']:.1f} us, empty C FMU {ovh['empty_us']:.1f} us")

        exu, exu_note = (None, "not run (--no-exudyn)") if args.no_exudyn else exudyn_rows(refs["planar_none_wo4_pos"], repeat)
        if exu:
            for r in exu:
                log(f"Exudyn h = {r.setting:g}: {r.wall:.3f} s, error {r.error:.2e}")

        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        pareto_plot(ladders, exu, out / "pareto.png")
        md = report(ladders, declared, stiff, ovh, exu, exu_note, ref_checks, repeat, args,
                    time.perf_counter() - t_start, shipped, limits)
        (out / "benchmarks.md").write_text(md + _kept_section(out / "benchmarks.md"))
        print(md)
        log(f"wrote {out / 'benchmarks.md'} and {out / 'pareto.png'} ({time.perf_counter() - t_start:.0f} s)")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


def fmu_overhead_table(ovh: dict) -> str:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import fmu_runtime

    return fmu_runtime.overhead_table(ovh)


def report(ladders, declared, stiff, ovh, exu, exu_note, ref_checks, repeat, args, total, shipped=(),
           limits=()) -> str:
    cmd = "python benchmarks/bench.py" + (" --quick" if args.quick else "") + (
        f" --repeat {args.repeat}" if args.repeat != 3 and not args.quick else "")
    L = ["# Benchmarks: speed against accuracy", "",
         f"Generated by `{cmd}` ({total:.0f} s). Machine: {machine()}.", "",
         "Every run is `fmpy.simulate_fmu` on the scene's FMU with a 1 ms output interval and the "
         "solver chosen by FMU parameters (`solver.method`, `solver.tolerance` or `solver.step`); "
         f"wall time is the median of {repeat} run(s) of the whole call. RHS evaluations count the "
         "integration (a scene with reaction outputs adds one evaluation of Eq. 18 per output point). "
         "Error: max over the output points of the length coordinates (m) against dop853 at 1e-13 "
         "in process. `_pos` scenes declare positions only. See `benchmarks/bench.py` for details.", "",
         "Runtime: every FMU is built with the default C runtime (`overcon build`: the FMI layer, the "
         "integrators and the model's evaluation in C, no Python in the FMU). Steps, evaluations, friction "
         "iterations and the drift (max |Phi| at the step ends) are read from the same run in process "
         "(`overcon.kernel.Run`, which the C FMU runs bit for bit). Each FMU run as a user runs it (a fresh "
         "process): `python benchmarks/fmu_runtime.py`.", ""]
    titles = {"planar_f45_wo4_pos": "Planar friction (joints 4, 5), 0-4 s, positions only",
              "spatial_MN_wo5_pos": "Spatial friction (M, N), 0-10 s, positions only",
              "planar_none_wo4_pos": "Planar frictionless, 0-4 s, positions only"}
    for n in ("planar_f45_wo4_pos", "spatial_MN_wo5_pos", "planar_none_wo4_pos"):
        if n not in ladders:
            continue
        L += [f"## {titles[n]}", "", f"Reference check: |dop853(1e-13) - dop853(1e-11)| = {ref_checks[n]:.1e} m.", "",
              table(ladders[n]), ""]
        if n == "planar_none_wo4_pos":
            if exu:
                L += ["Peer, same mechanism in Exudyn (default generalized-alpha solver, fixed step h, sensors "
                      "every 1 ms; wall time of `SolveDynamic` only, no FMI), same run:", "",
                      "| solver | step h (s) | wall (s), median | steps | max pos. error (m) |", "|---|---:|---:|---:|---:|"]
                for r in exu:
                    L.append(f"| {r.method} | {r.setting:g} | {r.wall:.3f} | {r.steps} | {fmt(r.error)} |")
                L += ["", "Matched accuracy (our fastest FMU run at least as accurate as each Exudyn run):", "",
                      "| Exudyn h | Exudyn error | Exudyn wall | overcon FMU (fastest as accurate) | wall | ratio overcon/Exudyn |",
                      "|---:|---:|---:|---|---:|---:|"]
                for r in exu:
                    f = fastest(ladders[n], r.error) if np.isfinite(r.error) else None
                    if f:
                        L.append(f"| {r.setting:g} | {r.error:.1e} | {r.wall:.3f} | {f.method} {f.label} ({f.error:.1e}) | "
                                 f"{f.wall:.3f} | {f.wall / r.wall:.2f} |")
                    else:
                        L.append(f"| {r.setting:g} | {fmt(r.error, '.1e')} | {r.wall:.3f} | none as accurate | - | - |")
                L.append("")
            else:
                L += [f"Peer: {exu_note}.", ""]
    L += ["## What the scene declares: cost per scene", "",
          f"Same solver for all rows ({DECLARE_SETTING['planar'][0]}, tol {DECLARE_SETTING['planar'][1]:g}); "
          "fmpy records every output.", "",
          "| scene | Real outputs | wall (s), median | RHS evals (integration) | max pos. error (m) |",
          "|---|---:|---:|---:|---:|"]
    for what, n_out, r in declared:
        L.append(f"| {r.scene}: {what} | {n_out} | {r.wall:.3f} | {r.evaluations} | {fmt(r.error)} |")
    if stiff:
        L += ["", "## Stiff case: sticking inside the regularisation band", "",
              "planar_f145_wo6 (positions only) with mu = 1 in joints 1, 4, 5 (FMU parameters `joint*.mu`, `joint*.v_reg`), 0-4 s. "
              "The pre-check calls this motion non-unique (friction on joint 1): it serves "
              "here only as the stiff example (slider 1 sticks; stiffness about mu N / (m v_reg)). Error against "
              "radau at 1e-11 in process; explicit runs: wall time until the fmi2Discard, median not taken.", "",
              "| v_reg | method | setting | wall (s) | RHS evals | steps | max pos. error (m) | outcome |",
              "|---:|---|---|---:|---:|---:|---:|---|"]
        for v_reg, r in stiff:
            L.append(f"| {v_reg:g} | {r.method} | {r.label} | {r.wall:.3f} | {r.evaluations} | {r.steps} | "
                     f"{fmt(r.error)} | {r.note} |")
    L += ["", "## FMI overhead per communication point", "",
          "Our C-runtime FMU against the smallest FMU a host can run (`benchmarks/empty_fmu/empty_fmi2.c`: the "
          "same outputs, a doStep that only advances time), both through `fmpy.simulate_fmu` in one process; "
          "the cost per point is the slope between the two grids, so the integration (the same on both grids) "
          "drops out (`benchmarks/fmu_runtime.py --overhead`).", "",
          fmu_overhead_table(ovh), ""]
    if limits:
        L += ["## The limit: time per evaluation against the linear algebra", "",
              "In process (no FMI), positions only: one right-hand-side evaluation in the core "
              "(`overcon.kernel.Kernel.evaluate`, one ctypes call, at the end of the first step after the "
              "middle of the run, warm-started from the friction forces at the step before) beside the cost "
              "of the linear algebra one evaluation needs at that state, with LAPACK on the same arrays: the "
              "Cholesky factorisation of S = J_R^T M^-1 J_R (dpotrf), the back-substitutions for lam0 and for "
              "the friction columns W (dpotrs), and per friction iteration (the whole run's mean) the Newton "
              "matrix's LU factorisation and solve (dgetrf/dgetrs); best of 5 x 2000 calls each.", "",
              "| scene | solver | S size | friction unknowns | friction it./eval | us per evaluation, core | "
              "dpotrf (us) | dpotrs x2 (us) | Newton LU per it. (us) | linear algebra (us) | ratio |",
              "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for m in limits:
            L.append(f"| {m['scene']} | {m['method']} tol = {m['tol']:g} | {m['size']} | {m['nx']} | {m['its']:.2f} | "
                     f"{m['per_eval_us']:.1f} | {m['factor_us']:.1f} | {m['solves_us']:.1f} | "
                     f"{m['newton_us']:.1f} | {m['linalg_us']:.1f} | {m['ratio']:.1f} |")
        L += ["", "Both columns include a Python call each (a few us for the core's evaluation through ctypes, "
              "about 1 us per scipy LAPACK call); the core does its own factorisations, not LAPACK's."]
        L.append("")
    L += ["## Targets (issue 14)", ""]
    for n, limit in TARGETS.items():
        f = fastest(ladders.get(n, []), 1e-6)
        L.append(f"- {titles[n]} to 1e-6 m, target <= {limit:g} s: " + (
            f"fastest {f.method} {f.label}: {f.wall:.2f} s, error {f.error:.1e} m -> "
            f"{'met' if f.wall <= limit else 'NOT met'}" if f else "no run reached 1e-6 m"))
    for r in shipped:
        limit = SHIPPED_TARGETS[r.scene]
        L.append(f"- The same as shipped ({r.scene}, every declared output), {r.method} {r.label}, target <= "
                 f"{limit:g} s: {r.wall:.2f} s -> {'met' if r.wall <= limit else 'NOT met'}")
    if exu:
        ratios = []
        for r in exu:
            f = fastest(ladders.get("planar_none_wo4_pos", []), r.error) if np.isfinite(r.error) else None
            ratios.append(f"{f.wall / r.wall:.2f} at {r.error:.1e} m" if f else f"none as accurate as {r.error:.1e} m")
        ok = all(" at " in x and float(x.split()[0]) <= PEER_RATIO for x in ratios)
        L.append(f"- Planar frictionless against Exudyn at matched accuracy, target <= {PEER_RATIO:g}x at every "
                 f"accuracy: {'; '.join(ratios)} -> {'met' if ok else 'NOT met'}")
    ratio = ovh['ours_us'] / ovh['empty_us']
    L.append(f"- FMI overhead per doStep, target <= {OVERHEAD_RATIO:g}x an empty C FMU's: {ovh['ours_us']:.1f} us vs "
             f"{ovh['empty_us']:.1f} us: ratio {ratio:.2f} -> {'met' if ratio <= OVERHEAD_RATIO else 'NOT met'}")
    L += ["", "### Where the time goes", ""]
    if limits:
        ratios = [m["ratio"] for m in limits]
        L.append(f"- The limit table: one evaluation of Eq. 18 in the core (one call) costs {min(ratios):.1f} to "
                 f"{max(ratios):.1f} times the LAPACK calls of its linear algebra made one by one through scipy; at "
                 "these sizes those calls' own Python overhead is a large part of their figure.")
    L += [
          "- At a 1 ms output interval fmpy's own work per communication point (the empty FMU's figure above) is "
          "a fixed cost of every run: 4000 (planar) or 10000 (spatial) points.",
          "- As shipped, every output point with reactions needs one evaluation of Eq. 18 at the interpolated "
          "state (the multipliers of a step are exact only at its end, where they are reused): 4001 (planar) or "
          "10001 (spatial) extra evaluations, more than the integration's own. A host that reads positions only "
          "does not pay for them.",
          "- The singularity watch (core/watch.c, after every accepted step) is part of every run: its share of "
          "the core's time per paper scene is printed by `python benchmarks/hot_path.py`."]
    L += ["", "![error vs wall time](pareto.png)", ""]
    return "\n".join(L)


if __name__ == "__main__":
    sys.exit(main())
