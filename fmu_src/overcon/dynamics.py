"""Direct dynamics with a chosen elimination and Coulomb joint friction (paper Eq. 11, 18, 23).

With the retained equations R (the eliminated ones carry lam = 0), Eq. 18 reads

    M h' + J_R lam_R = Q + Q_f(lam),    J_R^T h' = gamma_R - 2 a Phi_h h - a^2 Phi   (Baumgarte)

M is diagonal and positive, so it is solved through the Schur complement
``S = J_R^T M^-1 J_R`` (Cholesky, factored once per evaluation):
``lam_R = S^-1 (J_R^T M^-1 (Q + Q_f) - gamma_R)``, ``h' = M^-1 (Q + Q_f - J_R lam_R)``.
S is singular when the kept equations are dependent at this configuration (a singular position):
that raises :class:`overcon.evaluation.SingularConfiguration`.

Friction: Q_f depends on lam only through the friction joints' multipliers ``x`` (the retained
friction rows, ``plan.friction_xrows``) and acts only on the velocities of the friction joints'
bodies (``plan.friction_cols``), so with ``W = S^-1 J_R^T M^-1`` restricted to those columns
(one multi-column back-substitution with the evaluation's one Cholesky factor)
``lam_R = lam0 + W qf(x)`` and the solve is the small fixed point ``x = lam0_x + W_x qf(x)``.
Solve (decided here): Newton's method on it from the last converged lam (warm start), Jacobian
``I - W_x dqf/dx`` with dqf/dx from each joint module's optional ``friction_jacobian`` (forward
differences of its ``friction`` for a type without one), kept for the next step while a step
reduces the residual 1000-fold; typically 2-4 force evaluations. If Newton gives up
(NEWTON_MAX_ITER force evaluations, a residual growing twice, a singular Newton matrix), a damped
Newton solve from the same start (a fresh Jacobian every step, backtracking line search on the
residual: :func:`_damped_newton_reduced`, ``Evaluation.damped``); if that gives up too, the
robust path of before runs from the warm start: fixed-point iteration accelerated by Anderson
mixing (depth 3), on non-convergence or divergence (residual growth over 3 iterations) Newton's
method on ``x - G(x) = 0`` with a finite-difference Jacobian and a backtracking line search
(``Evaluation.fallback``); if that fails too, :class:`FrictionSolveError` names the time, the
joints and the residual. Convergence everywhere: ``|G(x) - x| <= tol (1 + |x|)`` (infinity norms,
N). The returned lam is G(x) of the last iterate, so h' and lam are consistent to that residual.
``Evaluation.iterations`` counts evaluations of the friction forces.

Hot path: the friction forces of all friction joints of a type come from one call of the joint
module's ``friction`` (per-evaluation constants from ``friction_setup``, computed once before the
iteration), and the Cholesky factor/solve call LAPACK's dpotrf/dpotrs directly through SciPy's
public ``scipy.linalg.lapack`` (with scipy's finiteness checks and messages); the Newton matrix
is factored with dgetrf/dgetrs from there too.

Solver options: :func:`evaluate` reads ``baumgarte``, ``friction_tol`` and ``friction_max_iter``
from the :class:`overcon.spec.SolverSpec` it is given (the Model carries none).

This module is the reference implementation. :mod:`overcon.kernel` has the same evaluation in C
(``core/``, selected by the solver setting ``kernel``); every evaluation it cannot finish the
way this module would (a singular position, the fallback of the friction solve, ...) is repeated
here (``newton_failed`` skips a Newton solve the kernel already tried at that state).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import LinAlgError
from scipy.linalg.lapack import dgetrf, dgetrs, dpotrf, dpotrs

from .evaluation import Frames, SingularConfiguration, applied_forces, constraints, frames, gamma, jacobian_h_blocks
from .model import AssemblyPlan, Model
from .spec import SolverSpec

# numpy private API, kept for a measured hot-path gain: numpy.linalg.lstsq without its Python-level
# wrapping (the same LAPACK gelsd call, the same bits; tests/test_hot_path.py checks equality):
# 13.5 us instead of 17.4 us per 4x3 solve on this machine, one solve per Anderson-accelerated
# friction iteration (several per evaluation of Eq. 18). Without it: the public call.
try:
    from numpy.linalg import _umath_linalg
    from numpy.linalg._linalg import _raise_linalgerror_lstsq
    _LSTSQ = _umath_linalg.lstsq
except (ImportError, AttributeError):  # pragma: no cover - other numpy layouts
    _LSTSQ = None


class FrictionSolveError(ArithmeticError):
    """The friction fixed point (Eq. 18) did not converge, even with the Newton fallback."""


@dataclass
class Evaluation:
    """Result of one evaluation of Eq. 18 at (t, q, h)."""

    hdot: np.ndarray
    lam: np.ndarray  # (m,), zeros at eliminated equations
    frames: Frames
    iterations: int = 0
    fallback: bool = False  # the fixed-point fallback ran (both Newton solves gave up)
    S: np.ndarray | None = None  # Schur complement J_R^T M^-1 J_R (for conditioning checks)
    qf: np.ndarray | None = None  # friction forces on plan.friction_cols (Newton path; a warm start)
    damped: bool = False  # the undamped Newton solve gave up and the damped one ran
    friction: np.ndarray | None = None  # friction forces on plan.friction_cols, whichever solve found them


def _chkfinite(a: np.ndarray) -> np.ndarray:
    """scipy's asarray_chkfinite for a float array (same error)."""
    if not np.isfinite(a).all():
        raise ValueError("array must not contain infs or NaNs")
    return a


