"""The integration methods offered to scene files and FMUs (the C core's: overcon.kernel.Run), a
misspelled solver option refused, the implicit ``radau`` method on the stiff cases that stop the
explicit methods (sticking inside a small regularisation band), and the lockstep grid of the
comparison, which repeats rk4 runs at the stable step the core names. The accuracy, orders,
dense output, state round trips and stop reasons of the core's integrators: tests/test_core_integrators.py
and tests/test_core_integrate.py."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from overcon import kernel, scene, spec
from overcon.fmu.variables import rule
from overcon.checks import compile_checked

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
ALL = ("dopri5", "dop853", "rk4", "radau")


def setup(name, method, *, mu=None, stop_time=1.0, tolerance=1e-8, **solver):
    sc = scene.as_scene(scene.load(MECH / f"{name}.toml"), stop_time=stop_time, tolerance=tolerance)
    if mu is not None:
        sc = dataclasses.replace(sc, friction_params={k: dataclasses.replace(v, mu=mu)
                                                      for k, v in sc.friction_params.items()})
    return compile_checked(sc), dataclasses.replace(sc.solver, kernel="c", method=method, **solver)


def positions(model, ys):
    return np.asarray(ys)[:, [i for _, i in model.position_outputs]]


def test_every_method_is_offered_everywhere(tmp_path):
    """The scene's methods are the core's, the FMU parameter takes each, a scene file names one."""
    assert set(kernel.C_METHODS) == set(spec.METHODS) == set(ALL)
    for m in ALL:
        assert rule("solver.method").check(m) is None
    assert rule("solver.method").check("rk45") is not None
    text = (MECH / "planar_f45_wo4.toml").read_text().replace("[solver]", '[solver]\nmethod = "radau"')
    (tmp_path / "s.toml").write_text(text.replace('mechanism = "planar_sliders.toml"',
                                                  f'mechanism = "{(MECH / "planar_sliders.toml").as_posix()}"'))
    assert scene.load(tmp_path / "s.toml").solver.method == "radau"


def test_misspelled_solver_option_is_an_error(tmp_path):
    """Strict contract: a misspelled option in [solver] is refused, naming the file and the key,
    never swallowed."""
    text = (MECH / "planar_f45_wo4.toml").read_text().replace("[solver]", "[solver]\ntolerence = 1e-8")
    path = tmp_path / "s.toml"
    path.write_text(text.replace('mechanism = "planar_sliders.toml"',
                                 f'mechanism = "{(MECH / "planar_sliders.toml").as_posix()}"'))
    with pytest.raises(scene.SceneError, match="tolerence") as exc:
        scene.load(path)
    assert str(path) in str(exc.value)


def test_radau_agrees_with_explicit_methods_on_a_nonstiff_case():
    """planar_f45_wo4 over 2 s on a 10 ms grid: radau at 1e-8 within 1e-6 m of dop853 at 1e-11
    (30 tolerances, tests/test_core_integrators.py's GLOBAL bound, is 3e-7: a factor 3 more for
    the 2 s against that test's 0.5 s), on the constraints."""
    grid = np.arange(0.01, 2.0, 0.01)
    model, solver = setup("planar_f45_wo4", "dop853", stop_time=2.0, tolerance=1e-11)
    ref = kernel.Run(model, solver)
    want = positions(model, [ref.advance(t) for t in grid])
    run = kernel.Run(model, dataclasses.replace(solver, method="radau", tolerance=1e-8))
    got = positions(model, [run.advance(t) for t in grid])
    assert np.max(np.abs(got - want)) < 1e-6
    assert run.info["max_drift"] < 1e-8


def test_stiff_sticking_case_stops_dopri5_and_radau_integrates_it():
    """Planar friction in joints 1, 4, 5 with mu = 1: the sliders stick inside the regularisation
    band (stiffness mu N / (m v_reg) ~ 2e4 1/s). dopri5 stops with a stiffness report (status 9);
    radau runs through on the constraints, in fewer than 2000 evaluations, and its result
    converges with the tolerance (1e-8 against 1e-10: < 1e-7 m, under 30 tolerances of the looser
    run, tests/test_core_integrators.py's GLOBAL bound)."""
    model, solver = setup("planar_f145_wo6", "dopri5", mu=1.0)
    with pytest.raises(kernel.RunStopped, match="stiff") as exc:
        kernel.Run(model, solver).advance(1.0)
    assert exc.value.status == 9
    grid = np.arange(0.01, 1.0001, 0.01)
    runs = {tol: kernel.Run(model, dataclasses.replace(solver, method="radau", tolerance=tol)) for tol in (1e-8, 1e-10)}
    out = {tol: positions(model, [r.advance(t) for t in grid]) for tol, r in runs.items()}
    a = runs[1e-8].info
    assert np.all(np.isfinite(out[1e-8])) and a["max_drift"] < 1e-9
    assert np.max(np.abs(out[1e-8] - out[1e-10])) < 1e-7
    assert a["evaluations"] < 2000


def test_radau_failure_is_reported_with_time():
    """A right-hand side that cannot be evaluated (friction solve capped at 1 iteration) ends the
    run with the time and a reason, not with garbage."""
    model, solver = setup("planar_f45_wo4", "radau", mu=1.0, friction_max_iter=1)
    run = kernel.Run(model, solver)
    with pytest.raises(kernel.RunStopped, match=r"t = ") as exc:
        run.advance(1.0)
    assert exc.value.status != 0 and np.all(np.isfinite(run.y))


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
