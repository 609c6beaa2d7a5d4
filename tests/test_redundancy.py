"""``[scene] redundancy = "min-norm"``: every equation kept, minimum-norm multipliers. It equals
the paper's elimination wherever the friction set is unique, and gives one motion where the
eliminations disagree."""
from __future__ import annotations

import dataclasses
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from overcon import scene
from overcon.checks import compile_checked
from overcon.cli import main
from overcon.kernel import support
from overcon.precheck import precheck
from overcon.simulate import run

MECH = Path(__file__).resolve().parents[1] / "mechanisms"
LOCKSTEP = '\n[solver]\nmethod = "rk4"\nstep = 0.005\n'


def _variant(tmp_path: Path, name: str, eliminate: str | None, stop: float = 2.0) -> Path:
    """The paper scene ``name`` on the lockstep grid, with ``eliminate`` (None: min-norm)."""
    text = (MECH / f"{name}.toml").read_text()
    text = re.sub(r"\[solver\][^\[]*", "", text).replace('mechanism = "', f'mechanism = "{MECH}/', 1)
    text = re.sub(r"^stop_time = .*$", f"stop_time = {stop}", text, flags=re.M)
    line = 'redundancy = "min-norm"' if eliminate is None else f"eliminate = {eliminate}"
    text = re.sub(r"^eliminate = .*$", line, text, flags=re.M)
    path = tmp_path / f"{name}_{'mn' if eliminate is None else 'e'}.toml"
    path.write_text(text + LOCKSTEP)
    return path


def _positions(path: Path):
    spec = scene.load(path)
    model = compile_checked(spec)
    res = run(model, spec.solver)
    # the compiled core ran every evaluation (nothing handed back to the numpy path)
    assert res.kernel_note.startswith("right-hand side: compiled kernel"), res.kernel_note
    cols = [i for i, n in enumerate(res.names) if n.rsplit(".", 1)[1] in ("x", "y", "z", "phi", "alpha", "beta", "gamma")]
    return model, res.values[:, cols]


@pytest.mark.parametrize("name, eliminate", [("planar_f45_wo4", "[4]"), ("spatial_MN_wo5", "[5]")])
def test_min_norm_equals_the_elimination_on_a_unique_friction_set(tmp_path, name, eliminate):
    """Identical rk4 steps, both in the compiled core: the two differ by round-off only, far below
    the issue's 1e-9 m."""
    model, mn = _positions(_variant(tmp_path, name, None))
    assert model.elimination_mode == "min-norm" and model.eliminated == () and len(model.retained) == model.m
    assert support(model) is None  # the core's rank-revealing solve (core/kkt_minnorm.c)
    _, el = _positions(_variant(tmp_path, name, eliminate))
    assert np.max(np.abs(mn - el)) <= 1e-9


def test_min_norm_gives_one_motion_where_the_eliminations_disagree(tmp_path, capsys):
    _, wo4 = _positions(_variant(tmp_path, "planar_f1_wo4", "[4]"))
    _, wo6 = _positions(_variant(tmp_path, "planar_f1_wo4", "[6]"))
    path = _variant(tmp_path, "planar_f1_wo4", None)
    _, mn = _positions(path)
    assert np.max(np.abs(wo4 - wo6)) > 0.1  # the paper's non-unique group
    assert np.max(np.abs(mn - wo4)) > 1e-3 and np.max(np.abs(mn - wo6)) > 1e-3  # a third motion
    _, again = _positions(path)
    assert np.array_equal(mn, again)
    assert main(["simulate", str(path), "--stop-time", "0.05", "--out", str(tmp_path / "o.csv")]) == 0
    err = capsys.readouterr().err
    assert ("this run uses the minimum-norm multipliers (redundancy = 'min-norm'): one motion, chosen without "
            "physical ground; the eliminations give others") in err
    assert main(["check", str(path)]) == 1
    assert "redundancy = 'min-norm': the runs use the minimum-norm multipliers" in capsys.readouterr().out


