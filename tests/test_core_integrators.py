"""dop853 and radau in the C core (core/integrate_rk.c, core/integrate_radau.c, core/lu.c) against
the Python integrators (overcon.integrators.Dop853, Radau5) on the same right-hand side
(overcon.simulate.Simulation with solver.kernel = "c"), through overcon.kernel.Run and the C FMU.

- dop853 takes the Python run's steps bit for bit (the same tableau, the same accept and reject
  decisions, both summing in index order), also the dense output and its three extra stages.
- radau factors its Newton matrices with its own LU (core/lu.c and linalg.c, not LAPACK's), so it
  agrees with the Python run within the integration tolerance, with the same step counts to a few
  percent (measured at tolerance 1e-9, 0.6 s: the same steps on every scene below, largest state
  difference 0.64 tolerance on spatial_GH_wo9, 0.32 on the four-bar, round-off elsewhere).
- A state saved as bytes mid-run continues bit for bit; a C FMU with either method equals the
  in-process kernel.Run."""
from __future__ import annotations

import ctypes
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from overcon import kernel, scene as scene_mod
from overcon.checks import compile_checked
from overcon.simulate import Simulation, SimulationError

from test_core_integrate import REL, rel, setup

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
METHOD = {"dopri5": 0, "dop853": 2, "radau": 3}


def constants(method: str, name: str) -> np.ndarray:
    """ovk_integrator_constants(method, name) as a (rows, cols) array (a copy of the core's)."""
    lib = kernel.library()[0]
    f = lib.ovk_integrator_constants
    f.restype = ctypes.c_int
    f.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.POINTER(ctypes.POINTER(ctypes.c_double)),
                  ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_int)]
    data, rows, cols = ctypes.POINTER(ctypes.c_double)(), ctypes.c_int(), ctypes.c_int()
    status = f(METHOD[method], name.encode(), ctypes.byref(data), ctypes.byref(rows), ctypes.byref(cols))
    assert status == 0, (method, name)
    return np.ctypeslib.as_array(data, shape=(rows.value * cols.value,)).reshape(rows.value, cols.value).copy()


def same_bits(a, b) -> bool:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a.size == b.size and a.tobytes() == b.ravel().tobytes()


def test_constants_are_scipys_bit_for_bit():
    """The tableaux written out in C equal SciPy's: dop853's from scipy.integrate._ivp.
    dop853_coefficients (12 stages, then the 3 extra stages of the dense output), dopri5's from
    RK45, radau's from SciPy's radau module (MU: mu_real, Re and Im of mu_complex)."""
    from scipy.integrate import RK45
    from scipy.integrate._ivp import dop853_coefficients as d8, radau as rd

    s = d8.N_STAGES
    want = {"C": d8.C[:s], "A": d8.A[:s, :s], "B": d8.B, "E3": d8.E3, "E5": d8.E5, "D": d8.D,
            "A_EXTRA": d8.A[s + 1:], "C_EXTRA": d8.C[s + 1:]}
    for name, value in want.items():
        assert same_bits(constants("dop853", name), value), name
    for name in ("C", "B", "E", "P"):
        assert same_bits(constants("dopri5", name), getattr(RK45, name)), name
    assert same_bits(constants("dopri5", "A"), RK45.A)
    for name in ("C", "E", "T", "TI", "P"):
        assert same_bits(constants("radau", name), getattr(rd, name)), name
    assert same_bits(constants("radau", "MU"), [rd.MU_REAL, rd.MU_COMPLEX.real, rd.MU_COMPLEX.imag])


DOP853_CASES = ["planar_none_wo4", "planar_f145_wo6", "spatial_GH_wo9", "spatial_MN_wo5", "examples/door",
                "examples/carriage", "examples/loop"]


