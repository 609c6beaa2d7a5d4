"""Integrators (overcon.integrators): every method registered for scene files and FMUs, exact
state round trips, results independent of the output grid, and the implicit ``radau`` method on
the stiff cases that stop the explicit methods (sticking inside a small regularisation band)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from overcon import integrators, scene, spec
from overcon.fmu import statecodec
from overcon.fmu.variables import rule
from overcon.checks import compile_checked
from overcon.simulate import Simulation, SimulationError, run_scene

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
ALL = ("dopri5", "dop853", "rk4", "radau")


def scene_of(name, *, mu=None, v_reg=None, stop_time=1.0, tolerance=1e-8, **solver):
    sc = scene.as_scene(scene.load(MECH / f"{name}.toml"), stop_time=stop_time, tolerance=tolerance)
    changes = {k: v for k, v in (("mu", mu), ("v_reg", v_reg)) if v is not None}
    if changes:
        sc = dataclasses.replace(sc, friction_params={k: dataclasses.replace(v, **changes)
                                                      for k, v in sc.friction_params.items()})
    if solver:
        sc = dataclasses.replace(sc, solver=dataclasses.replace(sc.solver, **solver))
    return sc


def positions(res):
    return res.values[:, [i for i, n in enumerate(res.names) if n.split(".")[1] in ("x", "y", "z", "phi")]]


def test_every_method_is_offered_everywhere(tmp_path):
    assert set(integrators.METHODS) == set(spec.METHODS) == set(ALL)
    for m in ALL:
        assert rule("solver.method").check(m) is None
    text = (MECH / "planar_f45_wo4.toml").read_text().replace("[solver]", '[solver]\nmethod = "radau"')
    (tmp_path / "s.toml").write_text(text.replace('mechanism = "planar_sliders.toml"',
                                                  f'mechanism = "{(MECH / "planar_sliders.toml").as_posix()}"'))
    assert scene.load(tmp_path / "s.toml").solver.method == "radau"


@pytest.mark.parametrize("method", ALL)
def test_state_round_trip_bit_for_bit(method):
    """get_state at t1, continue to t2; set_state (through the FMU state codec) and continue
    again: identical bits, also for the counters."""
    sc = scene_of("planar_f45_wo4", step=2e-3)
    model = compile_checked(sc)
    sim = Simulation(model, sc.solver, method=method)
    sim.advance(0.3)
    saved = statecodec.loads(statecodec.dumps(sim.get_state()))
    a = [sim.outputs(t, sim.advance(t)) for t in (0.31, 0.45, 0.6)]
    ev_a = sim.evaluations
    fresh = Simulation(model, sc.solver, method=method)
    fresh.set_state(saved)
    b = [fresh.outputs(t, fresh.advance(t)) for t in (0.31, 0.45, 0.6)]
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert fresh.evaluations == ev_a
    sim.set_state(saved)  # and back in the same instance
    c = [sim.outputs(t, sim.advance(t)) for t in (0.31, 0.45, 0.6)]
    assert all(np.array_equal(x, y) for x, y in zip(a, c))


@pytest.mark.parametrize("method", ALL)
def test_results_do_not_depend_on_the_output_grid(method):
    """Dense output only reads: a fine grid and a coarse one give the same bits where they meet,
    and the same number of right-hand-side evaluations for the integration."""
    sc = scene_of("planar_f45_wo4", stop_time=0.5, step=2e-3)
    fine = run_scene(sc, method=method, output_interval=2.0**-10)  # binary fractions: the coarse
    coarse = run_scene(sc, method=method, output_interval=2.0**-3)  # times are exactly fine ones
    idx = np.searchsorted(fine.time, coarse.time)
    assert np.array_equal(fine.time[idx], coarse.time)
    assert np.array_equal(fine.values[idx], coarse.values)
    assert fine.steps == coarse.steps


def test_radau_agrees_with_explicit_methods_on_a_nonstiff_case():
    ref = positions(run_scene(scene_of("planar_f45_wo4", stop_time=2.0, tolerance=1e-11), method="dop853"))
    res = run_scene(scene_of("planar_f45_wo4", stop_time=2.0, tolerance=1e-8), method="radau")
    assert np.max(np.abs(positions(res) - ref)) < 1e-6
    assert res.max_drift < 1e-8


def test_stiff_sticking_case_stops_dopri5_and_radau_integrates_it():
    """Planar friction in joints 1, 4, 5 with mu = 1: the sliders stick inside the regularisation
    band (stiffness mu N / (m v_reg) ~ 2e4 1/s). dopri5 stops with a stiffness report; radau runs
    through, and its result converges with the tolerance (1e-8 against 1e-10: < 1e-7 m)."""
    with pytest.raises(SimulationError, match="stiff"):
        run_scene(scene_of("planar_f145_wo6", mu=1.0), method="dopri5")
    a = run_scene(scene_of("planar_f145_wo6", mu=1.0, tolerance=1e-8), method="radau")
    b = run_scene(scene_of("planar_f145_wo6", mu=1.0, tolerance=1e-10), method="radau")
    assert np.all(np.isfinite(a.values)) and a.max_drift < 1e-9
    assert np.max(np.abs(positions(a) - positions(b))) < 1e-7
    assert a.evaluations < 2000


@pytest.mark.parametrize("v_reg", [1e-6, 1e-7])
def test_radau_tiny_regularisation_sticking(v_reg):
    """v_reg = 1e-6 and 1e-7 with sticking (mu = 1, joints 1, 4, 5): radau stays cheap (stiffness
    1e3-1e4 times that of v_reg = 1e-3), finite, on the constraints; the sticking slider creeps
    by less than v_reg x time (here 0-1 s) and the result converges with the tolerance."""
    a = run_scene(scene_of("planar_f145_wo6", mu=1.0, v_reg=v_reg, tolerance=1e-8), method="radau")
    b = run_scene(scene_of("planar_f145_wo6", mu=1.0, v_reg=v_reg, tolerance=1e-10), method="radau")
    assert np.all(np.isfinite(a.values)) and a.max_drift < 1e-9
    x1 = a.column("slider1.x")
    assert np.max(np.abs(x1 - 2.0)) < v_reg * 1.0
    assert np.max(np.abs(positions(a) - positions(b))) < 1e-9
    assert a.evaluations < 5000


def test_radau_failure_is_reported_with_time():
    """A right-hand side that cannot be evaluated (friction solve capped at 1 iteration) ends the
    run with the time and a reason, not with garbage."""
    sc = scene_of("planar_f45_wo4", mu=1.0, friction_max_iter=1)
    with pytest.raises(SimulationError, match=r"t = "):
        run_scene(sc, method="radau")


def _decay(t, y):
    return -y


@pytest.mark.parametrize("method", ALL)
def test_unknown_option_is_an_error(method):
    """Strict contract: a misspelled option is refused by the class and by ``create``, never
    swallowed."""
    cls = integrators.METHODS[method]
    options = {"tolerance": 1e-8, "max_step": 0.1, "step": 1e-2}
    good = {k: v for k, v in options.items() if k in cls.OPTIONS}
    cls(_decay, 0.0, np.ones(2), **good)  # the declared options are accepted
    with pytest.raises(TypeError, match="tolerence"):
        cls(_decay, 0.0, np.ones(2), **good, tolerence=1e-8)
    with pytest.raises(TypeError, match="tolerence"):
        integrators.create(method, _decay, 0.0, np.ones(2), **options, tolerence=1e-8)
    itg = integrators.create(method, _decay, 0.0, np.ones(2), **options)  # others' options: passed over
    itg.step()
    assert itg.t > 0.0 and itg.nsteps == 1


def test_tableaux_equal_scipy_private_constants():
    """The constants read through SciPy's public classes (or written out for Radau) are bitwise
    SciPy's private ones the integrators used before."""
    from scipy.integrate._ivp import dop853_coefficients as D
    from scipy.integrate._ivp import radau as R
    c, n = integrators.Dop853, D.N_STAGES
    for ours, theirs in ((c.A, D.A[:n, :n]), (c.B, D.B), (c.C, D.C[:n]), (c.E3, D.E3), (c.E5, D.E5),
                         (c.D, D.D), (c.A_EXTRA, D.A[n + 1:]), (c.C_EXTRA, D.C[n + 1:])):
        assert np.array_equal(ours, theirs)
    assert (c.n_stages, c.N_STAGES_EXTENDED, c.INTERPOLATOR_POWER) == (n, D.N_STAGES_EXTENDED, D.INTERPOLATOR_POWER)
    r = integrators.Radau5
    for name in ("C", "E", "T", "TI", "P", "TI_REAL", "TI_COMPLEX", "MU_REAL", "MU_COMPLEX"):
        assert np.array_equal(getattr(r, name), getattr(R, name)), name


