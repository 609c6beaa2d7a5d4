"""The compiled core's failure and fallback statuses, each forced through the Python binding
(overcon.kernel.Kernel), with what each returns: the status, the core's message, the friction
counters, and for the friction solve's stages (Newton, damped Newton, the robust path's fixed
point and finite-difference Newton) a solution whose friction obeys the law at its multipliers
and whose accelerations satisfy the kept rows (tests/test_core_rows.py's checks). Also:
workspaces share nothing (two instances, two threads: the same bits), and a model the core
refuses is refused with its message."""
from __future__ import annotations

import ctypes
import threading
from pathlib import Path

import numpy as np
import pytest

from overcon import kernel, scene as scene_mod
from overcon.checks import compile_checked

from test_core_rows import EQ_REL, check_friction_at, equation_residuals, force_scale
from test_kernel import MECH, kernel_for, spec_of, states

TWO_PINS = Path(__file__).resolve().parent / "data" / "two_pins" / "two_pins_wo3.toml"


def test_singular_position():
    """A bar on two pins with Phi3 (pin2's x row) eliminated: the kept y rows of both pins are
    [0, 1, -+sin phi], so at phi = 0 (unit mass) S has two equal rows of exact numbers and its
    Cholesky pivot is exactly 0. The core returns OVK_SINGULAR naming the pivot and the row; at
    phi = 0.3 it solves the equations of motion."""
    spec = scene_mod.as_scene(scene_mod.load(TWO_PINS))
    model = compile_checked(spec, check_initial=False)
    assert list(model.retained) == [0, 1, 3]
    k = kernel_for(model, spec.solver)
    y = np.zeros(6)
    assert k.evaluate(0.0, y) is None and k.last_status == 1
    assert kernel.STATUS[1] == "singular position (S not positive definite)"
    assert k.last_message == ("singular position: S = Phi_h M^-1 Phi_h^T is not positive definite "
                              "(Cholesky pivot 2 of 3, retained row 3)")
    y[2] = 0.3
    got = k.evaluate(0.0, y)
    assert got is not None and k.last_status == 0 and k.last_message == ""
    Qf, acc, elim = equation_residuals(k, model, spec.solver, y, got)
    assert np.max(np.abs(Qf)) <= EQ_REL * force_scale(model, y, got) and acc <= EQ_REL and elim == 0.0


def assert_solution(k, model, spec, y, got) -> None:
    """got (an evaluation at y) is a solution: the kept acceleration rows hold, the eliminated
    rows carry lam = 0, each friction joint's output at lam is its law, and the returned friction
    forces are a fixed point of the friction solve: warm-started from them, the core's own
    convergence test (residual <= friction_tol (1 + |x|)) holds at the first check, with lam
    within 1e3 friction_tol (1 + |lam|) of the returned one."""
    _, acc, elim = equation_residuals(k, model, spec.solver, y, got)
    assert acc <= EQ_REL and elim == 0.0, acc
    check_friction_at(k, model, spec, y, got, assembled=False)
    limit = k._cmodel.max_iter
    k._cmodel.max_iter = spec.solver.friction_max_iter
    try:
        again = k.evaluate(0.0, y, qf_guess=got[2])
    finally:
        k._cmodel.max_iter = limit
    assert again is not None and again[3] == 1, (k.last_message, again and again[3])
    bound = 1e3 * spec.solver.friction_tol * (1.0 + float(np.max(np.abs(got[1]))))
    assert np.max(np.abs(again[1] - got[1])) <= bound


@pytest.mark.parametrize("name", ["planar_f145_wo6", "spatial_GHMN_wo18"])
def test_newton_finishes_at_the_paper_states(name):
    """Stage 1, the analytic Newton on the friction multipliers: at random states near the paper's
    initial one it finishes, undamped, within its 12 force evaluations, and returns a solution."""
    spec = spec_of(name)
    model = compile_checked(spec)
    k = kernel_for(model, spec.solver)
    done = 0
    for y in states(model, 10, seed=2):
        got = k.evaluate(0.0, y)
        if got is None or k.damped:
            continue
        assert k.last_status == 0 and 1 <= got[3] <= 12
        assert_solution(k, model, spec, y, got)
        done += 1
    assert done >= 5, done


