"""The integrators and the run in C (core/integrate_rk.c, core/sim.c through overcon.kernel.Run)
against the Python run (overcon.simulate.Simulation with solver.kernel = "c", the same right-hand
side): the same accepted steps, states, dense outputs, derived outputs, counters and failures,
and a byte state that restores a run exactly."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from overcon import kernel, scene as scene_mod
from overcon.checks import compile_checked
from overcon.simulate import Simulation, SimulationError

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
REL = 1e-12
"""C run against Python run, per state entry (relative to max(1, |entry|)): the same arithmetic in
the same order (both sum in a fixed order, without the BLAS), so round-off at most."""
CASES = [("planar_none_wo4", "dopri5"), ("planar_f145_wo6", "dopri5"), ("planar_f1_wo4", "dopri5"),
         ("spatial_GH_wo9", "dopri5"), ("spatial_GHMN_wo18", "dopri5"), ("examples/door", "dopri5"),
         ("examples/fourbar", "dopri5"), ("examples/loop", "dopri5"), ("planar_f45_wo4", "rk4"),
         ("spatial_MN_wo5", "rk4"), ("examples/carriage", "rk4")]


def setup(name, method, stop_time=0.6, mu=None, **solver):
    sc = scene_mod.as_scene(scene_mod.load(MECH / f"{name}.toml"), stop_time=stop_time)
    if mu is not None:
        sc = dataclasses.replace(sc, friction_params={k: dataclasses.replace(v, mu=mu)
                                                      for k, v in sc.friction_params.items()})
    model = compile_checked(sc)
    return model, dataclasses.replace(sc.solver, kernel="c", method=method, **solver)


def rel(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b)) / np.maximum(1.0, np.abs(np.asarray(b))), initial=0.0))


@pytest.mark.parametrize("name, method", CASES)
def test_c_run_takes_the_python_steps(name, method):
    """Step for step: the same times, states and next step sizes, then the same counters (right-
    hand sides, friction force evaluations), constraint drift and monitor ratio."""
    model, solver = setup(name, method)
    sim = Simulation(model, solver)
    run = kernel.Run(model, solver)
    itg = sim._integrator
    assert run.info["t"] == itg.t and np.array_equal(run.y, itg.y)
    while itg.t < model.scene.stop_time:
        sim.advance(itg.t + 1e-9)  # exactly one step (far longer than 1e-9 s), with Simulation's step-end checks
        run.step()
        info = run.info
        assert rel(info["t"], itg.t) <= REL and rel(run.y, itg.y) <= REL, itg.t
        if method == "dopri5":
            assert rel(info["h"], itg.h) <= REL
    assert sim.kernel_repeats == 0  # the Python run never left the core's right-hand side
    assert info["nsteps"] == itg.nsteps > 10 and info["nfev"] == itg.nfev
    assert info["evaluations"] == sim.evaluations and info["friction_iterations"] == sim.friction_iterations
    assert rel(info["max_drift"], sim.max_drift) <= REL and info["max_drift"] > 0.0
    assert info["min_ratio"] == pytest.approx(sim.monitor.min_ratio, rel=1e-9)  # Jacobi against LAPACK's SVD


@pytest.mark.parametrize("name, method", [("planar_f145_wo6", "dopri5"), ("spatial_GH_wo9", "dopri5"),
                                          ("planar_f45_wo4", "rk4"), ("examples/fourbar", "dopri5")])
def test_c_run_outputs_equal_python_outputs(name, method):
    """On an output grid that does not meet the steps: y by dense output and the reactions and
    friction forces (the last evaluation's multipliers at a step end, else one solve warm-started
    from the step-end forces) equal the Python run's."""
    model, solver = setup(name, method)
    sim = Simulation(model, solver)
    run = kernel.Run(model, solver)
    plan = sim._derived
    for t in np.arange(0.0, model.scene.stop_time, 0.0123)[1:]:
        y_py = sim.advance(t)
        y_c = run.advance(t)
        assert rel(y_c, y_py) <= REL
        if plan.size:
            want = sim.derived_outputs(t, y_py)
            got = plan.values_from_kernel(*run.outputs(t, y_c))
            assert rel(got, want) <= REL
    assert run.info["evaluations"] == sim.evaluations  # outputs never counted as the run's evaluations