@pytest.mark.parametrize("h_lambda, stable", [(2.5, True), (2.78, True), (2.8, False), (10.0, False)])
def test_rk4_refuses_a_step_beyond_its_stability_boundary(h_lambda, stable):
    """y' = -lambda y: rk4's amplification |R(-h lambda)| exceeds 1 beyond h lambda = 2.785; the
    stage-based estimate of rho is exact for a linear problem, so the guard trips exactly there,
    names the time and a stable step, and the comparison can read that step."""
    from overcon.verdict import next_lockstep_step

    lam, h = 1000.0, h_lambda / 1000.0
    itg = integrators.RK4(lambda t, y: -lam * y, 0.0, np.array([1.0, 2.0]), step=h)
    if stable:
        for _ in range(5):
            itg.step()
        assert abs(itg.y[0]) <= 1.0  # damped
        return
    with pytest.raises(integrators.UnstableStep, match=r"t = 0 s: rk4 is unstable with the fixed step") as exc:
        itg.step()
    assert itg.t == 0.0 and itg.nsteps == 0  # the step is refused, the state kept
    assert exc.value.stable_step == pytest.approx(2.0 / lam, rel=1e-9)  # data: rho is exact here
    assert f"a step of at most {2.0 / lam:.2g} s is stable" in str(exc.value)  # and said to people
    assert next_lockstep_step(h, [exc.value.stable_step]) == pytest.approx(min(h / 4, 0.002), rel=0.5)
    assert next_lockstep_step(h, [exc.value.stable_step]) <= 2.0 / lam


