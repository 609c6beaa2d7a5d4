"""Tests of overcon.analysis on hand-written Jacobians (Fraczek & Wojtyra 2011, §2.2, App. B)."""

from __future__ import annotations

import dataclasses
import itertools
import json

import numpy as np
import pytest

from overcon import analysis as an
from overcon.analysis import (
    analyse,
    auto_eliminate,
    equilibrate,
    independent_columns,
    joint_uniqueness,
    null_space,
    numerical_rank,
    rank_tolerance,
    to_json,
)

EPS = np.finfo(float).eps


# --------------------------------------------------------------------------- the paper's planar J

Q_STAR = np.array([2, 0, 0, 0, 2, 0, 2, 1, 0, 1, 2, 0], dtype=float)
PLANAR_GROUPS = {f"joint{i + 1}": [2 * i, 2 * i + 1] for i in range(6)}
PLANAR_UNIQUE = [False, False, False, True, True, True]
TRANSLATIONAL_ROWS = np.array([True, True, False] * 4)  # x_i, y_i rows vs phi_i rows of J
LENGTH_EQUATIONS = np.array([1, 0, 1, 0, 1, 0, 1, 1, 1, 1, 1, 1], dtype=bool)  # Phi1,3,5,7..12


def planar_phi(q):
    """The paper's planar constraint equations Phi1..Phi12 (§4.1, B.7)."""
    x1, y1, p1, x2, y2, p2, x3, y3, p3, x4, y4, p4 = q
    c2, s2 = np.cos(p2), np.sin(p2)
    return np.array([
        y1,
        p1,
        x2,
        p2,
        (x1 - x2) * (c2 - s2) + (y1 - y2) * (s2 + c2),
        p1 - p2,
        x1 - x3 - np.sin(p3),
        y1 - y3 + np.cos(p3),
        x2 - x4 + np.cos(p4),
        y2 - y4 + np.sin(p4),
        x3 - np.sin(p3) - x4 - np.cos(p4),
        y3 + np.cos(p3) - y4 - np.sin(p4),
    ])


def planar_phi_q(q, printed=False):
    """Exact Phi_q (12 x 12) of ``planar_phi``; ``printed=True`` puts the paper's 0 (B.8/B.9)
    where the exact dPhi5/dphi2 = -(x1-x2)(sin phi2 + cos phi2) + (y1-y2)(cos phi2 - sin phi2)."""
    x1, y1, p1, x2, y2, p2, x3, y3, p3, x4, y4, p4 = q
    X1, Y1, P1, X2, Y2, P2, X3, Y3, P3, X4, Y4, P4 = range(12)
    c2, s2 = np.cos(p2), np.sin(p2)
    c3, s3, c4, s4 = np.cos(p3), np.sin(p3), np.cos(p4), np.sin(p4)
    A = np.zeros((12, 12))
    A[0, Y1] = 1
    A[1, P1] = 1
    A[2, X2] = 1
    A[3, P2] = 1
    A[4, [X1, X2, Y1, Y2]] = [c2 - s2, -(c2 - s2), s2 + c2, -(s2 + c2)]
    A[4, P2] = 0.0 if printed else -(x1 - x2) * (s2 + c2) + (y1 - y2) * (c2 - s2)
    A[5, [P1, P2]] = [1, -1]
    A[6, [X1, X3, P3]] = [1, -1, -c3]
    A[7, [Y1, Y3, P3]] = [1, -1, -s3]
    A[8, [X2, X4, P4]] = [1, -1, -s4]
    A[9, [Y2, Y4, P4]] = [1, -1, c4]
    A[10, [X3, P3, X4, P4]] = [1, -c3, -1, s4]
    A[11, [Y3, P3, Y4, P4]] = [1, -s3, -1, -c4]
    return A


def planar_q(psi):
    """The mechanism's one-DOF family of assembled configurations (psi = 0 is q*).

    K = (s, 0), L = (0, s) with s = 2 (sin psi + cos psi); phi3 = psi, phi4 = -psi.  s = 0
    (psi = -pi/4) is the singular position K = L = O.
    """
    s = 2.0 * (np.sin(psi) + np.cos(psi))
    p3, p4 = psi, -psi
    return np.array([s, 0, 0, 0, s, 0, s - np.sin(p3), np.cos(p3), p3, np.cos(p4), s + np.sin(p4), p4])


