"""The run in C (core/sim.c over core/integrate_rk.c and integrate_radau.c, through
overcon.kernel.Run), checked by what it must do rather than against another implementation: a byte
state that restores a run exactly, work budgets and stop reasons, rk4's stability guard on a
linear case where its stable step is known, two runs in one process or in two threads giving the
same bits (no global mutable state), the watch's stops and re-chosen eliminations against the
geometry and against runs that do not need them, the energy ledger's balance, and the friction
solve's robust path returning solutions the core's Newton accepts."""
from __future__ import annotations

import dataclasses
import threading
from pathlib import Path

import numpy as np
import pytest

from overcon import kernel, scene as scene_mod
from overcon.checks import compile_checked

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
GLOBAL = 30.0
"""The global error of a run allowed, in tolerances (tests/test_core_integrators.py: measured 0.27
to 9.6 against SciPy's DOP853 on the paper's scenes and a quaternion example)."""


def setup(name, method, stop_time=0.6, mu=None, **solver):
    sc = scene_mod.as_scene(scene_mod.load(MECH / f"{name}.toml"), stop_time=stop_time)
    if mu is not None:
        sc = dataclasses.replace(sc, friction_params={k: dataclasses.replace(v, mu=mu)
                                                      for k, v in sc.friction_params.items()})
    model = compile_checked(sc)
    return model, dataclasses.replace(sc.solver, kernel="c", method=method, **solver)


def rel(a, b) -> float:
    """The largest difference relative to max(1, |b|), entry by entry."""
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b)) / np.maximum(1.0, np.abs(np.asarray(b))), initial=0.0))


def positions(model, y):
    return np.asarray(y)[[i for _, i in model.position_outputs]]


@pytest.mark.parametrize("method", ["dopri5", "rk4", "dop853", "radau"])
def test_state_bytes_restore_the_run_bit_for_bit(method):
    """get_state at t1, continue to t2 (outputs inside a step: dop853's dense coefficients and
    radau's LU factors are part of the bytes); set_state and continue again: the same bits and
    counters; a state of another run (other sizes), of the same model under another method, or a
    truncated one is refused and leaves the run as it was."""
    model, solver = setup("planar_f145_wo6", method)
    run = kernel.Run(model, solver)
    run.advance(0.2)
    saved = run.get_state()
    a = [run.advance(t) for t in (0.23, 0.31, 0.4)]
    info_a = run.info
    run.set_state(saved)
    b = [run.advance(t) for t in (0.23, 0.31, 0.4)]
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert {k: v for k, v in run.info.items() if k not in kernel.WALL_TIMES} == {
        k: v for k, v in info_a.items() if k not in kernel.WALL_TIMES}
    other = kernel.Run(*setup("planar_none_wo4", method))
    with pytest.raises(kernel.RunStopped, match="set state"):
        other.set_state(saved)
    other_method = kernel.Run(model, dataclasses.replace(solver, method="dopri5" if method == "radau" else "radau"))
    with pytest.raises(kernel.RunStopped, match="set state: "):
        other_method.set_state(saved)
    with pytest.raises(kernel.RunStopped, match="set state"):
        run.set_state(saved[:-8])
    assert np.array_equal(run.y, b[-1]) or run.info["t"] >= 0.4


def test_step_budget_stops_the_run_and_a_call_budget_too():
    """The life budget (max_steps) and one call's budget stop with status 11, naming the steps."""
    model, solver = setup("planar_f45_wo4", "dopri5")
    run = kernel.Run(model, solver, max_steps=5)
    with pytest.raises(kernel.RunStopped, match=r"work budget exhausted: 5 internal steps \(max_steps = 5\)") as e:
        run.advance(0.5)
    assert e.value.status == 11 and run.info["nsteps"] == 5
    run = kernel.Run(model, solver)
    with pytest.raises(kernel.RunStopped, match=r"integration stopped: .*4 internal steps > 3 allowed for this step"):
        run.advance(0.5, max_steps=3)