@pytest.mark.parametrize("name", DOP853_CASES)
def test_dop853_c_run_takes_the_python_steps(name):
    """Step for step: the same times, states and next step sizes; the same right-hand side count
    (so the same rejected attempts: 12 evaluations each), friction force evaluations, stiff steps
    and constraint drift."""
    model, solver = setup(name, "dop853")
    sim = Simulation(model, solver)
    run = kernel.Run(model, solver)
    itg = sim._integrator
    while itg.t < model.scene.stop_time:
        sim.advance(itg.t + 1e-9)  # exactly one step, with Simulation's step-end checks
        run.step()
        info = run.info
        assert rel(info["t"], itg.t) <= REL and rel(run.y, itg.y) <= REL and rel(info["h"], itg.h) <= REL, itg.t
    assert sim.kernel_repeats == 0
    assert info["nsteps"] == itg.nsteps > 10 and info["nfev"] == itg.nfev
    assert info["evaluations"] == sim.evaluations and info["friction_iterations"] == sim.friction_iterations
    assert info["stiff_steps"] == itg.stiff_steps
    assert rel(info["max_drift"], sim.max_drift) <= REL


def test_dop853_cases_include_rejected_steps():
    """The step-for-step cases exercise the reject branch (an attempt costs 12 evaluations)."""
    model, solver = setup("planar_f145_wo6", "dop853")
    run = kernel.Run(model, solver)
    run.advance(model.scene.stop_time)
    attempts = (run.info["nfev"] - 1) / 12
    assert attempts > run.info["nsteps"] + 5


@pytest.mark.parametrize("name", ["planar_f145_wo6", "spatial_GH_wo9", "examples/fourbar", "examples/door"])
def test_dop853_outputs_equal_python_outputs(name):
    """On an output grid that does not meet the steps: y by the 7th-order dense output (its three
    extra stages evaluated by the right-hand side that leaves the run alone), the reactions and
    friction forces equal the Python run's; outputs are not counted as the run's evaluations."""
    model, solver = setup(name, "dop853")
    sim = Simulation(model, solver)
    run = kernel.Run(model, solver)
    plan = sim._derived
    for t in np.arange(0.0, model.scene.stop_time, 0.0123)[1:]:
        y_py, y_c = sim.advance(t), run.advance(t)
        assert rel(y_c, y_py) <= REL, t
        if plan.size:
            assert rel(plan.values_from_kernel(*run.outputs(t, y_c)), sim.derived_outputs(t, y_py)) <= REL
    assert run.info["evaluations"] == sim.evaluations


@pytest.mark.parametrize("method", ["dop853", "radau"])
def test_outputs_never_alter_the_trajectory(method):
    """A run read on a fine output grid (dense output inside most steps: dop853's extra stages,
    radau's collocation polynomial) and a run that only steps are the same run: after the same
    number of steps the same bits and counters."""
    model, solver = setup("planar_f145_wo6", method)
    read = kernel.Run(model, solver)
    for t in np.arange(0.0, 0.3, 0.0007)[1:]:
        read.advance(t)
    plain = kernel.Run(model, solver)
    while plain.info["nsteps"] < read.info["nsteps"]:
        plain.step()
    assert np.array_equal(plain.y, read.y)
    assert {k: v for k, v in plain.info.items() if k not in kernel.WALL_TIMES} == {
        k: v for k, v in read.info.items() if k not in kernel.WALL_TIMES}


def _stiff_scene():
    """planar_f145_wo6 with mu = 1 and v_reg = 1e-6 m/s: sticking inside a tiny regularisation band."""
    sc = scene_mod.as_scene(scene_mod.load(MECH / "planar_f145_wo6.toml"), stop_time=1.0)
    sc = dataclasses.replace(sc, friction_params={k: dataclasses.replace(v, mu=1.0, v_reg=1e-6)
                                                  for k, v in sc.friction_params.items()})
    return compile_checked(sc), sc.solver