def _cho_factor(S: np.ndarray):
    """scipy.linalg.cho_factor(S) (upper, no clean-up), same errors, less call overhead."""
    _chkfinite(S)
    if S.ndim != 2 or S.shape[0] != S.shape[1] or S.size == 0:
        from scipy.linalg import cho_factor
        return cho_factor(S)
    c, info = dpotrf(S, lower=0, overwrite_a=0, clean=0)
    if info > 0:
        raise LinAlgError(f"{info}-th leading minor of the array is not positive definite")
    if info < 0:
        raise ValueError(f'LAPACK reported an illegal value in {-info}-th argument on entry to "POTRF".')
    return c, False


MIN_NORM_RTOL = 1e-9
"""Rank threshold of the min-norm solve, relative to the largest singular value of M^-1/2 J (as
the pre-check's :data:`overcon.analysis.DEFAULT_RTOL`)."""


@dataclass(frozen=True)
class _PseudoInverse:
    """S^+ (m, m): the "factor" of the min-norm solve."""

    P: np.ndarray


def _min_norm_inverse(J: np.ndarray, Minv: np.ndarray) -> _PseudoInverse:
    """S^+ for S = J^T M^-1 J of every equation (redundancy "min-norm",
    :data:`overcon.spec.REDUNDANCY_METHODS`): from the SVD M^-1/2 J = U s V^T,
    S^+ = V_r s_r^-2 V_r^T over the singular values above :data:`MIN_NORM_RTOL` x s_1. S^+ b is
    the multiplier vector of least norm among those that give the accelerations (all of them do,
    the redundant directions are in null(J) and exert no force)."""
    _chkfinite(J)
    u, s, vt = np.linalg.svd(np.sqrt(Minv)[:, None] * J, full_matrices=False)
    keep = s > max(MIN_NORM_RTOL, max(J.shape) * np.finfo(float).eps) * (s[0] if s.size else 0.0)
    v = vt[keep]
    return _PseudoInverse((v.T / (s[keep] ** 2)) @ v)


def _cho_solve(factor, b: np.ndarray) -> np.ndarray:
    """scipy.linalg.cho_solve(factor, b) for a 1-D b, same errors, less call overhead (or S^+ b
    for the factor of :func:`_min_norm_inverse`)."""
    if isinstance(factor, _PseudoInverse):
        return factor.P @ b
    c, lower = factor
    _chkfinite(b)
    if c.shape[1] != b.shape[0] or b.size == 0:
        from scipy.linalg import cho_solve
        return cho_solve(factor, b)
    x, info = dpotrs(c, b, lower=lower, overwrite_b=0)
    if info != 0:
        raise ValueError(f"illegal value in {-info}th argument of internal potrs")
    return x


def _lstsq(A: np.ndarray, b: np.ndarray, rcond: float) -> np.ndarray:
    """``np.linalg.lstsq(A, b, rcond)[0]`` for 2-D float A (m >= 1) and 1-D b."""
    if _LSTSQ is None or A.shape[0] == 0:
        return np.linalg.lstsq(A, b, rcond=rcond)[0]
    with np.errstate(call=_raise_linalgerror_lstsq, invalid="call", over="ignore", divide="ignore",
                     under="ignore"):
        x = _LSTSQ(A, b[:, None], rcond, signature="ddd->ddid")[0]
    return x[:, 0].copy()


