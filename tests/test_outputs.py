"""Simulation outputs: the batched reactions and friction forces equal the per-joint
functions of overcon.evaluation bit for bit, and an output at the end of a step reuses that
step's evaluation of Eq. 18 (no second solve), equal to a fresh solve within the friction
tolerance."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from overcon import scene as scene_mod
from overcon.dynamics import evaluate
from overcon.evaluation import frames, friction_output, physical_reaction
from overcon.checks import compile_checked
from overcon.simulate import Simulation

MECH = Path(__file__).resolve().parent.parent / "mechanisms"


def setup(name, **changes):
    spec = scene_mod.as_scene(scene_mod.load(MECH / f"{name}.toml"), **changes)
    return compile_checked(spec), spec


@pytest.mark.parametrize("name", ["planar_f145_wo4", "planar_none_wo6", "spatial_GHMN_wo5", "spatial_MN_wo18"])
def test_batched_outputs_equal_per_joint_functions(name):
    model, spec = setup(name)
    sim = Simulation(model, spec.solver)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = model.q0 + 0.02 * rng.standard_normal(model.n)
        h = rng.standard_normal(model.nh)
        ev = evaluate(model, 0.0, q, h, solver=spec.solver)
        f = frames(model, q, h)
        expected = [q[i] for _, i in model.position_outputs]
        for j in model.reaction_joints:
            expected.extend(physical_reaction(model, model.joints[j], f, ev.lam))
        expected.extend(friction_output(model, model.joints[j], f, ev.lam) for j in model.friction_outputs)
        got = np.concatenate((sim.position_outputs(np.concatenate([q, h])),
                              sim._derived.values(model, f, ev.lam)))
        assert np.array_equal(np.array(expected), got)


def test_output_at_a_step_end_reuses_the_step_evaluation():
    """rk4 with 10 ms steps: at t = 0.05 s (a step end) outputs() takes lam from the step's last
    right-hand side (the evaluation count does not grow); a fresh solve there agrees within the
    friction solve's tolerance (both satisfy |G(x) - x| <= tol (1 + |x|))."""
    model, spec = setup("spatial_MN_wo5", stop_time=0.1)
    sim = Simulation(model, spec.solver, method="rk4", step=0.01)
    y = sim.advance(0.05)
    assert sim.t == 0.05 and sim._last_eval[0] == 0.05
    n = sim.evaluations
    out = sim.outputs(0.05, y)
    assert sim.evaluations == n
    ev = evaluate(model, 0.05, y[: model.n], y[model.n:], solver=spec.solver)
    fresh = np.concatenate((sim.position_outputs(y), sim._derived.values(model, ev.frames, ev.lam)))
    scale = 1.0 + float(np.max(np.abs(ev.lam)))
    assert np.max(np.abs(out - fresh)) <= 1e3 * spec.solver.friction_tol * scale
    state = sim.get_state()
    other = Simulation(model, spec.solver, method="rk4", step=0.01)
    other.set_state(state)
    assert np.array_equal(other.outputs(0.05, y), out)  # the reused evaluation is part of the state


def test_forces_history_extrapolates_linearly():
    """The friction solve's warm start: exact for forces linear in time within twice the
    distance of the last two solves, the last forces beyond that; a solve at the same time
    replaces the newest entry (stages at one time); a round trip through the state is exact."""
    from overcon.simulate import _ForcesHistory

    hist = _ForcesHistory()
    assert hist.guess(0.0) is None
    hist.push(0.0, None)  # a solve without forces (the fallback path): nothing kept
    assert hist.guess(0.0) is None
    line = lambda t: np.array([1.0 + 2.0 * t, -3.0 * t])  # noqa: E731
    hist.push(0.0, line(0.0))
    assert np.array_equal(hist.guess(0.5), line(0.0))  # one entry: the last forces
    hist.push(0.25, line(0.25) + 1.0)
    hist.push(0.25, line(0.25))  # same time: replaces, keeps t = 0 as the older entry
    for t in (0.1, 0.3, 0.5):
        assert np.allclose(hist.guess(t), line(t), rtol=0, atol=1e-15)
    assert np.array_equal(hist.guess(0.8), line(0.25))  # more than twice the distance ahead
    other = _ForcesHistory()
    other.set_state(hist.state())
    assert np.array_equal(other.guess(0.4), hist.guess(0.4))