@pytest.mark.parametrize("method", ["dopri5", "rk4", "dop853", "radau"])
def test_state_bytes_restore_the_run_bit_for_bit(method):
    """get_state at t1, continue to t2 (outputs inside a step: dop853's dense coefficients and
    radau's LU factors are part of the bytes); set_state and continue again: the same bits and
    counters; a state of another run (other sizes), of the same model under another method, or a
    truncated one is refused and leaves the run as it was."""
    model, solver = setup("planar_f145_wo6", method)
    run = kernel.Run(model, solver)
    run.advance(0.2)
    saved = run.get_state()
    a = [run.advance(t) for t in (0.23, 0.31, 0.4)]
    info_a = run.info
    run.set_state(saved)
    b = [run.advance(t) for t in (0.23, 0.31, 0.4)]
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert {k: v for k, v in run.info.items() if k not in kernel.WALL_TIMES} == {
        k: v for k, v in info_a.items() if k not in kernel.WALL_TIMES}
    other = kernel.Run(*setup("planar_none_wo4", method))
    with pytest.raises(kernel.RunStopped, match="set state"):
        other.set_state(saved)
    other_method = kernel.Run(model, dataclasses.replace(solver, method="dopri5" if method == "radau" else "radau"))
    with pytest.raises(kernel.RunStopped, match="set state: "):
        other_method.set_state(saved)
    with pytest.raises(kernel.RunStopped, match="set state"):
        run.set_state(saved[:-8])
    assert np.array_equal(run.y, b[-1]) or run.info["t"] >= 0.4


def test_rk4_unstable_step_names_the_python_stable_step():
    """rk4 beyond its stability boundary (sticking friction, a step of 20 ms): the C run stops
    at the same time as the Python run, with the same stable step (a number) and the same words."""
    model, solver = setup("planar_f145_wo6", "rk4", mu=1.0, step=0.02, stop_time=1.0)
    with pytest.raises(SimulationError) as py:
        Simulation(model, solver).advance(1.0)
    assert py.value.stable_step is not None
    with pytest.raises(kernel.RunStopped) as c:
        kernel.Run(model, solver).advance(1.0)
    assert c.value.status == 10
    assert rel(c.value.stable_step, py.value.stable_step) <= REL
    assert str(c.value) == str(py.value)


def test_step_budget_stops_the_run_and_a_call_budget_too():
    """The life budget (max_steps) and one call's budget stop with status 11, naming the steps."""
    model, solver = setup("planar_f45_wo4", "dopri5")
    run = kernel.Run(model, solver, max_steps=5)
    with pytest.raises(kernel.RunStopped, match=r"work budget exhausted: 5 internal steps \(max_steps = 5\)") as e:
        run.advance(0.5)
    assert e.value.status == 11 and run.info["nsteps"] == 5
    run = kernel.Run(model, solver)
    with pytest.raises(kernel.RunStopped, match=r"integration stopped: .*4 internal steps > 3 allowed for this step"):
        run.advance(0.5, max_steps=3)


def test_singular_position_stops_both_runs_alike(tmp_path):
    """The sliders driven through K = L = O (free length 0): a finite step jumps over the rank
    loss; both runs see r fall then rise inside one step, locate its minimum on the dense output
    (golden section), judge the whole Jacobian rank deficient there, and stop at the same instant
    with the same message."""
    text = (MECH / "planar_sliders.toml").read_text().replace("free_length = 3.0", "free_length = 0.0")
    path = tmp_path / "l0.toml"
    path.write_text(text)
    sc = scene_mod.as_scene(scene_mod.load(path), stop_time=2.0)
    model = compile_checked(sc)
    solver = dataclasses.replace(sc.solver, kernel="c")
    sim = Simulation(model, solver)
    with pytest.raises(SimulationError, match=r"passed a singular position \(between the steps.*rank deficient \(rank 10 < 11") as py:
        sim.advance(2.0)
    assert sim.kernel_repeats == 0
    run = kernel.Run(model, solver)
    with pytest.raises(kernel.RunStopped) as c:
        run.advance(2.0)
    assert c.value.status == 12 and str(c.value) == str(py.value)
    assert run.info["min_ratio"] == pytest.approx(sim.monitor.min_ratio, rel=1e-9)


