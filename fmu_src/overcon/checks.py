"""Admit a compiled :class:`overcon.model.Model` at its initial state: the checks that evaluate it
(the compiled core's rows, :func:`overcon.kernel.rows_sparse`), run after :func:`overcon.model.compile_model` and before any run.

- :func:`check_initial_state` (with :func:`check_euler_q0`): q0/h0 on the constraint manifold;
- :func:`resolve_elimination`: the eliminated equations checked (or chosen, ``"auto"``) from the
  rank of the Jacobian at q0;
- :func:`admit`: both, returning the model with its elimination applied;
- :func:`compile_checked`: compile, then admit (what ``check``, ``simulate`` and ``build`` use).
"""
from __future__ import annotations

import itertools

from dataclasses import replace

import numpy as np

from . import analysis
from .kernel import KernelUnavailable, jacobian, rows_sparse
from .kernel import rigid_rows as kernel_rigid_rows
from .joints import TYPES, InitialFrames
from .joints.spatial_rows import POINT_ROW
from .kinematics import SIN_BETA_MIN, euler_singular
from .model import InconsistentInitialState, Model, ModelError, _rotations, compile_model
from .spec import SceneSpec


def compile_checked(scene: SceneSpec, *, check_initial: bool = True,
                    eliminate_field: str = "scene.eliminate") -> Model:
    """:func:`overcon.model.compile_model`, then :func:`admit`."""
    return admit(compile_model(scene), check_initial=check_initial, eliminate_field=eliminate_field)


def admit(model: Model, *, check_initial: bool = True, eliminate_field: str = "scene.eliminate") -> Model:
    """The compiled ``model`` with ``scene.eliminate`` applied. Raises ModelError for an
    elimination the mechanism does not admit (removing an independent equation, or leaving
    dependent ones), naming the equations and the field that gave them, ``eliminate_field``
    (``scene.eliminate``, or the command line's ``--eliminate`` when it overrides the scene; the
    callers name the file), and :class:`InconsistentInitialState` for q0/h0 off the constraints
    (before the elimination is checked: a rank at an inconsistent q0 means nothing).
    ``check_initial=False`` skips that check: only for evaluating kinematics at arbitrary
    configurations (tests); a Simulation checks again."""
    rows = check_initial_state(model) if check_initial else None  # Phi_h at q0, read once
    check_drivers(model)
    if model.scene.redundancy == "min-norm":  # every equation kept; the solve is rank-revealing
        return replace(model, retained=np.arange(model.m), eliminated=(), elimination_mode="min-norm")
    fz = None
    if model.scene.redundancy == "compliant":
        fz = factored_q0(model, rows)
        eliminated, mode = rigid_elimination(model, fz), "compliant"
    elif model.scene.eliminate == "auto":
        fz = factored_q0(model, rows)
        eliminated, mode = resolve_elimination(model, "auto", eliminate_field, fz)
    else:
        eliminated, mode = resolve_elimination(model, model.scene.eliminate, eliminate_field)
    admitted = with_eliminated(model, eliminated, mode)
    if fz is not None:  # the pre-check reads the same factorisation (precheck.analyse_model)
        object.__setattr__(admitted, "factored_q0", fz)
    return admitted


def analysed_rows(model: Model) -> list[int] | None:
    """The equations (0-based) the pre-check analyses: under redundancy "compliant" the rigid ones
    (the compliant joints' equations are forces), else all (None)."""
    if not model.compliant_rows.size:
        return None
    compliant = set(int(r) for r in model.compliant_rows)
    return [i for i in range(model.m) if i not in compliant]


