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
