"""Runs that pass singular positions (``[solver] singular = "pass"``): the augmented Lagrangian
solve of the kept equations (core/kkt_al.c) with mass-orthogonal projections after every step
(core/project.c). Acceptance of issue 23: the generated parallelogram linkages (K = 3, 10, 40
cranks) and the N-four-bar (N = 2, 10, 40) go through their flat positions, stay on the
parallelogram branch (every crank at the first one's angle, and that angle the one of the 1-DOF
equivalent integrated at tight tolerance), and keep the constraint drift <= 1e-8; the N-four-bar
N = 2 completes 20 s with 20 ``singular`` events at the flat instants. Where the rank is regular
the multipliers are the eliminated form's, so the paper's friction is unchanged."""
from __future__ import annotations

import csv
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
from overcon.cli import main, single_threaded_blas
from overcon.simulate import Simulation, SimulationError, run

ROOT = Path(__file__).resolve().parents[1]
MECH = ROOT / "mechanisms"
G = 9.81

pytestmark = pytest.mark.skipif(kernel.library()[0] is None, reason="singular = 'pass' runs on the compiled kernel")


def _nfourbar():
    spec = importlib.util.spec_from_file_location("nfourbar", MECH / "examples" / "nfourbar.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _scene(path: Path):
    return scene_mod.as_scene(scene_mod.load(path))


def _passing(spec):
    return dataclasses.replace(spec.solver, singular="pass")


def parallelogram(k: int, out: Path, stop_time: float) -> Path:
    """A coupler (mass k - 1 kg, along x) on k parallel cranks of 1 m (1 kg, 0.0833 kg m^2 about
    the centre) from (i, 0), i = 0..k-1, started upright and falling clockwise at 1 rad/s, so that
    every link lies on the ground line at about 0.71 s and, the cranks hanging down and swinging on
    round, again at 1.23 s; k - 2 redundant equations, eliminated by
    ``eliminate = "auto"`` (the precheck's generator, tests/test_precheck_methods.py, with a motion)."""
    lines = ['[mechanism]', f'name = "pgpass{k}"', 'kind = "planar"', 'gravity = [0.0, -9.81]']
    for i in range(k):
        lines += ['[[bodies]]', f'name = "crank{i}"', 'mass = 1.0', 'inertia = 0.0833',
                  f'q0 = [{i}.0, 0.5, {math.pi / 2!r}]', 'h0 = [0.5, 0.0, -1.0]']
    lines += ['[[bodies]]', 'name = "coupler"', f'mass = {k - 1.0}', 'inertia = 1.0',
              f'q0 = [{(k - 1) / 2}, 1.0, 0.0]', 'h0 = [1.0, 0.0, 0.0]']
    for i in range(k):
        lines += ['[[joints]]', f'name = "G{i}"', 'type = "revolute"', f'body_i = "crank{i}"', 'body_j = "base"',
                  's_i = [-0.5, 0.0]', f's_j = [{i}.0, 0.0]',
                  '[[joints]]', f'name = "C{i}"', 'type = "revolute"', f'body_i = "crank{i}"', 'body_j = "coupler"',
                  's_i = [0.5, 0.0]', f's_j = [{i - (k - 1) / 2}, 0.0]']
    out.mkdir(parents=True, exist_ok=True)
    (out / f"pgpass{k}.toml").write_text("\n".join(lines) + "\n")
    scene = out / f"pgpass{k}_scene.toml"
    scene.write_text("\n".join([
        "[scene]", f'name = "pgpass{k}_scene"', f'mechanism = "pgpass{k}.toml"', "friction = []",
        'eliminate = "auto"', f"stop_time = {stop_time!r}", "[outputs]", 'positions = ["crank0.phi"]',
        "[solver]", "tolerance = 1e-9", 'singular = "pass"', ""]))
    return scene


def one_dof(inertia: float, moment: float, times: np.ndarray):
    """The crank angle of the parallelogram branch (every crank at phi, the couplers translating):
    I phi'' = -g c cos(phi), I and c the linkage's (kg m^2, kg m), from phi = pi/2, phi' = -1 rad/s;
    DOP853 at 1e-13. Also the instants where the linkage lies flat (sin phi = 0)."""
    def f(t, y):
        return [y[1], -G * moment * math.cos(y[0]) / inertia]

    def flat(t, y):
        return math.sin(y[0])
    sol = solve_ivp(f, (0.0, float(times[-1])), [math.pi / 2, -1.0], t_eval=times, events=flat, rtol=1e-13,
                    atol=1e-13, method="DOP853")
    return sol.y[0], sol.t_events[0]


def _crank_angles(sim: Simulation, model, times, cranks: list[int]):
    """Crank angles (rad) at ``times`` (>0), the run's events and its max drift."""
    out = []
    with single_threaded_blas():
        for t in times:
            y = sim.advance(float(t))
            out.append([y[model.nq_b * b + 2] for b in cranks])
    return np.array(out)


def _branch(phis: np.ndarray, ref: np.ndarray, sim: Simulation, flats: int, ref_tol: float) -> None:
    """On the parallelogram branch: every crank at the first one's angle (1e-6 rad), the first at
    the 1-DOF equivalent's (``ref_tol``), the drift within 1e-8, one ``singular`` event per flat
    position passed."""
    assert np.max(np.abs(phis - phis[:, :1])) < 1e-6
    assert np.max(np.abs(phis[:, 0] - ref)) < ref_tol
    assert sim.max_drift <= 1e-8
    assert [e[1] for e in sim.events if e[1] != "rank-change"] == ["singular"] * flats
    _rank_dips(sim)


def _singular_times(sim) -> np.ndarray:
    return np.array([e[0] for e in sim.events if e[1] == "singular"])


def _rank_dips(sim) -> None:
    """The rank recorded along the motion leaves its regular value only next to a flat instant
    and is back at the end of that step: ``rank a -> b`` then ``rank b -> a``, each within 0.05 s
    of a ``singular`` event. (b is below a at the instant itself. At a step end a few 1e-5 s from
    it, b can be above a: the singular value of the mechanism's own motion, round-off elsewhere,
    measured 1.4e-10 of sigma_max there for K = 40, is judged against the pre-check's rank
    tolerance, 1e-9 of sigma_max, after the equilibration.)"""
    ranks = [e for e in sim.events if e[1] == "rank-change"]
    pairs = [tuple(int(x) for x in e[2].removeprefix("rank ").split(" -> ")) for e in ranks]
    assert len(pairs) % 2 == 0 and all(away == back[::-1] and away[0] == pairs[0][0]
                                       for away, back in zip(pairs[::2], pairs[1::2])), pairs
    times = _singular_times(sim)
    assert all(np.min(np.abs(times - e[0])) < 0.05 for e in ranks)


@pytest.mark.parametrize("k", [3, 10, 40])
def test_generated_parallelograms_pass_their_flat_position_on_the_parallelogram_branch(tmp_path, k):
    """Through both flat positions (0.71 s, 1.23 s) up to 1.6 s. The branch that leaves it (the
    coupler folding onto the ground, cranks turning apart) would move the cranks off the first's
    angle at once; the 1-DOF equivalent here has I = k (0.0833 + 0.25) + (k - 1) kg m^2 and
    c = k / 2 + k - 1 kg m. Measured: 2e-10 rad between cranks, 1e-6 rad from the 1-DOF angle."""
    spec = _scene(parallelogram(k, tmp_path, 1.6))
    model = compile_checked(spec)
    times = np.linspace(0.05, 1.6, 32)
    ref, flats = one_dof(k * (0.0833 + 0.25) + (k - 1), k / 2 + k - 1, times)
    sim = Simulation(model, spec.solver)
    phis = _crank_angles(sim, model, times, list(range(k)))
    assert len(flats) == 2
    _branch(phis, ref, sim, 2, 1e-5)
    assert np.max(np.abs(_singular_times(sim) - flats)) < 2e-5


def _nfourbar_run(tmp_path: Path, n: int, stop: float):
    _, path = _nfourbar().write(n, tmp_path / f"n{n}", stop_time=stop, singular="pass")
    spec = _scene(path)
    model = compile_checked(spec)
    times = np.linspace(0.05, stop, int(round(stop / 0.05)))
    ref, flats = one_dof((n + 1) / 3 + n, (n + 1) / 2 + n, times)
    sim = Simulation(model, spec.solver)
    cranks = [model.body_names.index(f"crank{i}") for i in range(n + 1)]
    return sim, _crank_angles(sim, model, times, cranks), ref, flats


def test_nfourbar_2_completes_20_s_with_20_singular_events_at_the_flat_instants(tmp_path):
    """Issue 26's acceptance alternative: 20 flat positions in 20 s, each recorded once at the
    instant the 1-DOF equivalent lies flat (I = (N + 1)/3 + N kg m^2, c = (N + 1)/2 + N kg m);
    measured: 1.2e-5 rad from it after 20 s at tolerance 1e-9, events within 3e-6 s."""
    sim, phis, ref, flats = _nfourbar_run(tmp_path, 2, 20.0)
    assert len(flats) == 20
    _branch(phis, ref, sim, 20, 1e-4)
    assert np.max(np.abs(_singular_times(sim) - flats)) < 2e-5


@pytest.mark.parametrize("tolerance", [1e-12, 1e-6])
def test_nfourbar_2_passes_its_flat_positions_at_tight_and_loose_tolerances(tmp_path, tolerance):
    """The acceleration solve changes method near a flat position (the direct solve of S where
    the kept rows are regular, the AL iteration near and at the flat position: kkt_al.c); a jump
    in y' there would stop a tight-tolerance run at its first flat position (step size below the
    minimum). Through three flat positions at 1e-12 and at 1e-6, on the branch."""
    _, path = _nfourbar().write(2, tmp_path, stop_time=3.0, singular="pass")
    spec = _scene(path)
    model = compile_checked(spec)
    times = np.linspace(0.05, 3.0, 60)
    ref, flats = one_dof(1 + 2, 1.5 + 2, times)
    sim = Simulation(model, dataclasses.replace(spec.solver, tolerance=tolerance), max_steps=200_000)
    phis = _crank_angles(sim, model, [*times], [model.body_names.index(f"crank{i}") for i in range(3)])
    assert len(flats) == 3
    _branch(phis, ref, sim, 3, 1e-3 if tolerance > 1e-9 else 1e-4)


@pytest.mark.parametrize("n, stop, flats", [(10, 20.0, 20), (40, 1.6, 2)])
def test_nfourbar_10_and_40_pass_their_flat_positions_on_the_parallelogram_branch(tmp_path, n, stop, flats):
    """N = 10 over the benchmark's 20 s; N = 40 through its first two flat positions (0.71 and
    1.23 s; the whole 20 s is in benchmarks/nfourbar.py). Measured: 2.6e-5 rad (N = 10, 20 s)."""
    sim, phis, ref, _ = _nfourbar_run(tmp_path, n, stop)
    _branch(phis, ref, sim, flats, 1e-4)


def test_the_c_run_counts_the_singular_positions_it_passes(tmp_path):
    """core/sim.c under formulation AL (projection, FSAL again, the watch going on) counts the
    singular positions it records as events, names the last, and keeps the projection's drift
    within its tolerance (the one it has near a singular position, where its corrections converge
    linearly: OVK_PROJ_SLACK times OVK_PROJ_TOL, core/project.c; measured 1.3e-11)."""
    _, path = _nfourbar().write(2, tmp_path, stop_time=3.0, singular="pass")
    spec = _scene(path)
    model = compile_checked(spec)
    c_run = kernel.Run(model, spec.solver)
    c_run.advance(3.0)
    info = c_run.info
    singular = [e for e in c_run.events if e[1] == "singular"]
    assert info["singular_passed"] == len(singular) == 3  # flat at 0.71, 1.23 and 2.66 s
    assert info["last_singular"] == pytest.approx(singular[-1][0], abs=1e-8)  # the event's time, %.9g
    assert info["projection_drift"] <= kernel.PROJECTION_SLACK * kernel.PROJECTION_TOL


def test_the_certified_skip_decides_as_the_factorisation(tmp_path):
    """Between flat positions the watch's certified bounds decide the uniqueness along the motion
    without a factorisation (unique.c, ovk_unique_certified): after every interval in which it
    did, the run reports full rank and every reaction unique, and the whole rule (Kernel.unique,
    the banded factorisation) says the same at the run's step end; and the skip is taken (3 times
    over the 1.5 s: the uniqueness is evaluated after steps ending with r < 1e-3, and the passages,
    interpolated near the flat positions by core/sim_pass.c, take few of them; 29 before)."""
    _, path = _nfourbar().write(10, tmp_path, stop_time=1.5, singular="pass")
    spec = _scene(path)
    model = compile_checked(spec)
    run = kernel.Run(model, spec.solver)
    k = kernel.Kernel(kernel.library()[0], model, spec.solver)
    checked, before = 0, 0
    for t in np.arange(0.01, 1.5, 0.01):
        run.advance(float(t))
        certified = run.info["along_certified"]
        if certified > before:  # an evaluation in this interval was decided by the certificate
            rank, unique, _ = run.uniqueness()
            full, verdicts = k.unique(run.y)  # the step end the run's last evaluation is at, or after
            assert rank == full == model.m and all(verdicts) and all(unique.values())
            checked += 1
        before = certified
    assert run.info["along_certified"] > 0 and checked > 0


@pytest.mark.parametrize("name", ["planar_f45_wo4", "planar_f1_wo6", "spatial_GHMN_wo5", "examples/door_h1_wo_hinge2",
                                  "examples/carriage_guide_wo_rod", "examples/loop_A1_wo_A2"])
def test_where_the_rank_is_regular_the_multipliers_are_the_eliminated_forms(name):
    """Friction scenes of the paper and the examples (planar, Euler and quaternion spatial), at
    six states of their motion: the AL multipliers (those the friction law uses) equal the
    eliminated form's to 1e-10 relative (measured at most 1.2e-11), y' to 3e-8 of its largest
    entry (measured 3.6e-9: h' = M^-1 (Q - J^T lam) where Q and J^T lam nearly cancel)."""
    spec = _scene(MECH / f"{name}.toml")
    model = compile_checked(spec)
    lib, _ = kernel.library()
    stop, passing = kernel.Kernel(lib, model, spec.solver), kernel.Kernel(lib, model, _passing(spec))
    sim = Simulation(model, spec.solver)
    y = np.concatenate([model.q0, model.h0])
    for t in np.linspace(0.0, 1.0, 6):
        if t > 0:
            y = sim.advance(t)
        a, b = stop.evaluate(t, y), passing.evaluate(t, y)
        assert a is not None and b is not None
        assert np.max(np.abs(a[1] - b[1])) <= 1e-10 * np.max(np.abs(a[1]))
        assert np.max(np.abs(a[0] - b[0])) <= 3e-8 * np.max(np.abs(a[0]))


def test_projection_is_mass_orthogonal_and_reaches_the_constraints(tmp_path):
    """ovk_project on a state pushed off the N-four-bar's constraints: |Phi| <= tol after, the
    velocities satisfy Phi_h h = 0, and the velocity correction is M-orthogonal to the constraint
    tangent space (M dh in the row space of Phi_h: it does no work along an admissible motion)."""
    _, path = _nfourbar().write(3, tmp_path, singular="pass")
    spec = _scene(path)
    model = compile_checked(spec)
    k = kernel.Kernel(kernel.library()[0], model, spec.solver)
    rng = np.random.default_rng(1)
    y = np.concatenate([model.q0, model.h0]) + 1e-4 * rng.standard_normal(model.n + model.nh)
    yp, drift = k.project(0.0, y)
    phi, J, _ = k.rows(yp)
    assert drift <= kernel.PROJECTION_TOL and np.max(np.abs(phi)) <= kernel.PROJECTION_TOL
    h, hp = y[model.n:], yp[model.n:]
    assert np.max(np.abs(J @ hp)) < 1e-10
    dh = (hp - h) / model.Minv  # M (h* - h)
    coef, *_ = np.linalg.lstsq(J.T, dh, rcond=None)
    # to the round-off of one AL solve: cond(M + alpha J^T J) ~ 1e6 times eps times |M h| (1 kg m/s)
    assert np.max(np.abs(J.T @ coef - dh)) < 1e-9 * np.max(np.abs(h / model.Minv))
    with pytest.raises(kernel.ProjectionFailed, match=r"after 1 corrections"):
        k.project(0.0, y + 1e-1, max_iter=1)


def test_an_expired_elimination_keeps_its_behaviour_under_pass(tmp_path):
    """The parallelogram of tests/test_watch.py with friction on G0 (its reaction is not unique)
    and Phi11 eliminated: only the kept equations lose rank at the upright position, so the run
    stops there as under "stop" (the elimination decides the motion), at the same instant. (Under
    "stop" the friction solve fails on the step into it first, and the failure is reported as the
    expiry; the AL solve takes that step, and the watch finds the expiry after it.)"""
    from test_watch import _parallelogram
    spec = _scene(_parallelogram(tmp_path, "G0", "[11]"))
    model = compile_checked(spec)
    expired = r"the elimination chosen at the start (expires|has expired).*with friction on G0, whose reaction is not unique"
    with pytest.raises(SimulationError, match=expired) as stop:
        run(model, spec.solver)
    with pytest.raises(SimulationError, match=expired) as passing:
        run(model, _passing(spec))
    t_stop, t_pass = (float(str(e.value).split("t = ")[1].split(" s")[0]) for e in (stop, passing))
    assert abs(t_pass - t_stop) < 1e-6


def test_simulate_singular_flag_events_and_refusals(tmp_path, capsys):
    """``overcon simulate --singular pass`` runs through and writes the ``singular`` events;
    the deprecated ``--kernel numpy`` warns and runs the core; a bad scene value is bad input
    (exit 2), named."""
    _, path = _nfourbar().write(2, tmp_path, stop_time=1.5)
    out, events = tmp_path / "o.csv", tmp_path / "ev.csv"
    assert main(["simulate", str(path), "--out", str(out), "--singular", "pass", "--events", str(events)]) == 0
    rows = [r for r in csv.DictReader(events.open()) if r["kind"] != "rank-change"]
    assert [r["kind"] for r in rows] == ["singular", "singular"]
    assert "rank deficient" in rows[0]["detail"] and "passed" in rows[0]["detail"]
    assert main(["simulate", str(path), "--out", str(out)]) == 3  # the default stops at the first
    capsys.readouterr()
    # the deprecated --kernel numpy runs the core, and says so
    assert main(["simulate", str(path), "--out", str(out), "--singular", "pass", "--kernel", "numpy"]) == 0
    assert "--kernel numpy: solver.kernel = 'numpy' is deprecated" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text(path.read_text().replace("[solver]", '[solver]\nsingular = "maybe"'))
    assert main(["simulate", str(bad), "--out", str(out)]) == 2
    assert "solver.singular" in capsys.readouterr().err
