"""Integrators with plain-array state and dense output (registry ``METHODS``).

The FMUs have no inputs, so the integrator takes its own steps and the communication/output grid
only *reads* the solution by dense output: results do not depend on the output grid, and the whole
integrator state is a few arrays (``get_state``/``set_state`` give an exact round trip).

- ``dopri5``: Dormand-Prince 5(4) with the standard step-size control and its 4th-order dense
  output. The Butcher tableau (C, A, B, E, P) is taken from SciPy's ``RK45`` class (data only; the
  stepping loop is ours so that its state can be saved and restored bit for bit). Tolerances:
  ``rtol = atol = tolerance``; ``max_step`` caps the step.
- ``dop853``: Dormand-Prince 8(5,3) (Hairer's DOP853) with 7th-order dense output; far more
  accurate per step at tight tolerances.
- ``rk4``: classical fixed-step Runge-Kutta 4 with step ``step`` (s); dense output by cubic Hermite
  interpolation between steps (4th order in y at the steps, 3rd order between them).
- ``radau``: implicit Radau IIA of order 5 (3 stages, L-stable) for stiff problems, e.g. sticking
  inside a tiny friction regularisation band; simplified Newton iterations with a finite-difference
  Jacobian of the right-hand side, reused over steps; error control with the embedded 3rd-order
  estimate and step-size control of Hairer & Wanner (Solving ODEs II, Sec. IV.8), following SciPy's
  ``Radau`` (constants from there); dense output by the collocation polynomial (no evaluations).

A right-hand side ``fun(t, y)`` may raise; the exception propagates with the time attached by the
caller.

Contract (every class in ``METHODS``, in the manner of SciPy's ``OdeSolver``)
----------------------------------------------------------------------------
``cls(fun, t0, y0, **options)`` takes exactly the keyword options named in ``cls.OPTIONS``
(required ones without a default); an unknown or misspelled option is a ``TypeError`` (no
``**kwargs`` swallow it). :func:`create` selects the method by name and passes it only the options
of ``OPTIONS``, so a caller may hand over one settings record for all methods. After construction
``fun`` has been evaluated once at (t0, y0). Attributes: ``t``, ``y`` (current state), ``f``
(= fun(t, y)), ``t_old``/``y_old`` (start of the last step), ``nfev``, ``nsteps``. Methods:

- ``step()``: one accepted step (may raise :class:`StepSizeTooSmall`,
  :class:`StiffnessDetected`, or what ``fun`` raises); advances ``t`` strictly;
- ``dense(t)``: the solution at ``t_old <= t <= t``, without changing the state;
- ``get_state() -> dict`` / ``set_state(dict)``: an exact round trip of the whole state (plain
  arrays and numbers, for FMI get/set FMU state).

SciPy is used through its public API: the tableaux are read from the public classes
``scipy.integrate.RK45`` and ``DOP853``; Radau's constants are written out below with the
formulas of SciPy's ``radau`` module (tests/test_integrators.py checks them bit for bit).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import DOP853 as _DOP853
from scipy.integrate import RK45 as _RK45
from scipy.linalg import lu_factor, lu_solve

from .verdict import LOCKSTEP_UNSTABLE

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0


class StepSizeTooSmall(ArithmeticError):
    pass


class StiffnessDetected(ArithmeticError):
    """The explicit method's step is limited by stability, not accuracy (Hairer's test)."""


STIFF_STEPS = 15
"""Stiffness test of Hairer's DOPRI5/DOP853: h * rho > 3.25 (dopri5) or 6.1 (dop853) on 15 accepted steps (a run of
six non-stiff steps resets the count),
rho = |f(y_new) - f(y_6)| / |y_new - y_6| estimating the dominant eigenvalue. Stiff steps are
counted (``stiff_steps``, reported); when stability also forces the step below
STIFF_STEP_FRACTION * max_step (e.g. sticking inside a very small friction regularisation band)
the run stops with StiffnessDetected instead of crawling."""
STIFF_STEP_FRACTION = 0.01
STABILITY_LIMITED = 0.6
"""A step with h * rho above STABILITY_LIMITED * stiff_h_rho is taken as limited by stability for the
stop criterion: with very small v_reg (1e-6) the step-size control settles just inside the
stability boundary (dopri5: h * rho = 2.77, below Hairer's 3.25, measured on planar_f145_wo6 with
mu = 1), and a run that met only Hairer's threshold would crawl on at 1e-7 s steps for hours."""