def factored_q0(model: Model, rows: tuple | None = None) -> analysis.Factored:
    """The one factorisation (:func:`overcon.analysis.factorise_nonzeros`) of Phi_h^T at q0, of
    its :func:`analysed_rows` columns: the one admission made when it chose the elimination
    (``auto``, or the rigid equations' under "compliant"), else made now (``rows``: Phi_h at q0
    by its nonzeros, :func:`overcon.kernel.rows_sparse`, when the caller has it). Elimination and
    pre-check read the same matrix with the same rule, so they share it. Phi_h is never dense
    here: its nonzeros are transposed and factorised as they are."""
    if model.factored_q0 is not None:
        return model.factored_q0
    eq, col, val = rows_sparse(model, model.q0)[1] if rows is None else rows  # equation, coordinate, value
    kept = analysed_rows(model)
    m = model.m
    if kept is not None:  # the rigid equations, numbered in their order
        position = np.full(model.m, -1)
        position[kept] = np.arange(len(kept))
        sel = position[eq] >= 0
        eq, col, val, m = position[eq[sel]], col[sel], val[sel], len(kept)
    order = np.lexsort((eq, col))  # Phi_h^T row-major: coordinates, then equations
    return analysis.factorise_nonzeros((model.nh, m), col[order], eq[order], val[order])


def with_eliminated(model: Model, eliminated, mode: str | None = None) -> Model:
    """``model`` keeping every equation but the 1-based ``eliminated`` ones (elimination mode
    ``mode``, default the model's): at admission, and when a run chooses them again."""
    gone = set(eliminated)
    retained = np.array([i for i in range(model.m) if i + 1 not in gone], int)
    return replace(model, retained=retained, eliminated=tuple(eliminated),
                   elimination_mode=model.elimination_mode if mode is None else mode)


def check_initial_state(model: Model, tol: float = 1e-9) -> tuple:
    """Refuse q0/h0 off the constraint manifold: |Phi| or |Phi_h h0| above tol (m or rad; m/s
    or rad/s), scaled by max(1, max |q0|) (max(1, max |h0|)); a non-finite value is refused too.
    Raises :class:`InconsistentInitialState` naming the violated equations, their joints and
    the mechanism file that holds q0/h0; first, for z-x-z Euler bodies, a q0 at the Euler
    singularity (:func:`check_euler_q0`). Returns Phi_h at q0, which it evaluated, by its
    nonzeros (:func:`overcon.kernel.rows_sparse`: equations, coordinates, values)."""
    check_euler_q0(model)
    joint_of = {r + 1: c.name for c in model.joints for r in c.rows}
    mech = model.scene.mechanism
    where = f" (bodies' q0/h0 in {mech.source or mech.name})"

    def eqs(numbers) -> str:
        return ", ".join(f"Phi{i} (joint {joint_of.get(i, '?')})" for i in numbers)

    Phi, (eq, col, val) = _rows_q0(model, where)
    drivers = [c for c in model.joints if c.type == "driver"]
    for c in drivers:  # a driver's motion starts at its coordinate's value at q0: zero
        r = c.rows[0]
        if not abs(Phi[r]) <= tol * max(1.0, float(np.max(np.abs(model.q0)))):
            raise InconsistentInitialState(
                f"driver {c.name}: the motion starts at {-Phi[r]:.6g} at the start time "
                f"{model.scene.start_time:g} s, but a driver prescribes joint {model.joints[c.p['joint']].name}'s "
                "coordinate from its value at q0, where it is 0 (start the motion at 0)")
    with np.errstate(all="ignore"):
        scale = max(1.0, float(np.max(np.abs(model.q0))))
        bad = [i + 1 for i in np.flatnonzero(~(np.abs(Phi) <= tol * scale))]
        if bad:
            point, axes = _split_violations(model, Phi, bad)
            parts = []
            if point:
                absphi = np.where(np.isfinite(Phi), np.abs(Phi), np.inf)
                worst = max(point, key=lambda i: absphi[i - 1])
                parts.append(f"initial coordinates q0 violate the constraints {eqs(point)}: largest "
                             f"|Phi{worst}| = {abs(Phi[worst - 1]):.3g}")
            for (j, meaning), rows in axes.items():
                c = model.joints[j]
                R0 = _rotations(model, np.asarray(model.q0, float))
                text = TYPES[c.type].violation_text(meaning, c.p, InitialFrames(R0[c.bi], R0[c.bj]))
                parts.append(f"joint {c.name} (joints[{j}]): {text}: {', '.join(f'Phi{i}' for i in rows)} "
                             f"(joints[{j}].axis_i, joints[{j}].axis_j or the bodies' q0 are wrong)")
            raise InconsistentInitialState("; ".join(parts) + where)
        vel = np.bincount(eq, val * np.asarray(model.h0, float)[col], minlength=model.m)  # Phi_h h0
        if drivers:  # + Phi_t of the rheonomic equations
            from .kernel import rows_kernel
            vel = vel + rows_kernel(model).phi_t(model.scene.start_time, np.concatenate([model.q0, model.h0]))
            for c in drivers:
                r = c.rows[0]
                if not abs(vel[r]) <= tol * max(1.0, float(np.max(np.abs(model.h0)))):
                    raise InconsistentInitialState(
                        f"driver {c.name}: the initial velocities h0 give joint {model.joints[c.p['joint']].name} a "
                        f"rate that differs from the motion's at the start time by {vel[r]:.6g} (h0 must move the "
                        f"joint as the driver does){where}")
        hscale = max(1.0, float(np.max(np.abs(model.h0))))
        bad = [i + 1 for i in np.flatnonzero(~(np.abs(vel) <= tol * hscale))]
    if bad:
        raise InconsistentInitialState(f"initial velocities h0 violate the velocity constraints {eqs(bad)}{where}")
    return eq, col, val


