"""The compiled core's stages checked by independent means, with nothing of a second engine:

- coordinate rates (planar, z-x-z Euler angles, quaternions) against central differences of the
  rotation matrix the coordinates define (written here from the definitions: R = Rz Rx Rz, and
  the unit quaternion's matrix);
- every joint type's Phi_h against central differences of the core's Phi along the coordinate
  rates of each unit velocity, and gamma against differences of Phi_h h along the motion;
- the evaluation (Kernel.evaluate) against the equations it solves, M h' + Phi_h^T lam = Q + Q_f
  and Phi_h h' = gamma - 2 a Phi_h h - a^2 Phi on the kept rows (docs/reference/conventions.md), with Q the
  loads' Newton-Euler forces written here from their definitions;
- the friction outputs at the returned multipliers against each joint type's friction law
  (docs/joint-friction.md, paper App. A) evaluated here from the joint's reaction outputs and
  relative velocity, and the friction forces' power in the equations of motion against the
  outputs times the sliding velocities.

The helpers are shared with the other tests of the core (tests/test_kernel.py, test_core.py, ...)."""
from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from overcon import scene as scene_mod
from overcon.checks import compile_checked

from test_kernel import (EXAMPLES, MECH, example_spec, kernel_for, quaternion_spec, random_axis_model,
                         random_planar_model, rel, spec_of, states)

EPS_FD = 1e-6
"""Central-difference step along the motion (s, at rates of order 1): truncation error
EPS_FD^2/6 |third derivative| ~ 1e-13 of the scale, round-off 1e-16 |Phi| / EPS_FD ~ 1e-10."""
FD_REL = 1e-7
"""Differences agree with the core's derivatives to this, relative to the largest entry (at least
1): a thousand times the round-off bound above, and far below a wrong sign or a missing term."""
EQ_REL = 1e-9
"""The residuals of the equations of motion at the core's y' and lam, relative to the largest
term: the KKT solve's round-off, eps cond(S) <= 4e-11 at these states (the worst, the example
four-bar's S, has cond 1.6e5), and with friction the friction solve's tolerance (1e-12 relative
on the multipliers) times the friction law's slope; a wrong term is of the order of the term."""


# ----------------------------------------------------------------------------- definitions

def rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def quat_of_euler(angles) -> np.ndarray:
    """The unit quaternion (scalar first) of z-x-z angles: qz(alpha) qx(beta) qz(gamma)."""
    a, b, g = (0.5 * float(x) for x in angles)
    qa = np.array([math.cos(a), 0.0, 0.0, math.sin(a)])
    qb = np.array([math.cos(b), math.sin(b), 0.0, 0.0])
    qg = np.array([math.cos(g), 0.0, 0.0, math.sin(g)])
    return quat_mul(quat_mul(qa, qb), qg)


def quat_mul(p, q) -> np.ndarray:
    p0, pv, q0, qv = p[0], np.asarray(p[1:]), q[0], np.asarray(q[1:])
    return np.concatenate([[p0 * q0 - pv @ qv], p0 * qv + q0 * pv + np.cross(pv, qv)])


def rotation(model, q: np.ndarray, b: int) -> np.ndarray:
    """Body b's rotation body -> global at q (2x2 planar, 3x3 spatial; identity for the base, b < 0):
    planar Rot(phi); z-x-z Rz(alpha) Rx(beta) Rz(gamma) (paper Eq. 40); a quaternion's rotation of
    e / |e| (the core normalises)."""
    d = model.dim
    if b < 0:
        return np.eye(d)
    qb = q[b * model.nq_b:(b + 1) * model.nq_b]
    if d == 2:
        c, s = math.cos(qb[2]), math.sin(qb[2])
        return np.array([[c, -s], [s, c]])
    if model.rotation == "quaternion":
        e0, e1, e2, e3 = qb[3:] / np.linalg.norm(qb[3:])
        return np.array([[e0 * e0 + e1 * e1 - e2 * e2 - e3 * e3, 2 * (e1 * e2 - e0 * e3), 2 * (e1 * e3 + e0 * e2)],
                         [2 * (e1 * e2 + e0 * e3), e0 * e0 - e1 * e1 + e2 * e2 - e3 * e3, 2 * (e2 * e3 - e0 * e1)],
                         [2 * (e1 * e3 - e0 * e2), 2 * (e2 * e3 + e0 * e1), e0 * e0 - e1 * e1 - e2 * e2 + e3 * e3]])
    return rz(qb[3]) @ rx(qb[4]) @ rz(qb[5])