def test_robust_friction_path_succeeds_and_fails_where_numpy_does():
    """States where the core's Newton and damped Newton give up (spatial paper mechanism, mu up
    to 3, fast random velocities), cold-started: where both the C robust path (fixed point, then
    finite-difference Newton) and the numpy path's converge, they give the same multipliers
    within what two solves to the friction tolerance can differ by (1e-9 relative); where both
    fail, both say so. On these hard states the iterations are sensitive to round-off (another
    BLAS kernel changes numpy's), so one path may converge where the other gives up: the
    solution found must then be one the other path accepts when started from it."""
    from overcon.dynamics import FrictionSolveError, evaluate

    outcomes = {"both": 0, "neither": 0, "one": 0}
    for name in ("spatial_MN_wo5", "spatial_GHMN_wo18"):
        for mu in (1.0, 3.0):
            model, solver = setup(name, "dopri5", mu=mu)
            k = kernel.Kernel(kernel.library()[0], model, solver)
            rng = np.random.default_rng(1)
            for _ in range(30):
                y = np.concatenate([model.q0 + 0.05 * rng.standard_normal(model.n),
                                    model.h0 + 3.0 * rng.standard_normal(model.nh)])
                if k.evaluate(0.0, y) is not None or k.last_status != 2:
                    continue
                failed = k.newton_failed()
                c = k.evaluate_robust(y)
                try:
                    ev = evaluate(model, 0.0, y[: model.n], y[model.n:], solver=solver, newton_failed=failed)
                except FrictionSolveError:
                    ev = None
                if c is None and ev is None:
                    assert k.last_status == 2 and "did not converge" in k.last_message
                    outcomes["neither"] += 1
                elif c is not None and ev is not None:
                    assert rel(c[1], ev.lam) <= 1e-9 and rel(c[0][model.n:], ev.hdot) <= 1e-9
                    outcomes["both"] += 1
                else:
                    _accepted_by_the_other(model, solver, k, y, c, ev)
                    outcomes["one"] += 1
    assert outcomes["both"] >= 5 and outcomes["neither"] >= 5, outcomes


def _accepted_by_the_other(model, solver, k, y, c, ev):
    """The solution one path found, given to the other as its start, is accepted there (the same
    multipliers within 1e-9 relative): it solves the same equations."""
    from overcon.dynamics import evaluate

    if c is not None:
        again = evaluate(model, 0.0, y[: model.n], y[model.n:], c[1], solver=solver)
        assert rel(again.lam, c[1]) <= 1e-9
    else:
        again = k.evaluate(0.0, y, ev.lam)
        assert again is not None, k.last_message
        assert rel(again[1], ev.lam) <= 1e-9


# ----------------------------------------------------------------------------- the watch (core/watch.c)

def _watch_scene(path, stop_time):
    sc = scene_mod.as_scene(scene_mod.load(path), stop_time=stop_time)
    model = compile_checked(sc)
    return model, dataclasses.replace(sc.solver, kernel="c")


def _stepwise(model, solver, sim=None):
    """Both runs step for step until one stops: (the Python exception or None, the C RunStopped
    or None, the Simulation); every step the same t and state."""
    sim = sim or Simulation(model, solver)
    run = kernel.Run(model, solver)
    itg, py, c = sim._integrator, None, None
    while itg.t < model.scene.stop_time and py is None and c is None:
        try:
            sim.advance(itg.t + 1e-9)
        except SimulationError as exc:
            py = exc
        try:
            run.step()
        except kernel.RunStopped as exc:
            c = exc
        assert run.info["nsteps"] == sim._integrator.nsteps
        if py is None and c is None:
            assert run.info["t"] == sim._integrator.t and np.array_equal(run.y, sim._integrator.y)
    return py, c, sim


