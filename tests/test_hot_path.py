"""The batched joint modules (the only production form), Model.plan, vectorized frames and
coordinate rates and the direct LAPACK calls in dynamics against the plain per-joint reference
(tests/reference_joints), at random configurations of both paper mechanisms. The batched forms
reproduce the per-joint arithmetic exactly; the tolerance here is 1e-14 (relative to the array's
scale), and the reported outputs (reactions, friction forces) are checked bit for bit."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import reference_joints as ref
from overcon import dynamics, evaluation
from overcon import scene as scene_mod
from overcon.evaluation import (applied_forces, constraints, coordinate_rates, frames, friction_output, gamma,
                                generalized_force, jacobian_h, physical_reaction)
from overcon.joints import TYPES
from overcon.kinematics import cross3, cross3_rows, euler_H, euler_H_rows, euler_R, euler_R_rows
from overcon.model import build_plan
from overcon.checks import compile_checked

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
SCENES = ["planar_f145_wo4", "planar_f45_wo6", "spatial_GHMN_wo5", "spatial_MN_wo18"]
TOL = 1e-14


def close(a, b, tol=TOL):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert a.shape == b.shape
    scale = max(1.0, float(np.max(np.abs(b), initial=0.0)))
    assert np.max(np.abs(a - b), initial=0.0) <= tol * scale


def model_of(name, **scene_changes):
    spec = scene_mod.as_scene(scene_mod.load(MECH / f"{name}.toml"))
    if scene_changes:
        spec = dataclasses.replace(spec, **scene_changes)
    return compile_checked(spec)


def random_states(model, n=25, seed=0, scale=0.4):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        q = model.q0 + scale * rng.standard_normal(model.n)
        h = 2.0 * rng.standard_normal(model.nh)
        yield q, h


def applied_forces_reference(model, f):
    """The per-body/per-load form of applied_forces (np.cross for the gyroscopic terms)."""
    nb, d, k = model.nb, model.dim, model.nq_b
    Q = np.zeros((nb, k))
    Q[:, :d] = model.mass[:, None] * model.gravity[None, :]
    if model.kind == "spatial":
        Q[:, 3:] -= np.cross(f.w[:nb], model.inertia * f.w[:nb])
    for ld in model.loads:
        if ld.type == "force":
            Q[ld.bi, :d] += ld.value
        elif ld.type == "torque":
            Q[ld.bi, d:] += ld.value if model.kind == "planar" else f.R[ld.bi].T @ ld.value
        else:
            pi = f.r[ld.bi] + f.R[ld.bi] @ ld.s_i
            pj = f.r[ld.bj] + f.R[ld.bj] @ ld.s_j
            dvec = pi - pj
            length = float(np.linalg.norm(dvec))
            F = -ld.stiffness * (length - ld.free_length) * dvec / length
            for b, point, sign in ((ld.bi, pi, 1.0), (ld.bj, pj, -1.0)):
                if b >= 0:
                    Q[b] += generalized_force(model, f, b, point, sign * F)
    return Q.reshape(-1)


@pytest.mark.parametrize("name", SCENES)
def test_batched_assembly_equals_per_joint(name):
    model = model_of(name)
    for q, h in random_states(model):
        f = frames(model, q, h)
        close(constraints(model, f), ref.constraints(model, f))
        close(jacobian_h(model, f), ref.jacobian(model, f))
        close(gamma(model, f), ref.gamma(model, f))
        close(applied_forces(model, f), applied_forces_reference(model, f))


@pytest.mark.parametrize("name", SCENES)
def test_batched_joint_functions_equal_single(name):
    """Every joint module's batch against the per-joint reference, joint by joint."""
    model = model_of(name)
    plan = model.plan
    for q, h in random_states(model, n=10, seed=1):
        f = frames(model, q, h)
        for g in plan.groups:
            mod = g.module
            js = [model.joints[j] for j in g.joints]
            phi = mod.phi(g.data, f)
            Ji, Jj = mod.jac_h(g.data, f)
            gam = mod.gamma(g.data, f)
            A = mod.reaction_transform(g.data, f)
            for n, c in enumerate(js):
                close(phi[n], ref.ref(c).phi(c, f))
                close(Ji[n], ref.ref(c).jac_h(c, f)[0])
                close(Jj[n], ref.ref(c).jac_h(c, f)[1])
                close(gam[n], ref.ref(c).gamma(c, f))
                close(A[n], ref.ref(c).reaction_transform(c, f))