def position(model, q, b) -> np.ndarray:
    return np.zeros(model.dim) if b < 0 else q[b * model.nq_b: b * model.nq_b + model.dim].copy()


def velocity(model, h, b) -> tuple[np.ndarray, np.ndarray]:
    """(v global, omega global: 3-vector, planar (0, 0, phi')) of body b (zeros for the base);
    h holds spatial angular velocities in body axes, turned global by the caller's R."""
    if b < 0:
        return np.zeros(model.dim), np.zeros(3)
    hb = h[b * model.nh_b:(b + 1) * model.nh_b]
    if model.dim == 2:
        return hb[:2].copy(), np.array([0.0, 0.0, hb[2]])
    return hb[:3].copy(), hb[3:].copy()


def omega_global(model, q, h, b) -> np.ndarray:
    w = velocity(model, h, b)[1]
    return w if model.dim == 2 else rotation(model, q, b) @ w


def point_velocity(model, q, h, b, p) -> np.ndarray:
    """Velocity (global) of the material point of body b at the global point p."""
    if b < 0:
        return np.zeros(model.dim)
    v = velocity(model, h, b)[0]
    arm = np.zeros(3)
    arm[: model.dim] = p - position(model, q, b)
    return v + np.cross(omega_global(model, q, h, b), arm)[: model.dim]


def cross2(a, b) -> float:
    return a[0] * b[1] - a[1] * b[0]


def applied_forces(model, y) -> np.ndarray:
    """Q (nh) at y from the loads' definitions (Newton-Euler): gravity m g at each centre of mass;
    spatial bodies the gyroscopic moment -w x (J w) in body axes; a force (global, N) at the
    centre of mass; a torque (global, N m) turned into body axes; a spring k (|d| - L0) between
    its attachment points pulling them together (L0 = 0: -k d), with its moment about each body's
    centre of mass."""
    q, h = y[: model.n], y[model.n:]
    d, k = model.dim, model.nh_b
    Q = np.zeros(model.nh)
    inertia = np.asarray(model.inertia, float).reshape(model.nb, -1) if d == 3 else None
    for b in range(model.nb):
        Q[b * k: b * k + d] += model.mass[b] * np.asarray(model.gravity, float)
        if d == 3:
            w = h[b * k + 3: b * k + 6]
            Q[b * k + 3: b * k + 6] -= np.cross(w, inertia[b] * w)

    def add(b, F, p):  # force F (global) at the global point p on body b
        if b < 0:
            return
        Q[b * k: b * k + d] += F
        arm = p - position(model, q, b)
        if d == 2:
            Q[b * k + 2] += cross2(arm, F)
        else:
            R = rotation(model, q, b)
            Q[b * k + 3: b * k + 6] += np.cross(R.T @ arm, R.T @ F)

    for ld in model.loads:
        if ld.type == "force":
            Q[ld.bi * k: ld.bi * k + d] += np.asarray(ld.value, float)
        elif ld.type == "torque":
            if d == 2:
                Q[ld.bi * k + 2] += float(np.asarray(ld.value, float).reshape(-1)[0])
            else:
                Q[ld.bi * k + 3: ld.bi * k + 6] += rotation(model, q, ld.bi).T @ np.asarray(ld.value, float)
        else:
            pi = position(model, q, ld.bi) + rotation(model, q, ld.bi) @ np.asarray(ld.s_i, float)
            pj = position(model, q, ld.bj) + rotation(model, q, ld.bj) @ np.asarray(ld.s_j, float)
            dv = pi - pj
            L = float(np.linalg.norm(dv))
            F = -ld.stiffness * dv if ld.free_length == 0.0 else -ld.stiffness * (L - ld.free_length) * dv / L
            add(ld.bi, F, pi)
            add(ld.bj, -F, pj)
    return Q


# ----------------------------------------------------------------------------- checks shared by the tests