def test_wall_time_budgets_stop_the_run():
    """The run's wall-time budget (max_wall_time) and one call's stop with status 11, naming it."""
    model, solver = setup("planar_f45_wo4", "dopri5")
    with pytest.raises(kernel.RunStopped, match=r"work budget exhausted: wall time .*\(max_wall_time = 1e-09 s\)") as e:
        kernel.Run(model, solver, max_wall_time=1e-9).advance(0.5)
    assert e.value.status == 11
    with pytest.raises(kernel.RunStopped, match=r"s wall time > 1e-09 s allowed for this step") as e:
        kernel.Run(model, solver).advance(0.5, max_wall_time=1e-9)
    assert e.value.status == 11


@pytest.mark.parametrize("method", ["dopri5", "rk4"])
def test_settings_the_core_cannot_take_are_refused(method):
    """A tolerance, max_step or fixed step that is not a positive finite number is refused when the
    run is made (status and words), never clamped."""
    model, solver = setup("planar_f45_wo4", method)
    bad = {"dopri5": [{"tolerance": 0.0}, {"tolerance": float("nan")}, {"max_step": -1.0}],
           "rk4": [{"step": 0.0}, {"step": float("inf")}]}[method]
    for change in bad:
        with pytest.raises(kernel.RunStopped, match="cannot start: .*not a method and settings the C integrators take"):
            kernel.Run(model, dataclasses.replace(solver, **change))


SLIDER = """[mechanism]
name = "slider"
kind = "planar"
gravity = [0.0, -9.81]
[[bodies]]
name = "block"
mass = 2.0
inertia = 1.0
q0 = [0.0, 0.0, 0.0]
h0 = [V0, 0.0, 0.0]
[[joints]]
name = "guide"
type = "translational"
body_i = "block"
body_j = "base"
s_A = [0.0, 0.0]
s_B = [0.0, 0.0]
v = [0.0, 1.0]
psi = 0.0
[joints.friction]
law = "regularised"
mu = 0.1
length = 0.2
v_reg = 1e-3
"""


def _linear_slider(tmp_path, step):
    """A block on a horizontal guide with friction, moving at 1e-5 m/s, inside the regularisation
    band (1e-3 m/s) at every stage of the steps below: its motion along the guide is linear,
    v' = -lambda v, with lambda = mu N / (m v_reg) = mu g / v_reg ~ 981 1/s. lambda is read off the
    core's right-hand side (a difference quotient, exact for a linear law up to round-off)."""
    (tmp_path / "slider.toml").write_text(SLIDER.replace("V0", "1e-5"))
    sc = scene_mod.as_scene(scene_mod.load(tmp_path / "slider.toml"), friction=["guide"], stop_time=1.0)
    model = compile_checked(sc)
    solver = dataclasses.replace(sc.solver, kernel="c", method="rk4", step=step)
    k = kernel.Kernel(kernel.library()[0], model, solver)
    y0 = np.concatenate([model.q0, model.h0])
    y1 = y0.copy()
    y1[model.n] *= 0.5
    lam = -(k.evaluate(0.0, y0)[0][model.n] - k.evaluate(0.0, y1)[0][model.n]) / (y0[model.n] - y1[model.n])
    assert lam == pytest.approx(0.1 * 9.81 / 1e-3, rel=1e-9)
    return model, solver, lam