def _friction_setup(plan: AssemblyPlan, f: Frames, blocks_i: list | None = None) -> list:
    """Per-evaluation constants of every friction group (frames only). With ``blocks_i``, the
    (J_X)_i blocks of every joint group (:func:`overcon.evaluation.jacobian_h_blocks`), each
    friction group takes its rows of its type's block instead of calling ``jac_h`` again (a
    batched ``jac_h`` gives each joint the numbers it gets alone: the same bits)."""
    if blocks_i is None:
        return [g.module.friction_setup(g.data, f) for g in plan.friction]
    return [g.module.friction_setup(g.data, f, blocks_i[g.group][g.in_group]) for g in plan.friction]


def evaluate(model: Model, t: float, q: np.ndarray, h: np.ndarray, lam_guess: np.ndarray | None = None,
             *, solver: SolverSpec, qf_guess: np.ndarray | None = None, newton_failed: int = 0) -> Evaluation:
    """Accelerations h' and multipliers lam at (t, q, h) (Eq. 18 with elimination), with the
    Baumgarte frequency and friction-solve settings of ``solver``. Warm start of the friction
    solve: ``qf_guess`` (the friction forces on ``plan.friction_cols`` of a nearby evaluation,
    its ``Evaluation.qf``) gives the first iterate lam0_x + W_x qf_guess, one fixed-point step
    taken with this state's lam0 and W and without evaluating a force; else ``lam_guess``'s
    friction multipliers; else lam0. ``newton_failed``: the force evaluations of a Newton solve
    already tried at this very state (the compiled kernel's, :mod:`overcon.kernel`), which gave
    up: the robust path starts at once (what it would do after its own Newton gave up; the
    count is added to ``Evaluation.iterations``)."""
    a, tol, max_iter = solver.baumgarte, solver.friction_tol, solver.friction_max_iter
    plan = model.plan
    f = frames(model, q, h)
    Phi_h, blocks_i = jacobian_h_blocks(model, f)
    R = model.retained
    PR = Phi_h[R]
    JR = PR.T
    g = gamma(model, f)[R]
    Phi = constraints(model, f) if a > 0.0 or model.compliant_rows.size else None
    if a > 0.0:
        g = g - 2.0 * a * (PR @ h) - a * a * Phi[R]
    Q = applied_forces(model, f)
    if model.compliant_rows.size:
        lam_R, S, solve_many = _compliant_solve(model, t, PR, g, Q, h, Phi, f)
    else:
        MinvJ = model.Minv[:, None] * JR
        S = JR.T @ MinvJ
        factor = _factor(model, t, S, JR)
        MinvJT = MinvJ.T
        lam_R = _cho_solve(factor, MinvJT @ Q - g)

        def solve_many(cols):
            return _cho_solve_many(factor, MinvJT[:, cols])
    lam = np.zeros(model.m)
    iterations, fallback, damped, qf_out = 0, False, False, None
    if model.friction_joints:
        ctx = _friction_setup(plan, f, blocks_i)
        lam0 = lam_R
        xrows = plan.friction_xrows
        cols = plan.friction_cols
        W = solve_many(cols)  # lam_R = lam0 + W qf(x)
        if qf_guess is not None:
            x0 = lam0[xrows] + W[xrows] @ qf_guess
        else:
            x0 = (lam0 if lam_guess is None else lam_guess[R])[xrows]
        if newton_failed:
            qf, iterations, ok = None, newton_failed, False
        else:
            x, qf, iterations, ok = _newton_reduced(plan, ctx, lam0[xrows], W[xrows], x0, tol, max_iter)
            if not ok:  # the damped Newton solve from the same start
                damped = True
                x, qf, more, ok = _damped_newton_reduced(plan, ctx, lam0[xrows], W[xrows], x0, tol, max_iter)
                iterations += more
        if ok:
            qf_out = qf
            lam_R = lam0 + W @ qf
        else:
            fallback = True
            start = lam0.copy() if lam_guess is None else lam_guess[R].copy()
            lam_R, qf, iterations = _robust_friction(model, ctx, lam0, W, start, t, solver, iterations)
        Q = Q.copy()
        Q[cols] += qf
    lam[R] = lam_R
    hdot = model.Minv * (Q - JR @ lam_R)
    return Evaluation(hdot=hdot, lam=lam, frames=f, iterations=iterations, fallback=fallback, S=S, qf=qf_out,
                      damped=damped or (newton_failed > 0), friction=qf if model.friction_joints else None)


