"""The friction laws' mu(s)/s and its slope in the compiled core (core/friction.c, through
``ovk_law_eval``): the factor of the slip velocity in the spherical joint's friction force
(F = (mu(|v|)/|v|) |N| v, overcon.friction_laws) and the derivative its Newton Jacobian uses.
mu(s)/s equals the laws written out from their definitions, and the slope equals a finite
difference of mu(s)/s below, at and above the regularisation speed and far above it."""
from __future__ import annotations

import ctypes
import math

import pytest

from overcon import kernel

REGULARISED, STRIBECK = 1, 2  # core/core.h LAW_REGULARISED, LAW_STRIBECK (overcon.kernel._LAWS)
OVK_OK, OVK_INVALID = 0, 7
EPS = 2.0 ** -52

# (law, mu, v_reg, mu_static, v_stribeck): the default regularisation with and without a Stribeck
# peak, and a peak narrower than the regularisation band (the exponential then varies below v_reg)
LAWS = {"regularised": (REGULARISED, 0.3, 1e-3, None, None),
        "stribeck": (STRIBECK, 0.3, 1e-3, 0.5, 1e-2),
        "stribeck_narrow": (STRIBECK, 0.4, 1e-2, 0.9, 3e-3)}
SIZE = 0.05  # lp[2], the joint's friction size: not used by the law


@pytest.fixture(scope="module")
def lib():
    lib, reason = kernel.library()
    if lib is None:
        pytest.skip(reason)
    return lib


def _lp(law):
    _, mu, v_reg, mu_static, v_stribeck = law
    # the packing of overcon.kernel._law_constants: mu, v_reg, size, mu_static, v_stribeck
    return (ctypes.c_double * kernel.NLP)(mu, v_reg, SIZE, 0.0 if mu_static is None else mu_static,
                                          1.0 if v_stribeck is None else v_stribeck)


def _eval(lib, law, s):
    f, slope = ctypes.c_double(), ctypes.c_double()
    status = lib.ovk_law_eval(_lp(law), law[0], s, ctypes.byref(f), ctypes.byref(slope))
    assert status == OVK_OK, (law, s)
    return f.value, slope.value


def _defined(law, s):
    """mu(s)/s from the definitions (overcon.friction_laws, docs/explanation/decisions.md, "Friction law"): the signed
    coefficient mu(v) = clip(v / v_reg, -1, 1) (mu + (mu_static - mu) exp(-(v / v_stribeck)^2))
    (regularised: without the exponential term) divided by v = s > 0; at s = 0 its limit."""
    kind, mu, v_reg, mu_static, v_stribeck = law
    magnitude = mu if kind == REGULARISED else mu + (mu_static - mu) * math.exp(-((s / v_stribeck) ** 2))
    if s == 0.0:
        return magnitude / v_reg
    return min(s / v_reg, 1.0) * magnitude / s


def _speeds(law):
    v_reg = law[2]
    speeds = [0.0, 0.3 * v_reg, 0.999 * v_reg, v_reg, 1.001 * v_reg, 3.0 * v_reg, 0.1, 10.0, 1e3]
    if law[0] == STRIBECK:
        speeds += [0.5 * law[4], law[4], 2.0 * law[4]]
    return sorted(set(speeds))


def _scale(law, s):
    """The length on which mu(s)/s varies at s: s above v_reg (as 1/s), v_reg below it, and the
    Stribeck speed where the exponential still counts (exp(-36) ~ 2e-16 beyond 6 v_stribeck)."""
    kind, _, v_reg, _, v_stribeck = law
    length = max(s, v_reg)
    return min(length, v_stribeck) if kind == STRIBECK and s < 6.0 * v_stribeck else length