def test_redundancy_setting_is_checked(tmp_path):
    text = (MECH / "planar_f1_wo4.toml").read_text().replace('mechanism = "', f'mechanism = "{MECH}/', 1)
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("[scene]", '[scene]\nredundancy = "min_norm"', 1))
    with pytest.raises(scene.SceneError, match=r"scene.redundancy: unknown method 'min_norm' \(known: 'eliminate', "
                                               r"'min-norm', 'compliant'\)"):
        scene.load(bad)
    both = tmp_path / "both.toml"  # eliminate is kept and does not apply (a warning says so)
    both.write_text(text.replace("[scene]", '[scene]\nredundancy = "min-norm"', 1))
    model = compile_checked(scene.load(both))
    assert model.eliminated == () and model.elimination_mode == "min-norm"
    assert "scene.eliminate (Phi4) does not apply under redundancy = 'min-norm', which chooses the equations " \
           "itself" in precheck(model).warnings
    mn = _variant(tmp_path, "planar_f1_wo4", None)
    with pytest.raises(scene.SceneError, match=r"--eliminate: does not apply: the scene's redundancy is 'min-norm', "
                                               r"which chooses no elimination"):
        scene.as_scene(scene.load(mn), eliminate="4")


# ------------------------------------------------------------------ the compiled core against the numpy path

def states_along_a_run(model, solver, times=(0.0, 0.05, 0.1)):
    """States on the constraint manifold: the scene's own run at ``times`` (s)."""
    from overcon.simulate import Simulation
    sim = Simulation(model, solver)
    return [sim.advance(t) for t in times]


def constraint_residuals(model, solver, states, rows=None):
    """At each state: the core's evaluation (y', lam) and the relative residual of the
    acceleration constraint Phi_h h' = gamma - 2 a Phi_h h - a^2 Phi (Baumgarte, a =
    ``solver.baumgarte``; Phi, Phi_h, gamma from the core's rows) over ``rows`` (default all);
    returns [(y', lam, Phi_h, residual)]."""
    from overcon.kernel import Kernel, library, rows_at
    k = Kernel(library()[0], model, solver)
    a = solver.baumgarte
    out = []
    for y in states:
        got = k.evaluate(0.0, y)
        assert got is not None, k.last_message
        q, h = y[: model.n], y[model.n:]
        phi, J, gam = rows_at(model, q, h)
        hdot = got[0][model.n:]
        rhs = gam - 2.0 * a * (J @ h) - a * a * phi
        sel = slice(None) if rows is None else list(rows)
        res = float(np.max(np.abs((J @ hdot - rhs)[sel]), initial=0.0)) / max(1.0, float(np.max(np.abs(rhs[sel]), initial=0.0)))
        out.append((got[0], got[1], J, res))
    return out


@pytest.mark.parametrize("path", ["planar_f1_wo4.toml", "spatial_MN_wo5.toml", "examples/door_h1_wo_hinge2.toml",
                                  "examples/loop_A1_wo_A2.toml"])
def test_core_min_norm_gives_the_minimum_norm_multipliers(path):
    """Under min-norm every equation is kept: the accelerations satisfy all of them (Baumgarte's
    form, to 1e-9 relative), and the multipliers are the minimum-norm ones, with no component in
    the null space of Phi_h^T (the self-equilibrated reactions the redundancy allows: 1e-9 of
    |lam|). The motion equals the elimination's where friction is on unique joints:
    test_min_norm_equals_the_elimination_on_a_unique_friction_set."""
    import scipy.linalg
    spec = dataclasses.replace(scene.load(MECH / path), redundancy="min-norm", eliminate=())
    model = compile_checked(spec)
    assert support(model) is None and model.elimination_mode == "min-norm"
    for _, lam, J, res in constraint_residuals(model, spec.solver, states_along_a_run(model, spec.solver)):
        assert res <= 1e-9, res
        N = scipy.linalg.null_space(J.T, rcond=1e-9)
        assert N.shape[1] == model.m - np.linalg.matrix_rank(J, tol=1e-9 * np.linalg.norm(J, 2))
        assert float(np.max(np.abs(N.T @ lam), initial=0.0)) <= 1e-9 * max(1.0, float(np.max(np.abs(lam))))