def planar_J(q=Q_STAR, printed=False):
    return planar_phi_q(q, printed).T


def verdicts(a):
    return [a.joints[name].unique for name in PLANAR_GROUPS]


def assert_planar_reference(a):
    assert (a.n_coordinates, a.n_equations, a.rank, a.dof, a.redundant) == (12, 12, 11, 1, 1)
    for name, expected in zip(PLANAR_GROUPS, PLANAR_UNIQUE):
        v = a.joints[name]
        assert v.unique is expected, name
        assert v.methods == {"rank": expected, "svd": expected, "qr": expected}, name
        assert v.agree is True, name
        assert v.rank_defect == (0 if expected else 1), name


# --------------------------------------------------------------------------- helpers


def test_rank_and_tolerance_helpers():
    A = np.diag([1.0, 1e-5, 1e-12])
    assert numerical_rank(A) == 2
    assert numerical_rank(A, rtol=1e-4) == 1
    assert numerical_rank(A, rtol=0.0) == 3  # floor max(n, m) * eps = 6.7e-16 < 1e-12
    assert numerical_rank(A, tol=2.0) == 0
    assert rank_tolerance(A) == pytest.approx(1e-9)
    assert rank_tolerance(7.0 * A) == pytest.approx(7e-9)
    assert rank_tolerance(A, rtol=0.0) == pytest.approx(3 * EPS)
    assert numerical_rank(np.zeros((3, 2))) == 0
    assert numerical_rank(np.zeros((0, 4))) == 0
    assert rank_tolerance(np.zeros((2, 2))) == 0.0
    with pytest.raises(ValueError, match="rtol must be a finite non-negative number, got -1.0"):
        numerical_rank(A, rtol=-1.0)
    with pytest.raises(ValueError, match=r"expected a 2-D matrix, got shape \(3,\)"):
        numerical_rank(np.ones(3))
    with pytest.raises(ValueError, match="matrix contains NaN or inf"):
        numerical_rank(np.array([[1.0, np.nan]]))


def test_equilibrate_scales_rows_and_columns_and_drops_roundoff_rows():
    rng = np.random.default_rng(1)
    J = rng.standard_normal((5, 4)) * np.array([1e3, 1, 1e-3, 1, 1])[:, None]
    J[4, :] = 1e-17  # a round-off row (e.g. cos(pi/2) products)
    Jh, d_r, d_c = equilibrate(J)
    J0 = J.copy()
    J0[4, :] = 0.0
    np.testing.assert_allclose(Jh, d_r[:, None] * J0 * d_c[None, :], rtol=1e-14)
    np.testing.assert_allclose(np.abs(Jh[:4]).max(axis=1), 1.0, atol=2e-3)
    np.testing.assert_allclose(np.abs(Jh).max(axis=0), 1.0, atol=2e-3)
    assert not Jh[4].any()
    # the round-off row does not gain rank
    J = np.vstack([np.eye(3), np.full((1, 3), 1e-17)])
    assert analyse(J, {}).rank == 3


def test_null_space_svd_and_qr():
    J = planar_J()
    for method in ("svd", "qr"):
        N = null_space(J, method=method)
        assert N.shape == (12, 1)
        np.testing.assert_allclose(N.T @ N, np.eye(1), atol=1e-12)
        np.testing.assert_allclose(J @ N, 0.0, atol=1e-12)
    # the null vector involves only Phi2, Phi4, Phi6 (the angle equations): (1, -1, -1)/sqrt(3)
    nu = null_space(J)[:, 0]
    nu = nu * np.sign(nu[1])
    expected = np.zeros(12)
    expected[[1, 3, 5]] = np.array([1, -1, -1]) / np.sqrt(3)
    np.testing.assert_allclose(nu, expected, atol=1e-12)
    assert null_space(np.eye(3)).shape == (3, 0)
    np.testing.assert_array_equal(null_space(np.zeros((2, 3))), np.eye(3))
    with pytest.raises(ValueError, match=r"unknown null-space method 'lu' \(use 'svd' or 'qr'\)"):
        null_space(J, method="lu")