def test_dop853_stiffness_stop_equals_python():
    """Sticking inside a tiny regularisation band: dop853's stiffness test stops both runs at the
    same instant with the same words (status 9), naming radau."""
    model, solver = _stiff_scene()
    solver = dataclasses.replace(solver, kernel="c", method="dop853")
    with pytest.raises(SimulationError) as py:
        Simulation(model, solver).advance(1.0)
    with pytest.raises(kernel.RunStopped) as c:
        kernel.Run(model, solver).advance(1.0)
    assert c.value.status == 9 and str(c.value) == str(py.value)
    assert "the problem is stiff for dop853" in str(c.value) and "radau" in str(c.value)


RADAU_CASES = ["planar_f45_wo4", "planar_f145_wo6", "spatial_GH_wo9", "spatial_MN_wo5", "examples/door",
               "examples/fourbar"]


@pytest.mark.parametrize("name", RADAU_CASES)
def test_radau_agrees_with_python_within_the_tolerance(name):
    """On a 10 ms grid to 0.6 s, against a tight reference (the core's dop853 at 1e-13): the C
    radau's error is at most twice the Python radau's plus the tolerance (relative to max(1,
    |entry|)); accepted steps and right-hand side evaluations within 3 %, every evaluation on the
    core's right-hand side. Not the two runs' difference against the tolerance: their LUs differ
    (the Python one is LAPACK's, so the BLAS kernel's), which can change a step-size decision and
    then the runs differ by their global error, up to 1.3 tolerances measured (examples/fourbar,
    OpenBLAS Prescott); each run's own global error reaches 31 tolerances (planar_f145_wo6)."""
    model, solver = setup(name, "radau")
    sim = Simulation(model, solver)
    run = kernel.Run(model, solver)
    ref = kernel.Run(model, dataclasses.replace(solver, method="dop853", tolerance=1e-13))
    for t in np.arange(0.0, model.scene.stop_time, 0.01)[1:]:
        y_py, y_c, y_ref = sim.advance(t), run.advance(t), ref.advance(t)
        assert rel(y_c, y_ref) <= 2.0 * rel(y_py, y_ref) + solver.tolerance, t
    itg, info = sim._integrator, run.info
    assert sim.kernel_repeats == 0
    assert abs(info["nsteps"] - itg.nsteps) <= 0.03 * itg.nsteps and itg.nsteps > 20
    assert abs(info["nfev"] - itg.nfev) <= 0.03 * itg.nfev
    assert info["evaluations"] == info["nfev"]  # a radau run evaluates only for its integrator


def test_radau_runs_the_stiff_friction_the_explicit_methods_stop_on():
    """Sticking inside a 1e-6 m/s regularisation band: the C dopri5 run stops as stiff (status 9),
    the C radau run reaches 1 s in tens of steps and ends within the tolerance of the Python radau
    run."""
    model, solver = _stiff_scene()
    with pytest.raises(kernel.RunStopped) as c:
        kernel.Run(model, dataclasses.replace(solver, kernel="c", method="dopri5")).advance(1.0)
    assert c.value.status == 9
    solver = dataclasses.replace(solver, kernel="c", method="radau", tolerance=1e-8)
    run = kernel.Run(model, solver)
    y_c = run.advance(1.0)
    sim = Simulation(model, solver)
    y_py = sim.advance(1.0)
    assert run.info["nsteps"] < 100 and abs(run.info["nsteps"] - sim._integrator.nsteps) <= 1
    assert rel(y_c, y_py) <= solver.tolerance