def _combine(K, w) -> np.ndarray:
    """sum_j w[j] K[j] (K: rows of stages), summed elementwise in the order j = 0, 1, ... from
    zero. Not ``K.T @ w``: that matrix-vector product goes to the BLAS, whose kernel (chosen by the
    CPU at run time) may fuse multiply-adds and reorder the sum, and the error estimate of an
    embedded pair is a difference of nearly equal numbers, so those last bits move the step sizes
    (measured: 1e-10 relative in h after three steps). In this fixed order the steps do not depend
    on the CPU and equal core/integrate_rk.c's bit for bit (tests/test_core_integrate.py)."""
    acc = np.zeros(K.shape[1])
    for j in range(len(w)):
        acc = acc + K[j] * w[j]
    return acc


def _sum_squares(x: np.ndarray) -> float:
    """sum of x_i^2 in index order from zero (not the BLAS dot product: see :func:`_combine`)."""
    return sum((x * x).tolist())


class AdaptiveRK:
    """Embedded explicit Runge-Kutta pair with step-size control (the loop of SciPy's
    ``RungeKutta``, with plain-array state). Subclasses give the tableau, the error norm, the
    stiffness threshold and the dense output."""

    n_stages: int
    error_order: int
    stiff_h_rho: float
    name: str

    OPTIONS = ("tolerance", "max_step", "first_step", "detect_stiffness", "dense_fun")

    def __init__(self, fun, t0, y0, *, tolerance, max_step, first_step=None, detect_stiffness=True,
                 dense_fun=None):
        self.fun = fun
        self.dense_fun = dense_fun or fun  # evaluations for dense output only (must not alter state)
        self.detect_stiffness = detect_stiffness
        self.n_stiff = self.n_nonstiff = self.stiff_steps = self.n_limited = 0
        self.rtol = self.atol = float(tolerance)
        self.max_step = float(max_step)
        self.t = float(t0)
        self.y = np.array(y0, float)
        self.f = fun(self.t, self.y)
        self.h = min(self.max_step, first_step or 1e-4)
        self.nfev = 1
        self.nsteps = 0
        # the last accepted step: t_old, y_old, h_old and its stages K
        self.t_old, self.y_old, self.h_old, self.K = self.t, self.y.copy(), 0.0, None
        self._dense_cache = None

    def step(self) -> None:
        t, y, f = self.t, self.y, self.f
        n = y.size
        min_step = 10.0 * np.abs(np.nextafter(t, np.inf) - t)
        h = min(self.h, self.max_step)
        exponent = -1 / (self.error_order + 1)
        while True:
            if not h >= min_step:  # also a NaN step: never loops
                raise StepSizeTooSmall(f"t = {t:.9g} s: step size {h:.3g} s below the minimum")
            K = np.empty((self.n_stages + 1, n))
            K[0] = f
            for s in range(1, self.n_stages):
                y_stage = y + _combine(K[:s], self.A[s, :s]) * h
                K[s] = self.fun(t + self.C[s] * h, y_stage)
            y_new = y + h * _combine(K[:-1], self.B)
            f_new = self.fun(t + h, y_new)
            K[-1] = f_new
            self.nfev += self.n_stages
            scale = self.atol + np.maximum(np.abs(y), np.abs(y_new)) * self.rtol
            err = self._error_norm(K, h, scale)
            if err < 1.0:
                factor = MAX_FACTOR if err == 0 else min(MAX_FACTOR, SAFETY * err ** exponent)
                self.t_old, self.y_old, self.h_old, self.K = t, y, h, K
                self._dense_cache = None
                self.t, self.y, self.f = t + h, y_new, f_new
                self.h = h * factor
                self.nsteps += 1
                self._stiffness_test(h, K[-1] - K[-2], y_new - y_stage)
                return
            h *= max(MIN_FACTOR, SAFETY * err ** exponent)

    def _stiffness_test(self, h, df, dy) -> None:
        den = _sum_squares(dy)
        h_rho = h * math.sqrt(_sum_squares(df) / den) if den > 0.0 else 0.0
        if h_rho > self.stiff_h_rho:
            self.n_stiff, self.n_nonstiff = self.n_stiff + 1, 0
        else:
            self.n_nonstiff += 1
            if self.n_nonstiff >= 6:  # Hairer: six non-stiff steps in a row clear the count
                self.n_stiff = 0
        if self.n_stiff >= STIFF_STEPS:
            self.stiff_steps += 1
        self.n_limited = self.n_limited + 1 if h_rho > STABILITY_LIMITED * self.stiff_h_rho else 0
        limited = self.n_stiff >= STIFF_STEPS or self.n_limited >= 10 * STIFF_STEPS
        if limited and self.detect_stiffness and h < STIFF_STEP_FRACTION * self.max_step:
            raise StiffnessDetected(
                f"t = {self.t:.9g} s: the problem is stiff for {self.name} (step {h:.3g} s limited by "
                f"stability on {max(self.n_stiff, self.n_limited)} steps in a row); e.g. a small friction "
                "regularisation velocity: increase v_reg or use the method for stiff problems, radau")

    def dense(self, t: float) -> np.ndarray:
        if t == self.t:
            return self.y.copy()
        if self._dense_cache is None:
            self._dense_cache = self._dense_setup()
        return self._dense_eval(self._dense_cache, (t - self.t_old) / self.h_old)

    def get_state(self) -> dict:
        return {"t": self.t, "y": self.y.copy(), "f": self.f.copy(), "h": self.h,
                "t_old": self.t_old, "y_old": self.y_old.copy(), "h_old": self.h_old,
                "K": None if self.K is None else self.K.copy(), "nfev": self.nfev, "nsteps": self.nsteps,
                "n_stiff": self.n_stiff, "n_nonstiff": self.n_nonstiff, "stiff_steps": self.stiff_steps,
                "n_limited": self.n_limited}

    def set_state(self, s: dict) -> None:
        self.t, self.y, self.f, self.h = s["t"], s["y"].copy(), s["f"].copy(), s["h"]
        self.t_old, self.y_old, self.h_old = s["t_old"], s["y_old"].copy(), s["h_old"]
        self.K = None if s["K"] is None else s["K"].copy()
        self._dense_cache = None
        self.nfev, self.nsteps = s["nfev"], s["nsteps"]
        self.n_stiff, self.n_nonstiff, self.stiff_steps = s["n_stiff"], s["n_nonstiff"], s["stiff_steps"]
        self.n_limited = s.get("n_limited", 0)


