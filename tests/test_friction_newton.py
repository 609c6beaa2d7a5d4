"""The friction solve's Newton path (overcon.dynamics): the joint modules' analytic
``friction_jacobian`` against finite differences, the friction laws' ``mu_over_speed_slope``
against finite differences, and the solve itself against the paper's fixed point (written with
the per-joint reference functions): the same solution within a bound that follows from the
friction tolerance, for the analytic Jacobian, for a joint type without one (finite
differences) and through the fixed-point fallback."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import reference_joints as ref
from overcon import dynamics
from overcon import scene as scene_mod
from overcon.evaluation import applied_forces, frames
from overcon.friction_laws import make_law
from overcon.checks import compile_checked
from overcon.spec import FrictionSpec

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
SCENES = ["planar_f145_wo4", "planar_f45_wo6", "planar_f145_wo6", "spatial_GHMN_wo5", "spatial_GHMN_wo9", "spatial_MN_wo18"]


def scene_of(name):
    return scene_mod.as_scene(scene_mod.load(MECH / f"{name}.toml"))


def random_states(model, n, seed, scale):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield model.q0 + scale * rng.standard_normal(model.n), 2.0 * rng.standard_normal(model.nh)


@pytest.mark.parametrize("name", SCENES)
def test_friction_jacobian_matches_central_differences(name):
    """d(Qi, Qj)/d lam of every friction joint type with a friction_jacobian, at random states
    and multipliers: central differences (step 1e-6 max(1, |lam|) N) agree to 1e-7 relative."""
    model = compile_checked(scene_of(name))
    rng = np.random.default_rng(11)
    checked = 0
    for q, h in random_states(model, 8, 12, 0.3):
        f = frames(model, q, h)
        for g in model.plan.friction:
            cx = g.module.friction_setup(g.data, f)
            lam = 50.0 * rng.standard_normal(g.x_index.shape)
            dQi, dQj = g.module.friction_jacobian(g.data, cx, lam)
            step = 1e-6 * max(1.0, float(np.abs(lam).max()))
            for c in range(lam.shape[1]):
                lp, lm = lam.copy(), lam.copy()
                lp[:, c] += step
                lm[:, c] -= step
                (Pi, Pj), (Mi, Mj) = g.module.friction(g.data, cx, lp), g.module.friction(g.data, cx, lm)
                for fd, an in (((Pi - Mi) / (2 * step), dQi[..., c]), ((Pj - Mj) / (2 * step), dQj[..., c])):
                    assert np.max(np.abs(fd - an)) <= 1e-7 * max(1.0, float(np.max(np.abs(fd))))
                    checked += 1
    assert checked > 0


@pytest.mark.parametrize("kw", [{"law": "regularised"}, {"law": "stribeck", "mu_static": 0.5, "v_stribeck": 2e-3}])
def test_mu_over_speed_slope_matches_differences(kw):
    law = make_law(FrictionSpec(mu=0.3, size=0.1, v_reg=1e-3, **kw))
    for s in (2e-4, 7e-4, 1.5e-3, 3e-3, 0.2, 4.0):
        d = 1e-6 * s
        fd = (law.mu_over_speed(s + d) - law.mu_over_speed(s - d)) / (2 * d)
        assert abs(fd - law.mu_over_speed_slope(s)) <= 1e-6 * max(1.0, abs(fd))


def reference_solution(model, solver, q, h):
    """The paper's fixed point with the per-joint reference functions and scipy's Cholesky,
    iterated to 1e-3 of the solver's friction tolerance: (lam_R, hdot)."""
    from scipy.linalg import cho_factor, cho_solve

    f = frames(model, q, h)
    R = model.retained
    Phi_h = ref.jacobian(model, f)
    JR = Phi_h[R].T
    a = solver.baumgarte
    g = ref.gamma(model, f)[R] - 2.0 * a * (Phi_h[R] @ h) - a * a * ref.constraints(model, f)[R]
    Q = applied_forces(model, f)
    MinvJ = model.Minv[:, None] * JR
    factor = cho_factor(JR.T @ MinvJ)
    lam0 = cho_solve(factor, MinvJ.T @ Q - g)

    def full(lr):
        out = np.zeros(model.m)
        out[R] = lr
        return out

    def G(lr):
        return lam0 + cho_solve(factor, MinvJ.T @ ref.friction_generalized(model, f, full(lr)))

    lr, _, ok = dynamics._fixed_point(G, lam0.copy(), dynamics_xrows(model), 1e-3 * solver.friction_tol, 1000)
    if not ok:
        lr, _, ok = dynamics._newton(G, lr, dynamics_xrows(model), 1e-3 * solver.friction_tol, 1000)
    if not ok:
        return None
    Qf = ref.friction_generalized(model, f, full(lr))
    return lr, model.Minv * (Q + Qf - JR @ lr)


def dynamics_xrows(model):
    pos = {row: k for k, row in enumerate(model.retained)}
    return [pos[r] for j in model.friction_joints for r in model.joints[j].rows if r in pos]


