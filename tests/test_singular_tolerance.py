"""The error against the tolerance through singular positions (issue 40, item 2): the N-four-bar
(mechanisms/examples/nfourbar.py) with N = 2 and ``singular = "pass"`` over the benchmark's 20 s,
20 flat positions, B0's x (crank0.x + 0.5 cos(crank0.phi)) against the exact branch (every crank
at phi, I phi'' = -g c cos(phi), I = 3 kg m^2, c = 3.5 kg m; benchmarks/nfourbar.py's reference).
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


def _run(model, solver, method: str, tolerance: float) -> tuple[np.ndarray, Simulation]:
    sim = Simulation(model, dataclasses.replace(solver, method=method, tolerance=tolerance), max_steps=200_000)
    return np.array([_b0_x(model, sim.advance(float(t))) for t in TIMES]), sim


@pytest.fixture(scope="module")
def nfourbar(tmp_path_factory):
    model, solver = _model(tmp_path_factory.mktemp("nfourbar2"))
    return model, solver, _reference()


@pytest.mark.parametrize("method", ["dop853", "dopri5"])
def test_every_tolerance_passes_the_20_flat_positions_within_the_measured_floor(nfourbar, method):
    """Tolerances 1e-9, 1e-10 and 1e-12: all 20 flat positions passed, each once, and B0's x within
    5e-5 m of the branch over the 20 s. Measured (docs/benchmarks.md): at most 2.7e-5 m; the error
    that the passages leave is about 1e-5 m whatever the tolerance (the next test), and dopri5 at
    1e-8 is above it by its own error (6.3e-5 m, ten times less per decade of the tolerance)."""
    model, solver, ref = nfourbar
    for tolerance in (1e-9, 1e-10, 1e-12):
        x, sim = _run(model, solver, method, tolerance)
        assert sum(1 for e in sim.events if e[1] == "singular") == 20, (method, tolerance)
        assert np.max(np.abs(x - ref)) <= 5e-5, (method, tolerance, float(np.max(np.abs(x - ref))))


@pytest.mark.xfail(strict=True, reason="issue 40 item 2 is not met: each passage loses about 1e-7 J to the "
                   "step-end velocity projection whatever the tolerance (docs/benchmarks.md, 'Error against "
                   "tolerance through the singular positions')")
@pytest.mark.parametrize("method", ["dop853", "dopri5"])
def test_the_error_falls_with_the_tolerance_through_the_flat_positions(nfourbar, method):
    """Issue 40's acceptance: the error of B0's x over the 20 s falls at every step of the tolerance
    from 1e-6 to 1e-12 and is at most 1e-8 m at 1e-12 (strict xfail: a fix makes it pass, and the
    marker must then go)."""
    model, solver, ref = nfourbar
    errors = [float(np.max(np.abs(_run(model, solver, method, tol)[0] - ref)))
              for tol in (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12)]
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] <= 1e-8, errors


@pytest.mark.parametrize("saved_at", [0.7135, 0.7142, 0.7151])
def test_a_run_restored_near_a_flat_position_goes_on_bit_for_bit(nfourbar, saved_at):
    """The acceleration solve of a step (direct or AL, from the watch's r: core/sim.c) changes twice
    around each flat position (0.7139 and 0.7151 s at tolerance 1e-10), and where it changes the
    first stage of the next step is evaluated again under the new solve. That decision is taken
    from the saved state alone: a run restored before, inside and after the AL's window goes on
    exactly as the run that was not interrupted."""
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