class Dopri5(AdaptiveRK):
    """Dormand-Prince 5(4), 4th-order dense output (tableau from SciPy's RK45)."""

    C, A, B, E, P = _RK45.C, _RK45.A, _RK45.B, _RK45.E, _RK45.P
    n_stages = 6
    error_order = 4
    stiff_h_rho = 3.25
    name = "dopri5"

    def _error_norm(self, K, h, scale):
        return math.sqrt(_sum_squares(_combine(K, self.E) * h / scale) / scale.size)

    def _dense_setup(self):
        return [_combine(self.K, self.P[:, c]) for c in range(self.P.shape[1])]

    def _dense_eval(self, Q, x):
        p = np.cumprod(np.full(len(Q), x))
        return self.y_old + self.h_old * (Q[0] * p[0] + Q[1] * p[1] + Q[2] * p[2] + Q[3] * p[3])


class Dop853(AdaptiveRK):
    """Dormand-Prince 8(5,3) (Hairer's DOP853) with its 7th-order dense output, which needs three
    extra stages per step; they are evaluated only when an output falls inside the step, with
    ``dense_fun`` (which must not change the integration's state, so outputs never alter the
    trajectory). Coefficients from SciPy's ``dop853_coefficients``."""

    n_stages = _DOP853.n_stages
    A, B, C = _DOP853.A, _DOP853.B, _DOP853.C
    E3, E5, D = _DOP853.E3, _DOP853.E5, _DOP853.D
    A_EXTRA, C_EXTRA = _DOP853.A_EXTRA, _DOP853.C_EXTRA
    N_STAGES_EXTENDED = n_stages + 1 + len(A_EXTRA)  # 16: the step's stages, f(y_new), 3 extra
    INTERPOLATOR_POWER = 3 + len(D)  # 7
    error_order = 7
    stiff_h_rho = 6.1
    name = "dop853"

    def _error_norm(self, K, h, scale):
        """Hairer's norm from the 5th- and 3rd-order estimates, summed in index order (:func:`_combine`,
        :func:`_sum_squares`: core/integrate_rk.c takes the same steps bit for bit)."""
        err5 = _combine(K, self.E5) / scale
        err3 = _combine(K, self.E3) / scale
        e5, e3 = _sum_squares(err5), _sum_squares(err3)
        if e5 == 0.0 and e3 == 0.0:
            return 0.0
        return abs(h) * e5 / math.sqrt((e5 + 0.01 * e3) * len(scale))

    def _dense_setup(self):
        h, n = self.h_old, self.y.size
        K = np.empty((self.N_STAGES_EXTENDED, n))
        K[: self.n_stages + 1] = self.K
        for s, (a, c) in enumerate(zip(self.A_EXTRA, self.C_EXTRA), start=self.n_stages + 1):
            K[s] = self.dense_fun(self.t_old + c * h, self.y_old + _combine(K[:s], a[:s]) * h)
        F = np.empty((self.INTERPOLATOR_POWER, n))
        delta = self.y - self.y_old
        F[0] = delta
        F[1] = h * K[0] - delta
        F[2] = 2 * delta - h * (self.f + K[0])
        for r in range(len(self.D)):
            F[3 + r] = h * _combine(K, self.D[r])
        return F

    def _dense_eval(self, F, x):
        """y_old + the nested polynomial (((F[-1] x + F[-2]) (1 - x) + F[-3]) x + ...) in x: its
        scalar weight per row of F first (suffix products of the factors x, 1 - x, x, ...), then
        one weighted sum of the rows (:func:`_combine`) instead of two array operations per row."""
        n = len(F)
        w, p = [0.0] * n, 1.0
        for i in range(n):  # F[i] is multiplied by the factors of rows n - 1 - i ... 0 of F[::-1]
            p *= x if (n - 1 - i) % 2 == 0 else 1 - x
            w[i] = p
        return _combine(F, w) + self.y_old


