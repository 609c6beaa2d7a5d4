"""The compiled core's friction solve (core/friction.c, friction_robust.c): its Newton path gives
the solution of the paper's fixed point (the core's robust path, a different iteration, at the
same state), within a bound that follows from the friction tolerance, and each is a solution
(the law holds at its multipliers: tests/test_core_rows.py); warm starts at or near the solution.
The stages forced one by one: tests/test_core.py."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from overcon import scene as scene_mod
from overcon.checks import compile_checked

from test_core_rows import check_friction_at, equation_residuals
from test_kernel import kernel_for

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
SCENES = ["planar_f145_wo4", "planar_f45_wo6", "planar_f145_wo6", "spatial_GHMN_wo5", "spatial_GHMN_wo9", "spatial_MN_wo18"]


def scene_of(name):
    return scene_mod.as_scene(scene_mod.load(MECH / f"{name}.toml"))


def random_states(model, n, seed, scale):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield np.concatenate([model.q0 + scale * rng.standard_normal(model.n), 2.0 * rng.standard_normal(model.nh)])


def agree(got, ref, model, solver):
    """Two solutions of one evaluation: lam and h' within 1e3 tol (1 + |lam|), which leaves room
    for a contraction factor up to 0.999 (|x - x*| <= residual / (1 - L))."""
    R = list(model.retained)
    scale = 1.0 + float(np.max(np.abs(ref[1][R])))
    bound = 1e3 * solver.friction_tol * scale
    assert np.max(np.abs(got[1][R] - ref[1][R])) <= bound
    assert np.max(np.abs(got[0] - ref[0])) <= bound * float(np.max(model.Minv)) * 10.0


@pytest.mark.parametrize("name", SCENES)
def test_newton_solve_matches_fixed_point(name):
    """The analytic Newton path converges (undamped) in a few force evaluations, and the core's
    robust path (the Anderson fixed point, after both Newtons were made to give up) finds the
    same solution at the same state; both obey the friction law and the kept acceleration rows."""
    sc = scene_of(name)
    model = compile_checked(sc)
    k = kernel_for(model, sc.solver)
    compared = 0
    for y in random_states(model, 6, 6, 0.02):
        got = k.evaluate(0.0, y)
        if got is None or k.damped:  # (the state has no solution the Newton reaches: test_core.py)
            continue
        assert 1 <= got[3] <= 12
        try:  # the robust path runs only after both Newtons gave up: one force evaluation each
            k._cmodel.max_iter = 1
            assert k.evaluate(0.0, y) is None and k.last_status == 2
        finally:
            k._cmodel.max_iter = sc.solver.friction_max_iter
        ref = k.evaluate_robust(y)
        assert ref is not None, k.last_message
        agree(got, ref, model, sc.solver)
        for sol in (got, ref):
            _, acc, elim = equation_residuals(k, model, sc.solver, y, sol)
            assert acc <= 1e-9 and elim == 0.0
            check_friction_at(k, model, sc, y, sol, assembled=False)
        compared += 1
    assert compared >= 4, compared


def test_warm_start_at_the_solution_converges_at_once():
    """Warm-started from its own converged multipliers, or from its friction forces, the solve
    stops at the first check with the same solution."""
    sc = scene_of("spatial_MN_wo18")
    model = compile_checked(sc)
    k = kernel_for(model, sc.solver)
    for y in random_states(model, 3, 6, 0.02):
        got = k.evaluate(0.0, y)
        again = k.evaluate(0.0, y, lam_guess=got[1])
        assert again is not None and again[3] == 1
        agree(again, got, model, sc.solver)
        forces = k.evaluate(0.0, y, qf_guess=got[2])
        assert forces is not None and forces[3] == 1
        agree(forces, got, model, sc.solver)


def test_forces_warm_start_at_a_nearby_state():
    """qf_guess from a nearby state (h changed by 1e-3) is a valid start: the solution of a cold
    start, within the tolerance bound."""
    sc = scene_of("planar_f145_wo4")
    model = compile_checked(sc)
    k = kernel_for(model, sc.solver)
    for y in random_states(model, 4, 6, 0.02):
        cold = k.evaluate(0.0, y)
        near = y.copy()
        near[model.n:] *= 1 + 1e-3
        qf = k.evaluate(0.0, near)[2]
        warm = k.evaluate(0.0, y, qf_guess=qf)
        assert cold is not None and warm is not None and not k.damped
        agree(warm, cold, model, sc.solver)
