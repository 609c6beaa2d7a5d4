"""The one factorisation at scale (:func:`overcon.analysis._factorise`): on large generated
linkages it gives the rank, the null space and the SVD test's verdicts of one dense SVD of the
whole Jacobian; its certificate sends a matrix whose loops are too close to the rank threshold
to the dense SVD; the pre-check of a 1000-body chain runs through ``overcon check``."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from overcon import analysis as an
from overcon.cli import main
from overcon.kernel import jacobian
from overcon.precheck import joint_groups
from test_precheck_methods import _model, linkage

EPS = np.finfo(float).eps


def _dense(A: np.ndarray, rtol: float = an.DEFAULT_RTOL):
    """Rank, tolerance, null basis and kappa of one dense SVD of A (the SVD test before)."""
    s, vh = an._svd_full(A)
    tol = max(rtol, max(A.shape) * EPS) * s[0]
    r = int(np.count_nonzero(s > tol))
    return r, tol, vh.T[:, r:], s[0] / s[r - 1]


CASES = [("planar", "chain", 300, 0), ("spatial", "chain", 120, 0), ("planar", "loops", 200, 12),
         ("spatial", "loops", 100, 8), ("planar", "cranks", 80, 0), ("spatial", "cranks", 40, 0), ("planar", "forest", 240, 0),
         ("spatial", "forest", 90, 0), ("planar", "tree", 250, 0)]


@pytest.mark.parametrize("kind,shape,n,loops", CASES, ids=lambda v: str(v))
def test_structured_factorisation_is_the_dense_svd_on_large_linkages(tmp_path, kind, shape, n, loops):
    model = _model(linkage(np.random.default_rng(n), kind, shape, n, tmp_path / "m.toml", loops))
    J = jacobian(model, model.q0).T
    A = an.equilibrate(J)[0]
    f = an._factorise(A, an.DEFAULT_RTOL)
    r, tol, N, kappa = _dense(A)
    assert f.route == "blocks" and f.r == r
    # ||A||_2 from Lanczos (a lower bound): 7e-5 low on a chain of equal links, whose top
    # singular values cluster; the rank above does not depend on it (the certificate's band)
    assert tol * (1 - 1e-3) <= f.tol <= tol * (1 + 1e-12)
    # the same subspace: the projectors agree to the basis round-off bound of the B test
    bound = an.B_NOISE_FACTOR * max(A.shape) * EPS * kappa
    assert np.abs(f.N @ f.N.T - N @ N.T).max() <= bound
    assert f.N.shape == N.shape and np.allclose(f.N.T @ f.N, np.eye(N.shape[1]), atol=1e-12)
    if shape != "cranks":
        assert f.peeled  # the structure is used: a leaf was peeled
    # the SVD test's verdicts, joint by joint, from the dense basis and from the analysis
    a = an.analyse(J, joint_groups(model), methods="svd")
    assert a.rank == r
    limit = max(an.DEFAULT_RTOL, an.B_NOISE_FACTOR * max(A.shape) * EPS * kappa) * np.linalg.norm(A, 2)
    for name, cols in joint_groups(model).items():
        B = A[:, cols] @ N[cols, :]
        dense_unique = B.size == 0 or np.linalg.norm(B, axis=1).max() <= limit
        assert a.joints[name].unique == dense_unique, name


def _coupled(delta: float) -> np.ndarray:
    """Row 0 peels column 0 (a leaf: D = [1], so sigma_min of the peeled part is 1); rows 1-2 x
    columns 1-3 are a loop block (wide: it cannot peel) with rows [1, 1, 1] and [1, 1, 1 + delta],
    its smallest singular value ~ 0.4 delta, coupled to column 0 by row 1."""
    A = np.zeros((3, 4))
    A[0, 0] = A[1, 0] = 1.0
    A[1, 1:] = 1.0
    A[2, 1:] = [1.0, 1.0, 1.0 + delta]
    return A


def test_certificate_sends_a_loop_near_the_threshold_to_the_dense_svd():
    tol = an.DEFAULT_RTOL * np.linalg.norm(_coupled(0.0), 2)
    per_delta = np.linalg.svd(_coupled(1e-6)[1:, 1:], compute_uv=False)[-1] / 1e-6
    near = _coupled(1.5 * tol / per_delta)  # block singular value 1.5 tol: inside (tol, c tol], c ~ 2
    f = an._factorise(near, an.DEFAULT_RTOL)
    assert f.route == "dense" and f.r == _dense(near)[0]
    far = _coupled(1e-3)  # far above the threshold: the blocks decide
    f = an._factorise(far, an.DEFAULT_RTOL)
    assert f.route == "blocks" and f.peeled == (0,) and f.r == _dense(far)[0] == 3
    exact = _coupled(0.0)  # a true redundancy in the loop block: row 1 = row 0 + row 2
    f = an._factorise(exact, an.DEFAULT_RTOL)
    assert f.route == "blocks" and f.r == _dense(exact)[0] == 2 and f.N.shape == (4, 2)
    assert np.all(f.N[0] == 0.0) and np.abs(exact @ f.N).max() <= 1e-15


def _star(parts: int, delta: float) -> np.ndarray:
    """A hub row (row 0) on ``parts`` parts, part k row k + 1 = [1, 1] on columns 2k, 2k + 1 (its
    null vector (1, -1) / sqrt 2); the hub row reads [1, 1 + delta] on each part, so the hub
    rows' matrix G on the parts' null vectors is delta / sqrt 2 per part (rank 1 unless 0)."""
    A = np.zeros((parts + 1, 2 * parts))
    for k in range(parts):
        A[k + 1, 2 * k:2 * k + 2] = 1.0
        A[0, 2 * k:2 * k + 2] = [1.0, 1.0 + delta]
    return A


def test_hub_block_is_the_dense_svd_and_its_certificate_refuses_near_the_threshold():
    """A block with a hub row (more than _HUB_DEGREE equations on it) goes through its hubs: far
    from the threshold the certificate holds and the rank and null space are the dense SVD's.
    With G's singular value 1.5 tol the parts and G alone would say rank parts + 1, but A's
    smallest singular value is 0.53 tol (the coupling F): the certificate refuses and the dense
    SVD of the block decides (rank parts)."""
    parts = an._HUB_DEGREE // 2 + 1
    tol = an.DEFAULT_RTOL * np.linalg.norm(_star(parts, 0.0), 2)
    near = 1.5 * tol / np.sqrt(parts / 2)  # ||G|| = delta sqrt(parts / 2)
    for delta, certified, rank in [(0.5, True, parts + 1), (0.0, True, parts), (near, False, parts)]:
        A = _star(parts, delta)
        n, m = A.shape
        rr, cc = np.nonzero(A)
        rows_of, cols_of = an._pattern(rr, cc, n, m)
        hub = an._hub(A, tuple(range(n)), tuple(range(m)), rows_of, cols_of, np.ones(m, bool))
        assert hub is not None and hub.S == (0,) and len(hub.parts) == parts
        t = max(an.DEFAULT_RTOL, max(n, m) * EPS) * np.linalg.norm(A, 2)
        got = hub.finish(A, tuple(range(m)), t, t)
        assert (got is not None) == certified
        r, _, N, kappa = _dense(A)
        f = an._factorise(A, an.DEFAULT_RTOL)
        assert f.r == r == rank
        bound = an.B_NOISE_FACTOR * max(n, m) * EPS * kappa
        assert np.abs(f.N @ f.N.T - N @ N.T).max() <= bound
        if certified:
            assert got.rank == r and got.N.shape == N.shape and np.abs(got.N @ got.N.T - N @ N.T).max() <= bound


def test_decoupled_blocks_and_zero_columns():
    """A loop of rank 1, a leaf that peels, and an equation with an all-zero column: the loop's
    singular values are computed, the leaf's columns have no null component, and the zero
    column is a null vector of its own."""
    A = np.zeros((4, 5))
    A[:2, :2] = [[1.0, 2.0], [2.0, 4.0]]  # rank 1
    A[2:, 2:4] = [[3.0, 1.0], [1.0, 2.0]]  # rank 2: peels
    f = an._factorise(A, an.DEFAULT_RTOL)
    assert f.route == "blocks" and sorted(f.peeled) == [2, 3] and f.r == 3 == _dense(A)[0]
    np.testing.assert_allclose(f.sigma, [5.0, 0.0], atol=1e-15)
    assert f.N.shape == (5, 2) and np.abs(A @ f.N).max() <= 1e-15 and np.all(f.N[2:4] == 0.0)
    assert [abs(x) for x in f.N[4]] in ([0.0, 1.0], [1.0, 0.0])
    assert an.numerical_rank(A) == 3 and an.independent_columns(A) in ([0, 2, 3], [1, 2, 3])


def test_check_of_a_1000_body_chain(tmp_path, capsys):
    """The pre-check at the body limit answers (all joints unique: a chain has no redundancy)."""
    from test_robust import chain
    path = chain(1000, tmp_path / "chain.toml")
    assert main(["check", str(path), "--json", "--friction", "none"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["n_coordinates"], report["rank"], report["dof"]) == (3000, 2000, 1000)
    assert report["methods_run"] == ["svd"] and all(j["unique"] for j in report["joints"])


@pytest.mark.parametrize("kind,shape,n,loops", [("planar", "chain", 60, 0), ("spatial", "loops", 40, 4),
                                               ("planar", "forest", 45, 0)], ids=lambda v: str(v))
def test_left_inverse_norms_bound_the_peeled_part(tmp_path, kind, shape, n, loops):
    """1 / sigma_min(B) <= ||L||_F <= the one-pass bound, B the peeled rows x peeled columns."""
    model = _model(linkage(np.random.default_rng(n), kind, shape, n, tmp_path / "m.toml", loops))
    A = an.equilibrate(jacobian(model, model.q0).T)[0]
    rr, cc = np.nonzero(A)
    rows_of, cols_of = [[] for _ in range(A.shape[1])], [[] for _ in range(A.shape[0])]
    for i, c in zip(rr.tolist(), cc.tolist()):
        rows_of[c].append(i)
        cols_of[i].append(c)
    steps, _, _ = an._peel(A, rows_of, cols_of, an.DEFAULT_RTOL * np.linalg.norm(A))
    assert steps
    R = [i for rows, _, _ in steps for i in rows]
    C = [c for _, cols, _ in steps for c in cols]
    B = A[np.ix_(R, C)]
    assert np.all(A[np.ix_(R, sorted(set(range(A.shape[1])) - set(C)))] == 0.0)  # A = [[B, 0], [X, A']]
    exact, bound = an._left_inverse_norm(A, steps, cols_of), an._left_inverse_bound(A, steps, cols_of)
    assert 1.0 / np.linalg.svd(B, compute_uv=False)[-1] <= exact * (1 + 1e-12) and exact <= bound * (1 + 1e-12)


@pytest.mark.parametrize("path", sorted((Path(__file__).parents[1] / "mechanisms").glob("*.toml")) + ["cranks", "spatial"],
                         ids=lambda p: p if isinstance(p, str) else p.stem)
def test_the_cores_sparse_rows_are_the_dense_rows_nonzeros(tmp_path, path):
    """kernel.rows_sparse (core/rows_sparse.c), what admission and the pre-check read, gives Phi
    and exactly the nonzeros of the dense Phi_h of kernel.rows_at, in np.nonzero's order."""
    from overcon.kernel import rows_at, rows_sparse
    if path == "cranks":
        path = linkage(np.random.default_rng(5), "planar", "cranks", 30, tmp_path / "m.toml")
    elif path == "spatial":
        path = linkage(np.random.default_rng(6), "spatial", "loops", 40, tmp_path / "m.toml", 4)
    model = _model(path, check_initial=False)
    rng = np.random.default_rng(0)
    for h in (model.h0, rng.standard_normal(model.nh)):
        phi, J, _ = rows_at(model, model.q0, h)
        phi_s, (rr, cc, vals) = rows_sparse(model, model.q0, h)
        r0, c0 = np.nonzero(J)
        assert np.array_equal(phi, phi_s) and np.array_equal(rr, r0) and np.array_equal(cc, c0)
        assert np.array_equal(vals, J[r0, c0])