@pytest.mark.parametrize("h_lambda, stable", [(2.5, True), (2.78, True), (2.8, False), (10.0, False)])
def test_rk4_refuses_a_step_beyond_its_stability_boundary(tmp_path, h_lambda, stable):
    """y' = -lambda y along the guide: rk4's amplification |R(-h lambda)| exceeds 1 beyond
    h lambda = 2.785; the guard's estimate of rho from the stages is exact for a linear problem
    (k2 - k1 is an eigenvector here), so it trips exactly there, refuses the step (time, state and
    counters kept), and names 2 / lambda as a stable step, in its words and as data (within 1e-9:
    round-off and the friction solve's tolerance, 1e-12); the comparison's lockstep grid reads it."""
    from overcon.verdict import next_lockstep_step

    model, solver, lam = _linear_slider(tmp_path, 1.0)
    h = h_lambda / lam
    run = kernel.Run(model, dataclasses.replace(solver, step=h))
    y0 = run.y
    if stable:
        for _ in range(5):
            run.step()
        assert 0.0 < abs(run.y[model.n]) < abs(y0[model.n])  # damped
        return
    with pytest.raises(kernel.RunStopped, match=r"t = 0 s: rk4 is unstable with the fixed step") as exc:
        run.step()
    info = run.info
    assert exc.value.status == 10 and info["t"] == 0.0 and info["nsteps"] == 0 and np.array_equal(run.y, y0)
    assert exc.value.stable_step == pytest.approx(2.0 / lam, rel=1e-9)
    assert f"a step of at most {2.0 / lam:.2g} s is stable" in str(exc.value)
    assert next_lockstep_step(h, [exc.value.stable_step]) <= 2.0 / lam


def test_rk4_unstable_on_sticking_friction_names_a_stable_step():
    """rk4 beyond its stability boundary on the paper's sliders sticking (mu = 1, a step of 20 ms):
    the run stops (status 10) at the end of its last accepted step, the time its words name; the
    stable step it names is 2 / rho with the rho of its words. (The estimate of rho from the stages
    is exact only for a linear problem: test_rk4_refuses_a_step_beyond_its_stability_boundary.)"""
    model, solver = setup("planar_f145_wo6", "rk4", mu=1.0, step=0.02, stop_time=1.0)
    run = kernel.Run(model, solver)
    with pytest.raises(kernel.RunStopped) as c:
        run.advance(1.0)
    assert c.value.status == 10 and c.value.stable_step > 0.0
    rho = float(str(c.value).split(", rho = ")[1].split(" 1/s")[0])
    assert c.value.stable_step == pytest.approx(2.0 / rho, rel=1e-2)  # rho printed to 3 digits
    t_stop = run.info["t"]
    assert c.value.stable_step < solver.step and str(c.value).startswith(f"integration stopped: t = {t_stop:.9g} s")
    assert run.y is not None and np.all(np.isfinite(run.y))


def _identical(a, b):
    return all(np.array_equal(x, y) for x, y in zip(a, b))


@pytest.mark.parametrize("method", ["dopri5", "radau"])
def test_two_runs_in_one_process_and_in_two_threads_give_the_same_bits(method):
    """No global mutable state: a run alone, two runs stepped in turn in one process, and two runs
    in two threads at once (ctypes lets go of the GIL in the core) read the same bits on a grid,
    and the same counters."""
    model, solver = setup("planar_f145_wo6", method)
    grid = np.arange(0.0, 0.6, 0.0123)[1:]

    def alone():
        run = kernel.Run(model, solver)
        out = [run.advance(t) for t in grid]
        return out, {k: v for k, v in run.info.items() if k not in kernel.WALL_TIMES}
    want, info = alone()
    a, b = kernel.Run(model, solver), kernel.Run(model, solver)
    in_turn = [(a.advance(t), b.advance(t)) for t in grid]
    assert _identical([x for x, _ in in_turn], want) and _identical([y for _, y in in_turn], want)
    results = [None, None]

    def work(slot):
        results[slot] = alone()
    threads = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    for got, got_info in results:
        assert _identical(got, want) and got_info == info


def _singular_sliders(tmp_path):
    text = (MECH / "planar_sliders.toml").read_text().replace("free_length = 3.0", "free_length = 0.0")
    (tmp_path / "l0.toml").write_text(text)
    sc = scene_mod.as_scene(scene_mod.load(tmp_path / "l0.toml"), stop_time=2.0)
    return compile_checked(sc), dataclasses.replace(sc.solver, kernel="c")