# --------------------------------------------------------------------------- hand-written cases


def test_full_column_rank_all_unique():
    J = np.random.default_rng(2).standard_normal((7, 5))
    a = analyse(J, {"a": [0, 1], "b": [2], "c": [3, 4]})
    assert (a.rank, a.dof, a.redundant) == (5, 2, 0)
    for v in a.joints.values():
        assert v.unique and v.agree and v.rank_defect == 0
        assert v.B_svd.shape == (7, 0) and v.B_qr.shape == (7, 0)
    assert a.set_unique(["a", "b", "c"]).unique
    assert auto_eliminate(J) == []
    assert independent_columns(J) == [0, 1, 2, 3, 4]


def door_J(second_body=False):
    """A planar door (x, y, phi) hinged to ground at s_A = (-1, 0) and s_B = (1, 0) (phi = 0).

    Revolute to ground: Phi = r + R(phi) s - p;  d/dphi at phi = 0 is (-s_y, s_x).  Both hinges
    constrain x: one x equation is redundant and the x reactions are shared arbitrarily.
    With ``second_body``, a body 2 is pinned to the door at (0, 1) of the door and (0, -1) of body
    2 (joint C), and held in rotation by joint D (phi2 = 0).
    """
    n = 6 if second_body else 3
    cols = [
        [1, 0, 0], [0, 1, -1],  # A: x, y
        [1, 0, 0], [0, 1, 1],  # B: x, y
    ]
    J = np.zeros((n, 4 + (3 if second_body else 0)))
    J[:3, :4] = np.array(cols).T
    if second_body:
        # C: r1 + R1 (0, 1) - r2 - R2 (0, -1) = 0  -> d/dphi1 = (-1, 0), d/dphi2 = (-1, 0)
        J[:, 4] = [1, 0, -1, -1, 0, -1]
        J[:, 5] = [0, 1, 0, 0, -1, 0]
        J[:, 6] = [0, 0, 0, 0, 0, 1]  # D: phi2
    return J


def test_door_on_two_hinges():
    J = door_J()
    a = analyse(J, {"A": [0, 1], "B": [2, 3]})
    assert (a.n_coordinates, a.n_equations, a.rank, a.dof, a.redundant) == (3, 4, 3, 0, 1)
    for name in "AB":
        v = a.joints[name]
        assert not v.unique and v.agree and v.rank_defect == 1
        assert v.methods == {"rank": False, "svd": False, "qr": False}
        # the arbitrary part of the reaction is the x force only: B nonzero in the x row only
        assert abs(v.B_svd[0, 0]) == pytest.approx(1 / np.sqrt(2))
        np.testing.assert_allclose(v.B_svd[1:], 0.0, atol=1e-12)
        np.testing.assert_allclose(np.abs(v.B_qr), np.abs(v.B_svd), atol=1e-12)
    assert auto_eliminate(J) in ([0], [2])  # one of the two x equations


def test_door_with_second_body_unique_joints():
    J = door_J(second_body=True)
    groups = {"A": [0, 1], "B": [2, 3], "C": [4, 5], "D": [6]}
    a = analyse(J, groups)
    assert (a.rank, a.dof, a.redundant) == (6, 0, 1)
    assert {k: v.unique for k, v in a.joints.items()} == {"A": False, "B": False, "C": True, "D": True}
    assert all(v.agree for v in a.joints.values())
    assert a.set_unique(["C", "D"]).unique
    assert not a.set_unique(["A", "C"]).unique
    # joint_uniqueness on its own gives the same verdicts
    for name, cols in groups.items():
        assert joint_uniqueness(J, cols).unique == a.joints[name].unique


