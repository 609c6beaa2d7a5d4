"""Friction coefficient as a function of relative velocity, mu(v) (paper Fig. 1).

- A ``coulomb``: mu sign(v). Discontinuous at v = 0: for analysis only, refused for integration.
- B ``regularised`` (the paper's choice; a project decision, see docs/explanation/decisions.md): mu clip(v / v_reg, -1, 1).
- C ``stribeck``: B with a Stribeck peak, mu(v) = clip(v/v_reg, -1, 1) (mu + (mu_static - mu)
  exp(-(v / v_stribeck)^2)).

``v`` is the sliding velocity of body j relative to body i (m/s, or rad/s for the revolute
joint's relative angular velocity); the law is odd in v, so friction on body i acts along v and
never adds energy. The vector form used by spherical joints (A.14) is ``F = (mu(|v|)/|v|) |N| v``
(finite at |v| = 0 for B, C). The laws are evaluated in the compiled core (core/friction.c); this
module holds their constants for packing.

Names (decided here): one coefficient has one name on its way from the file to the solver, ``mu``
(file key, :class:`overcon.spec.FrictionSpec`, the FMU parameter ``<joint>.mu``, :class:`Law`).
"""
from __future__ import annotations

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


def make_law(spec: FrictionSpec, sizes=None) -> Law:
    """The law of ``spec``; ``sizes``: size key -> value of a type with several sizes
    (:meth:`overcon.joints.JointType.friction_sizes`), None for one."""
    return Law(spec.law, spec.mu, spec.v_reg, spec.size, spec.mu_static, spec.v_stribeck,
               tuple(sizes.items()) if sizes else ())
