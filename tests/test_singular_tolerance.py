"""The error against the tolerance through singular positions (issue 40, item 2): the N-four-bar
(mechanisms/examples/nfourbar.py) with N = 2 and ``singular = "pass"`` over the benchmark's 20 s,
20 flat positions, B0's x (crank0.x + 0.5 cos(crank0.phi)) against the exact branch (every crank
at phi, I phi'' = -g c cos(phi), I = 3 kg m^2, c = 3.5 kg m; benchmarks/nfourbar.py's reference).
Near each flat position the run interpolates y' along the motion (core/sim_pass.c).
docs/benchmarks.md ("Error against tolerance through the singular positions") has the table and
what was measured of the cause."""
from __future__ import annotations

import dataclasses
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from overcon import kernel
from overcon import scene as scene_mod
from overcon.checks import compile_checked
from overcon.simulate import Simulation

ROOT = Path(__file__).resolve().parents[1]
G = 9.81
STOP = 20.0
TIMES = np.round(np.arange(1, int(round(STOP / 0.01)) + 1) * 0.01, 10)

pytestmark = pytest.mark.skipif(kernel.library()[0] is None, reason="singular = 'pass' runs on the compiled kernel")


def _model(tmp_path: Path):
    spec_ = importlib.util.spec_from_file_location("nfourbar", ROOT / "mechanisms" / "examples" / "nfourbar.py")
    gen = importlib.util.module_from_spec(spec_)
    spec_.loader.exec_module(gen)
    _, path = gen.write(2, tmp_path, stop_time=STOP, singular="pass")
    spec = scene_mod.as_scene(scene_mod.load(path))
    return compile_checked(spec), spec.solver


def _reference() -> np.ndarray:
    inertia, moment = 3.0, 3.5
    sol = solve_ivp(lambda t, y: [y[1], -G * moment * math.cos(y[0]) / inertia], (0.0, STOP), [math.pi / 2, -1.0],
                    t_eval=TIMES, rtol=1e-13, atol=1e-13, method="DOP853")
    return np.cos(sol.y[0])


def _b0_x(model, y) -> float:
    b = model.body_names.index("crank0")
    return float(y[3 * b] + 0.5 * math.cos(y[3 * b + 2]))


def _run(model, solver, method: str, tolerance: float, max_step: float | None = None) -> tuple[np.ndarray, Simulation]:
    solver = dataclasses.replace(solver, method=method, tolerance=tolerance)
    if max_step is not None:
        solver = dataclasses.replace(solver, max_step=max_step)
    sim = Simulation(model, solver, max_steps=200_000)
    return np.array([_b0_x(model, sim.advance(float(t))) for t in TIMES]), sim


@pytest.fixture(scope="module")
def nfourbar(tmp_path_factory):
    model, solver = _model(tmp_path_factory.mktemp("nfourbar2"))
    return model, solver, _reference()


TOLERANCES = (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)


@pytest.fixture(scope="module")
def errors(nfourbar):
    """B0's largest error over the 20 s for each method and tolerance, max_step 1 s (the largest
    allowed), so that the tolerance alone sets the steps: at the scene's 0.05 s dop853 takes only
    0.05 s steps at 1e-6 and 1e-7, and the two runs are the same. Each run passes all 20 flat
    positions, each once."""
    model, solver, ref = nfourbar
    out = {}
    for method in ("dop853", "dopri5"):
        for tol in TOLERANCES:
            x, sim = _run(model, solver, method, tol, max_step=1.0)
            assert sum(1 for e in sim.events if e[1] == "singular") == 20, (method, tol)
            out[method, tol] = float(np.max(np.abs(x - ref)))
    return out


@pytest.mark.parametrize("method", ["dop853", "dopri5"])
def test_the_error_falls_with_the_tolerance_through_the_flat_positions(errors, method):
    """Issue 40's acceptance: the error of B0's x over the 20 s falls at every step of the tolerance
    from 1e-6 to 1e-12, for both methods. Measured (docs/benchmarks.md): dop853 1.1e-3, 7.9e-5,
    9.6e-6, 8.5e-7, 8.4e-8, 7.2e-9, 1.1e-9 m; dopri5 6.3e-3, 6.2e-4, 6.2e-5, 6.1e-6, 5.5e-7, 5.5e-8,
    8.9e-9 m. Before the interpolation near the flat positions (core/sim_pass.c) both stayed between
    1e-6 and 3e-5 m below 1e-8."""
    series = [errors[method, tol] for tol in TOLERANCES]
    assert all(b < a for a, b in zip(series, series[1:])), series


@pytest.mark.parametrize("method", ["dop853", "dopri5"])
def test_the_error_is_within_1e_8_m_at_tolerance_1e_12(errors, method):
    """Issue 40's acceptance: at most 1e-8 m at 1e-12. Measured 1.1e-9 m (dop853) and 8.9e-9 m
    (dopri5). How far that holds: over seven tolerances within 0.5% of 1e-12, dop853 gives 4.5e-10
    to 7.4e-9 m (the round-off of the direct solves near the flat positions) and dopri5 4.7e-9 to
    8.9e-9 m, most of it dopri5's own error (5.5e-8 m at 1e-11: 11% below the bound at worst),
    docs/benchmarks.md."""
    assert errors[method, 1e-12] <= 1e-8, errors[method, 1e-12]


@pytest.mark.parametrize("saved_at", [0.7135, 0.7142, 0.7151])
def test_a_run_restored_near_a_flat_position_goes_on_bit_for_bit(nfourbar, saved_at):
    """A step's right-hand side (the direct solve, or the interpolation along the motion of
    core/sim_pass.c, from the watch's r at its start, and again interpolated where a stage refuses the
    direct solve: core/sim.c) changes around each flat position (near 0.714 s), and where it changes
    the first stage of the next step is evaluated again. Those decisions are taken from the saved
    state alone, and the interpolation depends on the state alone: a run restored before, inside
    and after the window goes on exactly as the run that was not interrupted."""
    model, solver, _ = nfourbar
    solver = dataclasses.replace(solver, method="dop853", tolerance=1e-10)
    sim = Simulation(model, solver)
    sim.advance(saved_at)
    state = sim.get_state()
    first = [sim.advance(t) for t in (0.716, 0.75, 1.3)]
    other = Simulation(model, solver)
    other.set_state(state)
    again = [other.advance(t) for t in (0.716, 0.75, 1.3)]
    for a, b in zip(first, again):
        assert np.array_equal(a, b)
    assert sim.steps == other.steps
