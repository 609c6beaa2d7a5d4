"""The watch over singular positions along a run: it sees every instant where the kept
equations' Jacobian loses rank, whatever the multiplicity of the loss, and tells the mechanism's
singular positions apart from an elimination that has expired.

What is watched: r(q) = sigma_min / sigma_max of the kept Jacobian J_R = Phi_h[R], mass-weighted
(J_R M^-1/2) with unit-norm rows, so invariant to the length unit and to each equation's
scaling (dimensionless). Under ``redundancy = "min-norm"`` every equation is kept: an independent
subset chosen at the start is watched; under ``"compliant"`` the rigid equations are.

How (decided here): after every accepted step, r and its rate dr/dt along the motion (from the
SVD's singular vectors and J' = dJ/dq q', by a forward difference of J along q' over
``1e-7 / max(1, |q'|)`` s). A rank loss is a zero of a singular value, which r passes in a V
(it falls to 0 and rises again), whatever the number of singular values that vanish together;
so a step that starts with r falling and ends with r rising holds a minimum of r. That minimum
is located on the integrator's dense output by golden-section search (to 1e-9 of the step), and
judged like a step end: r < ``ratio_tol`` (default 1e-6) is a singular position at that instant.
The instant found depends on the trajectory only, not on where the steps happen to land, so the
stop time does not depend on the tolerance beyond the integration error. A minimum of r that
stays above ``ratio_tol`` (a near miss) costs the search and nothing else.

Which singular position (decided here): at the instant found, the whole Jacobian (every
equation, the same weighting) is judged too. If it keeps the rank the kept equations had at the
start, the mechanism is regular there and only the kept set lost rank: :class:`EliminationExpired`
(the caller may choose another set and go on). Else the mechanism itself is singular:
:class:`SingularPosition`, or, for a run that passes singular positions (``solver.singular =
"pass"``), a ``singular`` event handed to the run, which goes on. Under min-norm, an expired watch subset is chosen again silently (the
dynamics never used it).
"""
from __future__ import annotations

import math

import numpy as np

from .evaluation import SingularConfiguration, coordinate_rates, frames, jacobian_h

GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
DEGRADED_RATIO = 1e-3  # r of the kept equations below which the elimination counts as degrading ...
DEGRADED_MARGIN = 100.0  # ... when the whole Jacobian is at least this much better conditioned
SEARCH_REL = 1e-9  # golden-section search: stop when the bracket is below this fraction of the step


ALONG_RATIO = 1e-3
"""Below this r of the kept equations the uniqueness along the motion (:class:`Uniqueness`) is
evaluated at the step's end (decided: above it neither the rank nor a verdict can change, see
:class:`Uniqueness`; it is :data:`DEGRADED_RATIO`, where the watch judges the whole Jacobian anyway)."""


class SingularPosition(SingularConfiguration):
    """The mechanism is singular at ``t`` (s): its whole Jacobian lost rank there (``y``: the
    state there)."""

    def __init__(self, message: str, t: float, ratio: float, y: np.ndarray | None = None):
        super().__init__(message)
        self.t, self.ratio, self.y = t, ratio, y


class EliminationExpired(SingularConfiguration):
    """Only the kept equations lost rank at ``t`` (s); the whole Jacobian keeps its rank there.
    ``y`` is the state at ``t``; ``t_step`` the start of the step that reached it."""

    def __init__(self, message: str, t: float, ratio: float, y: np.ndarray, t_step: float):
        super().__init__(message)
        self.t, self.ratio, self.y, self.t_step = t, ratio, y, t_step


def shown_ratio(r: float) -> str:
    """r for a message: two digits, or "< 1e-09" below the level where it is round-off (the two
    right-hand-side paths, or two CPUs, differ there)."""
    return f"{r:.2g}" if r >= 1e-9 else "< 1e-09"


def numpy_jacobian(model, y: np.ndarray) -> np.ndarray:
    """Phi_h (m, nh) at the state y, on the numpy path."""
    return jacobian_h(model, frames(model, y[: model.n]))


def weighted_rows(model, y: np.ndarray, rows: np.ndarray, jac=None) -> np.ndarray:
    """Rows ``rows`` of Phi_h at state y (``jac(model, y)``, default :func:`numpy_jacobian`),
    times M^-1/2, each scaled to unit norm."""
    J = (jac or numpy_jacobian)(model, y)[rows] * np.sqrt(model.Minv)[None, :]
    return J / np.linalg.norm(J, axis=1, keepdims=True)


