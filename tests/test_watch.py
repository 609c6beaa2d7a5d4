"""The watch over singular positions (core/watch.c, in every run): every rank loss seen whatever its
multiplicity, at a time that does not depend on the tolerance; the mechanism told apart from an
elimination that expires; the kept equations chosen again when the motion does not depend on
them, and a stop naming the valid eliminations when it does; the events of a run."""
from __future__ import annotations

import csv
import json
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from overcon import scene as scene_mod
from overcon.checks import compile_checked
from overcon.cli import main
from overcon.simulate import Simulation, SimulationError, output_grid, run

EXAMPLES = Path(__file__).resolve().parents[1] / "mechanisms" / "examples"


def _nfourbar():
    spec = importlib.util.spec_from_file_location("nfourbar", EXAMPLES / "nfourbar.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _scene(path: Path, **kw):
    return scene_mod.as_scene(scene_mod.load(path), **kw)


def _first_flat_stop(tmp_path: Path, n: int, tolerance: float) -> float:
    _, scene = _nfourbar().write(n, tmp_path / f"n{n}_{tolerance:g}", stop_time=2.0, tolerance=tolerance)
    spec = _scene(scene)
    with pytest.raises(SimulationError, match=r"the mechanism's constraint Jacobian is rank deficient") as exc:
        run(compile_checked(spec), spec.solver)
    # the stop says the way on and what it does (issue 37, item 4)
    assert ('to go on through it, run with --singular pass (scene: [solver] singular = "pass"), which solves the '
            'kept equations in the augmented Lagrangian form and projects the state back onto the constraints '
            'after every step') in str(exc.value)
    return float(exc.value.partial.time[-1]), str(exc.value)


@pytest.mark.parametrize("n", [2, 4])
def test_nfourbar_stops_at_its_first_flat_position_whatever_the_tolerance(tmp_path, n):
    """The N-four-bar loses N of its rank when it lies flat (every crank along x, first at about
    0.714 s): an even loss for N = 2 and 4, which a determinant's sign cannot see. Both
    tolerances stop there, at the same time (the message's), and keep the rows before it."""
    times = []
    for tol in (1e-9, 1e-12):
        last_row, message = _first_flat_stop(tmp_path, n, tol)
        t_stop = float(message.split("t = ")[1].split(" s")[0])
        assert last_row <= t_stop < last_row + 0.05  # the file ends at an output point before the stop's step
        times.append(t_stop)
    assert abs(times[0] - times[1]) < 1e-3
    # the flat position itself: crank0 horizontal, from the frictionless run's energy (upright, 1 m/s)
    assert 0.70 < times[0] < 0.73


# ----------------------------------------------------------------------------- an expiring elimination

def _parallelogram(tmp_path: Path, friction: str | None, eliminate: str, k: int = 3) -> Path:
    """A coupler on k = 3 parallel cranks of 1 m, started at 60 deg and turning at 3 rad/s
    counter-clockwise, so it passes the upright position at about 0.2 s. Equations: G0 1-2,
    C0 3-4, G1 5-6, C1 7-8, G2 9-10, C2 11-12; one redundant (the cranks' axial self-stress).
    Eliminating Phi11 (C2's x row) is valid while the cranks are not upright: at the upright
    position the self-stress has no x component, so the other 11 equations lose rank there,
    while all 12 keep rank 11."""
    theta, omega = math.pi / 3, 3.0
    c, s = math.cos(theta), math.sin(theta)
    lines = ['[mechanism]', 'name = "pg3"', 'kind = "planar"', 'gravity = [0.0, -9.81]',
             '[[bodies]]', 'name = "coupler"', f'mass = {k - 1.0}', 'inertia = 1.0',
             f'q0 = [{(k - 1) / 2 + c!r}, {s!r}, 0.0]', f'h0 = [{-omega * s!r}, {omega * c!r}, 0.0]']
    for i in range(k):
        lines += ['[[bodies]]', f'name = "crank{i}"', 'mass = 1.0', 'inertia = 0.0833',
                  f'q0 = [{i + 0.5 * c!r}, {0.5 * s!r}, {theta!r}]',
                  f'h0 = [{-0.5 * omega * s!r}, {0.5 * omega * c!r}, {omega!r}]']
    for i in range(k):
        lines += ['[[joints]]', f'name = "G{i}"', 'type = "revolute"', f'body_i = "crank{i}"', 'body_j = "base"',
                  's_i = [-0.5, 0.0]', f's_j = [{i}.0, 0.0]',
                  '[joints.friction]', 'law = "regularised"', 'mu = 0.1', 'radius = 0.02', 'v_reg = 0.001',
                  '[[joints]]', f'name = "C{i}"', 'type = "revolute"', f'body_i = "crank{i}"', 'body_j = "coupler"',
                  's_i = [0.5, 0.0]', f's_j = [{i - (k - 1) / 2}, 0.0]']
    (tmp_path / "pg3.toml").write_text("\n".join(lines) + "\n")
    tag = "".join(ch for ch in eliminate if ch.isalnum())
    name = f"pg_{'f' if friction else 'none'}_{tag}"
    scene = tmp_path / f"{name}.toml"
    scene.write_text("\n".join([
        "[scene]", f'name = "{name}"', 'mechanism = "pg3.toml"', f"friction = {[friction] if friction else []}"
        .replace("'", '"'), f"eliminate = {eliminate}", "stop_time = 0.6",
        "[outputs]", 'positions = ["crank0.phi", "coupler.x", "coupler.y"]',
        "[solver]", "tolerance = 1e-10", "output_interval = 0.01", ""]))
    return scene


def _upright_time(result) -> float:
    """When crank0 stands upright (phi = pi/2), by linear interpolation of the output."""
    phi = result.column("crank0.phi")
    k = int(np.argmax(phi >= math.pi / 2))
    t0, t1 = result.time[k - 1], result.time[k]
    return float(t0 + (math.pi / 2 - phi[k - 1]) * (t1 - t0) / (phi[k] - phi[k - 1]))


def test_an_expired_elimination_is_chosen_again_when_the_motion_does_not_depend_on_it(tmp_path):
    given = _scene(_parallelogram(tmp_path, None, "[11]"))
    auto = _scene(_parallelogram(tmp_path, None, '"auto"'))
    res, ref = run(compile_checked(given), given.solver), run(compile_checked(auto), auto.solver)
    assert compile_checked(auto).eliminated != (11,)  # the reference never held the expiring set
    assert not ref.events
    assert [kind for _, kind, _ in res.events] == ["elimination-reselected"]
    t_event, _, detail = res.events[0]
    assert abs(t_event - _upright_time(ref)) < 1e-3
    assert detail.startswith("eliminated [11] -> [")
    positions = [res.names.index(n) for n in ("crank0.phi", "coupler.x", "coupler.y")]
    assert np.max(np.abs(res.values[:, positions] - ref.values[:, positions])) <= 1e-8  # the same motion (m, rad)


def test_with_friction_on_a_nonunique_joint_an_expired_elimination_stops_the_run(tmp_path):
    spec = _scene(_parallelogram(tmp_path, "G0", "[11]"))
    model = compile_checked(spec)
    with pytest.raises(SimulationError, match="the elimination chosen at the start expires") as exc:
        run(model, spec.solver)
    msg = str(exc.value)
    assert "while the mechanism stays regular: the elimination chosen at the start expires" in msg
    assert "with friction on G0, whose reaction is not unique, the elimination decides the motion" in msg
    assert "(eliminated: Phi11; other eliminations valid at the start and here: [2], [4]" in msg
    t_stop = float(msg.split("integration stopped: t = ")[1].split(" s")[0])
    frictionless = run(compile_checked(_scene(_parallelogram(tmp_path, None, '"auto"'))), spec.solver)
    assert abs(t_stop - _upright_time(frictionless)) < 5e-3  # friction slows it a little
    partial = exc.value.partial
    assert len(partial.time) and partial.time[-1] <= t_stop  # the rows before the stop are kept
    assert partial.events[-1][1] == "stopped"


def test_a_reselected_run_saves_and_restores_its_elimination(tmp_path):
    spec = _scene(_parallelogram(tmp_path, None, "[11]"))
    model = compile_checked(spec)
    sim = Simulation(model, spec.solver)
    sim.advance(0.3)
    assert [k for _, k, _ in sim.events] == ["elimination-reselected"]
    state, events = sim.get_state(), sim.events
    after = sim.advance(0.5)
    other = Simulation(model, spec.solver)
    other.set_state(state)  # the state holds the elimination chosen during the run (core/sim_state.c)
    assert other.events == events
    assert np.array_equal(other.advance(0.5), after)


def test_simulate_writes_the_events(tmp_path, capsys):
    scene = _parallelogram(tmp_path, None, "[11]")
    events = tmp_path / "events.csv"
    assert main(["simulate", str(scene), "--out", str(tmp_path / "o.csv"), "--events", str(events)]) == 0
    assert "events: elimination-reselected at t = 0.19" in capsys.readouterr().out
    rows = list(csv.reader(events.open()))
    assert rows[0] == ["time", "kind", "detail"] and [r[1] for r in rows[1:]] == ["elimination-reselected"]
    assert main(["simulate", str(scene), "--out", str(tmp_path / "o.csv"), "--events", str(tmp_path / "no" / "e.csv")]) == 2
    assert "--events " in capsys.readouterr().err


def test_output_grid_of_the_nfourbar_scene_is_the_benchmarks(tmp_path):
    """The generator's files: 2N + 1 links of 1 kg, 3N + 1 revolute joints, 20 s by default,
    and N < 1 refused."""
    mod = _nfourbar()
    mech, scene = mod.write(3, tmp_path)
    model = compile_checked(_scene(scene))
    assert model.nb == 7 and len(model.joints) == 10 and model.m == 20 and np.all(model.mass == 1.0)
    assert model.scene.stop_time == 20.0 and len(output_grid(0.0, 20.0, 0.01)) == 2001
    with pytest.raises(ValueError, match="N = 0: the N-four-bar needs N >= 1 loops"):
        mod.write(0, tmp_path)


def test_check_along_reports_the_uniqueness_at_every_output_point(tmp_path, capsys):
    """``check --along T``: segments of constant rank and non-unique friction joints over the
    run's output points, the run's stop when it stops, in the table and the JSON."""
    paper = Path(__file__).resolve().parents[1] / "mechanisms" / "planar_f45_wo4.toml"
    assert main(["check", str(paper), "--along", "0.5"]) == 0
    out = capsys.readouterr().out
    assert "along the motion (sampled every 0.01 s up to 0.5 s):\n  t = 0..0.5 s: rank 11; friction reactions unique" in out
    scene = _parallelogram(tmp_path, "G0", "[11]")
    assert main(["check", str(scene), "--along", "0.6", "--json"]) == 1
    doc = json.loads(capsys.readouterr().out)["along"]
    assert doc["segments"] == [{"from": 0.0, "to": 0.19, "rank": 11, "nonunique_friction_joints": ["G0"]}]
    assert "the elimination decides the motion" in doc["stopped"] and doc["interval"] == 0.01
    with pytest.raises(SystemExit, match="^2$") as exc:
        main(["check", str(scene), "--along", "0"])
    assert exc.value.code == 2 and "argument --along: must be a positive finite number, got 0" in capsys.readouterr().err


@pytest.mark.integration
def test_the_fmu_chooses_again_and_logs_the_event(tmp_path):
    """The FMU runs the same watch: an elimination that expires is chosen again, the event is
    logged (category logEvents), and the positions equal the in-process run's."""
    pytest.importorskip("fmpy")
    from _fmpy_logger import simulate_logged
    from overcon.fmu.build import build_scene
    from test_fmu import Logs
    scene = _parallelogram(tmp_path, None, "[11]")
    res = build_scene(scene, tmp_path / "out", echo=lambda s: None)
    assert res.status == "built", res.messages
    logs = Logs()
    out = simulate_logged(res.fmu, logs, debug_logging=True, stop_time=0.6, output_interval=0.01)
    events = [m for _, c, m in logs.records if c == "logEvents" and "event elimination-reselected" in m]
    assert len(events) == 1 and events[0].startswith("t = 0.19") and "eliminated [11] -> [" in events[0]
    ref = run(compile_checked(_scene(scene)), _scene(scene).solver)
    assert np.max(np.abs(out["crank0.phi"] - ref.column("crank0.phi"))) <= 1e-9


def test_bricard_with_equation_2_eliminated_completes_with_one_reselection():
    """Bricard's mechanism (benchmark A04, tests/data/bricard): with Phi2 eliminated the kept 29
    equations lose rank near t = 1.25 s while all 30 keep rank 29. The run chooses them again
    once they become ill-conditioned, completes 10 s, moves as the run under ``auto`` does
    (<= 1e-8 m) and keeps its energy (<= 1e-7 J at tolerance 1e-10)."""
    data = Path(__file__).resolve().parent / "data" / "bricard"
    given, auto = _scene(data / "bricard_wo2.toml"), _scene(data / "bricard_auto.toml")
    res, ref = run(compile_checked(given), given.solver), run(compile_checked(auto), auto.solver)
    assert compile_checked(auto).eliminated != (2,) and not ref.events
    assert [kind for _, kind, _ in res.events] == ["elimination-reselected"]
    assert 1.15 < res.events[0][0] < 1.25 and res.events[0][2].startswith("eliminated [2] -> [")
    assert res.time[-1] == 10.0
    positions = [n for n in res.names if n.startswith("rod")]
    cols = [res.names.index(n) for n in positions]
    assert np.max(np.abs(res.values[:, cols] - ref.values[:, cols])) <= 1e-8
    energy = res.column("energy.kinetic") + res.column("energy.potential")
    assert np.max(np.abs(energy - energy[0])) <= 1e-7
    assert np.ptp(res.column("energy.kinetic")) > 1.0  # it does move