@pytest.mark.parametrize("kind,shape,n,loops", [("spatial", "loops", 40, 4), ("planar", "cranks", 30, 0),
                                               ("spatial", "forest", 30, 0)], ids=lambda v: str(v))
def test_batched_joint_verdicts_are_each_joints_own(tmp_path, kind, shape, n, loops):
    """The analysis takes every joint's block, rank(A_P), B_P row norms and defect stacked by shape
    (analysis._joints, _b_defects): each joint's numbers are those it gets analysed alone (one
    joint in a batch of one), to the last bit, whatever the other joints in its stack."""
    model = _model(linkage(np.random.default_rng(n), kind, shape, n, tmp_path / "m.toml", loops))
    groups = joint_groups(model)
    fz = an.factorise(jacobian(model, model.q0).T)
    together = an.analyse(fz, groups, methods="svd")
    assert len({len(c) for c in groups.values()}) > 1 or shape == "cranks"  # stacks of several shapes
    assert not all(v.unique for v in together.joints.values())  # the defects' batch is not empty
    ctx = together._ctx
    for name, cols in groups.items():
        alone = an._joints(ctx, {name: tuple(cols)})[name]
        v = together.joints[name]
        assert (alone.rank_P, alone.b_ratio_svd, alone.rank_defect, alone.unique) == \
            (v.rank_P, v.b_ratio_svd, v.rank_defect, v.unique), name
        assert together.set_unique([name]).rank_defect == v.rank_defect