def test_newton_gives_up_and_damped_newton_finishes():
    """Stage 2: spatial states where the undamped Newton on the friction multipliers gives up (it
    grows twice or runs out of its 12 steps) and the damped Newton finishes: the evaluation
    succeeds with ``damped`` set, no message, and a solution."""
    found = 0
    for name in ("spatial_GH_wo9", "spatial_GHMN_wo18"):
        spec = spec_of(name)
        model = compile_checked(spec)
        k = kernel_for(model, spec.solver)
        rng = np.random.default_rng(107)
        for y in states(model, 30, seed=7):
            for lam_guess in (None, rng.standard_normal(model.m)):
                got = k.evaluate(0.0, y, lam_guess)
                if got is None or not k.damped:
                    continue
                found += 1
                assert k.last_status == 0 and k.last_message == "" and k.newton_failed() == 0
                assert_solution(k, model, spec, y, got)
    assert found >= 3, found  # 7 of these 120 evaluations take the damped path (x86-64, glibc)


def test_friction_solve_gives_up():
    """friction_max_iter = 2: neither Newton can finish in two force evaluations. The core returns
    OVK_FRICTION with the damped flag and both counts (``newton_failed``: the total), which is
    where a run goes on with the robust path (test_robust_path_stages); the message names the
    friction joints (planar_f45_wo4: joints 4 and 5, 0-based 3 and 4)."""
    spec = spec_of("planar_f45_wo4", friction_max_iter=2)
    model = compile_checked(spec)
    k = kernel_for(model, spec.solver)
    gave_up = 0
    for y in states(model, 3, seed=1):
        got = k.evaluate(0.0, y)
        if got is not None:  # the initial state at rest: one force evaluation suffices
            assert k.last_status == 0 and not k.damped
            continue
        gave_up += 1
        assert k.last_status == 2 and k.damped and k.newton_failed() == 4
        assert k.last_message == ("friction solve gave up: Newton after 2 force evaluations, damped Newton "
                                  "after 2 more (4 friction multipliers of joints[3], joints[4])")
    assert gave_up == 2


@pytest.mark.parametrize("name,limit", [("planar_f145_wo6", 2), ("spatial_GHMN_wo18", 3)])
def test_robust_path_stages(name, limit):
    """Stages 3 and 4, the robust path (core/friction_robust.c) after both Newtons gave up (the
    model's max_iter set to 2 for the evaluation, so each Newton stops after 2 force
    evaluations): with max_iter = ``limit`` the fixed point cannot converge within ``limit``
    iterations, so a result counting more than ``limit`` iterations was finished by the
    finite-difference Newton; with the scene's 50 the robust path finishes too. Each result is a
    solution. (The core reports the robust path's total count only, not which stage finished:
    with 50 the fixed point converges at the paper's states, but the test cannot tell it apart.)"""
    spec = spec_of(name)
    model = compile_checked(spec)
    k = kernel_for(model, spec.solver)
    by_newton = robust = 0
    try:
        for y in states(model, 12, seed=1):
            for robust_limit in (limit, spec.solver.friction_max_iter):
                k._cmodel.max_iter = 2
                if k.evaluate(0.0, y) is not None:
                    continue
                assert k.last_status == 2 and k.newton_failed() == 4
                k._cmodel.max_iter = robust_limit
                got = k.evaluate_robust(y)
                if got is None:  # (3 iterations each can be too few for the spatial one)
                    assert robust_limit == limit and k.last_status == 2
                    assert k.last_message.startswith("friction solve did not converge")
                    continue
                assert k.last_status == 0 and got[3] <= 2 * robust_limit
                assert_solution(k, model, spec, y, got)
                if robust_limit == limit:
                    by_newton += got[3] > limit
                else:
                    robust += 1
    finally:
        k._cmodel.max_iter = spec.solver.friction_max_iter
    assert by_newton >= 5 and robust >= 10, (by_newton, robust)


def test_non_finite_numbers():
    """A NaN position reaches the multipliers' right-hand side (Baumgarte), an infinite angle
    reaches S through the rotations: OVK_NONFINITE naming where."""
    spec = spec_of("spatial_MN_wo5")
    model = compile_checked(spec)
    k = kernel_for(model, spec.solver)
    y = np.concatenate([model.q0, model.h0])
    bad = y.copy()
    bad[0] = np.nan
    assert k.evaluate(0.0, bad) is None and k.last_status == 4
    assert k.last_message == "non-finite number in the multipliers' right-hand side (row 0)"
    bad = y.copy()
    bad[3] = np.inf  # alpha of the first body: cos and sin are NaN
    assert k.evaluate(0.0, bad) is None and k.last_status == 4
    assert k.last_message.startswith("non-finite number in S = Phi_h M^-1 Phi_h^T (row ")


def test_euler_singularity():
    """|sin beta| below 1e-3: OVK_EULER naming the body (its index) and the value."""
    spec = spec_of("spatial_MN_wo5")
    model = compile_checked(spec)
    k = kernel_for(model, spec.solver)
    y = np.concatenate([model.q0, model.h0])
    y[6 + 4] = -2e-4  # beta of the second body
    assert k.evaluate(0.0, y) is None and k.last_status == 3
    assert k.last_message == "Euler angles singular: body 1 has |sin beta| = 0.0002 < 0.001"