def test_c_run_of_min_norm_needs_the_watch_rows(tmp_path):
    """A run in C under min-norm watches an independent set of the rows, chosen above the core's
    layer (overcon.kernel.watch_rows): without them it refuses to start, naming why; with them it
    runs, and keeps the constraints (the motion itself: test_min_norm_equals_the_elimination_...)."""
    from overcon.checks import watch_rows
    from overcon.kernel import Run, RunStopped
    spec = scene.load(_variant(tmp_path, "planar_f1_wo4", None, stop=0.3))
    solver = dataclasses.replace(spec.solver, method="dopri5")
    model = compile_checked(spec)
    with pytest.raises(RunStopped, match="no rows for the singularity watch under redundancy 'min-norm'"):
        Run(model, solver)
    c = Run(model, solver, watch=watch_rows(model))
    c.advance(0.3)
    assert c.info["nsteps"] > 0 and c.info["max_drift"] < 1e-8


# ------------------------------------------------------------------ the FMU parameter redundancy

fmpy = pytest.importorskip("fmpy")

from _fmpy_logger import simulate_logged  # noqa: E402
from test_fmu import Logs  # noqa: E402


def _fmu(path: Path, out: Path, runtime: str) -> Path:
    from overcon.fmu import build as fmu_build
    lines: list[str] = []
    code, results = fmu_build.build_all([str(path)], out, refs=False, allow_nonunique=True, runtime=runtime,
                                        echo=lines.append, echo_err=lines.append)
    assert code == 0, lines
    assert f"runtime {runtime})" in "\n".join(lines), lines  # the C runtime covers every method
    return results[0].fmu


def _fmu_scene(tmp_path: Path, eliminate: str | None) -> Path:
    """planar_f1_wo4 over 0.3 s with ``eliminate`` (None: redundancy = "min-norm", its eliminate
    = [4] kept, which does not apply then), its mechanism file next to it (an FMU carries it)."""
    shutil.copy(MECH / "planar_sliders.toml", tmp_path / "planar_sliders.toml")
    text = re.sub(r"^stop_time = .*$", "stop_time = 0.3", (MECH / "planar_f1_wo4.toml").read_text(), flags=re.M)
    line = 'redundancy = "min-norm"\neliminate = [4]' if eliminate is None else f"eliminate = {eliminate}"
    path = tmp_path / f"f1_{'mn' if eliminate is None else 'e'}.toml"
    path.write_text(re.sub(r"^eliminate = .*$", line, text, flags=re.M))
    return path


def _simulate(fmu: Path, **start):
    """The continuous outputs (not the pre-check's constants, the build's verdicts) over 0.3 s."""
    r = fmpy.simulate_fmu(str(fmu), stop_time=0.3, output_interval=0.01, start_values=start)
    return np.array([r[n] for n in r.dtype.names[1:] if not n.endswith("unique")])


def test_redundancy_parameter_runs_as_the_scene_key(tmp_path):
    """The paper's non-unique group (friction in joint 1, Phi4 eliminated): the FMU's parameter
    redundancy = 2 (min-norm) gives the run of the scene file with redundancy = "min-norm",
    bit for bit, and not the scene's own (the eliminations' and min-norm's motions differ)."""
    own = _fmu(_fmu_scene(tmp_path, "[4]"), tmp_path / "e", "c")
    keyed = _fmu(_fmu_scene(tmp_path, None), tmp_path / "mn", "c")
    mn = _simulate(keyed)
    assert np.array_equal(_simulate(own, redundancy=2), mn)
    assert np.max(np.abs(_simulate(own) - mn)) > 1e-3
    assert np.array_equal(_simulate(keyed, redundancy=1), _simulate(own))  # eliminate: the scene's key [4]


def test_compliant_is_refused_without_compliant_joints(tmp_path):
    fmu = _fmu(_fmu_scene(tmp_path, "[4]"), tmp_path / "e", "c")
    logs = Logs()
    with pytest.raises(Exception, match="fmi2SetInteger"):
        simulate_logged(fmu, logs, stop_time=0.05, start_values={"redundancy": 3})
    said = [m for _, _, m in logs.records]
    assert any("parameter redundancy = 3 refused: must be one of 1 (eliminate), 2 (min-norm), got 3 (3 (compliant) "
               "needs a joint with a [joints.compliance] table: mechanism planar_sliders has none)" in s
               for s in said), said
    md = fmpy.read_model_description(str(fmu))
    (var,) = [v for v in md.modelVariables if v.name == "redundancy"]
    assert (var.type, var.causality, var.variability, var.start) == ("Enumeration", "parameter", "fixed", "1")
    assert [i.name for i in var.declaredType.items] == ["eliminate", "min-norm", "compliant"]