@pytest.mark.parametrize("name", SCENES + ["planar_f45_wo4", "spatial_GHMN_wo9"])
def test_reported_outputs_bitwise_equal_per_joint(name):
    """The reported reactions and friction forces (a joint as a batch of one) are bit for bit the
    per-joint reference's: what ci/baselines recorded before the single forms were removed."""
    model = model_of(name, friction_outputs="all")
    rng = np.random.default_rng(8)
    for q, h in random_states(model, n=10, seed=9):
        f = frames(model, q, h)
        lam = 50.0 * rng.standard_normal(model.m)
        lam[rng.integers(0, model.m)] = 0.0
        for c in model.joints:
            assert np.array_equal(physical_reaction(model, c, f, lam), ref.physical_reaction(model, c, f, lam))
        for j in model.friction_joints:
            c = model.joints[j]
            assert friction_output(model, c, f, lam) == ref.friction_output(model, c, f, lam)


@pytest.mark.parametrize("name", SCENES)
def test_batched_friction_equals_per_joint(name):
    model = model_of(name)
    plan = model.plan
    R = model.retained
    rng = np.random.default_rng(2)
    for q, h in random_states(model, n=15, seed=3):
        f = frames(model, q, h)
        ctx = dynamics._friction_setup(plan, f)
        lr = 50.0 * rng.standard_normal(len(R))
        lam = np.zeros(model.m)
        lam[R] = lr
        Qf = np.zeros(model.nh)
        Qf[plan.friction_cols] = dynamics._friction_forces_reduced(plan, ctx, lr[plan.friction_xrows])[0]
        close(Qf, ref.friction_generalized(model, f, lam))
        for g, cx in zip(plan.friction, ctx):  # joint by joint, with the joint's own fi
            lam_rows = np.concatenate((lr[plan.friction_xrows], [0.0]))[g.x_index]
            Qi, Qj = g.module.friction(g.data, cx, lam_rows)
            for n, j in enumerate(g.joints):
                c = model.joints[j]
                ref_i, ref_j = ref.ref(c).friction(c, f, ref.reaction_on_body_i(model, c, f, lam), c.law)
                close(Qi[n], ref_i)
                close(Qj[n], ref_j)


def test_spherical_friction_zero_reaction_gives_zero_force():
    model = model_of("spatial_GHMN_wo5")
    f = frames(model, model.q0 + 0.1, model.h0 + 1.0)
    g = model.plan.friction[0]
    cx = g.module.friction_setup(g.data, f)
    lam = np.ones((len(g.joints), 3))
    lam[1] = 0.0
    Qi, Qj = g.module.friction(g.data, cx, lam)
    assert np.all(Qi[1] == 0.0) and np.all(Qj[1] == 0.0)
    force = g.module.friction_force(g.data, cx, lam)
    assert force[1] == 0.0 and force[0] > 0.0
    c = model.joints[g.joints[0]]
    expected = ref.ref(c).friction(c, f, ref.ref(c).jac_h(c, f)[0].T @ lam[0], c.law)
    close(Qi[0], expected[0])
    close(Qj[0], expected[1])


@pytest.mark.parametrize("name", ["planar_f145_wo4", "spatial_GHMN_wo5"])
def test_frames_and_coordinate_rates(name):
    model = model_of(name)
    for q, h in random_states(model, n=10, seed=4):
        f = frames(model, q, h)
        qd = coordinate_rates(model, q, h)
        if model.kind == "spatial":
            for b in range(model.nb + 1):
                close(f.R[b], euler_R(f.angles[b]))
            ref = h.copy()
            for b in range(model.nb):
                s = model.body_slice(b)
                ref[s][3:] = euler_H(q[s][3:]) @ h[s][3:]
            close(qd, ref)
        else:
            close(qd, h)


def test_batched_kinematics_helpers():
    rng = np.random.default_rng(5)
    ang = rng.uniform(-4, 4, (200, 3))
    ang[:, 1] = np.where(np.abs(np.sin(ang[:, 1])) < 1e-2, 1.0, ang[:, 1])
    close(euler_R_rows(ang), np.array([euler_R(a) for a in ang]))
    close(euler_H_rows(ang), np.array([euler_H(a) for a in ang]))
    a, b = rng.standard_normal((200, 3)), rng.standard_normal((200, 3))
    close(cross3_rows(a, b), np.array([cross3(x, y) for x, y in zip(a, b)]))


def test_coordinate_rates_singularity_names_first_body():
    model = model_of("spatial_MN_wo5")
    q = model.q0.copy()
    q[model.body_slice(2)][4] = 0.0  # beta of link3
    q[model.body_slice(4)][4] = 0.0  # beta of link5
    with pytest.raises(ArithmeticError, match="link3"):
        coordinate_rates(model, q, model.h0)


def test_plan_follows_replaced_model():
    """A model whose retained equations were replaced gets its own matching plan (built by
    Model.__post_init__; no cache), and a Model's arrays cannot be written to."""
    model = model_of("planar_f45_wo4")
    row = model.joints[model.friction_joints[0]].rows[0]  # a friction row, retained in model
    assert row in model.retained and len(model.plan.friction_xrows) == sum(len(model.joints[j].rows)
                                                                          for j in model.friction_joints)
    other = dataclasses.replace(model, retained=np.array([i for i in range(model.m) if i != row]))
    expected = build_plan(other)
    assert len(other.plan.friction_xrows) == len(model.plan.friction_xrows) - 1  # the eliminated row reads 0
    assert np.array_equal(other.plan.friction_xrows, expected.friction_xrows)
    for arr in (model.q0, model.M, model.retained, model.joints[0].p["s_A"], model.plan.groups[0].data["s_A"],
                model.plan.groups[0].flat_i):
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 1.0