def ratio(J: np.ndarray) -> float:
    """sigma_min / sigma_max of J (1 for no rows)."""
    if not J.shape[0]:
        return 1.0
    sv = np.linalg.svd(J, compute_uv=False)
    return float(sv[-1] / sv[0])


def numerical_rank(J: np.ndarray, ratio_tol: float) -> int:
    """Singular values of J at or above ``ratio_tol`` times the largest."""
    if not J.shape[0]:
        return 0
    sv = np.linalg.svd(J, compute_uv=False)
    return int(np.sum(sv >= ratio_tol * sv[0]))


def ratio_and_rate(model, y: np.ndarray, rows: np.ndarray, jac=None, qdot=None) -> tuple[float, float]:
    """(r, dr/dt) at state y (see the module docstring): r = s_min / s_max; dr/dt from
    ds_k/dt = u_k^T J' v_k with J' by a forward difference of J along q' (``qdot``, default
    the coordinate rates at y). ``jac``: as :func:`weighted_rows`."""
    n = model.n
    if qdot is None:
        qdot = coordinate_rates(model, y[:n], y[n:])
    dt = 1e-7 / max(1.0, float(np.max(np.abs(qdot), initial=0.0)))
    y2 = y.copy()
    y2[:n] = y[:n] + dt * qdot
    J2 = weighted_rows(model, y2, rows, jac)
    J = weighted_rows(model, y, rows, jac)  # last: a caller's jac may keep the rows at y (the drift)
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    Jdot = (J2 - J) / dt
    ds_min = float(U[:, -1] @ Jdot @ Vt[-1])
    ds_max = float(U[:, 0] @ Jdot @ Vt[0])
    r = float(sv[-1] / sv[0])
    return r, (ds_min - r * ds_max) / float(sv[0])