def _instant(msg: str) -> float:
    return float(msg.split("t = ")[1].split(" s")[0])


def test_singular_position_is_located_between_the_steps_whatever_the_method(tmp_path):
    """The sliders driven through K = L = O (free length 0): a finite step jumps over the rank
    loss; the run sees r fall then rise inside one step, locates its minimum on the dense output
    (golden section), judges the whole Jacobian rank deficient there and stops (status 12). dopri5
    and rk4 (1 ms) locate it at dop853's instant at 1e-10 within 1e-5 s (the sliders move at 5.7
    m/s there; measured 1e-6 s apart), where K and L meet O: 1 ms before it the sliders' origins
    are within the way they cover in that time of the base's origin."""
    model, solver = _singular_sliders(tmp_path)
    stops = {}
    for method, tol in (("dop853", 1e-10), ("dopri5", 1e-9), ("rk4", 1e-9)):
        run = kernel.Run(model, dataclasses.replace(solver, method=method, tolerance=tol))
        with pytest.raises(kernel.RunStopped) as c:
            run.advance(2.0)
        assert c.value.status == 12 and "rank deficient (rank 10 < 11" in str(c.value)
        if method != "dop853":
            assert "the motion passed a singular position (between the steps" in str(c.value)
        stops[method] = _instant(str(c.value))
    assert max(stops.values()) - min(stops.values()) <= 1e-5, stops
    probe = kernel.Run(model, dataclasses.replace(solver, method="dop853", tolerance=1e-10))
    y = probe.advance(stops["dop853"] - 1e-3)
    speed = np.max(np.abs(y[model.n:]))
    names = [n for n, _ in model.position_outputs]
    at = dict(zip(names, positions(model, y)))
    near = 2e-3 * speed  # the way covered in the last 1 ms, twice: the speed changes within it
    assert abs(at["slider1.x"]) <= near and abs(at["slider2.y"]) <= near


def _watch_scene(path, stop_time, **solver):
    sc = scene_mod.as_scene(scene_mod.load(path), stop_time=stop_time)
    model = compile_checked(sc)
    return model, dataclasses.replace(sc.solver, kernel="c", **solver)


def test_n_four_bar_flat_position_stops_every_method_at_the_same_instant(tmp_path):
    """The N-four-bar (2 loops, eliminated form) reaches its flat position, an even-multiplicity
    rank loss where no singular value changes sign: dopri5 and radau stop there (status 12; inside
    a step or at a step's end in the watch's band) at one instant within 1e-5 s, the flat position of
    tests/test_watch.py (0.70-0.73 s, from the energy)."""
    import subprocess
    import sys
    subprocess.run([sys.executable, str(MECH / "examples" / "nfourbar.py"), "2", "--out", str(tmp_path)], check=True,
                   capture_output=True)
    stops = []
    for method in ("dopri5", "radau"):
        model, solver = _watch_scene(tmp_path / "nfourbar_2_scene.toml", 1.0, method=method)
        with pytest.raises(kernel.RunStopped) as c:
            kernel.Run(model, solver).advance(1.0)
        assert c.value.status == 12 and "singular position" in str(c.value) and "rank deficient" in str(c.value)
        stops.append(_instant(str(c.value)))
    assert abs(stops[0] - stops[1]) <= 1e-5 and 0.70 < stops[0] < 0.73, stops