RK4_STABILITY = 2.785
"""|h lambda| at the boundary of the classical Runge-Kutta method's stability region on the
negative real axis (2.7853): a fixed step beyond it amplifies the fast modes instead of damping
them."""


class UnstableStep(ArithmeticError):
    """A fixed step beyond the method's stability boundary (see :meth:`RK4.step`);
    ``stable_step`` (s) is the largest step the estimate calls stable, as data for the lockstep
    comparison (:class:`overcon.verdict.LockstepGrid`)."""

    def __init__(self, message: str, stable_step: float):
        super().__init__(message)
        self.stable_step = float(stable_step)


class RK4:
    """Classical Runge-Kutta 4 with the fixed step ``step`` (s); dense output by cubic Hermite
    interpolation between steps.

    Stability guard (decided here): a fixed step cannot adapt, so every step estimates the largest
    rate of the right-hand side from its own stages, rho = |k3 - k2| / |Y3 - Y2| with
    Y3 - Y2 = h/2 (k2 - k1) (the stiffness estimate of Hairer's explicit codes, here from stages 2
    and 3), and refuses the step with :class:`UnstableStep` when h rho > :data:`RK4_STABILITY`,
    naming the time and a step that would be stable (2/rho). Such a step would not be an
    inaccurate result but a wrong one: sticking inside a friction law's regularisation band has
    rho of about mu N / (m v_reg), and rk4 beyond its boundary turns the sticking into chatter of
    +-mu N (measured: h rho = 11 to 26 on a drawer's rail friction at 5 ms). Measured h rho on the
    paper's and the examples' scenes at 5 ms: at most 1.14 (spatial G, H)."""

    OPTIONS = ("step",)

    def __init__(self, fun, t0, y0, *, step):
        self.fun = fun
        self.step_size = float(step)
        self.t0 = float(t0)
        self.k = 0  # steps taken: t = t0 + k * step (no accumulation of round-off)
        self.t = self.t0
        self.y = np.array(y0, float)
        self.f = fun(self.t, self.y)
        self.nfev = 1
        self.nsteps = 0
        self.t_old, self.y_old, self.f_old = self.t, self.y.copy(), self.f.copy()

    def step(self) -> None:
        h, t, y = self.step_size, self.t, self.y
        k1 = self.f
        k2 = self.fun(t + h / 2, y + h / 2 * k1)
        k3 = self.fun(t + h / 2, y + h / 2 * k2)
        self._check_stability(h, k1, k2, k3)
        t_new = self.t0 + (self.k + 1) * h
        k4 = self.fun(t_new, y + h * k3)
        y_new = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        f_new = self.fun(t_new, y_new)
        self.nfev += 4
        self.t_old, self.y_old, self.f_old = t, y, k1
        self.k += 1
        self.t, self.y, self.f = t_new, y_new, f_new
        self.nsteps += 1

    def _check_stability(self, h: float, k1: np.ndarray, k2: np.ndarray, k3: np.ndarray) -> None:
        """Raise :class:`UnstableStep` when h rho > RK4_STABILITY (class docstring)."""
        den = 0.5 * h * math.sqrt(_sum_squares(k2 - k1))
        if den == 0.0:
            return
        h_rho = h * math.sqrt(_sum_squares(k3 - k2)) / den
        if h_rho > RK4_STABILITY:
            rho = h_rho / h
            raise UnstableStep(
                f"t = {self.t:.9g} s: {LOCKSTEP_UNSTABLE} with the fixed step {h:g} s (h*rho = {h_rho:.3g} > "
                f"{RK4_STABILITY}, rho = {rho:.3g} 1/s the fastest rate of the right-hand side, e.g. friction "
                f"sticking inside its regularisation band): a step of at most {2.0 / rho:.2g} s is stable; "
                "or use the method for stiff problems, radau", 2.0 / rho)

    def dense(self, t: float) -> np.ndarray:
        if t == self.t:
            return self.y.copy()
        h = self.t - self.t_old
        x = (t - self.t_old) / h
        h00, h10 = 2 * x**3 - 3 * x**2 + 1, x**3 - 2 * x**2 + x
        h01, h11 = -2 * x**3 + 3 * x**2, x**3 - x**2
        return h00 * self.y_old + h10 * h * self.f_old + h01 * self.y + h11 * h * self.f

    def get_state(self) -> dict:
        return {"k": self.k, "t": self.t, "y": self.y.copy(), "f": self.f.copy(), "t_old": self.t_old,
                "y_old": self.y_old.copy(), "f_old": self.f_old.copy(), "nfev": self.nfev, "nsteps": self.nsteps}

    def set_state(self, s: dict) -> None:
        self.k, self.t, self.y, self.f = s["k"], s["t"], s["y"].copy(), s["f"].copy()
        self.t_old, self.y_old, self.f_old = s["t_old"], s["y_old"].copy(), s["f_old"].copy()
        self.nfev, self.nsteps = s["nfev"], s["nsteps"]