def test_joint_with_dependent_own_columns_is_unique():
    """rank(J_P) < k: lam_P is not unique but f_P = J_P lam_P is (remark after Eq. 17)."""
    e = np.eye(4)
    J = np.column_stack([e[:, 0], 2.0 * e[:, 0], e[:, 1], e[:, 2] + e[:, 1], e[:, 3]])
    a = analyse(J, {"P": [0, 1], "Q": [2], "R": [3, 4]})
    assert (a.rank, a.redundant) == (4, 1)
    v = a.joints["P"]
    assert v.rank_P == 1 < len(v.columns)
    assert v.unique and v.agree and v.rank_defect == 0
    np.testing.assert_allclose(v.B_svd, 0.0, atol=1e-14)
    assert a.joints["Q"].unique and a.joints["R"].unique
    assert auto_eliminate(J) in ([0], [1])


def test_unique_reaction_is_the_same_for_every_multiplier_solution():
    """Meaning of the verdict: f_P = J_P lam_P is the same for lam and lam + nu, nu in null(J)."""
    J = planar_J()
    rng = np.random.default_rng(3)
    lam = rng.standard_normal(12)
    nu = null_space(J)[:, 0]
    a = analyse(J, PLANAR_GROUPS)
    for name, cols in PLANAR_GROUPS.items():
        f1 = J[:, cols] @ lam[cols]
        f2 = J[:, cols] @ (lam + 5.0 * nu)[cols]
        assert np.allclose(f1, f2, atol=1e-12) is a.joints[name].unique


# --------------------------------------------------------------------------- the paper's App. B.1


def test_planar_jacobian_is_the_derivative_of_the_equations():
    for q in (Q_STAR, planar_q(0.4), planar_q(-0.3) + 0.01):
        h = 1e-6
        fd = np.column_stack([
            (planar_phi(q + h * e) - planar_phi(q - h * e)) / (2 * h) for e in np.eye(12)
        ])
        np.testing.assert_allclose(planar_phi_q(q), fd, atol=1e-8)
    np.testing.assert_allclose(planar_phi(Q_STAR), 0.0, atol=1e-15)
    np.testing.assert_allclose(planar_phi(planar_q(0.7)), 0.0, atol=1e-14)
    assert planar_phi_q(Q_STAR)[4, 5] == pytest.approx(-4.0)  # the entry the paper prints as 0


@pytest.mark.parametrize("printed", [False, True], ids=["exact", "printed-B9"])
def test_planar_mechanism_at_q_star(printed):
    J = planar_J(printed=printed)
    a = analyse(J, PLANAR_GROUPS)
    assert_planar_reference(a)
    assert a.agree
    inv_sqrt3 = 1 / np.sqrt(3)
    # B.11: B_P of joints 1..3 hold +-1/sqrt(3) (sign of a null vector is arbitrary), 4..6 zero
    nonzero_rows = {"joint1": [2], "joint2": [5], "joint3": [2, 5]}  # phi1, phi2 rows
    for name, rows in nonzero_rows.items():
        for B in (a.joints[name].B_svd, a.joints[name].B_qr):
            assert B.shape == (12, 1)
            np.testing.assert_allclose(np.abs(B[rows, 0]), inv_sqrt3, atol=1e-12)
            np.testing.assert_allclose(np.delete(B[:, 0], rows), 0.0, atol=1e-12)
    b3 = a.joints["joint3"].B_svd[:, 0]
    assert b3[2] == pytest.approx(-b3[5])  # Phi6 = phi1 - phi2
    for name in ("joint4", "joint5", "joint6"):
        np.testing.assert_allclose(a.joints[name].B_svd, 0.0, atol=1e-12)
        np.testing.assert_allclose(a.joints[name].B_qr, 0.0, atol=1e-12)
    # B_qr = B_svd W with W orthogonal: equal row norms
    for v in a.joints.values():
        np.testing.assert_allclose(
            np.linalg.norm(v.B_qr, axis=1), np.linalg.norm(v.B_svd, axis=1), atol=1e-12
        )
    # also without equilibration (the paper's raw computation)
    assert_planar_reference(analyse(J, PLANAR_GROUPS, equilibrate=False))


def test_planar_exact_and_printed_variants_agree():
    exact = analyse(planar_J(), PLANAR_GROUPS)
    printed = analyse(planar_J(printed=True), PLANAR_GROUPS)
    assert to_json(exact) == to_json(printed)