def _factor(model: Model, t: float, S: np.ndarray, JR: np.ndarray):
    """The factor of S that :func:`_cho_solve` uses: Cholesky (a singular S is a singular
    position), or the pseudo-inverse of the min-norm method."""
    if model.elimination_mode == "min-norm":
        return _min_norm_inverse(JR, model.Minv)
    try:
        return _cho_factor(S)
    except LinAlgError as exc:
        raise SingularConfiguration(
            f"t = {t:.9g} s: the kept constraint equations became dependent (singular position); "
            "the Jacobian lost rank") from exc


def _compliant_solve(model: Model, t: float, PR: np.ndarray, g: np.ndarray, Q: np.ndarray, h: np.ndarray,
                     Phi: np.ndarray, f):
    """Eq. 18 with compliant joints (redundancy "compliant"): the multipliers of their equations
    are the spring-damper forces on the violation, lam_c = k Phi + d Phi_h h (so -J_c lam_c pulls
    the joint together, as a constraint's reaction would), known from the state; the rigid kept
    equations are solved with those forces applied. Returns (lam over the kept equations, the
    rigid S, the solve of friction columns: lam = lam(qf = 0) + W qf with W = 0 on compliant rows)."""
    R = model.retained
    c = np.isin(R, model.compliant_rows)
    r = ~c
    lam_c = model.row_stiffness[R[c]] * Phi[R[c]] + model.row_damping[R[c]] * (PR[c] @ h)
    if model.compliance_axes:
        _axis_forces(model, f, PR, Phi, h, lam_c, np.flatnonzero(c))
    Jr = PR[r].T
    MinvJr = model.Minv[:, None] * Jr
    S = Jr.T @ MinvJr
    factor = _factor(model, t, S, Jr) if S.size else None
    lam_R = np.empty(len(R))
    lam_R[c] = lam_c
    if factor is not None:
        lam_R[r] = _cho_solve(factor, MinvJr.T @ (Q - PR[c].T @ lam_c) - g[r])

    def solve_many(cols):
        W = np.zeros((len(R), len(cols)))
        if factor is not None:
            W[r] = _cho_solve_many(factor, MinvJr.T[:, cols])
        return W
    return lam_R, S, solve_many


def _axis_forces(model: Model, f, PR: np.ndarray, Phi: np.ndarray, h: np.ndarray, lam_c: np.ndarray,
                 cpos: np.ndarray) -> None:
    """The multipliers of the per-axis compliant joints (:class:`overcon.model.AxisCompliance`),
    written into ``lam_c`` (ordered as ``cpos``, the compliant rows' positions in ``PR``):
    lam = U^T K U Phi + U^T D U Phi_h h per row group, K = F diag(k) F^T and D likewise, F the
    joint frame in global axes (R_i frame), U the rows' directions in global axes."""
    at = {int(model.retained[p]): i for i, p in enumerate(cpos)}
    k = model.nh_b
    for ax in model.compliance_axes:
        F = f.R[ax.bi] @ ax.frame
        b = ax.bi if ax.bi >= 0 else ax.bj  # a moving body: its columns give the directions
        for rows, kv, dv, rot in ((ax.t_rows, ax.k_t, ax.d_t, False), (ax.r_rows, ax.k_r, ax.d_r, True)):
            if not rows:
                continue
            pos = np.searchsorted(model.retained, rows)
            if rot:  # angular columns are body axes: to global
                U = f.R[b] @ PR[pos, b * k + 3:b * k + 6].T
            else:
                U = PR[pos, b * k:b * k + 3].T
            FU = F.T @ U
            i = [at[r] for r in rows]
            lam_c[i] = FU.T @ (kv[:, None] * FU) @ Phi[list(rows)] + FU.T @ (dv[:, None] * FU) @ (PR[pos] @ h)


