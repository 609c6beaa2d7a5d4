"""The core's banded singular values and null-space basis (core/bandsvd.c, through
kernel.band_svd) against LAPACK's SVD (numpy): rows with narrow windows (a chain's Jacobian),
dense rows, rank-deficient and more rows than columns. The route decides the ranks of the
uniqueness along the motion and of the singularity watch, so its values must hold to the
accuracy a rank decision at 1e-9 sigma_1 needs, and its basis must span the same space."""
import numpy as np
import pytest

from overcon import kernel

EPS = np.finfo(float).eps


def banded_rows(rng, k, n, width, rank=None):
    """k rows of length n, row i nonzero on a window of `width` columns starting near i n / k,
    with `rank` independent rows at most (the others combinations of their neighbours)."""
    B = np.zeros((k, n))
    for i in range(k):
        lo = min(int(i * n / k), n - width)
        B[i, lo:lo + width] = rng.standard_normal(width)
    if rank is not None:  # dependent rows, never two adjacent: each a combination of its two neighbours
        B0 = B.copy()
        for i in rng.choice(np.arange(1, k - 1, 2), size=k - rank, replace=False):
            B[i] = 0.7 * B0[i - 1] - 1.3 * B0[i + 1]
    return B


def assert_values(B):
    sv = kernel.band_svd(B)[0]
    ref = np.linalg.svd(B, compute_uv=False)
    ref = np.concatenate([ref, np.zeros(B.shape[0] - ref.size)])
    # absolute accuracy of a backward-stable reduction: a few eps sigma_1 times the size
    assert np.max(np.abs(sv - ref)) <= 50 * EPS * max(B.shape) * ref[0]
    return sv, ref


@pytest.mark.parametrize("k,n,width", [(1, 3, 3), (12, 15, 6), (62, 63, 9), (80, 120, 12), (40, 40, 40)])
def test_values_match_lapack(k, n, width):
    rng = np.random.default_rng(k * 1000 + n)
    assert_values(banded_rows(rng, k, n, width))


def test_scrambled_rows_and_more_rows_than_columns():
    rng = np.random.default_rng(7)
    B = banded_rows(rng, 50, 60, 8)
    assert_values(B[rng.permutation(50)])
    assert_values(rng.standard_normal((30, 12)))  # 18 zero singular values from the shape alone
    assert_values(np.zeros((5, 4)))


@pytest.mark.parametrize("k,n,rank", [(20, 30, 17), (60, 63, 50), (45, 52, 44)])
def test_null_basis_spans_lapacks(k, n, rank):
    rng = np.random.default_rng(k + rank)
    B = banded_rows(rng, k, n, 7, rank)
    sv, ref = assert_values(B)
    tol = 1e-9 * ref[0]
    p = int(np.sum(ref <= tol))
    assert p == k - rank and ref[rank - 1] > 1e3 * tol  # a clear gap: the rank is no tie
    assert int(np.sum(sv <= tol)) == p
    _, N = kernel.band_svd(B, p, 0.1 * tol)
    assert np.allclose(N.T @ N, np.eye(p), atol=1e-12)
    # the dependencies of the rows: N^T B = 0, and the same space as LAPACK's trailing vectors
    assert np.max(np.abs(N.T @ B)) <= 1e-11 * ref[0]
    U = np.linalg.svd(B.T)[2][k - p:].T  # B^T = U S V^T: null(B^T) is V's trailing columns
    assert np.linalg.norm(N - U @ (U.T @ N)) <= 1e-10


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="non-finite"):
        kernel.band_svd(np.array([[1.0, np.nan], [0.0, 1.0]]))


@pytest.mark.parametrize("below,above", [(0.95, 1.05), (0.999, 1.001), (0.2, 50.0)])
def test_null_basis_when_the_cut_falls_in_a_cluster(below, above):
    """A rank cut between two close singular values (a mechanism near a flat position has a
    cluster of small values drifting through the threshold): the basis must still be the p least
    vectors' space, to the accuracy the gap allows (sin theta <= |E| / gap with |E| a few eps
    sigma_1), and orthonormal. With one block of p vectors the iteration converged at the rate
    (below / above)^2 per step and fell short of that at the first two cuts."""
    rng = np.random.default_rng(11)
    k, n, p, tol = 40, 44, 6, 1e-3
    values = np.concatenate([np.geomspace(1.0, 20 * tol, k - p - 3), [4 * tol, 2 * tol, above * tol],
                             [below * tol, 0.7 * tol, 0.5 * tol, 0.3 * tol, 0.1 * tol, 0.0]])
    Uo = np.linalg.qr(rng.standard_normal((k, k)))[0]
    Vo = np.linalg.qr(rng.standard_normal((n, n)))[0]
    B = Uo @ np.diag(values) @ Vo[:, :k].T  # B^T's null directions: Uo's last columns
    sv, _ = assert_values(B)
    assert int(np.sum(sv < tol)) == p
    _, N = kernel.band_svd(B, p, 0.1 * tol)
    assert np.allclose(N.T @ N, np.eye(p), atol=1e-12)
    target = Uo[:, k - p:]
    gap = (above - below) * tol
    assert np.linalg.norm(N - target @ (target.T @ N), 2) <= 1e3 * EPS * max(k, n) / gap
