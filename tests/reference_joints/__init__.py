"""Plain per-joint reference forms of the joint equations and their assembly (tests only).

Production code has one, batched, implementation per joint type (:mod:`overcon.joints`) and
evaluates a single joint as a batch of one. These modules keep the same equations written for one
joint at a time (``c`` a compiled joint with ``c.bi``, ``c.bj``, constants ``c.p``; ``f`` the
frames), as an independent form for tests/test_hot_path.py (batched against per-joint, bit for bit
where the reported outputs are concerned) and for the by-hand checks of tests/test_joints.py.
``jac_q`` (derivative by q, with Euler-angle derivatives) exists only here: production uses Phi_h.
"""
from __future__ import annotations

import numpy as np

from . import revolute, spherical, translational

REFERENCE = {"translational": translational, "revolute": revolute, "spherical": spherical}


def ref(c):
    """The reference module of compiled joint ``c``."""
    return REFERENCE[c.type]


def _place(model, out, c, blocks) -> None:
    Ji, Jj = blocks
    for b, block in ((c.bi, Ji), (c.bj, Jj)):
        if b >= 0:
            out[np.ix_(list(c.rows), range(b * model.nq_b, (b + 1) * model.nq_b))] += block


def constraints(model, f):
    """Phi (m,), joint by joint."""
    return np.concatenate([ref(c).phi(c, f) for c in model.joints])


def gamma(model, f):
    """gamma (m,), joint by joint."""
    return np.concatenate([ref(c).gamma(c, f) for c in model.joints])


def jacobian(model, f, which: str = "jac_h"):
    """Phi_h (``jac_h``) or the exact Phi_q (``jac_q``), (m, n), joint by joint."""
    out = np.zeros((model.m, model.n))
    for c in model.joints:
        _place(model, out, c, getattr(ref(c), which)(c, f))
    return out


def reaction_on_body_i(model, c, f, lam):
    """fi = (J_X)_i^T lam_X."""
    Ji, _ = ref(c).jac_h(c, f)
    return Ji.T @ lam[list(c.rows)]


def physical_reaction(model, c, f, lam):
    """-[A_i fi (auxiliary frame), fi[:dim] (global force)] of joint c."""
    fi = reaction_on_body_i(model, c, f, lam)
    local = ref(c).reaction_transform(c, f) @ fi
    n_local = len(c.components) - model.dim
    return -np.concatenate([local[:n_local], fi[: model.dim]])


def friction_output(model, c, f, lam):
    return float(ref(c).friction_force(c, f, reaction_on_body_i(model, c, f, lam), c.law))


def friction_generalized(model, f, lam):
    """Q_f (nh,) of all friction joints at the multipliers lam (all m), joint by joint."""
    Qf = np.zeros((model.nb, model.nq_b))
    for j in model.friction_joints:
        c = model.joints[j]
        Qi, Qj = ref(c).friction(c, f, reaction_on_body_i(model, c, f, lam), c.law)
        if c.bi >= 0:
            Qf[c.bi] += Qi
        if c.bj >= 0:
            Qf[c.bj] += Qj
    return Qf.reshape(-1)