@pytest.mark.parametrize("printed", [False, True], ids=["exact", "printed-B9"])
def test_planar_sets_eq17(printed):
    a = analyse(planar_J(printed=printed), PLANAR_GROUPS)
    cases = {
        ("joint4", "joint5"): (True, 0),
        ("joint4", "joint5", "joint6"): (True, 0),
        ("joint1",): (False, 1),
        ("joint1", "joint4", "joint5"): (False, 1),
        ("joint1", "joint2", "joint3"): (False, 1),  # 2+2+2 + 6 - 11: one shared relation
        (): (True, 0),
    }
    for names, (unique, defect) in cases.items():
        s = a.set_unique(names)
        assert s.unique is unique, names
        assert s.rank_defect == defect, names
        assert s.methods == {"rank": unique, "svd": unique, "qr": unique}, names
        assert s.agree and s.names == names
    assert a.set_unique("joint4").unique
    with pytest.raises(KeyError, match=r"unknown joint name\(s\) \['joint7'\]"):
        a.set_unique(["joint7"])
    with pytest.raises(ValueError, match="duplicate joint names"):
        a.set_unique(["joint4", "joint4"])


def test_planar_auto_elimination_removes_an_angle_equation():
    for printed in (False, True):
        J = planar_J(printed=printed)
        removed = auto_eliminate(J)
        keep = independent_columns(J)
        assert len(removed) == 1 and removed[0] in (1, 3, 5)  # Phi2, Phi4 or Phi6
        assert keep == sorted(set(range(12)) - set(removed))
        assert numerical_rank(J[:, keep]) == 11
        assert len(auto_eliminate(J, equilibrate=False)) == 1


def test_set_verdict_equals_all_members_unique_on_random_structures():
    """Eq. 17 by ranks <=> every member's B_P == 0 (and every member unique by ranks)."""
    rng = np.random.default_rng(4)
    checked = 0
    for trial in range(25):
        n, m = 7, 10
        basis = rng.standard_normal((n, 5))
        J = basis @ rng.standard_normal((5, m))  # rank 5: many shared dependencies
        # make some joints independent of everything else: private coordinates
        J[5:, :] = 0.0
        J[5, 0] = J[6, 1] = 1.0
        if trial % 2:
            J[:, 9] = J[:, 8]  # a dependency inside joint "e"
        groups = {"a": [0, 1], "b": [2, 3], "c": [4, 5], "d": [6, 7], "e": [8, 9]}
        a = analyse(J, groups)
        assert a.agree
        for k in range(1, 4):
            for names in itertools.combinations(groups, k):
                s = a.set_unique(names)
                assert s.agree
                assert s.unique == all(a.joints[nm].unique for nm in names)
                checked += 1
    assert checked == 25 * (5 + 10 + 10)


# --------------------------------------------------------------------------- scale invariance


def _scaled(kind, factor):
    J = planar_J()
    if kind == "scalar":
        return factor * J
    if kind == "rows":  # change of length unit seen on coordinates: translational rows
        return np.where(TRANSLATIONAL_ROWS, factor, 1.0)[:, None] * J
    if kind == "rows-both":  # translational up, rotational down
        return np.where(TRANSLATIONAL_ROWS, factor, 1.0 / factor)[:, None] * J
    if kind == "columns":  # equations in other units
        return J * np.where(LENGTH_EQUATIONS, factor, 1.0)[None, :]
    if kind == "units":  # q_x -> factor * q_x and length equations -> factor * Phi
        return (
            np.where(TRANSLATIONAL_ROWS, 1.0 / factor, 1.0)[:, None]
            * J
            * np.where(LENGTH_EQUATIONS, factor, 1.0)[None, :]
        )
    raise AssertionError(kind)