def agree(ev, expected, model, solver):
    """evaluate()'s lam and h' against the reference solution: both solve the same fixed point,
    the reference to 1e-3 tol; the bound 1e3 tol (1 + |lam|) leaves room for a contraction
    factor up to 0.999 (|x - x*| <= residual / (1 - L))."""
    lr, hdot = expected
    scale = 1.0 + float(np.max(np.abs(lr)))
    bound = 1e3 * solver.friction_tol * scale
    assert np.max(np.abs(ev.lam[model.retained] - lr)) <= bound
    assert np.max(np.abs(ev.hdot - hdot)) <= bound * float(np.max(model.Minv)) * 10.0


def cases(name, n=6):
    sc = scene_of(name)
    model = compile_checked(sc)
    out = []
    for q, h in random_states(model, n, 6, 0.02):
        expected = reference_solution(model, sc.solver, q, h)
        if expected is not None:
            out.append((q, h, expected))
    assert out
    return model, sc.solver, out


@pytest.mark.parametrize("name", SCENES)
def test_newton_solve_matches_fixed_point(name):
    """The analytic Newton path converges (no fallback) in a few force evaluations and gives
    the fixed point's solution."""
    model, solver, states = cases(name)
    for q, h, expected in states:
        ev = dynamics.evaluate(model, 0.0, q, h, solver=solver)
        assert not ev.fallback and 1 <= ev.iterations <= dynamics.NEWTON_MAX_ITER
        agree(ev, expected, model, solver)


@pytest.mark.parametrize("name", ["planar_f145_wo4", "spatial_GHMN_wo5"])
def test_joint_type_without_friction_jacobian_uses_differences(name, monkeypatch):
    """A joint module without the optional friction_jacobian (a new type): forward differences
    of its friction forces give the Newton matrix; same solution."""
    model, solver, states = cases(name)
    for g in model.plan.friction:
        monkeypatch.delattr(g.module, "friction_jacobian")
    for q, h, expected in states:
        ev = dynamics.evaluate(model, 0.0, q, h, solver=solver)
        assert not ev.fallback
        agree(ev, expected, model, solver)


@pytest.mark.parametrize("name", ["planar_f145_wo4", "spatial_GHMN_wo5"])
def test_damped_newton_when_newton_gives_up(name, monkeypatch):
    """Newton limited to one force evaluation cannot converge from lam0: the damped Newton solve
    takes over from the same start, flagged (not the fixed-point fallback), same solution."""
    model, solver, states = cases(name)
    monkeypatch.setattr(dynamics, "NEWTON_MAX_ITER", 1)
    damped = 0
    for q, h, expected in states:
        ev = dynamics.evaluate(model, 0.0, q, h, solver=solver)
        damped += ev.damped
        assert not ev.fallback
        agree(ev, expected, model, solver)
    assert damped > 0


@pytest.mark.parametrize("name", ["planar_f145_wo4", "spatial_GHMN_wo5"])
def test_fixed_point_fallback_when_newton_gives_up(name, monkeypatch):
    """Both Newton solves limited to one force evaluation cannot converge from lam0: the robust
    path (Anderson fixed point, then finite-difference Newton) takes over, flagged, same solution."""
    model, solver, states = cases(name)
    monkeypatch.setattr(dynamics, "NEWTON_MAX_ITER", 1)
    monkeypatch.setattr(dynamics, "DAMPED_MAX_ITER", 1)
    fell_back = 0
    for q, h, expected in states:
        ev = dynamics.evaluate(model, 0.0, q, h, solver=solver)
        fell_back += ev.fallback
        agree(ev, expected, model, solver)
    assert fell_back > 0


def test_warm_start_at_the_solution_converges_at_once():
    """Warm-started from its own converged multipliers, the solve stops at the first check."""
    model, solver, states = cases("spatial_MN_wo18", n=3)
    for q, h, _ in states:
        ev = dynamics.evaluate(model, 0.0, q, h, solver=solver)
        again = dynamics.evaluate(model, 0.0, q, h, ev.lam, solver=solver)
        assert again.iterations == 1 and not again.fallback
        assert np.max(np.abs(again.lam - ev.lam)) <= 1e3 * solver.friction_tol * (1 + np.max(np.abs(ev.lam)))
        forces = dynamics.evaluate(model, 0.0, q, h, solver=solver, qf_guess=ev.qf)  # the forces' warm start
        assert forces.iterations == 1 and not forces.fallback
        assert np.max(np.abs(forces.lam - ev.lam)) <= 1e3 * solver.friction_tol * (1 + np.max(np.abs(ev.lam)))


def test_forces_warm_start_at_a_nearby_state():
    """qf_guess from a nearby state (h changed by 1e-3) is a valid start: same solution as a
    cold start, within the tolerance bound."""
    model, solver, states = cases("planar_f145_wo4", n=4)
    for q, h, expected in states:
        near = dynamics.evaluate(model, 0.0, q, h * (1 + 1e-3), solver=solver)
        ev = dynamics.evaluate(model, 0.0, q, h, solver=solver, qf_guess=near.qf)
        assert not ev.fallback
        agree(ev, expected, model, solver)
