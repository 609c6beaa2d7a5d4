"""Output points of a run: every point inside the step at whose end the elimination is chosen
again comes from the step that was accepted (issue 37 item 1), in process and in the FMU."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from overcon import scene as scene_mod
from overcon.checks import compile_checked
from overcon.simulate import run

ROOT = Path(__file__).resolve().parents[1]
BRICARD = ROOT / "tests" / "data" / "bricard"


def _bricard(tmp_path: Path, which: str, stop_time: float = 1.5) -> Path:
    """Bricard's scene ``which`` (wo2: Phi2 eliminated; auto) at tolerance 1e-9, output every 5 ms."""
    text = (BRICARD / f"bricard_{which}.toml").read_text()
    (tmp_path / "bricard.toml").write_text((BRICARD / "bricard.toml").read_text())
    text = text.replace("stop_time = 10.0", f"stop_time = {stop_time!r}")
    text = text.replace("tolerance = 1e-10", "tolerance = 1e-9").replace("output_interval = 0.01", "output_interval = 0.005")
    path = tmp_path / f"bricard_{which}.toml"
    path.write_text(text)
    return path


def _positions(res) -> tuple[list[str], np.ndarray]:
    names = [n for n in res.names if n.startswith("rod")]
    return names, res.values[:, [res.names.index(n) for n in names]]


@pytest.mark.parametrize("method", ["dopri5", "dop853"])
def test_rows_inside_the_reselected_step_follow_the_accepted_trajectory(tmp_path, method):
    """Bricard with Phi2 eliminated, tolerance 1e-9, output every 5 ms: the elimination is chosen
    again at t = 1.208 s, at the end of a step that contains the output point t = 1.205 s. That
    row, like every other, is within 1e-8 m of the run under ``auto`` (the row was the state at
    the step's end, 5.2e-3 m off, when the restart dropped the step's dense output)."""
    given = scene_mod.as_scene(scene_mod.load(_bricard(tmp_path, "wo2")), solver={"method": method})
    auto = scene_mod.as_scene(scene_mod.load(_bricard(tmp_path, "auto")), solver={"method": method})
    res, ref = run(compile_checked(given), given.solver), run(compile_checked(auto), auto.solver)
    assert [kind for _, kind, _ in res.events] == ["elimination-reselected"] and not ref.events
    t_event = res.events[0][0]
    assert np.array_equal(res.time, ref.time)
    inside = (res.time > t_event - 0.02) & (res.time < t_event)  # rows of the last steps before the choice
    assert inside.sum() >= 3
    names, got = _positions(res)
    _, want = _positions(ref)
    worst = np.max(np.abs(got - want), axis=1)
    assert np.max(worst) <= 1e-8, (res.time[np.argmax(worst)], np.max(worst))


def test_rows_inside_the_reselected_step_in_the_fmu(tmp_path):
    """The same through the C FMU (co-simulation, a communication step of 5 ms): every output
    within 1e-8 m of the in-process run under ``auto``."""
    fmpy = pytest.importorskip("fmpy")
    from overcon.fmu import build as fmu_build

    path = _bricard(tmp_path, "wo2")
    lines: list[str] = []
    code, results = fmu_build.build_all([str(path)], tmp_path / "out", refs=False, allow_nonunique=True, runtime="c",
                                        echo=lines.append, echo_err=lines.append)
    assert code == 0, lines
    auto = scene_mod.as_scene(scene_mod.load(_bricard(tmp_path, "auto")))
    ref = run(compile_checked(auto), auto.solver)
    got = fmpy.simulate_fmu(str(results[0].fmu), stop_time=1.5, output_interval=0.005)
    assert np.allclose(got["time"], ref.time, rtol=0, atol=1e-12)
    names, want = _positions(ref)
    worst = np.max(np.abs(np.column_stack([got[n] for n in names]) - want), axis=1)
    assert np.max(worst) <= 1e-8, (ref.time[np.argmax(worst)], np.max(worst))


# ------------------------------------------------------------------------ the grid in the core
MECH = ROOT / "mechanisms"


def _spec(name: str, **kw):
    return scene_mod.as_scene(scene_mod.load(MECH / f"{name}.toml"), **kw)


@pytest.mark.parametrize("name", ["planar_f45_wo4", "spatial_MN_wo5", "examples/door_h1_wo_hinge2"])
def test_grid_rows_equal_the_point_by_point_outputs(name):
    """The whole grid computed inside the core (run, ovk_sim_grid) gives, bit for bit, the rows of
    advance() and outputs() point by point (ovk_sim_advance, ovk_sim_output_row): positions
    (quaternions normalised), reactions, friction forces, energies."""
    from overcon.simulate import Simulation, output_grid
    spec = _spec(name, stop_time=0.3)
    model = compile_checked(spec)
    res = run(model, spec.solver)
    sim = Simulation(model, spec.solver)
    grid = output_grid(spec.start_time, 0.3, spec.solver.output_interval)
    rows = np.array([sim.outputs(t, sim.advance(t)) for t in grid])
    assert res.values.shape == (len(grid), len(model.output_names()))
    assert np.array_equal(res.values, rows)
    assert sim.steps == res.steps and sim.evaluations == res.evaluations


def test_a_stopped_grid_keeps_its_rows(tmp_path):
    """A run stopped by its work budget: the SimulationError's partial result holds the rows
    computed before the stop, equal to an unstopped run's first rows."""
    from overcon.simulate import BudgetExceeded
    spec = _spec("planar_f45_wo4", stop_time=1.0)
    model = compile_checked(spec)
    full = run(model, spec.solver)
    with pytest.raises(BudgetExceeded) as exc:
        run(model, spec.solver, max_steps=full.steps // 2)
    part = exc.value.partial
    assert 0 < len(part.time) < len(full.time)
    assert np.array_equal(part.values, full.values[: len(part.time)])
    assert not np.isnan(part.values).any()


def test_grid_refuses_a_bad_plan_and_bad_times():
    """Numbers from outside are checked before they index: an output of another kind or out of
    range and times that go back are refused with a message naming them; the run is untouched."""
    from overcon import kernel
    from overcon.simulate import Simulation, SimulationError
    spec = _spec("planar_f45_wo4", stop_time=0.1)
    model = compile_checked(spec)
    sim = Simulation(model, spec.solver)
    for plan, match in (([(4, 0, 0)], r"output plan: output 0 \(kind 4"),
                        ([(kernel.OUT_KINDS["position"], model.n, 0)], r"output plan: output 0"),
                        ([(kernel.OUT_KINDS["reaction"], 0, 9)], r"output plan: output 0")):
        with pytest.raises(kernel.RunStopped, match=match):
            sim._run.output_row(0.0, np.concatenate([model.q0, model.h0]), np.array(plan))
        _, rows, stop = sim.grid(np.array([0.01]), np.array(plan))
        assert rows == 0 and isinstance(stop, SimulationError) and "output plan" in str(stop)
    _, rows, stop = sim.grid(np.array([0.02, 0.01]))
    assert rows == 0 and "not after the one before" in str(stop)
    assert sim.t == 0.0 and sim.steps == 0
    values, rows, stop = sim.grid(np.array([0.01, 0.02]))
    assert stop is None and rows == 2 and values.shape == (2, len(model.output_names()))
    _, rows, stop = sim.grid(np.array([-1.0]))
    assert rows == 0 and "before the run's last step" in str(stop)
