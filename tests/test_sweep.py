"""``overcon sweep``: parameter grids on Dask. Local clusters of 2 worker processes, the planar
friction-1 group (friction on joint 1, whose reaction is not unique), short stop times.

Covered: the grid syntax; the acceptance sweep (8 rows, 6 ok, 2 refused for mu < 0, measure ~0 at
mu = 0 and growing with mu, plot, Parquet); a value the FMU itself refuses (reason recorded); a
worker killed mid-sweep (every row once, all ok); an interrupted sweep continued with --resume; a
separately started ``dask scheduler`` + ``dask worker`` giving the same rows.
"""
from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("distributed")

from overcon.cli import main  # noqa: E402
from overcon.fmu.build import build_all  # noqa: E402
from overcon.tooling import InputError  # noqa: E402
from overcon.tooling import sweep  # noqa: E402
from overcon.verdict import lockstep_start_values  # noqa: E402

pytestmark = pytest.mark.integration  # every test here builds or runs FMUs, or shares a fixture that does

ROOT = Path(__file__).resolve().parent.parent
SCENES = [ROOT / "mechanisms" / "planar_f1_wo4.toml", ROOT / "mechanisms" / "planar_f1_wo6.toml"]
QUIET = dict(echo=lambda s: None)
NOT_COMPARED = ("wall [s]",)  # differs from run to run; every other column must be identical