def test_spring_points_coincide(tmp_path):
    """A spring of free length 0.5 m whose points coincide: OVK_SPRING naming the load."""
    text = (MECH / "planar_sliders.toml").read_text().replace("free_length = 3.0", "free_length = 0.5")
    (tmp_path / "planar_sliders.toml").write_text(text)
    (tmp_path / "s.toml").write_text((MECH / "planar_f45_wo4.toml").read_text())
    spec = scene_mod.as_scene(scene_mod.load(tmp_path / "s.toml"))
    model = compile_checked(spec, check_initial=False)
    n = next(i for i, ld in enumerate(model.loads) if ld.type == "spring")
    q = model.q0.copy()
    q[3 * model.loads[n].bi: 3 * model.loads[n].bi + 2] = 0.0
    k = kernel_for(model, spec.solver)
    assert k.evaluate(0.0, np.concatenate([q, model.h0])) is None and k.last_status == 5
    assert k.last_message == (f"spring loads[{n}]: attachment points coincide (distance 0 m) while its free "
                              "length is 0.5 m")


def test_invalid_arguments_and_models_are_refused():
    """An unknown guess mode, or a guess mode without its guess: OVK_INVALID with a message. A
    packed model outside what the core takes (more friction multipliers than equations, a bad body index) gets a
    workspace that refuses every call with the reason; Kernel raises it."""
    spec = spec_of("planar_f145_wo6")
    model = compile_checked(spec)
    k = kernel_for(model, spec.solver)
    py, pyd, plam, pqf, pits, pgq, _, pdamped = k._ptrs
    k._y[:] = np.concatenate([model.q0, model.h0])
    assert k._fn(k._pm, k._data, 0.0, py, 3, pgq, pyd, plam, pqf, pits, pdamped) == 7
    assert k._message() == "evaluate: guess_mode 3 is not 0, 1 or 2"
    assert k._fn(k._pm, k._data, 0.0, py, 1, None, pyd, plam, pqf, pits, pdamped) == 7
    assert k._message() == "evaluate: guess_mode 1 without a guess"
    lib, _ = kernel.library()
    nfj = k._cmodel.nfj  # more multipliers than the friction joints have equations
    for field, value, said in (("nx", 6 * nfj + 1, f"model: {6 * nfj + 1} friction multipliers for {nfj} friction "
                                "joints (at most 6 each)"),
                               ("dim", 3, "dim 3 with 3 coordinates and 3 velocities per body")):
        bad = kernel._CModel.from_buffer_copy(k._cmodel)
        setattr(bad, field, value)
        data = lib.ovk_make_data(ctypes.addressof(bad))
        try:
            assert lib.ovk_data_status(data) == 7 and said in lib.ovk_message(data).decode()
        finally:
            lib.ovk_free_data(data)
    jbi = np.array([c.bi for c in model.joints], np.int32)
    jbi[0] = model.nb  # a body that does not exist
    bad = kernel._CModel.from_buffer_copy(k._cmodel)
    bad.jbi = jbi.ctypes.data
    data = lib.ovk_make_data(ctypes.addressof(bad))
    try:
        assert lib.ovk_data_status(data) == 7
        assert lib.ovk_message(data).decode().startswith("model: joint 0 (type 2, 2 rows, bodies 4 and -1, law 1)")
    finally:
        lib.ovk_free_data(data)


def test_instances_share_nothing():
    """Two kernels of one model, evaluated interleaved in one thread and then concurrently in two
    threads (ctypes releases the GIL during the call), give the bits of one kernel alone."""
    spec = spec_of("spatial_GHMN_wo18")
    model = compile_checked(spec)
    ys = list(states(model, 12, seed=3))
    alone = kernel_for(model, spec.solver)
    want = [alone.evaluate(0.0, y) for y in ys]
    a, b = kernel_for(model, spec.solver), kernel_for(model, spec.solver)
    for y, w in zip(ys, want):
        for k in (a, b):
            got = k.evaluate(0.0, y)
            assert (got is None) == (w is None)
            if w is not None:
                assert all(np.array_equal(g, x) for g, x in zip(got[:3], w[:3])) and got[3] == w[3]
    results = {}

    def work(name, k):
        results[name] = [k.evaluate(0.0, y) for _ in range(20) for y in ys]

    threads = [threading.Thread(target=work, args=(n, k)) for n, k in (("a", a), ("b", b))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for name in ("a", "b"):
        for got, w in zip(results[name], want * 20):
            assert (got is None) == (w is None)
            if w is not None:
                assert all(np.array_equal(g, x) for g, x in zip(got[:3], w[:3]))