def test_lapack_wrappers_keep_scipy_errors():
    S = np.array([[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(np.linalg.LinAlgError, match="leading minor"):
        dynamics._cho_factor(S)
    with pytest.raises(ValueError, match="infs or NaNs"):
        dynamics._cho_factor(np.array([[np.nan, 0.0], [0.0, 1.0]]))
    factor = dynamics._cho_factor(np.array([[4.0, 2.0], [2.0, 3.0]]))
    with pytest.raises(ValueError, match="infs or NaNs"):
        dynamics._cho_solve(factor, np.array([np.inf, 1.0]))
    from scipy.linalg import cho_factor, cho_solve
    b = np.array([1.0, -2.0])
    ref = cho_solve(cho_factor(np.array([[4.0, 2.0], [2.0, 3.0]])), b)
    assert np.array_equal(dynamics._cho_solve(factor, b), ref)
    rng = np.random.default_rng(7)
    for n in (1, 2, 3):
        A, f = rng.standard_normal((6, n)), rng.standard_normal(6)
        assert np.array_equal(dynamics._lstsq(A, f, 1e-12), np.linalg.lstsq(A, f, rcond=1e-12)[0])


def test_every_joint_type_has_one_batched_form():
    """Each joint module has the batched functions only: no single-joint Phi next to a batch one."""
    for name, jt in TYPES.items():
        mod = jt.module
        friction = ("friction_setup", "friction", "friction_force") if jt.friction_size is not None else ()
        for fn in ("constants", "stack", "phi", "jac_h", "gamma", "reaction", *friction):
            assert callable(getattr(mod, fn, None)), (name, fn)
        assert not [n for n in vars(mod) if n.startswith("batch_")], name


def _same_bits(a, b):
    """Equal values of a friction context entry (arrays, lists, frames) bit for bit."""
    if isinstance(a, (np.ndarray, list, tuple)):
        a, b = np.asarray(a, float), np.asarray(b, float)
        return a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))
    return a is b


@pytest.mark.parametrize("name", SCENES + ["examples/door_h1_wo_hinge2", "examples/carriage_guide_wo_rod",
                                           "examples/fourbar_A_wo3_4_5", "examples/loop_A1_wo_A2"])
def test_friction_setup_from_jacobian_blocks(name):
    """The friction setup given the evaluation's (J_X)_i blocks (each friction group's rows of its
    type's block) equals the setup that calls jac_h on the friction joints alone, bit for bit."""
    model = model_of(name)
    assert model.friction_joints
    for q, h in random_states(model, n=5, seed=4):
        f = frames(model, q, h)
        blocks = evaluation.jacobian_h_blocks(model, f)
        assert np.array_equal(blocks[0], evaluation.jacobian_h(model, f))
        fast = dynamics._friction_setup(model.plan, f, blocks[1])
        slow = dynamics._friction_setup(model.plan, f)
        for cf, cs in zip(fast, slow):
            assert cf.keys() == cs.keys()
            for key in cf:
                assert _same_bits(cf[key], cs[key]), key


def test_frames_memo_not_shared():
    """Geometry cached on one evaluation's frames (Frames.cached) is never read for other frames,
    also not for a dataclasses.replace copy with other rotations."""
    model = model_of("planar_f145_wo4")
    (q1, h1), (q2, h2) = list(random_states(model, n=2, seed=5))
    f1, f2 = frames(model, q1, h1), frames(model, q2, h2)
    jacobian_h(model, f1), gamma(model, f1)  # fills f1's memo
    assert f1.memo
    mixed = dataclasses.replace(f1, r=f2.r, R=f2.R, v=f2.v, w=f2.w, phi=f2.phi)
    assert not mixed.memo
    assert np.array_equal(jacobian_h(model, mixed), jacobian_h(model, frames(model, q2, h2)))
    assert np.array_equal(gamma(model, mixed), gamma(model, frames(model, q2, h2)))


@pytest.mark.parametrize("name", ["spatial_GHMN_wo5", "examples/door_h1_wo_hinge2"])
def test_coordinate_rates_from_frames(name):
    """The Euler rates from the frames' cosines and sines equal those computed from q, bit for bit."""
    model = model_of(name)
    for q, h in random_states(model, n=10, seed=6):
        f = frames(model, q, h)
        if model.rotation != "quaternion":
            assert "euler.cos_sin" in f.memo
        assert np.array_equal(coordinate_rates(model, q, h, f), coordinate_rates(model, q, h))