def test_expired_elimination_is_chosen_again_and_the_motion_is_the_valid_eliminations(tmp_path):
    """The parallelogram eliminating Phi11 (tests/test_watch.py): at the upright position only the
    kept equations lose rank; the run chooses them again there (one elimination-reselected event),
    takes the step anew and goes on. The motion does not depend on the elimination (no friction),
    so it is that of the same scene under "auto" (valid at the upright position) within two runs'
    global errors (2 GLOBAL tolerances); a state saved after the event restores the kept set."""
    from test_watch import _parallelogram
    model, solver = _watch_scene(_parallelogram(tmp_path, None, "[11]"), 0.3)
    run = kernel.Run(model, solver)
    y = run.advance(0.3)
    (t_event, kind, detail), = run.events
    assert kind == "elimination-reselected" and detail.startswith("eliminated [11] -> [") and 0.0 < t_event < 0.3
    auto_model, auto_solver = _watch_scene(_parallelogram(tmp_path, None, '"auto"'), 0.3)
    auto = kernel.Run(auto_model, auto_solver)
    assert rel(positions(model, y), positions(auto_model, auto.advance(0.3))) <= 2 * GLOBAL * solver.tolerance
    assert not auto.events
    saved, later = run.get_state(), run.advance(0.4)
    again = kernel.Run(model, solver)
    again.set_state(saved)
    assert np.array_equal(again.advance(0.4), later)


def test_degrading_elimination_is_chosen_again_whatever_the_method():
    """The Bricard linkage eliminating Phi2: near 1.23 s the kept equations become ill-conditioned
    (r < 1e-3) while the whole Jacobian is not; dopri5 and radau each choose the elimination again
    at a step's end (the event names the ratio) and go on to 1.3 s, where their positions agree
    within two runs' global errors."""
    path = Path(__file__).resolve().parent / "data" / "bricard" / "bricard_wo2.toml"
    ends = []
    for method in ("dopri5", "radau"):
        model, solver = _watch_scene(path, 1.3, method=method)
        run = kernel.Run(model, solver)
        ends.append(positions(model, run.advance(1.3)))
        (t_event, kind, detail), = run.events
        assert kind == "elimination-reselected" and detail.startswith("eliminated [2] -> ")
        assert "became ill-conditioned: sigma_min/sigma_max" in detail and 1.1 < t_event < 1.3
    assert rel(ends[0], ends[1]) <= 2 * GLOBAL * solver.tolerance


def test_parallelogram_without_expiry_runs_through_and_keeps_the_motion(tmp_path):
    """The same parallelogram under "auto" (valid at the upright position): the watch sees r dip
    and rise without a stop or an event, and before the upright position the motion is that of the
    [11] elimination (valid there) within two runs' global errors."""
    from test_watch import _parallelogram
    model, solver = _watch_scene(_parallelogram(tmp_path, None, '"auto"'), 0.6)
    run = kernel.Run(model, solver)
    early = run.advance(0.1)
    run.advance(0.6)
    assert not run.events and run.info["nsteps"] > 20 and 0.0 < run.info["min_ratio"] < 1.0
    other_model, other_solver = _watch_scene(_parallelogram(tmp_path, None, "[11]"), 0.6)
    other = kernel.Run(other_model, other_solver)
    assert rel(positions(model, early), positions(other_model, other.advance(0.1))) <= 2 * GLOBAL * solver.tolerance


@pytest.mark.parametrize("name, method", [("planar_f145_wo6", "dopri5"), ("examples/carriage_guide_wo_rod", "rk4"),
                                          ("planar_sliders", "dopri5"), ("examples/door_h1_wo_hinge2", "radau")])