class SingularityMonitor:
    """The watch (module docstring) over one run. :meth:`check` after every accepted step;
    ``min_ratio`` is the smallest r seen (step ends and located minima)."""

    def __init__(self, model, y: np.ndarray, t0: float, ratio_tol: float = 1e-6, jac=None, passing=None):
        """``jac(model, y)``: Phi_h at y (the compiled core's rows where a run has it; default
        :func:`numpy_jacobian`). ``passing(t, message)``: given by a run that passes singular
        positions (``solver.singular = "pass"``): a singular position of the mechanism is handed
        to it, once per passage (the located minimum, else the first step end below ``ratio_tol``),
        instead of raising :class:`SingularPosition`."""
        self.model, self.ratio_tol, self.jac, self.passing = model, ratio_tol, jac, passing
        self._below = False  # passing: r was below ratio_tol at the last step end (the same passage)
        self.rows = self._watched_rows(model, y)
        self.full_rows = self._rigid_rows(model)
        self.kept_rank = len(self.rows)  # the kept equations are independent at the start
        self.min_ratio, self.t_prev, self.rate, self.ratio = np.inf, t0, 0.0, 1.0
        if not self.rows.size:  # nothing rigid to lose rank
            return
        r, self.rate = ratio_and_rate(model, y, self.rows, jac)
        self.ratio = r
        self._judge(t0, r, y, t0)

    @staticmethod
    def _rigid_rows(model) -> np.ndarray:
        if model.compliant_rows.size:  # compliant equations are forces: only the rigid ones can lose rank
            return np.setdiff1d(np.arange(model.m), model.compliant_rows)
        return np.arange(model.m)

    def _watched_rows(self, model, y) -> np.ndarray:
        if model.elimination_mode == "min-norm":  # every equation kept: watch an independent set of them
            from .analysis import independent_columns
            J = jacobian_h(model, frames(model, y[: model.n]))
            return np.array(independent_columns(J.T), int)
        if model.compliant_rows.size:
            return np.setdiff1d(model.retained, model.compliant_rows)
        return np.asarray(model.retained, int)

    def state(self) -> tuple:
        return (self.rows.copy(), self.t_prev, self.rate, self.min_ratio, self.ratio, self._below)

    def set_state(self, s: tuple) -> None:
        rows, self.t_prev, self.rate, self.min_ratio, self.ratio = s[:5]
        self._below = bool(s[5]) if len(s) > 5 else False
        self.rows = np.asarray(rows, int).copy()

    def check(self, t: float, y: np.ndarray, dense=None, qdot=None) -> bool:
        """After the step (t_prev, t]: raise :class:`SingularPosition` or
        :class:`EliminationExpired` if the kept Jacobian lost rank in it or at its end; return
        whether the elimination is degrading (:meth:`_degrading`). ``dense(tau)``: the state
        inside the step (the integrator's dense output)."""
        if not self.rows.size:
            return False
        r, rate = ratio_and_rate(self.model, y, self.rows, self.jac, qdot)
        self.ratio = r
        seen = self._below
        if self.rate < 0.0 < rate and dense is not None and t > self.t_prev:
            t_min, r_min = self._minimum(dense, self.t_prev, t)
            if r_min < r:
                seen = self._judge(t_min, r_min, dense(t_min), self.t_prev, passed=(self.t_prev, t), seen=seen)
        self._judge(t, r, y, self.t_prev, seen=seen)
        self._below = r < self.ratio_tol
        self.t_prev, self.rate = t, rate
        return self._degrading(r, y)

    def _degrading(self, r: float, y: np.ndarray) -> bool:
        """True when the kept equations are ill-conditioned (r < :data:`DEGRADED_RATIO`) while the
        whole Jacobian is much better conditioned there (its rank-th singular value ratio at least
        :data:`DEGRADED_MARGIN` times r): the elimination is on its way to expiring, and its
        ill-conditioning already costs accuracy (Baumgarte's correction and the multipliers are
        amplified by 1/r). Min-norm keeps every equation: never."""
        if r >= DEGRADED_RATIO or self.model.elimination_mode == "min-norm":
            return False
        J = weighted_rows(self.model, y, self.full_rows, self.jac)
        sv = np.linalg.svd(J, compute_uv=False)
        full = float(sv[self.kept_rank - 1] / sv[0]) if sv.size >= self.kept_rank else 0.0
        return full >= DEGRADED_MARGIN * r

    def expiring(self, t: float, y: np.ndarray, h: float):
        """After a step failed (the friction solve, the step size, ...) from the accepted state
        (t, y): (t*, y*) if the kept equations were about to lose rank, r falling to zero at its
        current rate within two steps of length h (t* = t + r / |dr/dt|, y* the positions moved
        on by q' (t* - t)), while the whole Jacobian keeps its rank at y*: the elimination
        expiring is the cause. Else None (min-norm keeps every equation: None)."""
        if not self.rows.size or self.model.elimination_mode == "min-norm" or self.rate >= 0.0 or h <= 0.0:
            return None
        dt = self.ratio / -self.rate
        if dt > 2.0 * h:
            return None
        n = self.model.n
        y_star = y.copy()
        y_star[:n] = y[:n] + dt * coordinate_rates(self.model, y[:n], y[n:])
        if numerical_rank(weighted_rows(self.model, y_star, self.full_rows, self.jac), self.ratio_tol) < self.kept_rank:
            return None  # the mechanism itself is singular there
        return t + dt, y_star

    def _minimum(self, dense, a: float, b: float) -> tuple[float, float]:
        """(tau, r(tau)) at the minimum of r on [a, b] along ``dense`` (golden section)."""
        f = lambda tau: ratio(weighted_rows(self.model, dense(tau), self.rows, self.jac))  # noqa: E731
        c, d = b - GOLDEN * (b - a), a + GOLDEN * (b - a)
        fc, fd = f(c), f(d)
        stop = max(SEARCH_REL * (b - a), 8.0 * np.finfo(float).eps * max(abs(a), abs(b)))  # within t's resolution
        while b - a > stop:
            if fc < fd:
                b, d, fd = d, c, fc
                c = b - GOLDEN * (b - a)
                fc = f(c)
            else:
                a, c, fc = c, d, fd
                d = a + GOLDEN * (b - a)
                fd = f(d)
        return (c, fc) if fc < fd else (d, fd)

    def _judge(self, t: float, r: float, y: np.ndarray, t_step: float, passed=None, seen: bool = False) -> bool:
        """Raise as the module docstring says; under ``passing``, return whether this passage of a
        singular position has been handed over (``seen``: already, by an earlier judgement)."""
        self.min_ratio = min(self.min_ratio, r)
        if r >= self.ratio_tol:
            return seen
        where = (f"t = {t:.9g} s: the motion passed a singular position (between the steps at "
                 f"t = {passed[0]:.9g} s and {passed[1]:.9g} s)" if passed else f"t = {t:.9g} s: singular position")
        full = numerical_rank(weighted_rows(self.model, y, self.full_rows, self.jac), self.ratio_tol)
        if full < self.kept_rank and self.passing is not None:
            if not seen:
                self.passing(t, f"{where}: the mechanism's constraint Jacobian is rank deficient (rank {full} < "
                                f"{self.kept_rank}; kept equations' sigma_min/sigma_max {shown_ratio(r)}): passed")
            return True
        if full < self.kept_rank:
            raise SingularPosition(
                f"{where}: the mechanism's constraint Jacobian is rank deficient (rank {full} < {self.kept_rank}; "
                f"kept equations' sigma_min/sigma_max {shown_ratio(r)}, below {self.ratio_tol:g})", t, r, y.copy())
        if self.model.elimination_mode == "min-norm":  # the watched subset expired, the dynamics never used it
            from .analysis import independent_columns
            self.rows = np.array(independent_columns(_full_jacobian(self.model, y)), int)
            return seen
        raise EliminationExpired(
            f"{where}: the kept equations are no longer independent (their sigma_min/sigma_max {shown_ratio(r)}, "
            f"below {self.ratio_tol:g}), while the mechanism is regular there (all equations keep rank {full}): the "
            "elimination chosen at the start has expired", t, r, y, t_step)