def _rows(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> list[Path]:
    out = tmp_path_factory.mktemp("sweep_fmus")
    code, res = build_all(SCENES, out, allow_nonunique=True, refs=False, validate=False, echo=lambda s: None,
                          echo_err=lambda s: None)
    assert code == 0, [m for r in res for m in r.messages]
    return [r.fmu for r in res]


@pytest.fixture(scope="module")
def accepted(tmp_path_factory):
    """The issue's acceptance command, through the command line (local cluster, 2 workers)."""
    import contextlib
    import io

    out = tmp_path_factory.mktemp("sweep_accept") / "D"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(["sweep", *map(str, SCENES), "--param", "joint1.mu=0,0.005,0.01,-1", "--stop-time", "2",
                     "--workers", "2", "--out", str(out)])
    return code, out, printed.getvalue()


# ---------------------------------------------------------------------------------------------
# grid (no cluster)

def test_grid_full_factorial_ranges_and_samples():
    specs = [sweep.parse_param("joint1.mu=0:0.02:5"), sweep.parse_param("joint1.v_reg=1e-3,1e-4")]
    sets = sweep.grid(specs, {"joint1.mu": "Real", "joint1.v_reg": "Real"})
    assert len(sets) == 10
    assert [s["joint1.mu"] for s in sets[::2]] == [0.0, 0.005, 0.01, 0.015, 0.02]
    assert sets[1] == {"joint1.mu": 0.0, "joint1.v_reg": 1e-4}
    sampled = [sweep.parse_param("joint1.mu=0:0.02"), sweep.parse_param("solver.friction_max_iter=50,100")]
    types = {"joint1.mu": "Real", "solver.friction_max_iter": "Integer"}
    a = sweep.grid(sampled, types, samples=20, seed=3)
    assert a == sweep.grid(sampled, types, samples=20, seed=3)  # reproducible from the seed
    assert a != sweep.grid(sampled, types, samples=20, seed=4)
    assert all(0.0 <= s["joint1.mu"] <= 0.02 for s in a)
    assert {s["solver.friction_max_iter"] for s in a} == {50, 100}


def test_samples_drawn_twice_are_two_rows_and_refused_values_need_no_cluster(fmus, tmp_path):
    """Every value refused by the FMU's rule: rows written without starting a cluster; a sample
    drawn twice keeps both of its rows (the sample number is part of the key)."""
    sw = sweep.prepare(tmp_path / "s", inputs=list(map(str, fmus)), params=["joint1.mu=-1,-2"], samples=3,
                       seed=1, **QUIET)
    out = sweep.run(sw, scheduler="tcp://127.0.0.1:1", progress=False, **QUIET)  # never contacted
    rows = _rows(out.csv)
    assert len(rows) == 6 and len({r["key"] for r in rows}) == 6
    assert sorted({r["sample"] for r in rows}) == ["1", "2", "3"]
    assert len({r["joint1.mu"] for r in rows}) < 3  # 3 draws from 2 values: a value was drawn twice
    assert all("must be in [0, 1e+06], got -" in r["status"] for r in rows)
    assert out.png.is_file()


@pytest.mark.parametrize("text, types, samples, message", [
    ("joint1.mu", {}, None, "NAME=V1"),
    ("joint1.mu=0:x:3", {}, None, "range bounds must be numbers"),
    ("joint1.mu=0.02:0:3", {}, None, "lo <= hi"),
    ("joint1.mu=0:1", {"joint1.mu": "Real"}, None, "give lo:hi:n"),
    ("joint1.mu=0:1:3", {"joint1.mu": "Real"}, 4, "n has no meaning"),
    ("joint1.mu=0,abc", {"joint1.mu": "Real"}, None, "'abc' is not a valid Real value for joint1.mu"),
    ("solver.friction_max_iter=1:9:3", {"solver.friction_max_iter": "Integer"}, None, "needs a Real parameter"),
])
def test_bad_param_syntax_names_the_param(text, types, samples, message):
    with pytest.raises(InputError, match=message) as err:
        sweep.grid([sweep.parse_param(text)], types, samples=samples)
    assert text in str(err.value)


def test_unknown_or_lockstep_parameter_exits_2(fmus, tmp_path, capsys):
    assert main(["sweep", *map(str, fmus), "--param", "joint9.mu=0,1", "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "joint9.mu is not a parameter of" in err and "joint1.mu" in err
    assert main(["sweep", *map(str, fmus), "--param", "solver.tolerance=1e-6,1e-8", "--out", str(tmp_path / "b")]) == 2
    assert "--lockstep-step 0" in capsys.readouterr().err
    assert main(["sweep", *map(str, fmus), "--param", "joint1.mu=0", "--resume", str(tmp_path / "a"),
                 "--out", str(tmp_path / "c")]) == 2


def test_measure_is_the_largest_position_difference_between_eliminations(fmus, tmp_path):
    """The group comparison on given results (no runs): a 1e-6 m shift of one output in one
    elimination is the measure; lockstep mode calls it not unique, adaptive mode gives no verdict."""
    import numpy as np

    for step, verdict in ((5e-3, "not unique"), (0, "")):
        sw = sweep.prepare(tmp_path / f"m{step}", inputs=list(map(str, fmus)), params=["joint1.mu=0.01"],
                           stop_time=0.1, lockstep_step=step, **QUIET)
        set_id, values = sw.sets[0]
        t = np.linspace(0.0, 0.1, 11)
        results = {}
        for k, f in enumerate(sw.groups["planar_f1"]):
            vals = {o.name: np.full_like(t, 0.5) for o in f.info.outputs}
            vals["link3.x"] = vals["link3.x"] + (1e-6 if k else 0.0)
            vals["link3.phi"] = vals["link3.phi"] + (3e-7 if k else 0.0)
            results[f.info.model] = {"status": "ok", "wall": 1.0, "time": t, "values": vals}
        rows = sweep._set_rows(sw, "planar_f1", set_id, values, results)
        assert len(rows) == 2
        for r in rows:
            assert float(r["max_diff [m]"]) == pytest.approx(1e-6, rel=1e-9)
            assert float(r["max_diff [rad]"]) == pytest.approx(3e-7, rel=1e-9)
            assert r["max_diff_output"] == "link3.x" and r["verdict"] == verdict
        sv = dict(sweep._experiment(sw, sw.groups["planar_f1"][0], values).start_values)
        assert sv == ({"solver.method": "rk4", "solver.step": 5e-3, "joint1.mu": 0.01} if step else {"joint1.mu": 0.01})


def test_adaptive_mode_accepts_solver_tolerance_and_seed_needs_samples(fmus, tmp_path, capsys):
    sw = sweep.prepare(tmp_path / "a", inputs=list(map(str, fmus)), params=["solver.tolerance=1e-6,1e-8"],
                       lockstep_step=0, **QUIET)
    assert [v for _, v in sw.sets] == [{"solver.tolerance": 1e-6}, {"solver.tolerance": 1e-8}]
    assert main(["sweep", *map(str, fmus), "--param", "joint1.mu=0", "--seed", "3", "--out", str(tmp_path / "b")]) == 2
    assert "--seed 3" in capsys.readouterr().err
    assert main(["sweep", *map(str, fmus), "--param", "joint1.mu=0", "--scheduler", "tcp://127.0.0.1:1",
                 "--workers", "2", "--out", str(tmp_path / "c")]) == 2
    assert "--workers" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# the acceptance sweep

def test_acceptance_rows_measure_and_plot(accepted):
    code, out, printed = accepted
    assert code == 0
    assert "planar_f1: 4 parameter set(s): 1 unique, 2 not unique, 1 without a measure" in printed
    assert "not unique from joint1.mu = 0.005" in printed
    rows = _rows(out / "sweep.csv")
    assert len(rows) == 8
    assert len({r["key"] for r in rows}) == 8
    ok = [r for r in rows if r["status"] == "ok"]
    bad = [r for r in rows if r["status"] != "ok"]
    assert len(ok) == 6 and len(bad) == 2
    for r in bad:
        assert float(r["joint1.mu"]) == -1.0
        assert "joint1.mu" in r["status"] and "must be in [0, 1e+06], got -1" in r["status"]
        assert r["max_diff [m]"] == "" and r["final slider1.x [m]"] == ""
    measure = {}
    for r in ok:
        assert float(r["wall [s]"]) > 0
        assert r["final slider1.x [m]"] != ""
        measure.setdefault(float(r["joint1.mu"]), set()).add(float(r["max_diff [m]"]))
    assert all(len(v) == 1 for v in measure.values())  # one measure per group and set
    m = {mu: v.pop() for mu, v in measure.items()}
    assert m[0.0] < 1e-12  # frictionless: the eliminations agree to round-off
    assert 1e-3 < m[0.005] < m[0.01]  # grows with mu
    verdicts = {float(r["joint1.mu"]): r["verdict"] for r in ok}
    assert verdicts == {0.0: "unique", 0.005: "not unique", 0.01: "not unique"}
    # final positions come from the lockstep run: with friction the two eliminations end apart
    finals = {(r["scene"], float(r["joint1.mu"])): float(r["final slider1.x [m]"]) for r in ok}
    assert abs(finals["planar_f1_wo4", 0.01] - finals["planar_f1_wo6", 0.01]) > 0.1
    png = out / "sweep.png"
    assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    try:
        import pyarrow.parquet as pq
    except ImportError:
        assert not (out / "sweep.parquet").exists()
    else:
        table = pq.read_table(out / "sweep.parquet")
        assert table.num_rows == 8 and "max_diff [m]" in table.column_names


def test_value_the_fmu_refuses_is_recorded_with_its_reason(fmus):
    """Without the pre-run rule check, the FMU refuses mu = -1 itself; the row gets its logged reason."""
    f = sweep._load_fmu(fmus[0])
    sw_ex = sweep.Experiment(0.0, 0.1, 0.01, tuple({**lockstep_start_values(5e-3), "joint1.mu": -1.0}.items()))
    res = sweep.run_task(f.data, f.sha, f.info, sw_ex)
    assert res["status"] != "ok"
    assert "joint1.mu" in res["status"] and "must be in [0, 1e+06], got -1" in res["status"]  # the FMU's own log message
    assert str(fmus[0]) in res["status"]  # names the FMU, not the worker's unpacked copy
    assert "\n" not in res["status"]


# ---------------------------------------------------------------------------------------------
# faults

@pytest.fixture(scope="module")
def cluster_client():
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


def test_killed_worker_loses_and_duplicates_no_row(fmus, cluster_client, tmp_path):
    client = cluster_client
    sw = sweep.prepare(tmp_path / "kill", inputs=list(map(str, fmus)), params=["joint1.mu=0,0.003,0.006"],
                       stop_time=0.5, **QUIET)
    killed = {}

    def kill_busy_worker(rows, client):
        if killed:
            return
        deadline = time.monotonic() + 10
        busy = {}
        while not busy and time.monotonic() < deadline:  # the next tasks are being handed out
            busy = {w: keys for w, keys in client.processing().items() if keys}
            time.sleep(0.05)
        assert busy, "no task running after the first set finished: nothing to kill"
        worker, keys = next(iter(busy.items()))
        pid = client.run(os.getpid, workers=[worker])[worker]
        os.kill(pid, signal.SIGKILL)
        killed.update(pid=pid, keys=set(keys))

    out = sweep.run(sw, client=client, progress=False, on_rows=kill_busy_worker, **QUIET)
    assert killed, "no worker was killed"
    rows = _rows(out.csv)
    keys = [r["key"] for r in rows]
    expected = {sweep.row_key(f.info.model, sid) for f in sw.fmus for sid, _ in sw.sets}
    assert sorted(keys) == sorted(expected)  # every row, each once
    assert all(r["status"] == "ok" for r in rows), [r["status"] for r in rows]
    assert killed["pid"] not in client.run(os.getpid).values()  # that process is gone; Dask reran its task

    def unpacked(dask_worker):  # client.run passes the worker object by this name
        d = Path(dask_worker.local_directory) / "overcon-fmus"
        return sorted(p.name for p in d.iterdir()) if d.is_dir() else []

    shas = {f.sha for f in sw.fmus}
    listed = list(client.run(unpacked).values())
    assert any(listed)  # the FMUs were unpacked in the workers' directories
    for names in listed:  # one directory per FMU and worker, no half-written one
        assert set(names) <= shas and len(names) == len(set(names))


def test_ctrl_c_keeps_finished_rows_and_resume_completes_the_sweep(fmus, cluster_client, tmp_path):
    """SIGINT to the whole process group (what Ctrl-C in a terminal sends): exit 130, the rows
    written so far are kept and all ok (no run killed by the signal is recorded as failed);
    ``--resume`` runs only the missing sets and leaves the kept rows untouched."""
    out = tmp_path / "intr"
    proc = subprocess.Popen([sys.executable, "-m", "overcon.cli", "sweep", *map(str, fmus), "--param",
                             "joint1.mu=0,0.003,0.006", "--stop-time", "0.5", "--workers", "2", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if (out / "sweep.csv").is_file() and len(_rows(out / "sweep.csv")) >= 2:
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the sweep ended before it could be interrupted"
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert f"--resume {out}" in err
    kept = _rows(out / "sweep.csv")
    assert 2 <= len(kept) < 6 and len({r["key"] for r in kept}) == len(kept)
    assert all(r["status"] == "ok" for r in kept), [r["status"] for r in kept]
    with pytest.raises(InputError, match="already holds a sweep"):
        sweep.prepare(out, inputs=list(map(str, fmus)), params=["joint1.mu=0"], **QUIET)
    again = sweep.prepare(out, resume=True, **QUIET)
    done = sweep.run(again, client=cluster_client, progress=False, **QUIET)
    assert not done.interrupted and done.written == 6 - len(kept)
    rows = _rows(out / "sweep.csv")
    assert len(rows) == 6 and len({r["key"] for r in rows}) == 6
    assert rows[:len(kept)] == kept  # the rows written before the interruption are untouched
    assert all(r["status"] == "ok" for r in rows)


# ---------------------------------------------------------------------------------------------
# an existing cluster

def test_external_scheduler_gives_the_same_rows(accepted, tmp_path):
    code, accept_out, _ = accepted
    assert code == 0
    dask_exe = Path(sys.executable).with_name("dask")
    sched_file = tmp_path / "scheduler.json"
    procs = []
    try:
        procs.append(subprocess.Popen([str(dask_exe), "scheduler", "--scheduler-file", str(sched_file), "--port", "0",
                                       "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        procs.append(subprocess.Popen([str(dask_exe), "worker", "--scheduler-file", str(sched_file), "--nworkers", "2",
                                       "--nthreads", "1", "--no-dashboard"],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path))
        from distributed import Client

        deadline = time.monotonic() + 60
        while not sched_file.is_file() and time.monotonic() < deadline:
            time.sleep(0.2)
        with Client(scheduler_file=str(sched_file), timeout="30s") as c:
            c.wait_for_workers(2, timeout=60)
            address = c.scheduler.address
        out = tmp_path / "ext"
        assert main(["sweep", *map(str, SCENES), "--param", "joint1.mu=0.01,-1", "--stop-time", "2",
                     "--scheduler", address, "--out", str(out)]) == 0
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
    local = {r["key"]: r for r in _rows(accept_out / "sweep.csv")}
    remote = _rows(out / "sweep.csv")
    assert len(remote) == 4
    for r in remote:
        ref = local[r["key"]]
        assert {k: v for k, v in r.items() if k not in NOT_COMPARED} == \
               {k: v for k, v in ref.items() if k not in NOT_COMPARED}


def test_sweep_and_compare_follow_one_lockstep_procedure(fmus, cluster_client, tmp_path, monkeypatch):
    """At joint1.mu = 0.016 rk4 is unstable at 5 ms (it names 0.0033 s): sweep and compare both
    repeat the group's lockstep runs through LockstepGrid.retry with the same stable steps, end on
    the same grid (0.0002 s) with the same positions, and give the same verdict; the sweep keeps
    the set (rows ok, the step recorded)."""
    from overcon import verdict
    from overcon.tooling.pipeline import compare_paths
    from overcon.tooling.run import read_series

    calls = []
    real = verdict.LockstepGrid.retry

    def spy(self, stable_steps):
        before = self.step
        again = real(self, stable_steps)
        calls.append((before, tuple(sorted(round(h, 9) for h in stable_steps)), again, self.step))
        return again

    monkeypatch.setattr(verdict.LockstepGrid, "retry", spy)
    sw = sweep.prepare(tmp_path / "sw", inputs=[str(f) for f in fmus], params=["joint1.mu=0.016"], stop_time=2, **QUIET)
    out = sweep.run(sw, client=cluster_client, progress=False, **QUIET)
    swept, calls[:] = list(calls), []
    res = compare_paths(fmus, tmp_path / "cmp", stop_time=2, settings={"joint1.mu": 0.016}, echo=lambda s: None)
    compared = list(calls)
    assert swept == compared and len(swept) == 2 and swept[0][0] == 5e-3 and swept[-1][-1] == pytest.approx(2e-4)
    assert all(again for _, _, again, _ in swept)
    rows = _rows(out.csv)
    assert [r["status"] for r in rows] == ["ok", "ok"] and {r["lockstep_step [s]"] for r in rows} == {"0.0002"}
    (c,) = res.comparisons
    assert c.lockstep_step == pytest.approx(2e-4) and {r["verdict"] for r in rows} == {c.verdict_text()} == {"not unique"}
    for r in rows:
        lock = read_series(tmp_path / "cmp" / "lockstep" / f"{r['scene']}.csv")
        assert float(r["final slider1.x [m]"]) == lock.values["slider1.x"][-1]  # the same runs, bit for bit
    assert "sweep: 1 (group, parameter set) pair(s): 1 decided, 0 failed" in sweep.summary(sw, rows)[0]