def test_radau_newton_failures_collapse_the_step_as_in_python():
    """spatial_MN_wo5 with mu = 3 and one force evaluation for the friction solve: the solve fails
    at the Newton iterates (a failed Newton iteration, as Radau5 counts an ArithmeticError of the
    right-hand side), radau halves the step until it falls below the resolution of t, and stops
    (status 8) at the Python run's instant and step size, naming the friction solve as the last
    failure (the core's words for it differ from numpy's)."""
    sc = scene_mod.as_scene(scene_mod.load(MECH / "spatial_MN_wo5.toml"), stop_time=0.5)
    sc = dataclasses.replace(sc, friction_params={k: dataclasses.replace(v, mu=3.0)
                                                  for k, v in sc.friction_params.items()})
    model = compile_checked(sc)
    solver = dataclasses.replace(sc.solver, kernel="c", method="radau", friction_max_iter=1, tolerance=1e-6)
    with pytest.raises(SimulationError) as py:
        Simulation(model, solver).advance(0.5)
    with pytest.raises(kernel.RunStopped) as c:
        kernel.Run(model, solver).advance(0.5)
    lead, cause = str(c.value).split(" (last failure: ")
    assert c.value.status == 8 and str(py.value).startswith(lead + " (last failure: ")
    assert "below the minimum" in lead and "friction solve did not converge" in cause


def test_radau_stops_at_a_singular_position_as_python(tmp_path):
    """The sliders driven through K = L = O (free length 0) under radau at tolerance 1e-6: both
    runs find r's minimum inside one step on radau's collocation polynomial and stop there with the
    same words (status 12), the instants within the tolerance (the steps differ by round-off)."""
    text = (MECH / "planar_sliders.toml").read_text().replace("free_length = 3.0", "free_length = 0.0")
    (tmp_path / "l0.toml").write_text(text)
    sc = scene_mod.as_scene(scene_mod.load(tmp_path / "l0.toml"), stop_time=2.0)
    model = compile_checked(sc)
    solver = dataclasses.replace(sc.solver, kernel="c", method="radau", tolerance=1e-6)
    with pytest.raises(SimulationError) as py:
        Simulation(model, solver).advance(2.0)
    with pytest.raises(kernel.RunStopped) as c:
        kernel.Run(model, solver).advance(2.0)

    def instant(msg):
        return float(msg.split("t = ")[1].split(" s")[0])
    assert c.value.status == 12
    assert abs(instant(str(c.value)) - instant(str(py.value))) <= solver.tolerance
    for words in ("the motion passed a singular position (between the steps", "rank deficient (rank 10 < 11"):
        assert words in str(c.value) and words in str(py.value)


def test_c_fmu_with_dop853_and_radau_equals_the_in_process_run(tmp_path):
    """The paper's planar_f45_wo4 built with the C runtime, its parameter solver.method set to
    dop853 and to radau, through fmpy over the default experiment: every output at every
    communication point equals the in-process kernel.Run's (the same C code and calls) to 1e-12."""
    fmpy = pytest.importorskip("fmpy")
    from overcon.fmu import build as fmu_build

    path = MECH / "planar_f45_wo4.toml"
    lines = []
    code, results = fmu_build.build_all([str(path)], tmp_path, refs=False, allow_nonunique=True, runtime="c",
                                        echo=lines.append, echo_err=lines.append)
    assert code == 0 and any("runtime c)" in line for line in lines), lines
    spec = scene_mod.load(path)
    model = compile_checked(spec)
    names = model.output_names()
    for method in ("dop853", "radau"):
        got = fmpy.simulate_fmu(str(results[0].fmu), output_interval=spec.solver.output_interval,
                                start_values={"solver.method": method})
        solver = dataclasses.replace(spec.solver, method=method)
        run, sim = kernel.Run(model, solver), Simulation(model, solver)
        assert len(got) == round(spec.stop_time / spec.solver.output_interval) + 1
        for k, t in enumerate(got["time"]):
            y = run.advance(t)
            want = np.concatenate([sim.position_outputs(y), sim._derived.values_from_kernel(*run.outputs(t, y))])
            row = np.array([got[n][k] for n in names])
            assert np.max(np.abs(row - want) / np.maximum(1.0, np.abs(want))) <= 1e-12, (method, t)
        assert run.info["nsteps"] > 50