def test_peeling_checks_every_leaf_at_once_and_walks_again_when_one_fails(monkeypatch):
    """The peeling's order is walked on the pattern and its leaves' SVDs taken stacked; a leaf of
    rank below its width (rows 0-1 on columns 0-1, rank 1) is not peeled, and the walk without it
    peels what a leaf-by-leaf walk peels: the leaves (rows 2-3, 4-5) and not the rank-1 pair."""
    A = np.zeros((6, 6))
    A[:2, :2] = [[1.0, 2.0], [2.0, 4.0]]  # rank 1: fails its check
    A[2:4, 2:4] = [[3.0, 1.0], [1.0, 2.0]]
    A[4:, 4:] = [[1.0, 0.5], [0.0, 1.0]]
    A[4, 3] = 0.25  # rows 4-5 touch column 3 of the step before: peeled after it
    rr, cc = np.nonzero(A)
    rows_of, cols_of = an._pattern(rr, cc, *A.shape)
    walks = []
    walk = an._peel_order
    monkeypatch.setattr(an, "_peel_order", lambda *a: walks.append(a[-1]) or walk(*a))
    steps, live_r, live_c = an._peel(A, rows_of, cols_of, 1e-9)
    assert len(walks) == 2 and walks[0] is None  # on the pattern, then again with the rank checks
    assert sorted(c for _, C, _ in steps for c in C) == [2, 3, 4, 5]
    assert list(live_c) == [True, True, False, False, False, False] and list(live_r[:2]) == [True, True]
    for R, C, P in steps:  # each D^+ is the pseudo-inverse of its D
        np.testing.assert_allclose(P @ A[np.ix_(R, C)], np.eye(len(C)), atol=1e-14)
    f = an._factorise(A, an.DEFAULT_RTOL)
    assert f.r == 5 == np.linalg.matrix_rank(A) and sorted(f.peeled) == [2, 3, 4, 5]