def rates(k, model, q, h) -> np.ndarray:
    """The core's coordinate rates q'(q, h) (ovk_evaluate's y'[:n])."""
    got = k.evaluate(0.0, np.concatenate([q, h]))
    assert got is not None, k.last_message
    return got[0][: model.n]


def solve(k, y):
    """The core's evaluation at y as a run does it: Kernel.evaluate (Newton, then damped Newton),
    and where both give up (status 2) Kernel.evaluate_robust (fixed point, then Newton with a
    difference Jacobian); None where that fails too (status in k.last_status)."""
    got = k.evaluate(0.0, y)
    if got is None and k.last_status == 2:
        got = k.evaluate_robust(y)
    return got


def rows_fd_errors(k, model, y) -> tuple[float, float]:
    """(Phi_h error, gamma error), relative (:func:`rel`), of the core's rows at y against central
    differences of the core's Phi: column c of Phi_h is d Phi / d eps along q + eps q'(q, e_c)
    (the rates of the unit velocity e_c; a quaternion's norm stabilisation moves e along itself,
    which leaves R(e / |e|) and so Phi unchanged to first order), and -gamma is d(Phi_h h)/dt along
    q + t q'(q, h) with h held (the paper's sign: Phi_h h' = gamma)."""
    n, nh = model.n, model.nh
    q, h = y[:n], y[n:]
    phi, J, gam = k.rows(y)
    fd = np.zeros_like(J)
    for c in range(nh):
        e = np.zeros(nh)
        e[c] = 1.0
        qd = rates(k, model, q, e)
        plus = k.rows(np.concatenate([q + EPS_FD * qd, h]))[0]
        minus = k.rows(np.concatenate([q - EPS_FD * qd, h]))[0]
        fd[:, c] = (plus - minus) / (2 * EPS_FD)
    qd = rates(k, model, q, h)
    plus = k.rows(np.concatenate([q + EPS_FD * qd, h]))[1] @ h
    minus = k.rows(np.concatenate([q - EPS_FD * qd, h]))[1] @ h
    return rel(fd, J), rel((plus - minus) / (2 * EPS_FD), -gam)


def consistent(k, model, y) -> tuple[np.ndarray, bool]:
    """(y moved onto the constraints, True) by the core's projection (positions, then velocities:
    Phi = 0 and Phi_h h = 0, every joint's relative motion one the joint allows), or, where the
    projection does not converge (random chains far from assembly), (y with h replaced by its part
    in the null space of the core's Phi_h, False)."""
    from overcon.kernel import ProjectionFailed

    try:
        return k.project(0.0, y)[0], True
    except ProjectionFailed:
        pass
    n = model.n
    _, s, Vt = np.linalg.svd(k.rows(y)[1])
    N = Vt[int(np.sum(s > 1e-10 * s[0])):].T
    return np.concatenate([y[:n], N @ (N.T @ y[n:])]), False


def equation_residuals(k, model, solver, y, got) -> tuple[np.ndarray, float, float]:
    """(Q_f, the kept rows' residual, the eliminated rows' |lam|) for the core's (y', lam) at y:
    Q_f = M h' + Phi_h^T lam - Q (zero without friction; the friction forces otherwise), the
    acceleration rows Phi_hR h' - (gamma - 2 a Phi_h h - a^2 Phi)_R relative to their scale."""
    n = model.n
    h = y[n:]
    ydot, lam = got[0], got[1]
    hd = ydot[n:]
    phi, J, gam = k.rows(y)
    a = solver.baumgarte
    R = np.asarray(model.retained, int)
    rhs = gam - 2 * a * (J @ h) - a * a * phi
    acc = J[R] @ hd - rhs[R]
    acc_scale = max(1.0, float(np.max(np.abs(J[R] @ hd))), float(np.max(np.abs(rhs[R]))))
    others = np.setdiff1d(np.arange(model.m), R)
    return (np.asarray(model.M) * hd + J.T @ lam - applied_forces(model, y),
            float(np.max(np.abs(acc))) / acc_scale, float(np.max(np.abs(lam[others]), initial=0.0)))


def force_scale(model, y, got) -> float:
    """The largest term of M h' = Q + ... (N or N m, at least 1): the scale of EQ_REL."""
    return max(1.0, float(np.max(np.abs(np.asarray(model.M) * got[0][model.n:]))),
               float(np.max(np.abs(applied_forces(model, y)))))