def test_n_four_bar_flat_position_stops_both_runs_at_the_same_instant(tmp_path):
    """The N-four-bar (2 loops, eliminated form) reaches its flat position, an even-multiplicity
    rank loss where no singular value changes sign: both runs take the same steps, find r's
    minimum inside the same step and stop with the same words (a singular position of the
    mechanism, status 12)."""
    import subprocess
    import sys
    subprocess.run([sys.executable, str(MECH / "examples" / "nfourbar.py"), "2", "--out", str(tmp_path)], check=True,
                   capture_output=True)
    py, c, _ = _stepwise(*_watch_scene(tmp_path / "nfourbar_2_scene.toml", 1.0))
    assert py is not None and c is not None, (py, c)
    assert "passed a singular position (between the steps" in str(py) and "rank deficient" in str(py)
    assert c.status == 12 and str(c) == str(py)


def _events_alike(c_events, py_events):
    """The C run's events are the Python run's (the stop's time read from its message: 9 digits)."""
    assert [e[1] for e in c_events] == [e[1] for e in py_events]
    for a, b in zip(c_events, py_events):
        assert abs(a[0] - b[0]) <= (1e-8 * max(1.0, abs(b[0])) if a[1] == "stopped" else 0.0) and a[2] == b[2]


def test_expired_elimination_is_chosen_again_by_the_c_run_as_by_python(tmp_path):
    """The parallelogram eliminating Phi11 (tests/test_watch.py): at the upright position only the
    kept equations lose rank; both runs choose them again there (pivoted QR: the core's and
    scipy's choose alike), take the step anew and go on: the same steps, the same state and the
    same elimination-reselected event; a state saved after it restores the kept set."""
    from test_watch import _parallelogram
    model, solver = _watch_scene(_parallelogram(tmp_path, None, "[11]"), 0.3)
    sim = Simulation(model, solver)
    sim.advance(0.3)
    (t_event, kind, detail), = sim.events
    assert kind == "elimination-reselected" and detail.startswith("eliminated [11] -> [")
    run = kernel.Run(model, solver)
    run.advance(0.3)
    _events_alike(run.events, sim.events)
    assert run.info["nsteps"] == sim._integrator.nsteps and np.array_equal(run.y, sim._integrator.y)
    saved, later = run.get_state(), run.advance(0.4)
    again = kernel.Run(model, solver)
    again.set_state(saved)
    assert np.array_equal(again.advance(0.4), later)


def test_degrading_elimination_is_chosen_again_by_the_c_run_as_by_python():
    """The Bricard linkage eliminating Phi2: near 1.206 s the kept equations become ill-conditioned
    (r < 1e-3) while the whole Jacobian is not; both runs choose the elimination again at that
    step's end (the same event, the ratio it names included) and go on: the same steps and state."""
    model, solver = _watch_scene(Path(__file__).resolve().parent / "data" / "bricard" / "bricard_wo2.toml", 1.3)
    sim = Simulation(model, solver)
    sim.advance(1.3)
    (t_event, kind, detail), = sim.events
    assert kind == "elimination-reselected" and detail.startswith("eliminated [2] -> ")
    assert "became ill-conditioned: sigma_min/sigma_max" in detail
    run = kernel.Run(model, solver)
    run.advance(1.3)
    _events_alike(run.events, sim.events)
    assert run.info["nsteps"] == sim._integrator.nsteps and np.array_equal(run.y, sim._integrator.y)