def check_drivers(model: Model) -> None:
    """Refuse a driver whose equation depends on the others at q0 (its coordinate is already fixed
    by the joints, or by another driver): ModelError naming the driver, its joint and the rank.
    The drivers are taken in file order, each must raise the rank of the equations before it."""
    drivers = [c for c in model.joints if c.type == "driver"]
    if not drivers:
        return
    J = _jacobian_q0(model)
    first = drivers[0].rows[0]
    rank = analysis.numerical_rank(J[:, :first])
    for c in drivers:
        r = analysis.numerical_rank(J[:, : c.rows[0] + 1])
        if r == rank:
            what = "angle" if c.p["coordinate"] == 0 else "displacement"
            joint = model.joints[c.p["joint"]].name
            raise ModelError(f"driver {c.name}: its equation depends on the constraints before it (rank stays {rank} "
                             f"with it): the {what} of joint {joint} is already fixed by the mechanism or another "
                             "driver; a driver prescribes a free coordinate")
        rank = r


def _rows_q0(model: Model, where: str) -> tuple[np.ndarray, tuple]:
    """(Phi, Phi_h by its nonzeros) at q0 from the compiled core (:func:`overcon.kernel.rows_sparse`);
    a q0 or h0 it cannot evaluate (a non-finite value) is an :class:`InconsistentInitialState`
    naming the mechanism file (``where``)."""
    y = np.concatenate([model.q0, model.h0])
    if not np.all(np.isfinite(y)):
        raise InconsistentInitialState(f"initial coordinates q0 or velocities h0 hold a non-finite value{where}")
    try:
        Phi, Jh = rows_sparse(model, model.q0, model.h0)
    except KernelUnavailable:
        raise
    except RuntimeError as exc:
        raise InconsistentInitialState(f"the constraints cannot be evaluated at q0: {exc}{where}") from None
    return Phi, Jh


def _jacobian_q0(model: Model) -> np.ndarray:
    """Phi_h^T (nh, m) at q0 (the analysis' orientation: a joint's equations are columns)."""
    return jacobian(model, model.q0).T