@pytest.mark.parametrize("name", list(LAWS))
def test_mu_over_speed_is_the_law_divided_by_the_speed(lib, name):
    """Within 4 roundings: the core divides mu(s) by max(s, v_reg), the definition multiplies by
    s / v_reg and divides by s (and both evaluate the same exponential)."""
    law = LAWS[name]
    for s in _speeds(law):
        got, _ = _eval(lib, law, s)
        want = _defined(law, s)
        assert abs(got - want) <= 4 * EPS * abs(want), (name, s, got, want)


@pytest.mark.parametrize("name", list(LAWS))
def test_slope_is_the_finite_difference_of_mu_over_speed(lib, name):
    """The slope equals a finite difference of mu(s)/s with the step h = eps^(1/3) L (L: the
    length on which mu(s)/s varies at s, :func:`_scale`), the step that balances the two errors
    of a central difference: truncation h^2/6 |f'''| and rounding ~ eps |f| / h. With
    |f'''| <= 6 F / L^3 (F = the largest mu over max(s, v_reg): mu/s has f''' = -6 mu/s^4, the
    Gaussian's third derivative is below 4 / v_stribeck^3) both are <= eps^(2/3) F / L, about
    4e-11 F / L; the bound asserted is 10 times their sum (the slopes themselves are of order
    F / L, so a wrong term in the slope misses by far more). mu(s)/s has a kink at v_reg (slope
    mu'(s)/v_reg below, (mu'(s) - mu(s)/s)/s from v_reg on, the value the core gives at v_reg);
    at v_reg and at 0 (no speeds below) the difference is the one-sided second-order one
    (-3 f(s) + 4 f(s + h) - f(s + 2h)) / (2h): truncation h^2/3 |f'''|, rounding 4 eps |f| / h,
    asserted within 10 times their sum too; elsewhere s +- h stays on one side of v_reg."""
    law = LAWS[name]
    _, mu, v_reg, mu_static, _ = law
    for s in _speeds(law):
        length = _scale(law, s)
        h = EPS ** (1.0 / 3.0) * length
        f0, slope = _eval(lib, law, s)
        big = max(mu, mu_static or 0.0) / max(s, v_reg)
        if s == 0.0 or s == v_reg:
            fd = (-3.0 * f0 + 4.0 * _eval(lib, law, s + h)[0] - _eval(lib, law, s + 2.0 * h)[0]) / (2.0 * h)
            bound = 10.0 * (4.0 * EPS * big / h + 2.0 * h * h * big / length ** 3)
        else:
            assert (s - h < v_reg) == (s + h < v_reg)
            fd = (_eval(lib, law, s + h)[0] - _eval(lib, law, s - h)[0]) / (2.0 * h)
            bound = 10.0 * (EPS * big / h + h * h * big / length ** 3)
        assert abs(slope - fd) <= bound, (name, s, slope, fd, bound)


def test_the_slope_has_the_kink_at_the_regularisation_speed(lib):
    """Just below v_reg the slope is mu'(s)/v_reg (0 for the regularised law), from v_reg on it
    is the derivative of mu(s)/s: -mu/v_reg^2 for the regularised law (exactly as written)."""
    law = LAWS["regularised"]
    _, mu, v_reg, _, _ = law
    assert _eval(lib, law, 0.999 * v_reg)[1] == 0.0
    assert _eval(lib, law, v_reg)[1] == pytest.approx(-mu / v_reg ** 2, rel=4 * EPS)


def test_invalid_arguments_are_refused(lib):
    """OVK_INVALID for a law the core has no formula for (0: no friction; 3), a negative or
    non-finite speed; the outputs are left as they were."""
    lp = _lp(LAWS["stribeck"])
    for law, s in ((0, 1.0), (3, 1.0), (STRIBECK, -1e-12), (STRIBECK, math.nan), (STRIBECK, math.inf)):
        f, slope = ctypes.c_double(-7.0), ctypes.c_double(-7.0)
        assert lib.ovk_law_eval(lp, law, s, ctypes.byref(f), ctypes.byref(slope)) == OVK_INVALID, (law, s)
        assert (f.value, slope.value) == (-7.0, -7.0)
