"""Simulation outputs: an output at the end of a step reuses that step's evaluation of Eq. 18
(no second solve), equal to a fresh solve of the compiled core within the friction tolerance;
an output inside a step equals a fresh solve there within the same tolerance; the position
outputs are the state's coordinates (quaternions normalised)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from overcon import kernel
from overcon import scene as scene_mod
from overcon.checks import compile_checked
from overcon.simulate import Simulation

MECH = Path(__file__).resolve().parent.parent / "mechanisms"


def setup(name, **changes):
    spec = scene_mod.as_scene(scene_mod.load(MECH / f"{name}.toml"), **changes)
    return compile_checked(spec), spec


def fresh_outputs(sim, model, spec, t, y):
    """The position outputs and the core's reactions and friction outputs from a cold solve of
    Eq. 18 at (t, y) (a Kernel of its own: no warm start), and the largest |lam|."""
    k = kernel.Kernel(kernel.library()[0], model, spec.solver)
    _, lam, _, _ = k.evaluate(t, y)
    reac, fric = k.outputs(y, lam)
    plan = kernel.output_plan(model)
    derived = [reac[a, b] if kind == kernel.OUT_KINDS["reaction"] else fric[a] for kind, a, b in plan.tolist()
               if kind in (kernel.OUT_KINDS["reaction"], kernel.OUT_KINDS["friction"])]
    return np.concatenate((sim.position_outputs(y), derived)), float(np.max(np.abs(lam)))


@pytest.mark.parametrize("name", ["planar_f145_wo4", "planar_none_wo6", "spatial_GHMN_wo5", "spatial_MN_wo18"])
def test_outputs_inside_a_step_equal_a_fresh_solve(name):
    """Inside a step the outputs come from a solve warm-started by the step ends' friction forces:
    the same solution as a cold solve within the friction solve's tolerance (both satisfy
    |G(x) - x| <= tol (1 + |x|); 1e3 covers the conditioning of the map from x to the outputs)."""
    model, spec = setup(name, stop_time=0.2)
    sim = Simulation(model, spec.solver)
    for t in (0.0123, 0.1, 0.1777):
        y = sim.advance(t)
        got = sim.outputs(t, y)
        want, lam = fresh_outputs(sim, model, spec, t, y)
        assert np.array_equal(got[: len(model.position_outputs)], want[: len(model.position_outputs)])
        assert np.max(np.abs(got - want)) <= 1e3 * spec.solver.friction_tol * (1.0 + lam)


def test_output_at_a_step_end_reuses_the_step_evaluation():
    """rk4 with 10 ms steps: at t = 0.05 s (a step end) outputs() takes lam from the step's last
    right-hand side (the evaluation count does not grow); a fresh solve there agrees within the
    friction solve's tolerance (both satisfy |G(x) - x| <= tol (1 + |x|))."""
    model, spec = setup("spatial_MN_wo5", stop_time=0.1)
    sim = Simulation(model, spec.solver, method="rk4", step=0.01)
    y = sim.advance(0.05)
    assert sim.t == 0.05
    n = sim.evaluations
    out = sim.outputs(0.05, y)
    assert sim.evaluations == n
    fresh, lam = fresh_outputs(sim, model, spec, 0.05, y)
    assert np.max(np.abs(out - fresh)) <= 1e3 * spec.solver.friction_tol * (1.0 + lam)
    state = sim.get_state()
    other = Simulation(model, spec.solver, method="rk4", step=0.01)
    other.set_state(state)
    assert np.array_equal(other.outputs(0.05, y), out)  # the reused evaluation is part of the state