def _split_violations(model: Model, Phi: np.ndarray, bad: list[int]):
    """The violated equations ``bad`` (1-based) split by their meaning
    (:attr:`overcon.joints.JointType.row_meanings`): (point rows and non-finite values, in order;
    {(joint index, meaning): its axis rows} in joint order)."""
    point, axes, bad = [], {}, set(bad)
    for c in model.joints:
        if c.type == "driver":
            continue  # checked first (check_initial_state)
        meanings = TYPES[c.type].row_meanings
        for k, r in enumerate(c.rows):
            if r + 1 not in bad:
                continue
            if meanings[k] == POINT_ROW or not np.isfinite(Phi[r]):
                point.append(r + 1)
            else:
                axes.setdefault((c.index, meanings[k]), []).append(r + 1)
    return sorted(point), axes


def check_euler_q0(model: Model) -> None:
    """Refuse a spatial body with z-x-z Euler angles whose q0 has |sin(beta)| below
    :data:`overcon.kinematics.SIN_BETA_MIN` (beta = q0[4], rad): the parametrisation is singular
    there, so the run could not start (:func:`overcon.kinematics.euler_H`). Raises
    :class:`InconsistentInitialState` naming the mechanism file, the body and its field q0, and
    the quaternion rotation that has no singularity."""
    if model.kind != "spatial" or model.rotation != "euler_zxz":
        return
    beta = np.asarray(model.q0, float).reshape(model.nb, model.nq_b)[:, 4]
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(euler_singular(np.sin(beta)))
    if len(bad):
        k = int(bad[0])
        mech = model.scene.mechanism
        raise InconsistentInitialState(
            f"body {model.body_names[k]!r}: bodies[{k}].q0 has beta = q0[4] = {beta[k]:.6g} rad, at the "
            f"z-x-z Euler angle singularity (|sin(beta)| = {abs(np.sin(beta[k])):.3g} < {SIN_BETA_MIN:g}) "
            "where the run cannot start; give beta away from 0 and pi, or set rotation = \"quaternion\" "
            f"in [mechanism] (no singularity) (bodies' q0 in {mech.source or mech.name})")


def rigid_elimination(model: Model, fz: analysis.Factored | None = None) -> list[int]:
    """Redundancy "compliant": the rigid equations (those of joints without compliance) that are
    dependent among themselves at q0, chosen like ``"auto"`` (1-based). The compliant equations
    are kept: they are forces, not constraints. ``fz``: :func:`factored_q0`, when made."""
    rigid = analysed_rows(model)
    if rigid is None:
        rigid = list(range(model.m))
    if not rigid:
        return []
    return sorted(rigid[k] + 1 for k in analysis.auto_eliminate(factored_q0(model) if fz is None else fz))


def resolve_elimination(model: Model, eliminate, field: str = "scene.eliminate",
                        fz: analysis.Factored | None = None) -> tuple[list[int], str]:
    """Check (or choose, for "auto") the eliminated equations at q0. Returns 1-based indices.
    Raises ModelError naming ``field`` (where ``eliminate`` was given) for an elimination the
    mechanism does not admit. ``fz``: :func:`factored_q0`, when made (``"auto"`` reads it)."""
    if eliminate == "auto":
        removed = sorted(i + 1 for i in analysis.auto_eliminate(factored_q0(model) if fz is None else fz))
        return removed, "auto"
    J = _jacobian_q0(model)
    r = analysis.numerical_rank(J)
    removed = sorted(eliminate)
    kept = [i for i in range(model.m) if i + 1 not in set(removed)]
    r_kept = analysis.numerical_rank(J[:, kept]) if kept else 0
    listed = ", ".join(f"Phi{i}" for i in removed) or "nothing"
    if r_kept < r:
        why = (f"{field}: eliminating {listed} removes an independent equation: rank of the kept equations is "
               f"{r_kept} < rank {r} of all {model.m}; the mechanism would gain {r - r_kept} DOF")
        raise _refused(model, J, r, why)
    if r_kept < len(kept):
        why = (f"{field}: eliminating {listed} leaves {len(kept)} equations of rank {r_kept}: "
               f"{len(kept) - r_kept} more must be eliminated (the mechanism has {model.m - r} redundant)")
        raise _refused(model, J, r, why)
    return removed, "given"


