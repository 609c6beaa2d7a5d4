"""Integrators with plain-array state and dense output (registry ``METHODS``).

The FMUs have no inputs, so the integrator takes its own steps and the communication/output grid
only *reads* the solution by dense output: results do not depend on the output grid, and the whole
integrator state is a few arrays (``get_state``/``set_state`` give an exact round trip).

- ``dopri5``: Dormand-Prince 5(4) with the standard step-size control and its 4th-order dense
  output. The Butcher tableau (C, A, B, E, P) is taken from SciPy's ``RK45`` class (data only; the
  stepping loop is ours so that its state can be saved and restored bit for bit). Tolerances:
  ``rtol = atol = tolerance``; ``max_step`` caps the step.
- ``rk4``: classical fixed-step Runge-Kutta 4 with step ``step`` (s); dense output by cubic Hermite
  interpolation between steps (4th order in y at the steps, 3rd order between them).

A right-hand side ``fun(t, y)`` may raise; the exception propagates with the time attached by the
caller.
"""
from __future__ import annotations

import numpy as np
from scipy.integrate._ivp.rk import RK45 as _RK45

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0


class StepSizeTooSmall(ArithmeticError):
    pass


class StiffnessDetected(ArithmeticError):
    """The explicit method's step is limited by stability, not accuracy (Hairer's test)."""


STIFF_H_RHO = 3.25
STIFF_STEPS = 15
"""dopri5 stiffness test (Hairer & Wanner, DOPRI5): h * rho > 3.25 on 15 accepted steps (a run of
six non-stiff steps resets the count),
rho = |f(y_new) - f(y_6)| / |y_new - y_6| estimating the dominant eigenvalue. Stiff steps are
counted (``stiff_steps``, reported); when stability also forces the step below
STIFF_STEP_FRACTION * max_step (e.g. sticking inside a very small friction regularisation band)
the run stops with StiffnessDetected instead of crawling."""
STIFF_STEP_FRACTION = 0.01


class Dopri5:
    C, A, B, E, P = _RK45.C, _RK45.A, _RK45.B, _RK45.E, _RK45.P
    n_stages = 6
    error_order = 4

    def __init__(self, fun, t0, y0, *, tolerance, max_step, first_step=None, detect_stiffness=True, **_):
        self.fun = fun
        self.detect_stiffness = detect_stiffness
        self.n_stiff = self.n_nonstiff = self.stiff_steps = 0
        self.rtol = self.atol = float(tolerance)
        self.max_step = float(max_step)
        self.t = float(t0)
        self.y = np.array(y0, float)
        self.f = fun(self.t, self.y)
        self.h = min(self.max_step, first_step or 1e-4)
        self.nfev = 1
        self.nsteps = 0
        # dense output of the last accepted step: (t_old, y_old, h, Q)
        self.t_old, self.y_old, self.Q = self.t, self.y.copy(), None

    def step(self) -> None:
        t, y, f = self.t, self.y, self.f
        n = y.size
        min_step = 10.0 * np.abs(np.nextafter(t, np.inf) - t)
        h = min(self.h, self.max_step)
        while True:
            if h < min_step:
                raise StepSizeTooSmall(f"t = {t:.9g} s: step size {h:.3g} s below the minimum")
            K = np.empty((self.n_stages + 1, n))
            K[0] = f
            for s in range(1, self.n_stages):
                dy = K[:s].T @ self.A[s, :s] * h
                y_stage = y + dy
                K[s] = self.fun(t + self.C[s] * h, y_stage)
            y_new = y + h * (K[:-1].T @ self.B)
            f_new = self.fun(t + h, y_new)
            K[-1] = f_new
            self.nfev += self.n_stages
            scale = self.atol + np.maximum(np.abs(y), np.abs(y_new)) * self.rtol
            err = np.sqrt(np.mean(((K.T @ self.E) * h / scale) ** 2))
            if err < 1.0:
                factor = MAX_FACTOR if err == 0 else min(MAX_FACTOR, SAFETY * err ** (-1 / (self.error_order + 1)))
                self.t_old, self.y_old, self.h_old = t, y, h
                self.Q = K.T @ self.P
                self.t, self.y, self.f = t + h, y_new, f_new
                self.h = h * factor
                self.nsteps += 1
                self._stiffness_test(h, K[-1] - K[-2], y_new - y_stage)
                return
            h *= max(MIN_FACTOR, SAFETY * err ** (-1 / (self.error_order + 1)))

    def _stiffness_test(self, h, df, dy) -> None:
        den = float(dy @ dy)
        if den > 0.0 and h * np.sqrt(float(df @ df) / den) > STIFF_H_RHO:
            self.n_stiff, self.n_nonstiff = self.n_stiff + 1, 0
        else:
            self.n_nonstiff += 1
            if self.n_nonstiff >= 6:  # Hairer: six non-stiff steps in a row clear the count
                self.n_stiff = 0
        if self.n_stiff >= STIFF_STEPS:
            self.stiff_steps += 1
        if self.n_stiff >= STIFF_STEPS and self.detect_stiffness and h < STIFF_STEP_FRACTION * self.max_step:
            raise StiffnessDetected(
                f"t = {self.t:.9g} s: the problem is stiff for dopri5 (step {h:.3g} s limited by "
                f"stability on {STIFF_STEPS} steps in a row); e.g. a small friction regularisation "
                "velocity: increase v_reg or use a method for stiff problems")

    def dense(self, t: float) -> np.ndarray:
        if t == self.t:
            return self.y.copy()
        x = (t - self.t_old) / self.h_old
        p = np.cumprod(np.full(self.Q.shape[1], x))
        return self.y_old + self.h_old * (self.Q @ p)

    def get_state(self) -> dict:
        return {"t": self.t, "y": self.y.copy(), "f": self.f.copy(), "h": self.h,
                "t_old": self.t_old, "y_old": self.y_old.copy(), "h_old": getattr(self, "h_old", 0.0),
                "Q": None if self.Q is None else self.Q.copy(), "nfev": self.nfev, "nsteps": self.nsteps,
                "n_stiff": self.n_stiff, "n_nonstiff": self.n_nonstiff,
                "stiff_steps": self.stiff_steps}

    def set_state(self, s: dict) -> None:
        self.t, self.y, self.f, self.h = s["t"], s["y"].copy(), s["f"].copy(), s["h"]
        self.t_old, self.y_old, self.h_old = s["t_old"], s["y_old"].copy(), s["h_old"]
        self.Q = None if s["Q"] is None else s["Q"].copy()
        self.nfev, self.nsteps = s["nfev"], s["nsteps"]
        self.n_stiff, self.n_nonstiff, self.stiff_steps = s["n_stiff"], s["n_nonstiff"], s["stiff_steps"]


class RK4:
    def __init__(self, fun, t0, y0, *, step, **_):
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
        t_new = self.t0 + (self.k + 1) * h
        k4 = self.fun(t_new, y + h * k3)
        y_new = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        f_new = self.fun(t_new, y_new)
        self.nfev += 4
        self.t_old, self.y_old, self.f_old = t, y, k1
        self.k += 1
        self.t, self.y, self.f = t_new, y_new, f_new
        self.nsteps += 1

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


METHODS = {"dopri5": Dopri5, "rk4": RK4}
