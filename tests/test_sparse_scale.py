"""Memory that grows with the nonzeros (issue 40): the core holds Phi_h by its nonzeros (each
equation on its joint's two bodies, core/core.h OVK_JROW), a run allocates the watch's dense
whole-Jacobian scratch only on the rare paths that factorise it (core/sim.c ovk_sim_dense), so
mechanisms far beyond the former 1000-body/1000-joint limits are checked and run: a coupler on
999 parallel cranks (1000 bodies, 1998 joints) is checked with its exact rank, and a 10,000-body
chain is checked and runs 1 s within 500 MB (peak resident size of a subprocess that does only
that). Figures and limits: docs/limits.md."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from overcon import scene
from overcon.cli import main
from test_precheck_methods import linkage

ROOT = Path(__file__).resolve().parents[1]
PEAK_MB = 500.0


def test_check_of_999_parallel_cranks_gives_the_exact_rank(tmp_path, capsys):
    """1000 bodies (a coupler and 999 cranks), 1998 revolute joints, 3996 equations on 3000
    coordinates: 999 - 2 = 997 of them redundant, so rank 2999 and one degree of freedom."""
    path = linkage(np.random.default_rng(1000), "planar", "cranks", 1000, tmp_path / "cranks.toml")
    assert main(["check", str(path), "--json", "--friction", "none"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["n_coordinates"], report["rank"], report["dof"]) == (3000, 2999, 1)
    assert len(report["joints"]) == 1998 and report["methods_run"] == ["svd"]
    assert len(report["eliminated"]) == 997  # the redundant equations the elimination removes
    assert report["problems"] == []


CHILD = textwrap.dedent("""
    import contextlib, io, json, resource, sys
    from pathlib import Path
    sys.path.insert(0, {tests!r})
    from test_robust import chain
    from overcon import scene
    from overcon.checks import compile_checked
    from overcon.cli import main
    from overcon.simulate import Simulation
    def peak_kb():  # this program's own peak (VmHWM); ru_maxrss would count the forking parent's too
        with open("/proc/self/status") as f:
            return int(next(l for l in f if l.startswith("VmHWM")).split()[1])
    out = Path({tmp!r})
    path = chain(10_000, out / "chain.toml")
    report = io.StringIO()
    with contextlib.redirect_stdout(report):
        code = main(["check", str(path), "--json", "--friction", "none"])
    (out / "check.json").write_text(report.getvalue())
    (out / "scene.toml").write_text("\\n".join([
        "[scene]", 'name = "chain10k"', 'mechanism = "chain.toml"', "friction = []", 'eliminate = "auto"', "stop_time = 1.0",
        "[outputs]", 'positions = ["b0.phi"]', "[solver]", "tolerance = 1e-6", ""]))
    spec = scene.as_scene(scene.load(out / "scene.toml"))
    sim = Simulation(compile_checked(spec), spec.solver)
    y = sim.advance(1.0)
    print(json.dumps({{"code": code, "t": sim.t, "wall": sim.info["wall_time"], "evaluations": sim.evaluations, "drift": sim.max_drift, "steps": sim.steps,
                      "y_finite": bool(all(v == v for v in y)),
                      "peak_mb": peak_kb() / 1024}}))
""")


def test_10000_body_chain_checks_and_runs_1_s_within_500_mb(tmp_path):
    """The pre-check and a 1 s run of a 10,000-body planar chain (30,000 coordinates, 20,000
    equations: a dense Phi_h alone would be 4.8 GB) in one subprocess whose peak resident size is
    bounded."""
    code = CHILD.format(tests=str(ROOT / "tests"), tmp=str(tmp_path))
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    res = json.loads(run.stdout.strip().splitlines()[-1])
    report = json.loads((tmp_path / "check.json").read_text())
    assert res["code"] == 0 and report["problems"] == []
    assert (report["n_coordinates"], report["rank"], report["dof"]) == (30_000, 20_000, 10_000)
    assert res["t"] >= 1.0 and res["y_finite"] and res["steps"] > 0
    assert res["drift"] < 1e-5  # m: the constraints held (links of 1 m)
    assert res["peak_mb"] <= PEAK_MB, res
    assert scene.MAX_BODIES >= 10_000 and scene.MAX_JOINTS >= 10_000