# ----------------------------------------------------------------------------- an expired elimination

def _full_jacobian(model, y: np.ndarray) -> np.ndarray:
    """Phi_h^T (nh, m) at the state y: the analysis' orientation (a joint's equations are columns)."""
    return jacobian_h(model, frames(model, y[: model.n])).T


def friction_on_nonunique(model, y: np.ndarray) -> list[str]:
    """Names of the friction joints (a nonzero coefficient) whose reaction is not unique at y:
    the joints through which the elimination decides the motion (paper, Eq. 17)."""
    from .analysis import analyse
    named = [model.joints[j] for j in model.friction_joints
             if not (model.joints[j].law.mu == 0 and not model.joints[j].law.mu_static)]
    if not named:
        return []
    rigid = [int(i) for i in SingularityMonitor._rigid_rows(model)]
    position = {row: k for k, row in enumerate(rigid)}
    groups = {c.name: [position[r] for r in c.rows if r in position] for c in model.joints}
    groups = {k: v for k, v in groups.items() if v}
    verdicts = {name: v.unique for name, v in analyse(_full_jacobian(model, y)[:, rigid], groups, methods="svd").joints.items()}
    return [c.name for c in named if not verdicts.get(c.name, True)]


def _kept_rank_ok(J: np.ndarray, eliminated: set[int], rank: int) -> bool:
    from .analysis import numerical_rank
    kept = [i for i in range(J.shape[1]) if i + 1 not in eliminated]
    return len(kept) == rank and numerical_rank(J[:, kept]) == rank


def reselected(model, y: np.ndarray):
    """The model with the eliminated equations chosen again at the state y (pivoted QR, as
    ``eliminate = "auto"`` does at q0; compliant equations stay as they are): (model, 1-based
    eliminated equations)."""
    from .analysis import auto_eliminate
    from .checks import with_eliminated
    rigid = [int(i) for i in SingularityMonitor._rigid_rows(model)]
    eliminated = sorted(rigid[k] + 1 for k in auto_eliminate(_full_jacobian(model, y)[:, rigid]))
    return with_eliminated(model, eliminated), eliminated