def _robust_friction(model: Model, ctx: list, lam0: np.ndarray, W: np.ndarray, start: np.ndarray, t: float,
                     solver: SolverSpec, iterations: int) -> tuple[np.ndarray, np.ndarray, int]:
    """The robust path of the friction solve, after Newton and damped Newton gave up: the
    Anderson-accelerated fixed point lam_R = lam0 + W qf(lam_R) from ``start``, then Newton with a
    finite-difference Jacobian. Returns (lam_R, the friction forces, ``iterations`` plus its own);
    raises :class:`FrictionSolveError` (time, joints, residual) when neither converges."""
    plan, tol, max_iter = model.plan, solver.friction_tol, solver.friction_max_iter
    xrows = plan.friction_xrows

    def G(lr):
        return lam0 + W @ _friction_forces_reduced(plan, ctx, lr[xrows])[0]

    lr, more, ok = _fixed_point(G, start, xrows, tol, max_iter)
    iterations += more
    if not ok:
        lr, more, ok = _newton(G, lr, xrows, tol, max_iter)
        iterations += more
    if not ok:
        res = np.max(np.abs(G(lr)[xrows] - lr[xrows]))
        names = ", ".join(model.joints[j].name for j in model.friction_joints)
        raise FrictionSolveError(
            f"t = {t:.9g} s: friction solve in joints {names} did not converge "
            f"(residual {res:.3g} N after {iterations} iterations: Newton, fixed point, "
            "then Newton with a finite-difference Jacobian)")
    return lr, _friction_forces_reduced(plan, ctx, lr[xrows])[0], iterations


def _cho_solve_many(factor, B: np.ndarray) -> np.ndarray:
    """S^-1 B for a 2-D B (columns solved at once) with the factor of :func:`_cho_factor` (S^+ B
    with that of :func:`_min_norm_inverse`)."""
    if isinstance(factor, _PseudoInverse):
        return factor.P @ B
    c, lower = factor
    if B.shape[1] == 0:
        return np.zeros((c.shape[0], 0))
    _chkfinite(B)
    X, info = dpotrs(c, B, lower=lower, overwrite_b=0)
    if info != 0:
        raise ValueError(f"illegal value in {-info}th argument of internal potrs")
    return X


NEWTON_MAX_ITER = 12
"""Evaluations of the friction forces in the Newton solve before the fixed-point fallback."""
NEWTON_REFRESH = 1e-3
"""The Newton solve keeps its Jacobian while each step reduces the residual at least this much
(a chord step; the first step of every evaluation uses a fresh Jacobian)."""


def _friction_forces_reduced(plan: AssemblyPlan, ctx: list, x: np.ndarray):
    """Friction forces on the velocities ``plan.friction_cols`` (ncols,) at the friction
    multipliers x = lam_R[friction_xrows] (eliminated rows read as 0), and the per-group inputs
    (lam, Qi, Qj) that :func:`_friction_jacobian_reduced` needs."""
    xp = np.concatenate((x, (0.0,)))
    qf = np.zeros(len(plan.friction_cols) + 1)
    parts = []
    for g, cx in zip(plan.friction, ctx):
        lam = xp[g.x_index]
        Qi, Qj = g.module.friction(g.data, cx, lam)
        np.add.at(qf, g.col_i, Qi)
        np.add.at(qf, g.col_j, Qj)
        parts.append((lam, Qi, Qj))
    return qf[:-1], parts


def _friction_jacobian_reduced(plan: AssemblyPlan, ctx: list, parts: list, nx: int) -> np.ndarray:
    """Derivative (ncols, nx) of :func:`_friction_forces_reduced`'s forces by x: from each joint
    module's optional ``friction_jacobian(d, ctx, lam)`` where it has one, else by forward
    differences of its ``friction`` (one batched call per equation of the type: a joint's forces
    depend on its own multipliers only)."""
    Dq = np.zeros((len(plan.friction_cols) + 1, nx + 1))
    for g, cx, (lam, Qi, Qj) in zip(plan.friction, ctx, parts):
        jac = getattr(g.module, "friction_jacobian", None)
        dQi, dQj = jac(g.data, cx, lam) if jac is not None else _fd_friction_jacobian(g, cx, lam, Qi, Qj)
        xi = g.x_index[:, None, :]
        np.add.at(Dq, (g.col_i[:, :, None], xi), dQi)
        np.add.at(Dq, (g.col_j[:, :, None], xi), dQj)
    return Dq[:-1, :nx]