# Radau IIA (order 5) constants, written with the formulas of SciPy's radau module (not public API)
_S6 = 6 ** 0.5
_RADAU_C = np.array([(4 - _S6) / 10, (4 + _S6) / 10, 1])
_RADAU_E = np.array([-13 - 7 * _S6, -13 + 7 * _S6, -1]) / 3
_RADAU_MU_REAL = 3 + 3 ** (2 / 3) - 3 ** (1 / 3)
_RADAU_MU_COMPLEX = (3 + 0.5 * (3 ** (1 / 3) - 3 ** (2 / 3)) - 0.5j * (3 ** (5 / 6) + 3 ** (7 / 6)))
_RADAU_T = np.array([
    [0.09443876248897524, -0.14125529502095421, 0.03002919410514742],
    [0.25021312296533332, 0.20412935229379994, -0.38294211275726192],
    [1, 1, 0]])
_RADAU_TI = np.array([
    [4.17871859155190428, 0.32768282076106237, 0.52337644549944951],
    [-4.17871859155190428, -0.32768282076106237, 0.47662355450055044],
    [0.50287263494578682, -2.57192694985560522, 0.59603920482822492]])
_RADAU_P = np.array([
    [13 / 3 + 7 * _S6 / 3, -23 / 3 - 22 * _S6 / 3, 10 / 3 + 5 * _S6],
    [13 / 3 - 7 * _S6 / 3, -23 / 3 + 22 * _S6 / 3, 10 / 3 - 5 * _S6],
    [1 / 3, -8 / 3, 10 / 3]])