def valid_eliminations(model, y: np.ndarray, limit: int = 10) -> list[str]:
    """Eliminations that are valid both at q0 and at the state y, as ``[a, b, ...]`` strings (at
    most ``limit``): with one redundant equation, every single equation that qualifies; else the
    set the pivoted QR chooses at y, if it qualifies at q0 too."""
    from .analysis import numerical_rank
    J0 = _full_jacobian(model, np.concatenate([model.q0, model.h0]))
    J1 = _full_jacobian(model, y)
    rank = numerical_rank(J0)
    if model.m - rank == 1:
        singles = [{i + 1} for i in range(model.m) if i not in set(int(r) for r in model.compliant_rows)]
    else:
        singles = [set(reselected(model, y)[1])]
    current = set(model.eliminated)
    good = [s for s in singles if s != current and _kept_rank_ok(J0, s, rank) and _kept_rank_ok(J1, s, rank)]
    return [f"[{', '.join(str(i) for i in sorted(s))}]" for s in good[:limit]]


# ----------------------------------------------------------------------------- uniqueness along the motion

class Uniqueness:
    """The uniqueness along the motion of one run: the whole Jacobian's rank and each joint's
    reaction verdict by the pre-check's one-factorisation rule (:func:`overcon.analysis.analyse`,
    ``methods = "svd"``, its tolerances; the compiled core's ``core/unique.c`` where the run has
    the core, the same rule), and ``motion_unique``: every friction joint with a nonzero law has
    a unique reaction (paper, Eq. 17; a property of the Jacobian, the same whatever the
    elimination; a compliant joint's reaction is unique).

    When (decided, for the cost: one SVD of the whole Jacobian with its right singular vectors):
    at the start, after an accepted step whose kept equations have r < :data:`ALONG_RATIO`, and
    at a singular position where the run stops (its located instant). Along a motion through
    regular positions neither can change in an interval: the equations hold along the motion, so
    the rank of all of them equals that of the kept ones while those are independent, and with
    the rank fixed the null space, hence each joint's B = J_P N_P, is analytic in q, so a verdict
    differs only at isolated instants, which no sampling sees. A change needs the kept Jacobian
    near its loss of rank, where r falls below :data:`ALONG_RATIO` first. :meth:`update` returns
    the events (time s, kind, detail) of a change, at the time of the evaluation (the step's end,
    or the located singular instant)."""

    def __init__(self, model, y: np.ndarray, kernel=None):
        self.model, self.kernel = model, kernel
        self.rank, self.unique = self._evaluate(y)

    def _evaluate(self, y: np.ndarray) -> tuple[int, dict]:
        model = self.model
        if self.kernel is not None:
            rank, verdicts = self.kernel.unique(y)
            return rank, {c.name: bool(v) for c, v in zip(model.joints, verdicts)}
        from .analysis import analyse
        rigid = [int(i) for i in SingularityMonitor._rigid_rows(model)]
        position = {row: k for k, row in enumerate(rigid)}
        groups = {c.name: [position[r] for r in c.rows if r in position] for c in model.joints}
        res = analyse(_full_jacobian(model, y)[:, rigid], {k: v for k, v in groups.items() if v}, methods="svd")
        return res.rank, {c.name: bool(res.joints[c.name].unique) if c.name in res.joints else True
                          for c in model.joints}

    def _acting(self) -> list[str]:
        from .precheck import frictionless
        return [self.model.joints[j].name for j in self.model.friction_joints
                if not frictionless(self.model.joints[j].law)]

    @property
    def motion_unique(self) -> bool:
        return all(self.unique[name] for name in self._acting())

    def update(self, t: float, y: np.ndarray) -> list[tuple[float, str, str]]:
        """Evaluate at the state y (time t, s) and return the events of a change."""
        rank, unique = self._evaluate(y)
        events = []
        if rank != self.rank:
            events.append((t, "rank-change", f"rank {self.rank} -> {rank}"))
        word = {True: "unique", False: "not unique"}
        changed = [f"{self.model.joints[j].name}: {word[self.unique[self.model.joints[j].name]]} -> "
                   f"{word[unique[self.model.joints[j].name]]}" for j in self.model.friction_joints
                   if unique[self.model.joints[j].name] != self.unique[self.model.joints[j].name]]
        was = self.motion_unique
        self.rank, self.unique = rank, unique
        if changed:
            detail = ", ".join(changed)
            if was != self.motion_unique:
                detail += f"; motion_unique {str(was).lower()} -> {str(self.motion_unique).lower()}"
            events.append((t, "uniqueness-change", detail))
        return events

    def state(self) -> tuple:
        return (self.rank, dict(self.unique))

    def set_state(self, s: tuple) -> None:
        self.rank, self.unique = s[0], dict(s[1])