def _fd_friction_jacobian(g, cx, lam: np.ndarray, Qi: np.ndarray, Qj: np.ndarray):
    """(dQi, dQj), each (k, n_coord, n_eq): forward differences of ``g.module.friction`` by the
    joints' multipliers lam (k, n_eq), step 1e-7 max(1, |lam|) (N)."""
    k, ne = lam.shape
    dQi = np.empty(Qi.shape + (ne,))
    dQj = np.empty(Qj.shape + (ne,))
    for c in range(ne):
        step = 1e-7 * np.maximum(1.0, np.abs(lam[:, c]))
        lp = lam.copy()
        lp[:, c] += step
        Pi, Pj = g.module.friction(g.data, cx, lp)
        dQi[..., c] = (Pi - Qi) / step[:, None]
        dQj[..., c] = (Pj - Qj) / step[:, None]
    return dQi, dQj


_IDENTITIES: dict = {}


def _identity(n: int) -> np.ndarray:
    """The (n, n) identity, made once per size (read-only)."""
    eye = _IDENTITIES.get(n)
    if eye is None:
        eye = _IDENTITIES[n] = np.eye(n)
        eye.flags.writeable = False
    return eye


def _newton_reduced(plan: AssemblyPlan, ctx: list, lam0x: np.ndarray, Wx: np.ndarray, x: np.ndarray,
                    tol: float, max_iter: int):
    """Newton's method on the friction multipliers x alone: x = G(x) = lam0x + Wx qf(x) (Wx =
    rows of S^-1 J_R^T M^-1 for x, columns for ``friction_cols``), Jacobian I - Wx dqf/dx,
    kept while it reduces the residual by NEWTON_REFRESH per step. Convergence as the fixed
    point's, ``|G(x) - x| <= tol (1 + |x|)``; gives up (converged False) on a non-finite or twice
    growing residual or after min(max_iter, NEWTON_MAX_ITER) force evaluations. Returns (x,
    qf(x), evaluations, converged)."""
    n_max = min(max_iter, NEWTON_MAX_ITER)
    eye = _identity(len(x))
    prev, growth, lu, piv = np.inf, 0, None, None
    for it in range(1, n_max + 1):
        qf, parts = _friction_forces_reduced(plan, ctx, x)
        r = lam0x + Wx @ qf - x
        res = np.abs(r).max(initial=0.0)
        if not math.isfinite(res):
            return x, qf, it, False
        if res <= tol * (1.0 + np.abs(x).max(initial=0.0)):
            return x, qf, it, True
        growth = growth + 1 if res >= prev else 0
        if growth >= 2 or it == n_max:
            return x, qf, it, False
        if lu is None or res > NEWTON_REFRESH * prev:
            Dq = _friction_jacobian_reduced(plan, ctx, parts, len(x))
            lu, piv, info = dgetrf(eye - Wx @ Dq)
            if info != 0:  # singular Newton matrix (or an illegal value): the fallback decides
                return x, qf, it, False
        prev = res
        dx, info = dgetrs(lu, piv, r)
        if info != 0:  # pragma: no cover - dgetrs fails only on illegal arguments
            return x, qf, it, False
        x = x + dx
    return x, qf, n_max, False


DAMPED_MAX_ITER = 30
"""Force evaluations of the damped Newton solve (the second stage of the friction solve)."""
ARMIJO = 1e-4
"""Sufficient decrease of the damped Newton solve's line search: a step a is taken when
``|r(x + a dx)| < (1 - ARMIJO a) |r(x)|`` (max norms); a is halved down to ARMIJO."""