VALID_SHOWN = 10
"""A refused elimination lists at most this many valid ones (and says when there are more)."""

VALID_TRIED = 2000
"""...found among at most this many candidate sets, in order (decided: each costs an SVD of the
Jacobian at q0; with one redundant equation every single equation is a candidate, so a mechanism
of up to 2000 equations is listed in full)."""


def valid_eliminations(model: Model, J: np.ndarray | None = None, r: int | None = None) -> tuple[list, bool]:
    """The eliminations the mechanism admits at q0 (1-based equation lists): the sets of
    m - rank equations whose removal keeps the rank, in lexicographic order, at most
    :data:`VALID_SHOWN` of them from at most :data:`VALID_TRIED` candidates; and whether the
    search stopped before the end (more may exist). ``J``, ``r``: the Jacobian at q0 (nh x m) and
    its rank, when at hand."""
    J = _jacobian_q0(model) if J is None else J
    r = analysis.numerical_rank(J) if r is None else r
    k = model.m - r
    if k <= 0:
        return [], False
    found, tried = [], 0
    for gone in itertools.combinations(range(model.m), k):
        if tried >= VALID_TRIED or len(found) >= VALID_SHOWN:
            return found, True
        tried += 1
        kept = [i for i in range(model.m) if i not in gone]
        if analysis.numerical_rank(J[:, kept]) == r:
            found.append([i + 1 for i in gone])
    return found, False


def joint_equations(model: Model) -> dict[str, list[int]]:
    """Joint name -> its 1-based equation numbers (what ``eliminate`` counts)."""
    return {c.name: [r + 1 for r in c.rows] for c in model.joints}


def _refused(model: Model, J: np.ndarray, r: int, why: str) -> ModelError:
    """The refusal of an elimination: ``why``, then the valid eliminations at q0 and each joint's
    equations, in the message and as data (``check --json``: keys ``valid_eliminations``,
    ``valid_eliminations_complete``, ``joint_equations``)."""
    valid, cut = valid_eliminations(model, J, r)
    shown = "; ".join("[" + ", ".join(map(str, v)) + "]" for v in valid) or "none"
    more = " (the first found; there may be more)" if cut else ""
    per_joint = ", ".join(f"{name} {_numbers(eqs)}" for name, eqs in joint_equations(model).items())
    text = (f"{why}. Valid eliminations at q0{more}: {shown}, or eliminate = \"auto\". "
            f"Equations per joint: {per_joint}")
    return ModelError(text, {"valid_eliminations": valid, "valid_eliminations_complete": not cut,
                             "joint_equations": joint_equations(model)})


def _numbers(eqs: list[int]) -> str:
    """1-based equations as ``Phi3`` or ``Phi3-Phi5`` (consecutive, as a joint's are)."""
    return f"Phi{eqs[0]}" if len(eqs) == 1 else f"Phi{eqs[0]}-Phi{eqs[-1]}"


def watch_rows(model) -> tuple[list[int], list[int]]:
    """(rows watched, rows of the whole rigid Jacobian) of a run's singularity watch
    (core/watch.c), chosen at the start: the kept equations; under ``redundancy = "min-norm"``
    (every equation kept) an independent set of them at q0 (pivoted QR,
    :func:`overcon.analysis.independent_columns`); under ``"compliant"`` the rigid kept ones."""
    if model.elimination_mode == "min-norm":
        rows = np.array(analysis.independent_columns(jacobian(model, model.q0).T), int)
    elif model.compliant_rows.size:
        rows = np.setdiff1d(model.retained, model.compliant_rows)
    else:
        rows = np.asarray(model.retained, int)
    return [int(r) for r in rows], [int(r) for r in kernel_rigid_rows(model)]