@pytest.mark.parametrize(
    "kind,factor",
    [("scalar", f) for f in (1e-3, 1e3, 1e-12, 1e12)]
    + [("rows", f) for f in (1e-3, 1e3, 1e6)]
    + [("rows-both", f) for f in (1e-3, 1e3)]
    + [("columns", f) for f in (1e-3, 1e3, 1e6)]
    + [("units", f) for f in (1e-3, 1e3, 1e6)],
)
def test_scale_invariance(kind, factor):
    a = analyse(_scaled(kind, factor), PLANAR_GROUPS)
    assert_planar_reference(a)
    for names, unique in (
        (("joint4", "joint5"), True),
        (("joint1",), False),
        (("joint1", "joint4", "joint5"), False),
    ):
        s = a.set_unique(names)
        assert s.unique is unique and s.agree


def test_random_diagonal_scalings_and_row_mixes():
    rng = np.random.default_rng(5)
    for printed in (False, True):
        J = planar_J(printed=printed)
        for _ in range(10):
            d_r = np.exp(rng.uniform(-7, 7, 12))
            d_c = np.exp(rng.uniform(-7, 7, 12))
            assert_planar_reference(analyse(d_r[:, None] * J * d_c[None, :], PLANAR_GROUPS))
            T = rng.standard_normal((12, 12))  # invertible coordinate change (cond ~ 1e1..1e3)
            assert_planar_reference(analyse(T @ J, PLANAR_GROUPS))


def test_raw_mode_rank_method_survives_row_scaling_that_fools_raw_svd():
    """Without equilibration, 1e6 between translational and rotational rows: the rank method
    (which decides ``unique``) is still right; the raw B tests may not be, which is flagged."""
    J = _scaled("rows-both", 1e3)
    raw = analyse(J, PLANAR_GROUPS, equilibrate=False)
    assert raw.rank == 11
    assert verdicts(raw) == PLANAR_UNIQUE
    assert all(v.methods["rank"] is v.unique for v in raw.joints.values())
    for v in raw.joints.values():
        assert v.agree == (v.methods["svd"] == v.methods["qr"] == v.unique)
    assert_planar_reference(analyse(J, PLANAR_GROUPS))  # equilibrated: all three right
    # scalar multiples never matter, with or without equilibration
    for f in (1e-3, 1e3):
        assert_planar_reference(analyse(f * planar_J(), PLANAR_GROUPS, equilibrate=False))


# --------------------------------------------------------------------------- near-singular


@pytest.mark.parametrize("delta", [0.3, 1e-3, 1e-6, 1e-8])
def test_near_singular_configuration_classifies_like_q_star(delta):
    """Close to (but not at) the singular position K = L = O: same rank and verdicts."""
    for printed in (False, True):
        J = planar_J(planar_q(-np.pi / 4 + delta), printed=printed)
        assert_planar_reference(analyse(J, PLANAR_GROUPS))


def test_general_configurations_classify_like_q_star():
    for psi in np.linspace(-0.7, 1.5, 9):
        assert_planar_reference(analyse(planar_J(planar_q(psi)), PLANAR_GROUPS))


def test_singular_position_loses_rank():
    a = analyse(planar_J(planar_q(-np.pi / 4)), PLANAR_GROUPS)
    assert (a.rank, a.dof, a.redundant) == (10, 2, 2)
    assert a.agree


# --------------------------------------------------------------------------- disagreement


def test_disagreement_by_crafted_tolerance_is_reported():
    """J_-P has a small but genuine dependency on P: B_P ~ 7e-5 relative.  With an (unwisely)
    large B threshold the SVD/QR tests call P unique; the rank test does not; agree is False."""
    delta = 1e-4
    J = np.array([[1.0, 0.0, delta], [0.0, 1.0, 1.0]])
    v = joint_uniqueness(J, [0])
    assert not v.unique and v.agree and v.rank_defect == 1
    v = joint_uniqueness(J, [0], b_rtol=1e-3)
    assert v.methods == {"rank": False, "svd": True, "qr": True}
    assert v.unique is False and v.agree is False
    a = analyse(J, {"P": [0], "R": [1, 2]}, b_rtol=1e-3)
    assert to_json(a)["joints"][0]["agree"] is False
    s = a.set_unique(["P"])
    assert s.methods == {"rank": False, "svd": True, "qr": True} and not s.agree and not s.unique