def test_next_lockstep_step_takes_only_unstable_failures():
    from overcon.verdict import LOCKSTEP_MIN_STEP, next_lockstep_step

    assert next_lockstep_step(5e-3, [0.00087]) == pytest.approx(8e-4)
    assert next_lockstep_step(5e-3, [0.00087, None]) is None  # another failure: no retry
    assert next_lockstep_step(5e-3, [0.004]) == pytest.approx(1e-3)  # at most h/4
    assert next_lockstep_step(2e-6, [5e-7]) is None  # below LOCKSTEP_MIN_STEP
    assert next_lockstep_step(5e-3, []) is None
    assert LOCKSTEP_MIN_STEP == 1e-6


def test_lockstep_grid_is_the_one_retry_procedure():
    """Every variant on one grid; repeated at the step the failures name, at most
    LOCKSTEP_RETRIES times; a failure that is not an unstable step ends it; the note says why."""
    from overcon.verdict import LOCKSTEP_RETRIES, LockstepGrid

    grid = LockstepGrid(5e-3)
    assert grid.note is None
    assert grid.retry([3.3e-3, 3.4e-3]) and grid.step == pytest.approx(1e-3)
    assert grid.note == ("rk4 unstable at the lockstep step 0.005 s (a step of at most 0.0033 s is stable); "
                         "lockstep runs repeated at 0.001 s")
    assert not grid.retry([7e-4, None]) and grid.step == pytest.approx(1e-3)
    grid = LockstepGrid(1.0)
    assert [grid.retry([0.9]) for _ in range(LOCKSTEP_RETRIES + 1)] == [True] * LOCKSTEP_RETRIES + [False]