def law_mu(law, v: float) -> float:
    """The paper's Fig. 1 law B (``regularised``) or C (``stribeck``) at the sliding velocity v:
    mu clip(v / v_reg, -1, 1), for C with mu + (mu_static - mu) exp(-(v / v_stribeck)^2) in place
    of mu; the expected value the core's friction outputs are held to."""
    magnitude = law.mu
    if law.name == "stribeck":
        magnitude = law.mu + (law.mu_static - law.mu) * math.exp(-(abs(v) / law.v_stribeck) ** 2)
    return min(max(v / law.v_reg, -1.0), 1.0) * magnitude


def friction_law(model, spec, q, h, c, reac, output) -> tuple[float, float]:
    """(the friction output joint c must have, the friction power of joint c) from its law at its
    reaction outputs ``reac`` (the components of its type, then the global force) and its
    relative velocity at (q, h) (docs/joint-friction.md; paper App. A for the planar and spherical
    joints): signed outputs for planar revolute/translational, spatial revolute and prismatic,
    point on line (power -output v_rel), magnitudes for spherical and cylindrical (power -output |slip|).
    ``output`` (the core's) only enters the power."""
    law, p = c.law, c.p
    bi, bj = c.bi, c.bj
    coef = functools.partial(law_mu, law)
    if c.type == "revolute":
        w = h[bj * 3 + 2] if bj >= 0 else 0.0
        w -= h[bi * 3 + 2] if bi >= 0 else 0.0
        want = coef(w) * law.size * math.hypot(reac[0], reac[1])
        return want, -output * w
    if c.type == "translational":
        Fy, T, F0 = reac[1], reac[2], reac[3:5]
        y_axis = np.asarray(F0) / Fy  # (Fx = 0: the reaction is normal to the guide) y' in global axes
        x_axis = np.array([y_axis[1], -y_axis[0]])
        pi = position(model, q, bi)
        v = float((point_velocity(model, q, h, bj, pi) - point_velocity(model, q, h, bi, pi)) @ x_axis)
        ell = law.size
        want = coef(v) * (abs(Fy - T / ell) + abs(T / ell))
        return want, -output * v
    if c.type in ("point_on_line", "spatial_point_on_line"):  # a force mu(v) N along the line at P_i
        P = position(model, q, bi) + rotation(model, q, bi) @ np.asarray(p["s_i"], float)
        u = rotation(model, q, bj) @ np.asarray(p["a_j"], float)
        v = float((point_velocity(model, q, h, bj, P) - point_velocity(model, q, h, bi, P)) @ u)
        N = float(np.linalg.norm(reac[:len(c.rows)]))  # planar |N|, spatial hypot(Fx, Fy)
        return coef(v) * N, -output * v
    Ri = rotation(model, q, bi)
    if c.type == "spherical":
        F = np.asarray(reac[:3])
        contact = Ri @ (-law.size * F / np.linalg.norm(F))  # s'_C = -rho F'/|F'| (body i axes)
        w_rel = omega_global(model, q, h, bj) - omega_global(model, q, h, bi)
        slip = float(np.linalg.norm(np.cross(w_rel, contact)))
        return coef(slip) * float(np.linalg.norm(F)), -output * slip
    axis = np.asarray(p["a_i"], float)  # axis_i, unit, body i axes
    u = Ri @ (axis / np.linalg.norm(axis))
    P = position(model, q, bi) + Ri @ np.asarray(p["s_i"], float)
    w_rel = float((omega_global(model, q, h, bj) - omega_global(model, q, h, bi)) @ u)
    v_rel = float((point_velocity(model, q, h, bj, P) - point_velocity(model, q, h, bi, P)) @ u)
    sizes = dict(law.sizes)
    if c.type == "spatial_revolute":
        Fx, Fy, Fz, Tx, Ty = reac[:5]
        L = sizes["length"]
        fp = np.array([Fx / 2 + Ty / L, Fy / 2 - Tx / L])  # F_perp/2 +- (T_perp x z)/L
        fm = np.array([Fx / 2 - Ty / L, Fy / 2 + Tx / L])
        Nr = float(np.linalg.norm(fp) + np.linalg.norm(fm))
        want = coef(w_rel) * (sizes["radius"] * Nr + sizes["collar_radius"] * abs(Fz))
        return want, -output * w_rel
    if c.type == "spatial_prismatic":
        Fx, Fy, Tx, Ty, Tz = reac[:5]
    else:
        (Fx, Fy, Tx, Ty), Tz = reac[:4], 0.0
    ell = sizes["length"]
    fB = np.array([Ty / ell, -Tx / ell])  # (T_perp x z)/l
    fA = np.array([Fx, Fy]) - fB
    N = float(np.linalg.norm(fA) + np.linalg.norm(fB))
    if c.type == "spatial_prismatic":
        N += abs(Tz) / sizes["radius"]
        return coef(v_rel) * N, -output * v_rel
    slip = math.hypot(v_rel, sizes["radius"] * w_rel)
    return coef(slip) * N, -output * slip


