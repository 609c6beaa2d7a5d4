"""Friction coefficient as a function of relative velocity, mu(v) (paper Fig. 1).

- A ``coulomb``: mu sign(v). Discontinuous at v = 0: for analysis only, refused for integration.
- B ``regularised`` (the paper's choice; a project decision, see README): mu clip(v / v_reg, -1, 1).
- C ``stribeck``: B with a Stribeck peak, mu(v) = clip(v/v_reg, -1, 1) (mu + (mu_static - mu)
  exp(-(v / v_stribeck)^2)).

``v`` is the sliding velocity of body j relative to body i (m/s, or rad/s for the revolute
joint's relative angular velocity); the law is odd in v, so friction on body i acts along v and
never adds energy. The vector form used by spherical joints (A.14) is
``F = mu_over_speed(|v|) |N| v`` with ``mu_over_speed(s) = coefficient(s)/s`` (finite at s = 0
for B, C).

Names (decided here): one coefficient has one name on its way from the file to the solver, ``mu``
(file key, :class:`overcon.spec.FrictionSpec`, the FMU parameter ``<joint>.mu``, :class:`Law`);
the velocity-dependent value is the method :meth:`Law.coefficient`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .spec import FrictionSpec


@dataclass(frozen=True)
class Law:
    """A friction law ``name`` (A, B, C above) with the kinetic coefficient ``mu``, the
    regularisation velocity ``v_reg``, the joint's friction size, for C ``mu_static`` and
    ``v_stribeck``, and ``sizes``: every friction size of the joint type by its key (m; the
    primary one is ``size``; empty for the planar and spherical types, which have one size)."""

    name: str
    mu: float
    v_reg: float
    size: float
    mu_static: float | None = None
    v_stribeck: float | None = None
    sizes: tuple[tuple[str, float], ...] = ()

    def size_of(self, key: str) -> float:
        """The friction size ``key`` (m)."""
        return dict(self.sizes)[key]

    def _magnitude(self, speed: float) -> float:
        if self.name == "stribeck":
            return self.mu + (self.mu_static - self.mu) * math.exp(-(speed / self.v_stribeck) ** 2)
        return self.mu

    def coefficient(self, v: float) -> float:
        """Signed friction coefficient mu(v) at the sliding velocity v."""
        if self.name == "coulomb":
            return math.copysign(self.mu, v) if v != 0.0 else 0.0
        return min(max(v / self.v_reg, -1.0), 1.0) * self._magnitude(abs(v))

    def mu_over_speed(self, speed: float) -> float:
        """mu(s)/s for s >= 0 (1/(m/s)); for law A it is infinite at s = 0 (raises)."""
        if self.name == "coulomb":
            if speed == 0.0:
                raise ZeroDivisionError("Coulomb law (variant A) has no finite mu(v)/v at v = 0")
            return self.mu / speed
        return self._magnitude(speed) / max(speed, self.v_reg)

    def mu_over_speed_slope(self, speed: float) -> float:
        """d(mu_over_speed)/ds at s >= 0 (1/(m/s)^2), the one-sided derivative from above at the
        kink s = v_reg (for the friction solve's Newton Jacobian; law A: raises at s = 0)."""
        if self.name == "coulomb":
            if speed == 0.0:
                raise ZeroDivisionError("Coulomb law (variant A) has no finite mu(v)/v at v = 0")
            return -self.mu / (speed * speed)
        slope = 0.0
        if self.name == "stribeck":
            x = speed / self.v_stribeck
            slope = -2.0 * x / self.v_stribeck * (self.mu_static - self.mu) * math.exp(-x * x)
        if speed < self.v_reg:
            return slope / self.v_reg
        return (slope - self._magnitude(speed) / speed) / speed


def make_law(spec: FrictionSpec, sizes=None) -> Law:
    """The law of ``spec``; ``sizes``: size key -> value of a type with several sizes
    (:meth:`overcon.joints.JointType.friction_sizes`), None for one."""
    return Law(spec.law, spec.mu, spec.v_reg, spec.size, spec.mu_static, spec.v_stribeck,
               tuple(sizes.items()) if sizes else ())
