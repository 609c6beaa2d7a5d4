"""The compiled core's failure and fallback statuses, each forced through the Python binding
(overcon.kernel.Kernel), with what each returns: the status, the core's message, the friction
counters; and the numpy path's answer to the same evaluation (it raises or falls back, so a run
fails or continues as it would without the core). Also: workspaces share nothing (two instances,
two threads: the same bits), and a model the core refuses is refused with its message."""
from __future__ import annotations

import ctypes
import dataclasses
import threading
from pathlib import Path

import numpy as np
import pytest

from overcon import kernel, scene as scene_mod
from overcon.checks import compile_checked
from overcon.dynamics import FrictionSolveError
from overcon.evaluation import SingularConfiguration
from overcon.kinematics import EulerSingularity

from test_kernel import MECH, REL, REL_OTHER_COUNT, kernel_for, numpy_eval, rel, spec_of, states

TWO_PINS = Path(__file__).resolve().parent / "data" / "two_pins" / "two_pins_wo3.toml"


def test_singular_position():
    """A bar on two pins with Phi3 (pin2's x row) eliminated: the kept y rows of both pins are
    [0, 1, -+sin phi], so at phi = 0 (unit mass) S has two equal rows of exact numbers and its
    Cholesky pivot is exactly 0. The core returns OVK_SINGULAR naming the pivot and the row; the
    numpy path raises SingularConfiguration; at phi = 0.3 both evaluate."""
    spec = scene_mod.as_scene(scene_mod.load(TWO_PINS))
    model = compile_checked(spec, check_initial=False)
    assert list(model.retained) == [0, 1, 3]
    k = kernel_for(model, spec.solver)
    y = np.zeros(6)
    assert k.evaluate(0.0, y) is None and k.last_status == 1
    assert kernel.STATUS[1] == "singular position (S not positive definite)"
    assert k.last_message == ("singular position: S = Phi_h M^-1 Phi_h^T is not positive definite "
                              "(Cholesky pivot 2 of 3, retained row 3)")
    with pytest.raises(SingularConfiguration, match="singular position"):
        numpy_eval(model, spec.solver, 0.0, y)
    y[2] = 0.3
    got = k.evaluate(0.0, y)
    assert got is not None and k.last_status == 0 and k.last_message == ""
    ref, ev = numpy_eval(model, spec.solver, 0.0, y)
    assert rel(got[0], ref) <= REL


def test_newton_gives_up_and_damped_newton_finishes():
    """Spatial states where the undamped Newton on the friction multipliers gives up (it grows
    twice or runs out of its 12 steps) and the damped Newton finishes: the evaluation succeeds with
    ``damped`` set, no message, and the numpy path's numbers (its own Newton cascade)."""
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
                ref, ev = numpy_eval(model, spec.solver, 0.0, y, lam_guess)
                assert not ev.fallback
                tol = REL if got[3] == ev.iterations else REL_OTHER_COUNT
                assert rel(got[0], ref) <= tol and rel(got[1], ev.lam) <= tol
    assert found >= 3, found  # 7 of these 120 evaluations take the damped path (x86-64, glibc)


def test_friction_solve_gives_up():
    """friction_max_iter = 2: neither Newton can finish in two force evaluations. The core returns
    OVK_FRICTION with the damped flag and both counts (``newton_failed`` hands the total to
    overcon.dynamics, whose fixed-point fallback then solves the evaluation)."""
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
                                  "after 2 more (4 friction multipliers)")
        try:
            _, ev = numpy_eval(model, spec.solver, 0.0, y)
        except FrictionSolveError:
            continue
        assert ev.fallback
    assert gave_up == 2


def test_non_finite_numbers():
    """A NaN position reaches the multipliers' right-hand side (Baumgarte), an infinite angle
    reaches S through the rotations: OVK_NONFINITE naming where; the numpy path raises."""
    spec = spec_of("spatial_MN_wo5")
    model = compile_checked(spec)
    k = kernel_for(model, spec.solver)
    y = np.concatenate([model.q0, model.h0])
    bad = y.copy()
    bad[0] = np.nan
    assert k.evaluate(0.0, bad) is None and k.last_status == 4
    assert k.last_message == "non-finite number in the multipliers' right-hand side (row 0)"
    with pytest.raises(ValueError, match="infs or NaNs"):
        numpy_eval(model, spec.solver, 0.0, bad)
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
    with pytest.raises(EulerSingularity, match="beta = -0.0002 rad"):
        numpy_eval(model, spec.solver, 0.0, y)


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


def _fd_models(tmp_path):
    """Frictionless models of every spatial joint type under both rotations: the example
    mechanisms (quaternions), the paper's spatial mechanism in quaternions, random chains of all
    six spatial types in Euler angles and in quaternions."""
    from test_kernel import example_spec, quaternion_spec, random_axis_model

    for name in ("door_none_wo_hinge2", "carriage_none_wo_rod", "fourbar_none_wo3_4_5", "loop_D_wo_A2"):
        spec = scene_mod.as_scene(example_spec(name), friction=[])
        yield name, spec, compile_checked(spec)
    spec = quaternion_spec(spec_of("spatial_none_wo5"))
    yield "spatial_none_wo5 (quaternions)", spec, compile_checked(spec)
    for rotation in ("euler_zxz", "quaternion"):
        spec, model = random_axis_model(tmp_path, rotation, 1, friction=False)
        yield f"random chain ({rotation})", spec, model


def test_core_rows_match_finite_differences(tmp_path):
    """The core's Phi_h and gamma (Kernel.rows) are the derivatives of its Phi: along q(t) with
    q'(0) the core's coordinate rates (ovk_evaluate's y'[:n]; quaternions with the norm
    stabilisation, which leaves e / |e| and so Phi unchanged to first order), central differences
    (step 1e-6) give d Phi/dt = Phi_h h and d(Phi_h h)/dt = -gamma (h held fixed) to 1e-7
    relative: the truncation error (1e-12) and round-off (1e-10) are far below that, a wrong
    entry of Phi_h or gamma (a sign, a term) far above."""
    eps = 1e-6
    for name, spec, model in _fd_models(tmp_path):
        k = kernel_for(model, spec.solver)
        n = model.n
        for y in states(model, 6, seed=11):
            got = k.evaluate(0.0, y)
            assert got is not None, (name, k.last_message)
            qd, h = got[0][:n], y[n:]
            phi, J, gam = k.rows(y)
            shifted = []
            for sign in (1.0, -1.0):
                z = y.copy()
                z[:n] += sign * eps * qd
                shifted.append(k.rows(z))
            dphi = (shifted[0][0] - shifted[1][0]) / (2 * eps)
            dJh = (shifted[0][1] @ h - shifted[1][1] @ h) / (2 * eps)
            assert rel(dphi, J @ h) <= 1e-7, (name, rel(dphi, J @ h))
            assert rel(dJh, -gam) <= 1e-7, (name, rel(dJh, -gam))