def check_friction_at(k, model, spec, y, got, assembled=True) -> float:
    """At the core's solution ``got`` at y: each friction joint's output equals its law at the
    returned multipliers (to EQ_REL of the joint's largest force term); returns the joints'
    friction power (sum of -output times sliding velocity). Off the constraints (``assembled``
    False) the planar translational joints are left out: the guide of body i and that of body j
    then differ, and the sliding velocity along "the" guide is not defined."""
    n = model.n
    q, h = y[:n], y[n:]
    reac, fric = k.outputs(y, got[1])
    reac, fric = reac.copy(), fric.copy()
    power = 0.0
    for j in model.friction_joints:
        c = model.joints[j]
        if c.type == "translational" and not assembled:
            continue
        want, pj = friction_law(model, spec, q, h, c, reac[j], fric[j])
        scale = max(1.0, float(np.max(np.abs(reac[j]))))  # (mu <= 0.5 times sizes <= 0.2 m times loads of this order)
        assert abs(fric[j] - want) <= EQ_REL * scale, (c.name, c.type, fric[j], want)
        power += pj
    return power


# ----------------------------------------------------------------------------- models

def fd_models(tmp_path):
    """Frictionless models of every joint type under both rotations: the paper's planar and
    spatial mechanisms (Euler; the spatial one also in quaternions), the example mechanisms
    (quaternions), random planar chains (revolute and translational, the base on either side) and
    random chains of all six spatial types in Euler angles and in quaternions."""
    for name in ("planar_none_wo4", "spatial_none_wo5"):
        spec = spec_of(name)
        yield name, spec, compile_checked(spec)
    spec = quaternion_spec(spec_of("spatial_none_wo5"))
    yield "spatial_none_wo5 (quaternions)", spec, compile_checked(spec)
    for name in ("door_none_wo_hinge2", "carriage_none_wo_rod", "fourbar_none_wo3_4_5", "loop_D_wo_A2"):
        spec = scene_mod.as_scene(example_spec(name), friction=[])
        yield name, spec, compile_checked(spec)
    for seed in range(2):
        spec, model = random_planar_model(tmp_path, seed, friction=False)
        yield f"random planar chain {seed}", spec, model
        for rotation_name in ("euler_zxz", "quaternion"):
            spec, model = random_axis_model(tmp_path, rotation_name, seed, friction=False)
            yield f"random spatial chain {seed} ({rotation_name})", spec, model


# ----------------------------------------------------------------------------- tests

@pytest.mark.parametrize("rotation_name", ["planar", "euler_zxz", "quaternion"])
def test_coordinate_rates_by_differences_of_the_rotation(tmp_path, rotation_name):
    """The core's q'(q, h): positions move with the velocity (r' = v, global), and the rotation the
    coordinates define moves with the angular velocity: central differences of R(q + t q') give
    R [w]x (body axes; planar: phi' = w), to FD_REL, at random states (quaternions off the unit
    sphere too: R(e/|e|))."""
    if rotation_name == "planar":
        spec, model = random_planar_model(tmp_path, 0, friction=False)
    else:
        spec, model = random_axis_model(tmp_path, rotation_name, 0, friction=False)
    k = kernel_for(model, spec.solver)
    checked = 0
    for y in states(model, 8, seed=4):
        q, h = y[: model.n], y[model.n:]
        qd = rates(k, model, q, h)
        for b in range(model.nb):
            v, w = velocity(model, h, b)
            assert rel(qd[b * model.nq_b: b * model.nq_b + model.dim], v) <= 1e-15
            dR = (rotation(model, q + EPS_FD * qd, b) - rotation(model, q - EPS_FD * qd, b)) / (2 * EPS_FD)
            R = rotation(model, q, b)
            if model.dim == 2:
                want = R @ np.array([[0.0, -w[2]], [w[2], 0.0]])
            else:
                want = R @ np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
            assert rel(dR, want) <= FD_REL, (b, rel(dR, want))
            checked += 1
    assert checked >= 8 * 3