def test_disagreement_by_broken_qr_basis_is_reported(monkeypatch):
    real = an._null_basis

    def wrong_qr(J, r, method):
        N = real(J, r, method)
        if method == "qr" and N.shape[1]:
            N = np.roll(N, 2, axis=0)  # orthonormal, but not a null basis any more
        return N

    monkeypatch.setattr(an, "_null_basis", wrong_qr)
    a = analyse(planar_J(), PLANAR_GROUPS)
    assert verdicts(a) == PLANAR_UNIQUE  # `unique` follows the rank method
    assert not a.agree
    disagreeing = [name for name, v in a.joints.items() if not v.agree]
    assert disagreeing  # and it is visible, per joint and in the JSON
    for name in disagreeing:
        v = a.joints[name]
        assert v.methods["qr"] != v.methods["rank"] == v.unique
        assert v.methods["svd"] == v.methods["rank"]
    js = {j["name"]: j for j in to_json(a)["joints"]}
    assert all(js[name]["agree"] is False for name in disagreeing)


# --------------------------------------------------------------------------- API details


def test_to_json():
    a = analyse(planar_J(), PLANAR_GROUPS)
    d = to_json(a)
    assert json.loads(json.dumps(d)) == d
    assert list(d) == ["n_coordinates", "n_equations", "rank", "dof", "redundant", "joints"]
    assert (d["n_coordinates"], d["n_equations"], d["rank"], d["dof"], d["redundant"]) == (12, 12, 11, 1, 1)
    assert [j["name"] for j in d["joints"]] == list(PLANAR_GROUPS)
    assert d["joints"][0] == {
        "name": "joint1",
        "unique": False,
        "methods": {"rank": False, "svd": False, "qr": False},
        "rank_defect": 1,
        "agree": True,
    }
    assert [j["unique"] for j in d["joints"]] == PLANAR_UNIQUE


def test_joint_order_and_non_consecutive_columns():
    J = planar_J()
    perm = np.random.default_rng(6).permutation(12)  # shuffle the equations
    Jp = J[:, perm]
    where = {int(c): i for i, c in enumerate(perm)}
    groups = {name: [where[c] for c in cols] for name, cols in reversed(PLANAR_GROUPS.items())}
    a = analyse(Jp, groups)
    assert list(a.joints) == list(groups)
    assert [a.joints[n].unique for n in PLANAR_GROUPS] == PLANAR_UNIQUE
    # uncovered columns are part of every J_-P
    partial = analyse(J, {"joint4": [6, 7], "joint1": [0, 1]})
    assert partial.joints["joint4"].unique and not partial.joints["joint1"].unique


def test_verdicts_are_immutable():
    a = analyse(planar_J(), PLANAR_GROUPS)
    v = a.joints["joint1"]
    with pytest.raises(dataclasses.FrozenInstanceError, match="cannot assign to field 'unique'"):
        v.unique = True
    with pytest.raises(dataclasses.FrozenInstanceError, match="cannot assign to field 'rank'"):
        a.rank = 3
    with pytest.raises(ValueError, match="read-only"):
        v.B_svd[0, 0] = 1.0


def test_input_validation():
    J = planar_J()
    with pytest.raises(ValueError, match="belongs to both"):
        analyse(J, {"a": [0, 1], "b": [1, 2]})
    with pytest.raises(ValueError, match="out of range"):
        analyse(J, {"a": [12]})
    with pytest.raises(ValueError, match="out of range"):
        joint_uniqueness(J, [-1])
    with pytest.raises(ValueError, match="duplicate"):
        joint_uniqueness(J, [0, 0])
    with pytest.raises(TypeError, match="column indices must be integers, got 0.5"):
        joint_uniqueness(J, [0.5])
    with pytest.raises(ValueError, match="b_rtol must be a finite non-negative number, got -1.0"):
        analyse(J, PLANAR_GROUPS, b_rtol=-1.0)