class Radau5:
    """Radau IIA, order 5 (Hairer & Wanner's RADAU5 as in SciPy's ``Radau``), with plain-array state.

    Each step solves the 3-stage collocation system by simplified Newton iterations with the
    matrices ``mu/h I - J`` (one real, one complex LU, kept while h and J stay); J is a
    forward-difference Jacobian of ``fun`` (n extra evaluations), recomputed only when Newton
    converges slowly or fails. ``rtol = atol = tolerance``; ``max_step`` caps the step. A right-hand
    side that fails at a Newton iterate (ArithmeticError, e.g. the friction solve) counts as a
    failed Newton iteration (the step is retried smaller); the last such reason is kept for the
    error message when the step size collapses.
    """

    name = "radau"
    C, E, T, TI, P = _RADAU_C, _RADAU_E, _RADAU_T, _RADAU_TI, _RADAU_P
    MU_REAL, MU_COMPLEX = _RADAU_MU_REAL, _RADAU_MU_COMPLEX
    TI_REAL, TI_COMPLEX = _RADAU_TI[0], _RADAU_TI[1] + 1j * _RADAU_TI[2]
    NEWTON_MAXITER = 6
    OPTIONS = ("tolerance", "max_step", "first_step")

    def __init__(self, fun, t0, y0, *, tolerance, max_step, first_step=None):
        self.fun = fun
        self.rtol = self.atol = float(tolerance)
        self.max_step = float(max_step)
        self.newton_tol = max(10 * np.finfo(float).eps / self.rtol, min(0.03, self.rtol ** 0.5))
        self.t = float(t0)
        self.y = np.array(y0, float)
        self.f = fun(self.t, self.y)
        self.nfev, self.njev, self.nlu, self.nsteps = 1, 0, 0, 0
        self.h_abs = min(self.max_step, first_step or 1e-4)
        self.h_abs_old = self.error_norm_old = None
        self.J = self._jacobian(self.t, self.y, self.f)
        self.current_jac = True
        self.lu_h = None  # step size of the LU factors below (None: none)
        self.LU_real = self.LU_complex = None
        self.t_old, self.y_old, self.Z = self.t, self.y.copy(), None
        self.last_failure = ""

    # -- pieces ----------------------------------------------------------------------------
    def _jacobian(self, t, y, f):
        """Forward differences, step sqrt(eps) max(|y_k|, 1) (units of y: m, rad, m/s, rad/s)."""
        n = y.size
        J = np.empty((n, n))
        delta = np.sqrt(np.finfo(float).eps) * np.maximum(np.abs(y), 1.0)
        for k in range(n):
            yk = y.copy()
            yk[k] += delta[k]
            J[:, k] = (self.fun(t, yk) - f) / (yk[k] - y[k])
        self.nfev += n
        self.njev += 1
        return J

    def _factor(self, h):
        n = self.y.size
        self.LU_real = lu_factor(self.MU_REAL / h * np.identity(n) - self.J)
        self.LU_complex = lu_factor(self.MU_COMPLEX / h * np.identity(n) - self.J)
        self.lu_h = h
        self.nlu += 2

    def _dense_poly(self, t):
        x = (t - self.t_old) / (self.t - self.t_old)
        return self.y_old + (self.Z.T @ self.P) @ np.cumprod(np.full(3, x))

    @staticmethod
    def _norm(x):
        return float(np.linalg.norm(x) / x.size ** 0.5)

    def _collocation(self, t, y, h, Z0, scale):
        """Simplified Newton on the collocation system; returns (converged, iterations, Z, rate)."""
        n = y.size
        M_real, M_complex = self.MU_REAL / h, self.MU_COMPLEX / h
        W = self.TI @ Z0
        Z = Z0
        F = np.empty((3, n))
        dW = np.empty_like(W)
        dW_norm_old = rate = None
        for k in range(self.NEWTON_MAXITER):
            try:
                for i in range(3):
                    F[i] = self.fun(t + self.C[i] * h, y + Z[i])
            except (ArithmeticError, np.linalg.LinAlgError) as exc:
                self.last_failure = str(exc)
                return False, k + 1, Z, rate
            finally:
                self.nfev += i + 1
            f_real = F.T @ self.TI_REAL - M_real * W[0]
            f_complex = F.T @ self.TI_COMPLEX - M_complex * (W[1] + 1j * W[2])
            dW_complex = lu_solve(self.LU_complex, f_complex)
            dW[0] = lu_solve(self.LU_real, f_real)
            dW[1], dW[2] = dW_complex.real, dW_complex.imag
            dW_norm = self._norm(dW / scale)
            if dW_norm_old is not None:
                rate = dW_norm / dW_norm_old
            if rate is not None and (rate >= 1 or rate ** (self.NEWTON_MAXITER - k) / (1 - rate) * dW_norm > self.newton_tol):
                return False, k + 1, Z, rate
            W = W + dW
            Z = self.T @ W
            if dW_norm == 0 or (rate is not None and rate / (1 - rate) * dW_norm < self.newton_tol):
                return True, k + 1, Z, rate
            dW_norm_old = dW_norm
        return False, self.NEWTON_MAXITER, Z, rate

    @staticmethod
    def _predict_factor(h_abs, h_abs_old, error_norm, error_norm_old):
        """Step-size factor of Hairer & Wanner's predictive controller. An error estimate of
        exactly 0 (e.g. a motion the collocation polynomial reproduces exactly: constant force,
        no friction) gives an infinite factor, which the caller caps at MAX_FACTOR, as in SciPy
        (there ``error_norm`` is a NumPy float; a Python float 0.0 ** -0.25 raises)."""
        if error_norm == 0:
            return np.inf
        if error_norm_old is None or h_abs_old is None or error_norm_old == 0:
            multiplier = 1.0
        else:
            multiplier = h_abs / h_abs_old * (error_norm_old / error_norm) ** 0.25
        return min(1.0, multiplier) * error_norm ** -0.25

    # -- one step --------------------------------------------------------------------------
    def step(self) -> None:
        t, y, f = self.t, self.y, self.f
        min_step = 10.0 * np.abs(np.nextafter(t, np.inf) - t)
        h_abs, h_abs_old, error_norm_old = self.h_abs, self.h_abs_old, self.error_norm_old
        if h_abs > self.max_step:
            h_abs, h_abs_old, error_norm_old = self.max_step, None, None
        rejected = False
        while True:
            if not h_abs >= min_step:  # also a NaN step: never loops
                why = f" (last failure: {self.last_failure})" if self.last_failure else ""
                raise StepSizeTooSmall(f"t = {t:.9g} s: step size {h_abs:.3g} s below the minimum{why}")
            h = h_abs
            Z0 = np.zeros((3, y.size)) if self.Z is None else (
                np.array([self._dense_poly(t + c * h) for c in self.C]) - y)
            scale = self.atol + np.abs(y) * self.rtol
            while True:
                if self.lu_h != h:
                    self._factor(h)
                converged, n_iter, Z, rate = self._collocation(t, y, h, Z0, scale)
                if converged or self.current_jac:
                    break
                self.J = self._jacobian(t, y, f)
                self.current_jac = True
                self.lu_h = None
            if not converged:
                h_abs *= 0.5
                self.lu_h = None
                continue
            y_new = y + Z[-1]
            ZE = Z.T @ self.E / h
            error = lu_solve(self.LU_real, f + ZE)
            scale = self.atol + np.maximum(np.abs(y), np.abs(y_new)) * self.rtol
            error_norm = self._norm(error / scale)
            safety = 0.9 * (2 * self.NEWTON_MAXITER + 1) / (2 * self.NEWTON_MAXITER + n_iter)
            if rejected and error_norm > 1:
                error = lu_solve(self.LU_real, self.fun(t, y + error) + ZE)
                self.nfev += 1
                error_norm = self._norm(error / scale)
            if not np.isfinite(error_norm):  # never accept a non-finite estimate: halve, as on failure
                self.last_failure = "non-finite error estimate"
                h_abs *= 0.5
                self.lu_h = None
                rejected = True
                continue
            if error_norm > 1:
                factor = self._predict_factor(h_abs, h_abs_old, error_norm, error_norm_old)
                h_abs *= max(MIN_FACTOR, safety * factor)
                self.lu_h = None
                rejected = True
                continue
            break
        recompute_jac = n_iter > 2 and rate is not None and rate > 1e-3
        factor = min(MAX_FACTOR, safety * self._predict_factor(h_abs, h_abs_old, error_norm, error_norm_old))
        if not recompute_jac and factor < 1.2:
            factor = 1.0
        else:
            self.lu_h = None
        t_new = t + h
        f_new = self.fun(t_new, y_new)  # last evaluation of the step: at the accepted state
        self.nfev += 1
        if recompute_jac:
            self.J = self._jacobian(t_new, y_new, f_new)
            self.current_jac = True
        else:
            self.current_jac = False
        self.h_abs_old, self.error_norm_old = h_abs, error_norm
        self.h_abs = h_abs * factor
        self.t_old, self.y_old, self.Z = t, y, Z
        self.t, self.y, self.f = t_new, y_new, f_new
        self.nsteps += 1
        self.last_failure = ""

    def dense(self, t: float) -> np.ndarray:
        if t == self.t or self.Z is None:
            return self.y.copy()
        return self._dense_poly(t)

    # -- state -----------------------------------------------------------------------------
    _ARRAYS = ("y", "f", "J", "y_old", "Z")
    _SCALARS = ("t", "h_abs", "h_abs_old", "error_norm_old", "current_jac", "lu_h", "t_old", "nfev",
                "njev", "nlu", "nsteps", "last_failure")

    def get_state(self) -> dict:
        s = {k: getattr(self, k) for k in self._SCALARS}
        s.update({k: None if getattr(self, k) is None else getattr(self, k).copy() for k in self._ARRAYS})
        if self.lu_h is not None:  # the factors themselves (complex as float pairs): exact restore
            s["lu_real"], s["piv_real"] = self.LU_real[0].copy(), self.LU_real[1].copy()
            s["lu_complex"], s["piv_complex"] = np.ascontiguousarray(self.LU_complex[0]).view(float).copy(), self.LU_complex[1].copy()
        return s

    def set_state(self, s: dict) -> None:
        for k in self._SCALARS:
            setattr(self, k, s[k])
        for k in self._ARRAYS:
            setattr(self, k, None if s[k] is None else np.array(s[k], float))
        if self.lu_h is not None:
            self.LU_real = (np.array(s["lu_real"], float), np.array(s["piv_real"]))
            self.LU_complex = (np.ascontiguousarray(s["lu_complex"], float).view(complex).copy(),
                               np.array(s["piv_complex"]))
        else:
            self.LU_real = self.LU_complex = None


METHODS = {"dopri5": Dopri5, "dop853": Dop853, "rk4": RK4, "radau": Radau5}


def create(method: str, fun, t0, y0, **options):
    """The integrator ``METHODS[method]`` started at (t0, y0), given those of ``options`` it
    declares in ``OPTIONS`` (the others belong to other methods, e.g. ``step`` to ``rk4`` only).
    A name that no method declares is refused: a misspelled option is an error, not ignored."""
    known = {name for cls in METHODS.values() for name in cls.OPTIONS}
    unknown = sorted(set(options) - known)
    if unknown:
        raise TypeError(f"unknown integrator option(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
    cls = METHODS[method]
    return cls(fun, t0, y0, **{k: v for k, v in options.items() if k in cls.OPTIONS})