def test_quaternion_rates_keep_the_norm_and_pull_it_back():
    """Quaternion rates: at a unit quaternion e' = e (x) (0, w)/2 (body axes) exactly; off the unit
    sphere the rates' radial part (e . e') has the sign that brings |e| back to 1 (norm
    stabilisation) and no tangential part beyond e (x) (0, w)/2 scaled by |e|."""
    spec = quaternion_spec(spec_of("spatial_none_wo5"))
    model = compile_checked(spec)
    k = kernel_for(model, spec.solver)
    rng = np.random.default_rng(8)
    q = model.q0.copy()
    h = rng.standard_normal(model.nh)
    qd = rates(k, model, q, h)
    for b in range(model.nb):
        e, w = q[7 * b + 3: 7 * b + 7], h[6 * b + 3: 6 * b + 6]
        assert abs(np.linalg.norm(e) - 1.0) < 1e-12
        assert rel(qd[7 * b + 3: 7 * b + 7], 0.5 * quat_mul(e, np.concatenate([[0.0], w]))) <= 1e-14
    for scale in (1.01, 0.99):
        z = q.copy()
        for b in range(model.nb):
            z[7 * b + 3: 7 * b + 7] *= scale
        qd = rates(k, model, z, h)
        for b in range(model.nb):
            e = z[7 * b + 3: 7 * b + 7]
            radial = float(e @ qd[7 * b + 3: 7 * b + 7])
            assert radial * (scale - 1.0) < 0.0, (scale, radial)


def test_rows_match_finite_differences(tmp_path):
    """Every joint type (planar revolute and translational; spherical, spatial revolute,
    prismatic, cylindrical, universal, fixed) under both rotations: the core's Phi_h, column by
    column, and gamma are the derivatives of its Phi (:func:`rows_fd_errors`) to FD_REL at random
    states off the constraints."""
    types = set()
    for name, spec, model in fd_models(tmp_path):
        k = kernel_for(model, spec.solver)
        types |= {(model.rotation if model.kind == "spatial" else "planar", c.type) for c in model.joints}
        for y in states(model, 4, seed=11):
            eJ, eg = rows_fd_errors(k, model, y)
            assert eJ <= FD_REL and eg <= FD_REL, (name, eJ, eg)
    spatial = {"spherical", "spatial_revolute", "spatial_prismatic", "spatial_cylindrical", "spatial_universal",
               "spatial_fixed"}
    assert {t for r, t in types if r == "euler_zxz"} == spatial
    assert {t for r, t in types if r == "quaternion"} == spatial
    assert {t for r, t in types if r == "planar"} == {"revolute", "translational"}


def test_rows_vanish_at_the_assembled_initial_states():
    """Phi = 0 (to 1e-12 m or rad) at the initial state of every paper and example scene, whose q0
    the scene files give assembled."""
    names = [p.stem for p in MECH.glob("*_wo*.toml")]
    examples = [p.stem for p in EXAMPLES.glob("*_wo*.toml") if not p.stem.startswith("compliant")]
    assert len(names) >= 20 and len(examples) >= 10
    for name in names + examples:
        spec = spec_of(name) if name in names else example_spec(name)
        model = compile_checked(spec)
        k = kernel_for(model, spec.solver)
        phi = k.rows(np.concatenate([model.q0, model.h0]))[0]
        assert np.max(np.abs(phi)) <= 1e-12, (name, np.max(np.abs(phi)))