def test_degenerate_shapes():
    a = analyse(np.zeros((3, 2)), {"a": [0], "b": [1]})
    assert (a.rank, a.dof, a.redundant) == (0, 3, 2)
    assert all(v.unique and v.agree for v in a.joints.values())  # f_P = 0 always
    a = analyse(np.zeros((3, 0)), {})
    assert (a.rank, a.dof, a.redundant) == (0, 3, 0) and a.joints == {}
    v = joint_uniqueness(np.eye(3), [])
    assert v.unique and v.agree
    assert independent_columns(np.zeros((2, 2))) == [] and auto_eliminate(np.zeros((2, 2))) == [0, 1]


# --------------------------------------------------------------------------- one factorisation


def test_one_factorisation_equals_the_three_tests_on_random_structures():
    """methods="svd" (one SVD of J, B_P = J_P N per joint) gives the verdicts and rank defects of
    the three tests (rank_defect from B: rank(J_P N) = rank(J_P) + rank(J_-P) - rank(J)), per
    joint and per set, and computes no raw bases."""
    rng = np.random.default_rng(7)
    for trial in range(25):
        n, m = 9, 14
        J = rng.standard_normal((n, 6)) @ rng.standard_normal((6, m))  # rank 6
        J[6:, :] = 0.0
        J[6, 0] = J[7, 1] = J[8, 2] = 1.0  # private coordinates: some joints unique
        if trial % 2:
            J[:, 13] = J[:, 12]  # a dependency inside joint "g"
        groups = {"a": [0, 1], "b": [2, 3], "c": [4, 5], "d": [6, 7], "e": [8, 9], "f": [10, 11], "g": [12, 13]}
        full, one = analyse(J, groups), analyse(J, groups, methods="svd")
        assert full.rank == one.rank
        for name in groups:
            f, o = full.joints[name], one.joints[name]
            assert o.methods == {"svd": f.methods["svd"]}
            assert (o.unique, o.rank_defect) == (f.unique, f.rank_defect), (trial, name)
            assert o.B_svd is None and o.B_qr is None
        for names in itertools.combinations(groups, 3):
            s, t = full.set_unique(names), one.set_unique(names)
            assert (t.unique, t.rank_defect) == (s.unique, s.rank_defect), (trial, names)
    with pytest.raises(ValueError, match=r"methods must be one of \['all', 'svd'\], got 'fast'"):
        analyse(np.eye(2), {"a": [0]}, methods="fast")


def _equilibrate_dense(J):
    """The Ruiz sweeps on the whole dense array (equilibrate's definition, for comparison)."""
    A = np.array(J, dtype=float)
    n, m = A.shape
    d_r, d_c = np.ones(n), np.ones(m)
    amax = float(np.abs(A).max()) if A.size else 0.0
    if amax == 0.0:
        return A, d_r, d_c
    floor = an.NOISE_FACTOR * max(n, m) * EPS * amax
    A[np.abs(A).max(axis=1) <= floor, :] = 0.0
    A[:, np.abs(A).max(axis=0) <= floor] = 0.0
    for _ in range(50):
        rn, cn = np.abs(A).max(axis=1), np.abs(A).max(axis=0)
        if max(np.abs(1 - rn[rn > 0]).max(initial=0.0), np.abs(1 - cn[cn > 0]).max(initial=0.0)) <= 1e-3:
            break
        sr = np.where(rn > 0, 1 / np.sqrt(np.where(rn > 0, rn, 1)), 1.0)
        sc = np.where(cn > 0, 1 / np.sqrt(np.where(cn > 0, cn, 1)), 1.0)
        A = sr[:, None] * A * sc[None, :]
        d_r, d_c = d_r * sr, d_c * sc
    return A, d_r, d_c


def test_equilibrate_on_the_nonzeros_is_the_dense_sweeps_bit_for_bit():
    rng = np.random.default_rng(11)
    for trial in range(200):
        n, m = rng.integers(1, 25, 2)
        A = rng.standard_normal((n, m)) * 10.0 ** rng.integers(-8, 8, (n, 1)) * 10.0 ** rng.integers(-5, 5, (1, m))
        A[rng.random((n, m)) < 0.6] = 0.0
        if trial % 3 == 0:
            A[rng.integers(0, n)] *= 1e-16  # a round-off row
        for got, want in zip(equilibrate(A), _equilibrate_dense(A)):
            np.testing.assert_array_equal(got, want)