def _damped_newton_reduced(plan: AssemblyPlan, ctx: list, lam0x: np.ndarray, Wx: np.ndarray, x: np.ndarray,
                           tol: float, max_iter: int):
    """Newton's method on x = lam0x + Wx qf(x) with a fresh Jacobian every step and a backtracking
    line search on the residual's max norm (:data:`ARMIJO`), from the start the undamped solve
    was given. Where the undamped solve wanders (sticking inside the regularisation band of a
    spherical joint, measured: residuals 50-90 N that never settle) this converges in 6-26 force
    evaluations, against about 50 of the fixed point. Gives up (converged False) on a singular
    Newton matrix, a step that no halving down to ARMIJO makes decrease, or after
    min(max_iter, DAMPED_MAX_ITER) force evaluations. Returns (x, qf(x), evaluations, converged)."""
    n_max = min(max_iter, DAMPED_MAX_ITER)
    eye = _identity(len(x))
    qf, parts = _friction_forces_reduced(plan, ctx, x)
    r = lam0x + Wx @ qf - x
    evals = 1
    while True:
        res = np.abs(r).max(initial=0.0)
        if not math.isfinite(res):
            return x, qf, evals, False
        if res <= tol * (1.0 + np.abs(x).max(initial=0.0)):
            return x, qf, evals, True
        if evals >= n_max:
            return x, qf, evals, False
        Dq = _friction_jacobian_reduced(plan, ctx, parts, len(x))
        lu, piv, info = dgetrf(eye - Wx @ Dq)
        if info != 0:
            return x, qf, evals, False
        dx, info = dgetrs(lu, piv, r)
        if info != 0:  # pragma: no cover - dgetrs fails only on illegal arguments
            return x, qf, evals, False
        a = 1.0
        while True:
            xn = x + a * dx
            qn, pn = _friction_forces_reduced(plan, ctx, xn)
            evals += 1
            rn = lam0x + Wx @ qn - xn
            if np.abs(rn).max(initial=0.0) < (1.0 - ARMIJO * a) * res:
                break
            a *= 0.5
            if a < ARMIJO or evals >= n_max:
                return x, qf, evals, False
        x, qf, parts, r = xn, qn, pn, rn


ANDERSON_DEPTH = 3
"""History length of the Anderson acceleration of the friction fixed point (0 = plain)."""


def _fixed_point(G, lr, xrows, tol, max_iter, depth=ANDERSON_DEPTH):
    """Fixed-point iteration x <- G(x) on the friction multipliers (the paper's method), with
    Anderson acceleration of the given depth (0: plain iteration) and divergence detection
    (residual growing 3 times in a row, or non-finite). Returns (lam_R, iterations, converged)."""
    x = lr[xrows].copy()
    g_full = G(lr)
    g = g_full[xrows]
    dF, dG = [], []
    f_prev = g_prev = None
    prev_res, growth = np.inf, 0
    for it in range(1, max_iter + 1):
        f = g - x
        res = np.abs(f).max(initial=0.0)
        if not math.isfinite(res):
            return g_full, it, False
        if res <= tol * (1.0 + np.abs(x).max(initial=0.0)):
            return g_full, it, True
        growth = growth + 1 if res > prev_res else 0
        if growth >= 3:
            return g_full, it, False
        prev_res = res
        if depth and f_prev is not None:
            dF.append(f - f_prev)
            dG.append(g - g_prev)
            del dF[:-depth], dG[:-depth]
        f_prev, g_prev = f, g
        if depth and dF:
            A = np.array(dF).T  # = np.column_stack(dF); lstsq copies it to Fortran order anyway
            coef = _lstsq(A, f, 1e-12)
            x = g - np.column_stack(dG) @ coef
        else:
            x = g
        trial = lr.copy()
        trial[xrows] = x
        g_full = G(trial)
        g = g_full[xrows]
    return g_full, max_iter, False


def _newton(G, lr, xrows, tol, max_iter):
    """Newton on F(x) = x - G(x)_x (friction multipliers x) with a finite-difference Jacobian
    and backtracking line search."""
    x = lr[xrows].copy()

    def lift(xv):
        out = lr.copy()
        out[xrows] = xv
        return out

    def F(xv):
        g = G(lift(xv))
        return xv - g[xrows], g

    Fx, g = F(x)
    n = len(x)
    for it in range(1, max_iter + 1):
        if not np.all(np.isfinite(Fx)):
            return lift(x), it, False
        scale = 1.0 + np.max(np.abs(x), initial=0.0)
        if np.max(np.abs(Fx), initial=0.0) <= tol * scale:
            full = g.copy()
            full[xrows] = x
            return full, it, True
        Jac = np.empty((n, n))
        for k in range(n):
            step = 1e-7 * max(1.0, abs(x[k]))
            xp = x.copy()
            xp[k] += step
            Jac[:, k] = (F(xp)[0] - Fx) / step
        try:
            dx = np.linalg.solve(Jac, -Fx)
        except np.linalg.LinAlgError:
            return lift(x), it, False
        norm0 = np.linalg.norm(Fx)
        alpha = 1.0
        while alpha > 1e-4:
            Fn, gn = F(x + alpha * dx)
            if np.linalg.norm(Fn) < (1.0 - 1e-4 * alpha) * norm0:
                break
            alpha *= 0.5
        else:
            return lift(x), it, False
        x = x + alpha * dx
        Fx, g = Fn, gn
    return lift(x), max_iter, False