@pytest.mark.parametrize("baumgarte", [10.0, 0.0])
def test_evaluation_solves_the_equations_of_motion(tmp_path, baumgarte):
    """Without friction, at random states: M h' + Phi_h^T lam = Q (the loads of the scene: gravity,
    gyroscopic moments, forces, torques, springs) and Phi_hR h' = gamma_R - 2 a (Phi_h h)_R -
    a^2 Phi_R on the kept rows, the eliminated rows' lam = 0, to EQ_REL of the largest term; every
    joint type, both rotations, every load type."""
    loads = set()
    for name, spec, model in fd_models(tmp_path):
        solver = spec.solver.__class__(**{**spec.solver.__dict__, "baumgarte": baumgarte})
        k = kernel_for(model, solver)
        loads |= {ld.type for ld in model.loads}
        for y in states(model, 6, seed=12):
            got = k.evaluate(0.0, y)
            assert got is not None, (name, k.last_message)
            Qf, acc, elim = equation_residuals(k, model, solver, y, got)
            assert np.max(np.abs(Qf)) <= EQ_REL * force_scale(model, y, got), (name, np.max(np.abs(Qf)))
            assert acc <= EQ_REL and elim == 0.0, (name, acc, elim)
    assert loads == {"force", "torque", "spring"}


def friction_models(tmp_path):
    """Models with friction in every joint type that has it (planar revolute and translational,
    spherical, spatial revolute, prismatic, cylindrical), both laws, both rotations."""
    for name in ("planar_f145_wo6", "spatial_GHMN_wo18"):
        spec = spec_of(name)
        yield name, spec, compile_checked(spec)
    spec = quaternion_spec(spec_of("spatial_GH_wo9"))
    yield "spatial_GH_wo9 (quaternions)", spec, compile_checked(spec)
    for name in ("door_h1_wo_hinge2", "carriage_guide_wo_rod", "loop_A1_wo_A2"):
        spec = example_spec(name)
        yield name, spec, compile_checked(spec)
    for seed in range(3):
        spec, model = random_planar_model(tmp_path, seed)
        yield f"random planar chain {seed}", spec, model
        for rotation_name in ("euler_zxz", "quaternion"):
            spec, model = random_axis_model(tmp_path, rotation_name, seed)
            yield f"random spatial chain {seed} ({rotation_name})", spec, model


def test_friction_obeys_its_law_at_the_returned_multipliers(tmp_path):
    """With friction, at random states moved onto the constraints (:func:`consistent`): each friction
    joint's output at the returned lam is its law at its reaction outputs and sliding velocity
    (:func:`friction_law`), the kept rows' accelerations hold as without friction, and the
    friction forces in the equations of motion, Q_f = M h' + Phi_h^T lam - Q, have, at assembled
    states, the power the outputs give (sum of -output times sliding velocity, <= 0), to EQ_REL of
    the largest term.
    Every joint type with friction, both laws, both rotations."""
    seen, laws, evaluated, powered = set(), set(), 0, 0
    for name, spec, model in friction_models(tmp_path):
        k = kernel_for(model, spec.solver)
        for y in states(model, 8, seed=13):
            y, assembled = consistent(k, model, y)
            got = solve(k, y)
            if got is None:  # (random chains: the friction solve may have no solution at a state)
                assert k.last_status == 2 and name.startswith("random"), (name, k.last_message)
                continue
            evaluated += 1
            Qf, acc, elim = equation_residuals(k, model, spec.solver, y, got)
            assert acc <= EQ_REL and elim == 0.0, (name, acc, elim)
            power = check_friction_at(k, model, spec, y, got, assembled)
            h = y[model.n:]
            scale = force_scale(model, y, got) * max(1.0, float(np.max(np.abs(h))))
            assert power <= EQ_REL * scale
            if assembled:  # (off the constraints the joint frames of body i and j disagree)
                assert abs(float(h @ Qf) - power) <= EQ_REL * scale, (name, float(h @ Qf), power)
                powered += 1
            seen |= {(model.rotation if model.kind == "spatial" else "planar", model.joints[j].type)
                     for j in model.friction_joints}
            laws |= {model.joints[j].law.name for j in model.friction_joints}
    assert laws == {"regularised", "stribeck"}
    assert {t for _, t in seen} == {"revolute", "translational", "spherical", "spatial_revolute",
                                    "spatial_prismatic", "spatial_cylindrical"}
    assert {r for r, _ in seen} == {"planar", "euler_zxz", "quaternion"}
    assert evaluated >= 60 and powered >= 30, (evaluated, powered)