def test_c_run_energy_ledger_balances(name, method):
    """Friction, constant forces and torques, springs, quaternions: on an output grid that does
    not meet the steps, kinetic + potential + dissipated - applied stays within 1e-7 J of its
    start at tolerance 1e-10 (and rk4 at 1 ms: its error is about the 1e-10 tolerance's, see
    test_core_integrators.py), the bound of tests/test_state_outputs.py; dissipated work never
    decreases; a state restored restores the ledger; a run without the ledger evaluates less and
    reads zero work."""
    model, solver = setup(name, method, stop_time=0.5, tolerance=1e-10)
    model = dataclasses.replace(model, energy_outputs=True)
    run = kernel.Run(model, solver)
    grid = np.arange(0.0, 0.5, 0.0123)[1:]
    e = np.array([run.energies(t, run.advance(t)) for t in grid])
    balance = e[:, 0] + e[:, 1] + e[:, 2] - e[:, 3]
    assert np.max(np.abs(balance - balance[0])) <= 1e-7, np.max(np.abs(balance - balance[0]))
    assert np.all(np.diff(e[:, 2]) >= 0.0)
    assert np.ptp(e[:, 0]) > 0.1  # energy is exchanged: the mechanism moves
    saved = run.get_state()
    later = run.energies(0.5, run.advance(0.5))
    run.set_state(saved)
    assert np.array_equal(run.energies(0.5, run.advance(0.5)), later)
    plain = kernel.Run(model, solver, energy=False)  # no ledger: no extra evaluations, the work reads 0
    plain.advance(0.5)
    assert plain.info["evaluations"] < run.info["evaluations"] or not model.friction_joints
    assert np.array_equal(plain.energies(0.5, plain.y)[2:], [0.0, 0.0])


def test_failed_step_of_an_expiring_elimination_stops_the_run_naming_the_valid_eliminations(tmp_path):
    """The parallelogram eliminating Phi11 with friction mu = 0.5 on G0 (tolerance 1e-8): the
    step over the upright position fails (the friction solve); r was falling fast enough to reach
    0 within two steps while all equations keep their rank, so the elimination expiring is the
    cause. The reaction of G0 is not unique, so the run stops there (status 14) naming the instant,
    the failure and why it stops."""
    from test_watch import _parallelogram
    model, solver = _watch_scene(_parallelogram(tmp_path, "G0", "[11]"), 0.6)
    model = compile_checked(dataclasses.replace(model.scene, friction_params={
        k: dataclasses.replace(v, mu=0.5) for k, v in model.scene.friction_params.items()}))
    solver = dataclasses.replace(solver, tolerance=1e-8)
    with pytest.raises(kernel.RunStopped) as c:
        kernel.Run(model, solver).advance(0.6)
    msg = str(c.value)
    assert c.value.status == 14
    assert "the kept equations lose rank here while the mechanism stays regular: the elimination chosen at the " \
           "start expires (the step from t = " in msg and "failed: t = " in msg and "friction solve" in msg
    assert "; with friction on G0, whose reaction is not unique, the elimination decides the motion, so the run " \
           "stops (eliminated: Phi11; other eliminations valid at the start and here: [" in msg


def test_robust_friction_path_returns_solutions_newton_accepts():
    """States where the core's Newton and damped Newton give up (spatial paper mechanism, mu up
    to 3, fast random velocities), cold-started: where the robust path (fixed point, then
    finite-difference Newton) converges, its multipliers, given back to the core's Newton as the
    start, are accepted (the same within 1e-9 relative, what two solves to the friction tolerance
    can differ by): they solve the friction equations; where it fails, it says so."""
    outcomes = {"converged": 0, "failed": 0}
    for name in ("spatial_MN_wo5", "spatial_GHMN_wo18"):
        for mu in (1.0, 3.0):
            model, solver = setup(name, "dopri5", mu=mu)
            k = kernel.Kernel(kernel.library()[0], model, solver)
            rng = np.random.default_rng(1)
            for _ in range(30):
                y = np.concatenate([model.q0 + 0.05 * rng.standard_normal(model.n),
                                    model.h0 + 3.0 * rng.standard_normal(model.nh)])
                if k.evaluate(0.0, y) is not None or k.last_status != 2:
                    continue
                c = k.evaluate_robust(y)
                if c is None:
                    assert k.last_status == 2 and "did not converge" in k.last_message
                    outcomes["failed"] += 1
                    continue
                again = k.evaluate(0.0, y, c[1])
                assert again is not None, k.last_message
                assert rel(again[1], c[1]) <= 1e-9 and rel(again[0], c[0]) <= 1e-9
                outcomes["converged"] += 1
    assert outcomes["converged"] >= 5 and outcomes["failed"] >= 5, outcomes
