"""What ``compare`` says (issue 37, items 5 and 6), on hand-made comparisons and runs (no FMU):
the summary's figure names its measure and unit (the deciding output farthest over its tolerance,
not the largest absolute difference), the adaptive runs' figure is given per unit, report.md
follows the same rule, and a lockstep run that rk4 found unstable is announced as repeated at the
smaller step, not as FAILED."""
from __future__ import annotations

from pathlib import Path

from overcon.tooling import SimulationFailed
from overcon.tooling import pipeline
from overcon.tooling.compare import Comparison, OutputDiff
from overcon.tooling.fmus import FmuInfo, Output
from overcon.tooling.report import summary_rows, verdict_line
from overcon.tooling.run import Experiment


def _info(model: str, elim: int) -> FmuInfo:
    outputs = (Output("crank.phi", "rad", "position"), Output("rod.phi", "rad", "position"),
               Output("slider.x", "m", "position"))
    return FmuInfo(Path(f"/x/{model}.fmu"), model, 0.0, 1.0, 0.01, 1e-9, outputs, "g", f"without eq. {elim}",
                   mechanism="m", friction=("j1",), eliminate=(elim,), motion_unique=False, lockstep=True)


def _comparison() -> Comparison:
    """crank.phi differs by 17.2 rad under a loose tolerance, rod.phi by 0.679 rad under a tight
    one: rod.phi is the deciding output farthest over its tolerance."""
    diffs = [OutputDiff("crank.phi", "rad", "position", True, 1.0, 20.0, 17.2, 0.9, 0.1),
             OutputDiff("rod.phi", "rad", "position", True, 1e-8, 1.0, 0.679, 0.7, 0.2),
             OutputDiff("slider.x", "m", "position", True, 1e-8, 1.0, 0.031, 0.03, 0.3)]
    infos = [_info("a", 4), _info("b", 6)]
    return Comparison("g", [i.label for i in infos], infos, [], diffs, False, None, None, mode="lockstep",
                      lockstep_step=5e-3, adaptive_diff={"crank.phi": 12.5, "rod.phi": 0.5, "slider.x": 0.02})


def test_the_summary_names_its_measure_and_units():
    line = verdict_line(_comparison())
    assert ("largest difference relative to its tolerance (lockstep): 0.679 rad in rod.phi (tolerance 1e-08 rad); "
            "adaptive runs' largest difference (not deciding): 0.02 m in slider.x, 12.5 rad in crank.phi") in line, line


def test_report_md_uses_the_same_rule():
    head, _, row = summary_rows([_comparison()])
    assert "largest difference relative to its tolerance (output, tolerance, runs)" in head
    assert "adaptive runs' largest difference per unit" in head
    assert "| 0.679 rad (rod.phi, 1e-08 rad, lockstep) | 0.02 m in slider.x, 12.5 rad in crank.phi |" in row, row


def test_a_lockstep_run_repeated_at_a_smaller_step_is_not_called_failed(tmp_path, monkeypatch):
    """rk4 unstable at 5 ms (it names 1 ms): both lockstep runs are repeated at 1 ms, said so; they
    fail again there (no stable step named: not repeated), and only then are they FAILED."""
    infos = [_info("a", 4), _info("b", 6)]
    calls = []

    def fake_run_jobs(jobs, *, workers=2, progress=True, timeout=None, echo=None, announce_failures=True):
        calls.append(([j.key for j in jobs], announce_failures))
        first = len(calls) == 1
        return {}, {j.key: SimulationFailed(f"{j.key} stopped", 1e-3 if first and j.key.startswith("lockstep/")
                                            else None) for j in jobs}

    monkeypatch.setattr(pipeline, "run_jobs", fake_run_jobs)
    lines = []
    exps = {i.model: Experiment(0.0, 1.0, 0.01) for i in infos}
    comparisons, _ = pipeline._run_and_compare({"g": infos}, exps, tmp_path, jobs=1, lockstep_step=5e-3,
                                               tolerance=None, echo=lines.append)
    assert [announce for _, announce in calls] == [False, False]
    assert sorted(calls[1][0]) == ["lockstep/a", "lockstep/b"]
    repeated = [ln for ln in lines if "repeated at step" in ln]
    assert sorted(repeated) == ["lockstep/a: repeated at step 0.001 s (rk4 unstable at 0.005 s)",
                                "lockstep/b: repeated at step 0.001 s (rk4 unstable at 0.005 s)"]
    failed = [ln for ln in lines if ln.endswith("FAILED (reason below)")]
    assert sorted(failed) == ["a: FAILED (reason below)", "b: FAILED (reason below)",
                              "lockstep/a: FAILED (reason below)", "lockstep/b: FAILED (reason below)"]
    # the repetition is said before the runs that failed for good
    assert lines.index(repeated[0]) < lines.index("lockstep/a: FAILED (reason below)")
    (c,) = comparisons
    assert c.failure is not None and "lockstep/a stopped" in c.failure