def test_parallelogram_without_expiry_keeps_the_python_steps(tmp_path):
    """The same parallelogram under the elimination "auto" chooses (valid at the upright
    position): the watch sees r dip and rise without a stop, and the C run takes the Python
    steps to the end, with the same smallest ratio within the two SVDs' round-off."""
    from test_watch import _parallelogram
    model, solver = _watch_scene(_parallelogram(tmp_path, None, '"auto"'), 0.6)
    py, c, sim = _stepwise(model, solver)
    assert py is None and c is None and not sim.events
    run = kernel.Run(model, solver)
    run.advance(0.6)
    assert run.info["nsteps"] == sim._integrator.nsteps > 20
    assert run.info["min_ratio"] == pytest.approx(sim.monitor.min_ratio, rel=1e-9)


# ----------------------------------------------------------------------------- energy outputs (core/energy.c)

@pytest.mark.parametrize("name, method", [("planar_f145_wo6", "dopri5"), ("examples/carriage_guide_wo_rod", "rk4"),
                                          ("planar_sliders", "dopri5"), ("examples/door_h1_wo_hinge2", "dopri5")])
def test_c_run_energies_equal_python_energies(name, method):
    """Friction, constant forces and torques, springs, quaternions: on an output grid that does
    not meet the steps the C run's energy.kinetic, potential, dissipated and applied equal the
    Python run's within round-off, its ledger costs the same evaluations, and the states stay
    equal (the ledger's solves never touch the integration's warm start); a state restored
    restores the ledger."""
    model, solver = setup(name, method, stop_time=0.5)
    model = dataclasses.replace(model, energy_outputs=True)
    sim, run = Simulation(model, solver), kernel.Run(model, solver)
    grid = np.arange(0.0, 0.5, 0.0123)[1:]
    for t in grid:
        y_py, y_c = sim.advance(t), run.advance(t)
        assert rel(y_c, y_py) <= REL
        e_py = sim.state_outputs(y_py, t)[-4:]
        assert rel(run.energies(t, y_c), e_py) <= REL, t
    assert run.info["evaluations"] == sim.evaluations
    assert abs(e_py[2]) + abs(e_py[3]) > 0.1 or "spring" in {ld.type for ld in model.loads}  # work done, or a spring
    saved = run.get_state()
    later = run.energies(0.5, run.advance(0.5))
    run.set_state(saved)
    assert np.array_equal(run.energies(0.5, run.advance(0.5)), later)
    plain = kernel.Run(model, solver, energy=False)  # no ledger: no extra evaluations, the work reads 0
    plain.advance(grid[-1])
    assert plain.info["evaluations"] < sim.evaluations or not model.friction_joints
    assert np.array_equal(plain.energies(grid[-1], plain.y)[2:], [0.0, 0.0])


def test_failed_step_of_an_expiring_elimination_stops_the_c_run_at_the_python_instant(tmp_path):
    """The parallelogram eliminating Phi11 with friction mu = 0.5 on G0 (tolerance 1e-8): the
    step over the upright position fails (the friction solve); r was falling fast enough to reach
    0 within two steps while all equations keep their rank, so the elimination expiring is the
    cause (SingularityMonitor.expiring). The reaction of G0 is not unique, so both runs stop
    there with the same words up to the failure's own (the core's friction message is worded
    differently): the instant, then the eliminations valid at the start and there (status 14)."""
    from test_watch import _parallelogram
    model, solver = _watch_scene(_parallelogram(tmp_path, "G0", "[11]"), 0.6)
    model = compile_checked(dataclasses.replace(model.scene, friction_params={
        k: dataclasses.replace(v, mu=0.5) for k, v in model.scene.friction_params.items()}))
    solver = dataclasses.replace(solver, tolerance=1e-8)
    with pytest.raises(SimulationError) as py:
        Simulation(model, solver).advance(0.6)
    with pytest.raises(kernel.RunStopped) as c:
        kernel.Run(model, solver).advance(0.6)
    lead = str(py.value).split("friction solve")[0]
    tail = "; with friction on G0, whose reaction is not unique, the elimination decides the motion, so the run stops"
    assert "the elimination chosen at the start expires (the step from t = " in lead and tail in str(py.value)
    assert c.value.status == 14 and str(c.value).startswith(lead + "friction solve")
    assert str(c.value)[str(c.value).index(tail):] == str(py.value)[str(py.value).index(tail):]
