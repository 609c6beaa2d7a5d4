"""Reaction-uniqueness analysis of a constraint Jacobian (Fraczek & Wojtyra 2011, §2.2, App. B).

Pure functions on plain numpy arrays; nothing here knows about models, scenes or joint types.

Glossary (paper symbols, spelled for code)
------------------------------------------
``J``            (n, m)  transposed constraint Jacobian ``Phi_q.T`` (Eq. 10-11); for spatial systems
                         the modified Jacobian of Eq. 7.  n coordinates (rows), m equations (columns).
``columns``      0-based column indices of ``J`` owned by one joint P (any order, need not be
                 consecutive).  ``J_P = J[:, columns]``, ``J_-P`` = all other columns.
``r``            ``rank(J)``; ``dof = n - r``; ``redundant = m - r`` (Eq. 13: ``dim Z = r < m``).
``f_P``          generalized reaction of joint P, ``f_P = J_P lam_P`` (Eq. 10).  ``lam`` solves the
                 rank-deficient Eq. 11, so ``lam`` is unique only up to ``null(J)``.
``N``            (m, m - r) orthonormal basis of ``null(J)``.

Theory (§2.2).  With ``Z = span(J)`` (Eq. 12), ``X = span(J_P)`` (Eq. 14) and ``Y = span(J_-P)``
(Eq. 16), ``f_P`` is uniquely determined iff ``Z = X (+) Y`` (direct sum).  Equivalently, iff
``J_P nu_P = 0`` for every ``nu`` in ``null(J)``: any two solutions ``lam`` differ by such a ``nu``.
For a set of joints K = {P1..Pp} the condition is Eq. 17, ``Z = X1 (+) ... (+) Xp (+) Y`` with Y
spanned by the columns of no member; it holds iff every member is individually unique (both say
``J_Pi nu_Pi = 0`` for all null vectors ``nu``), so the set verdict is checked both ways.

The three numerical tests ([7] of the paper, used in App. B.10-B.12 and B.19-B.21)
----------------------------------------------------------------------------------
rank comparison (B.10)
    ``rank_defect = rank(J_P) + rank(J_-P) - rank(J)``; 0 means direct sum (unique), > 0 not.
    For a set (Eq. 17): ``sum_i rank(J_Pi) + rank(J_Y) - rank(J)``.
SVD (B.11)
    ``J = U S V^T`` with V (m, m).  ``V_P`` = rows of V of joint P (k, m).  Since
    ``J V = sum_P J_P V_P = [U_r S_r | 0]``, ``J_P V_P = [D_P (n, r) | B_P (n, m - r)]`` where
    ``B_P = J_P N_P`` with ``N = V[:, r:]``.  Unique iff ``B_P == 0``.
QR (B.12)
    Column-pivoted QR of ``Phi_q = J^T`` (m, n): ``J^T Pi = Q R`` with Q (m, m).  The first r
    columns of Q span ``range(J^T)``, so the last m - r span its orthogonal complement
    ``null(J)``.  ``Q_P`` = rows of Q of joint P, ``J_P Q_P = [D_P | B_P]``, unique iff ``B_P == 0``.
    The same r (from the SVD) is used by all three methods.

The one factorisation (how the SVD test's null basis is computed: :func:`_factorise`)
-------------------------------------------------------------------------------------
Not one dense SVD of the whole matrix (O(n m min(n, m)), 20 s for a 1000-body chain) but one of
each block that is left after two exact reductions: (1) peeling: a set of coordinates (rows)
touched only by equations (columns) C on which they have full column rank forces every null
vector to vanish on C (a leaf body held by its joint; then whatever has become a leaf), so C is
dropped with those rows; (2) splitting: what is left falls apart into blocks that share no
coordinate and no equation, whose singular values together are the matrix's and whose null
spaces add up to its null space. The threshold is the whole matrix's (``tol`` below, with
||A||_2 bounded from both sides), and a certificate (sigma_min of the peeled part against the
blocks' singular values near ``tol``) proves the rank is the one one dense SVD of the whole
matrix gives; when it cannot, that dense SVD runs. A tree mechanism peels whole (no SVD at
all); a parallelogram linkage is one block, whose coupler's rows are hubs (more than
:data:`_HUB_DEGREE` equations on them): set aside, the block falls into one small part per crank,
factorised one by one, and the hub rows on those parts' null vectors are factorised last
(:meth:`_Hub.finish`, with its own certificate, the block's dense SVD when that fails). ``methods="all"`` also runs one dense SVD of the
whole matrix for the rank and QR tests (rank, tolerance and their kappa), so the cross-check
compares the one factorisation with independent computations.

Both B matrices are ``J_P`` times an orthonormal basis of the same null space, so
``B_qr = B_svd W`` for an orthogonal W: entries differ (and a null vector's sign is arbitrary),
but the row norms of B are identical in exact arithmetic.  The zero test below uses row norms.

Equilibration (what the decisions are computed on)
--------------------------------------------------
All three criteria are exactly invariant under ``J -> D_r J D_c`` for invertible diagonal D_r
(coordinate units: translational rows against rotational rows) and D_c (equation units):
``null(D_r J D_c) = D_c^-1 null(J)``, ``span(J_P D_cP)`` is just ``span(J_P)`` mapped by D_r, and
rank and direct sums survive invertible maps.  To make the *numerical* verdicts invariant too,
the decisions run on ``Jh = D_r J D_c`` from ``equilibrate`` (Ruiz 2001 iteration: rows and
columns scaled to unit max-norm, <= 50 sweeps, stop when all norms are within 1e-3 of 1).  Before
that, rows and columns whose max-norm is ``<= NOISE_FACTOR * max(n, m) * eps * max|J|``
(``NOISE_FACTOR = 100``) are round-off (e.g. ``cos(pi/2)`` products) and are set to zero, so they
are not blown up.  Reported ``B_svd`` / ``B_qr`` are the paper's, computed from the raw J (B.11
magnitudes, J's units); the zero test uses the equilibrated ones.  Pass ``equilibrate=False`` to
decide on the raw J.

Tolerances (all relative to the matrix scale)
---------------------------------------------
``eps`` = float64 machine epsilon; ``A`` is the matrix decided on (``Jh``, or J);
``sigma_1 = ||A||_2``; ``rtol`` defaults to ``DEFAULT_RTOL = 1e-9``.

rank
    A singular value counts iff ``sigma > tol``, ``tol = max(rtol, max(n, m) * eps) * sigma_1``
    (``rank_tolerance``).  The *same absolute* ``tol`` (from the whole matrix) is used for
    ``rank(J)``, ``rank(J_P)``, ``rank(J_-P)`` and ``rank(J_Y)``, so the dimension count of the
    direct-sum test is consistent.  Configurations with ``sigma_r / sigma_1 > rtol`` count as
    non-singular (the planar mechanism 1e-8 rad from its singular position K = L = O has
    ``sigma_r / sigma_1 ~ 5e-9`` and is still rank 11; at 1e-9 rad it is rank 10); a numerically
    drifted configuration whose "broken" redundancy leaves ``sigma / sigma_1 <= 1e-9`` is still
    seen as redundant.  ``rtol`` moves the boundary.
B_P == 0 (SVD and QR)
    ``max_i ||B_P[i, :]||_2 <= b_rtol * sigma_1`` with
    ``b_rtol = max(rtol, B_NOISE_FACTOR * max(n, m) * eps * kappa)``, ``B_NOISE_FACTOR = 100``,
    ``kappa = sigma_1 / sigma_r``, sigma_r the smallest singular value above tol of the matrices
    factorised (the SVD test: the blocks of the one factorisation, the whole matrix when nothing
    was peeled; the QR test: the whole matrix).  The second term bounds the round-off of a computed null-space
    basis (Wedin: angle error ~ eps * sigma_1 / sigma_r), so near-singular but non-singular
    configurations give no spurious nonzero B.  The row 2-norm is invariant to the choice of
    orthonormal null basis, so the SVD and QR B's are measured identically.  ``b_rtol`` can be
    overridden (keyword ``b_rtol``).

Scale invariance.  Scalar multiples of J change nothing; diagonal row/column scalings (units) are
removed by equilibration up to rounding.  Tests cover 1e-12..1e12 overall, 1e3 / 1e-3 / 1e6
coordinate-group row scalings and equation scalings, random diagonal scalings up to ~1e3 per
row/column, and random invertible row mixes.  Without equilibration (``equilibrate=False``, the
paper's raw form) a 1e6 ratio between translational and rotational rows already makes the raw
SVD/QR B tests miss genuine non-uniqueness while the rank test still answers correctly, and a
1e9 ratio breaks the rank test too.  The reported ``unique`` always follows the rank method; the
SVD/QR verdicts are reported beside it and any disagreement sets ``agree = False`` (never hidden).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Mapping, Sequence

import numpy as np
import scipy.linalg  # loaded with its BLAS at import: a caller's thread limit (threadpoolctl) then covers it

__all__ = [
    "DEFAULT_RTOL",
    "B_NOISE_FACTOR",
    "NOISE_FACTOR",
    "rank_tolerance",
    "numerical_rank",
    "equilibrate",
    "null_space",
    "independent_columns",
    "auto_eliminate",
    "Factored",
    "factorise",
    "factorise_nonzeros",
    "JointVerdict",
    "SetVerdict",
    "Analysis",
    "joint_uniqueness",
    "analyse",
    "to_json",
]

EPS = float(np.finfo(float).eps)
#: Default relative rank threshold: singular values <= DEFAULT_RTOL * sigma_1 are zero.
DEFAULT_RTOL = 1e-9
#: Safety factor on the round-off bound of a computed null-space basis (B_P == 0 test).
B_NOISE_FACTOR = 100.0
#: Rows/columns with max-norm <= NOISE_FACTOR * max(n, m) * eps * max|J| are round-off.
NOISE_FACTOR = 100.0

_METHODS = ("rank", "svd", "qr")
#: The tests a pre-check runs: ``"svd"``, the one-factorisation test (B.11: one SVD of J gives
#: null(J); a joint is unique iff J_P N_P = 0), or ``"all"``, with the rank comparison (B.10: two
#: SVDs per joint) and the QR test (B.12) as a cross-check.
METHOD_SETS = {"svd": ("svd",), "all": _METHODS}
_RUIZ_SWEEPS = 50
_RUIZ_TOL = 1e-3


# --------------------------------------------------------------------------- basic helpers


def _as_matrix(A) -> np.ndarray:
    A = np.asarray(A, dtype=float)
    if A.ndim != 2:
        raise ValueError(f"expected a 2-D matrix, got shape {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError("matrix contains NaN or inf")
    return A


def _svdvals(A: np.ndarray) -> np.ndarray:
    if A.size == 0:
        return np.zeros(0)
    return np.linalg.svd(A, compute_uv=False)


def _rtol(rtol: float | None, name: str = "rtol") -> float:
    if rtol is None:
        return DEFAULT_RTOL
    value = float(rtol)
    if not (np.isfinite(value) and value >= 0.0):
        raise ValueError(f"{name} must be a finite non-negative number, got {rtol!r}")
    return value


def _tol_from(s: np.ndarray, shape: tuple[int, int], rtol: float) -> float:
    if s.size == 0:
        return 0.0
    return max(rtol, max(shape) * EPS) * float(s[0])


def _rank_abs(A: np.ndarray, tol: float) -> int:
    if A.size == 0:
        return 0
    return int(np.count_nonzero(_svdvals(A) > tol))


def rank_tolerance(A, rtol: float | None = None) -> float:
    """Absolute singular-value threshold of ``A``: ``max(rtol, max(n, m) * eps) * ||A||_2``.

    ``rtol`` defaults to ``DEFAULT_RTOL`` (1e-9) and is never allowed below the LAPACK round-off
    level ``max(n, m) * eps``.  0.0 for an empty or all-zero matrix.
    """
    A = _as_matrix(A)
    return _factorise(A, _rtol(rtol), vectors=False).tol


def numerical_rank(A, rtol: float | None = None, *, tol: float | None = None) -> int:
    """Number of singular values of ``A`` that are ``> tol``.

    ``tol`` (absolute) defaults to ``rank_tolerance(A, rtol)``; pass it explicitly to rank a
    submatrix against the scale of a larger matrix (as the uniqueness tests do).  No
    equilibration here: this is the plain numerical rank of the given array, from the one
    factorisation (:func:`_factorise`: the rank one SVD of A gives, at the cost of A's structure).
    """
    A = _as_matrix(A)
    if tol is None:
        return _factorise(A, _rtol(rtol), vectors=False).r
    return _factorise(A, DEFAULT_RTOL, tol=float(tol), vectors=False).r


def equilibrate(J) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(Jh, d_r, d_c)`` with ``Jh = d_r[:, None] * J0 * d_c[None, :]``, rows and columns
    of unit max-norm (within 1e-3; Ruiz iteration, at most 50 sweeps).

    ``J0`` is J with round-off rows and columns (max-norm <= ``NOISE_FACTOR * max(n, m) * eps *
    max|J|``) set to zero; zero rows/columns keep scale 1.  Diagonal scaling preserves rank,
    null spaces (up to ``d_c``) and direct sums, so the uniqueness verdicts on Jh are those of J.
    """
    A = _as_matrix(J).copy()
    n, m = A.shape
    if A.size == 0:
        return A, np.ones(n), np.ones(m)
    # everything below touches the nonzeros only (a large mechanism's J is very sparse): the same
    # maxima, and the same products in the same order, as on the dense array
    rr, cc = np.nonzero(A)  # row-major: rr ascending
    keep, v, d_r, d_c = _ruiz(rr, cc, A[rr, cc], n, m)
    A[rr[~keep], cc[~keep]] = 0.0
    A[rr[keep], cc[keep]] = v
    return A, d_r, d_c


def _ruiz(rr: np.ndarray, cc: np.ndarray, vals: np.ndarray, n: int, m: int):
    """:func:`equilibrate` on the nonzeros ``vals`` at (rr, cc) (row-major) of an (n, m) matrix:
    (mask of the nonzeros kept, the kept ones' scaled values, d_r, d_c); the others are
    round-off set to zero."""
    d_r, d_c = np.ones(n), np.ones(m)
    v = np.abs(vals)
    amax = float(v.max()) if v.size else 0.0
    if amax == 0.0:
        return np.ones(vals.size, dtype=bool), vals.copy(), d_r, d_c
    floor = NOISE_FACTOR * max(n, m) * EPS * amax
    rmax = np.zeros(n)
    np.maximum.at(rmax, rr, v)
    v[(rmax <= floor)[rr]] = 0.0
    cmax = np.zeros(m)
    np.maximum.at(cmax, cc, v)
    v[(cmax <= floor)[cc]] = 0.0
    keep = v != 0.0
    rr, cc = rr[keep], cc[keep]
    v = vals[keep]
    by_col = np.argsort(cc, kind="stable")
    r_at, r_start = np.unique(rr, return_index=True)
    c_at, c_start = np.unique(cc[by_col], return_index=True)
    for _ in range(_RUIZ_SWEEPS):
        a = np.abs(v)
        rn = np.zeros(n)
        cn = np.zeros(m)
        if a.size:
            rn[r_at] = np.maximum.reduceat(a, r_start)
            cn[c_at] = np.maximum.reduceat(a[by_col], c_start)
        dev = max(
            float(np.abs(1.0 - rn[rn > 0]).max(initial=0.0)),
            float(np.abs(1.0 - cn[cn > 0]).max(initial=0.0)),
        )
        if dev <= _RUIZ_TOL:
            break
        sr = np.where(rn > 0, 1.0 / np.sqrt(np.where(rn > 0, rn, 1.0)), 1.0)
        sc = np.where(cn > 0, 1.0 / np.sqrt(np.where(cn > 0, cn, 1.0)), 1.0)
        v = sr[rr] * v * sc[cc]
        d_r *= sr
        d_c *= sc
    return keep, v, d_r, d_c


class _Sparse:
    """A matrix held by its nonzeros, row-major (CSR: ``indptr``, ``indices``, ``data``): what the
    one factorisation gathers from (:func:`_sub`), without the dense n x m array."""

    def __init__(self, shape: tuple[int, int], rr: np.ndarray, cc: np.ndarray, vals: np.ndarray):
        self.shape = (int(shape[0]), int(shape[1]))
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(rr, minlength=self.shape[0]))]).astype(np.intp)
        self.indices = np.asarray(cc, dtype=np.intp)
        self.data = np.asarray(vals, dtype=float)
        self.data.setflags(write=False)
        self._keys: tuple | None = None  # :meth:`stack`

    def nonzeros(self) -> tuple[np.ndarray, np.ndarray]:
        """``np.nonzero`` of the matrix (row-major, columns ascending in a row)."""
        return np.repeat(np.arange(self.shape[0]), np.diff(self.indptr)), self.indices

    def stack(self, R: np.ndarray, C: np.ndarray) -> np.ndarray:
        """The stack of the dense A[R[k]][:, C[k]] (R: (S, r), C: (S, c) indices): (S, r, c),
        each entry looked up among the nonzeros' sorted keys i * m + c."""
        if self._keys is None:
            rr, cc = self.nonzeros()
            keys = rr * self.shape[1] + cc
            order = np.argsort(keys, kind="stable")
            self._keys = (keys[order], self.data[order])
        keys, vals = self._keys
        q = R[:, :, None] * self.shape[1] + C[:, None, :]
        if not keys.size:
            return np.zeros(q.shape)
        at = np.minimum(np.searchsorted(keys, q), keys.size - 1)
        return np.where(keys[at] == q, vals[at], 0.0)

    def toarray(self) -> np.ndarray:
        out = np.zeros(self.shape)
        rr, cc = self.nonzeros()
        out[rr, cc] = self.data
        return out

    def sub(self, R, C) -> np.ndarray:
        """The dense submatrix of rows R x columns C (in their order)."""
        R, C = np.asarray(R, dtype=np.intp).reshape(-1), np.asarray(C, dtype=np.intp).reshape(-1)
        out = np.zeros((R.size, C.size))
        if not R.size or not C.size:
            return out
        starts = self.indptr[R]
        lens = self.indptr[R + 1] - starts
        at = np.repeat(starts - np.cumsum(lens) + lens, lens) + np.arange(int(lens.sum()))
        row = np.repeat(np.arange(R.size), lens)
        order = np.argsort(C, kind="stable")
        k = np.minimum(np.searchsorted(C[order], self.indices[at]), C.size - 1)
        hit = C[order][k] == self.indices[at]
        out[row[hit], order[k[hit]]] = self.data[at[hit]]
        return out


def _sub(A, R, C) -> np.ndarray:
    """A[R][:, C] as a dense array, A dense or :class:`_Sparse`."""
    if isinstance(A, np.ndarray):
        return A[np.ix_(list(R), list(C))]
    return A.sub(R, C)


def _gather(A, R: list, C: list) -> np.ndarray:
    """The stack of A[R[k]][:, C[k]] (each R[k] of one length, each C[k] of one length), A dense
    or :class:`_Sparse`: one gather for many small pieces of one shape."""
    R, C = np.array(R, dtype=np.intp), np.array(C, dtype=np.intp)
    if isinstance(A, np.ndarray):
        return A[R[:, :, None], C[:, None, :]]
    return A.stack(R, C)


def _nonzeros(A) -> tuple[np.ndarray, np.ndarray]:
    """``np.nonzero`` of A, dense or :class:`_Sparse`."""
    return np.nonzero(A) if isinstance(A, np.ndarray) else A.nonzeros()


def _values(A, rr: np.ndarray, cc: np.ndarray) -> np.ndarray:
    """A's values at its nonzeros (rr, cc) (for a :class:`_Sparse`, its own, in its order)."""
    return A[rr, cc] if isinstance(A, np.ndarray) else A.data


def _full(A) -> np.ndarray:
    return A if isinstance(A, np.ndarray) else A.toarray()


def _null_basis(J: np.ndarray, r: int, method: str) -> np.ndarray:
    m = J.shape[1]
    if r <= 0:
        return np.eye(m)
    if r >= m:
        return np.zeros((m, 0))
    if method == "svd":
        _, _, vh = np.linalg.svd(J, full_matrices=True)
        return vh.T[:, r:].copy()
    if method == "qr":
        q, _, _ = scipy.linalg.qr(J.T, mode="full", pivoting=True)
        return q[:, r:].copy()
    raise ValueError(f"unknown null-space method {method!r} (use 'svd' or 'qr')")


def null_space(J, rtol: float | None = None, *, method: str = "svd") -> np.ndarray:
    """Orthonormal basis (m, m - r) of ``null(J)`` of the raw ``J`` (n, m), r = ``numerical_rank(J, rtol)``.

    ``method="svd"``: the last m - r right singular vectors, ``V[:, r:]`` (App. B.11).
    ``method="qr"``: the last m - r columns of Q of the column-pivoted QR ``J^T Pi = Q R`` (B.12).
    """
    J = _as_matrix(J)
    s = _svdvals(J)
    r = int(np.count_nonzero(s > _tol_from(s, J.shape, _rtol(rtol))))
    return _null_basis(J, r, method)


def _decision_matrix(J: np.ndarray, use_equilibration: bool) -> np.ndarray:
    return equilibrate(J)[0] if use_equilibration else J


@dataclass(frozen=True, eq=False)
class Factored:
    """One factorisation of a Jacobian J (n, m), made once and read by :func:`independent_columns`
    (so :func:`auto_eliminate`) and :func:`analyse`: the raw J and the decision matrix A
    (equilibrated J, or J) held sparse (a large mechanism's J is nearly all zeros), and
    :func:`_factorise` of A with its null basis. Made by :func:`factorise`; passing it instead of
    J gives exactly the numbers passing J with the same ``rtol`` and ``equilibrate`` gives."""

    J: "_Sparse"  # the raw J
    A: "_Sparse"  # the decision matrix
    f: "_Factorisation"
    rtol: float
    equilibrate: bool

    @property
    def shape(self) -> tuple[int, int]:
        return self.A.shape

    def nonzeros(self) -> tuple[np.ndarray, np.ndarray]:
        """``np.nonzero`` of A (row-major, columns ascending in a row)."""
        return self.A.nonzeros()


def factorise(J, rtol: float | None = None, *, equilibrate: bool = True) -> Factored:
    """:class:`Factored` of ``J``: the one factorisation (with its null basis) of the decision
    matrix, for :func:`independent_columns` and :func:`analyse` to share."""
    J = _as_matrix(J)
    rr, cc = np.nonzero(J)
    return factorise_nonzeros(J.shape, rr, cc, J[rr, cc], rtol, equilibrate=equilibrate)


def factorise_nonzeros(shape: tuple[int, int], rr, cc, vals, rtol: float | None = None, *,
                       equilibrate: bool = True) -> Factored:
    """:func:`factorise` of the (n, m) matrix whose nonzeros are ``vals`` at rows ``rr`` and
    columns ``cc``, row-major (columns ascending in a row, as ``np.nonzero`` gives them): nothing
    here is n x m, the decision matrix is equilibrated and factorised on them."""
    n, m = int(shape[0]), int(shape[1])
    rr, cc = np.asarray(rr, dtype=np.intp), np.asarray(cc, dtype=np.intp)
    vals = np.asarray(vals, dtype=float)
    if not np.all(np.isfinite(vals)):
        raise ValueError("matrix contains NaN or inf")
    rt = _rtol(rtol)
    raw = _Sparse((n, m), rr, cc, vals)
    A = raw
    if equilibrate:
        keep, v, _, _ = _ruiz(rr, cc, vals, n, m)
        live = v != 0.0  # a scaled value that underflowed is a zero of the dense equilibrate's A too
        A = _Sparse((n, m), rr[keep][live], cc[keep][live], v[live])
    return Factored(J=raw, A=A, f=_factorise(A, rt, nonzeros=A.nonzeros()), rtol=rt, equilibrate=equilibrate)


def _decide(J: np.ndarray, rt: float, use_equilibration: bool) -> tuple[np.ndarray, tuple, "_Factorisation"]:
    """(decision matrix A, its nonzeros, :func:`_factorise` of A with its null basis)."""
    A = _decision_matrix(J, use_equilibration)
    nonzeros = np.nonzero(A)
    return A, nonzeros, _factorise(A, rt, nonzeros=nonzeros)


def _factored(J, rtol: float | None, equilibrate: bool) -> Factored | None:
    """``J`` itself when it is a :class:`Factored` made with this ``rtol`` (None: any) and
    ``equilibrate``, else None (the caller factorises)."""
    if not isinstance(J, Factored):
        return None
    if (rtol is not None and _rtol(rtol) != J.rtol) or equilibrate != J.equilibrate:
        raise ValueError(f"a Factored made with rtol={J.rtol}, equilibrate={J.equilibrate} was given with "
                         f"rtol={rtol}, equilibrate={equilibrate}")
    return J


def independent_columns(J, rtol: float | None = None, *, equilibrate: bool = True) -> list[int]:
    """A maximal linearly independent set of columns (equations) of ``J``, sorted, 0-based.

    From the one factorisation of the equilibrated J (raw J if ``equilibrate=False``;
    :func:`_factorise`; ``J`` may be its :class:`Factored`): every peeled column (it is in no
    dependency, so in every maximal
    independent set), and in each block of rank r_k < its width the first r_k pivots of the
    column-pivoted QR (``scipy.linalg.qr(..., pivoting=True)``) of that block (all its columns
    when r_k is its width). Blocks share no rows, so this is what the pivoted QR of the whole
    matrix picks in each block when nothing is peeled. Any maximal independent set is valid and
    the reactions of unique joints do not depend on the choice. Each block's pick is verified to
    have rank r_k (greedy fallback in pivot order otherwise).
    """
    fz = _factored(J, rtol, equilibrate)
    if fz is None:
        A = _decision_matrix(_as_matrix(J), equilibrate)
        f = _factorise(A, _rtol(rtol), vectors=False)
    else:
        A, f = fz.A, fz.f
    chosen = list(f.peeled)
    for (rows, cols), rk in zip(f.blocks, f.ranks):
        if rk == 0:
            continue
        if rk == len(cols):
            chosen += cols
            continue
        sub = _sub(A, rows, cols)
        _, piv = scipy.linalg.qr(sub, mode="r", pivoting=True)
        pick = [int(p) for p in piv[:rk]]
        if _rank_at(sub[:, pick], f.tol) != rk:  # pragma: no cover - pivoted QR failed to reveal the rank (Kahan-type matrix)
            pick = []
            for p in piv:
                if _rank_at(sub[:, pick + [int(p)]], f.tol) == len(pick) + 1:
                    pick.append(int(p))
                if len(pick) == rk:
                    break
        chosen += [cols[p] for p in pick]
    return sorted(chosen)


def _rank_at(A: np.ndarray, tol: float) -> int:
    """The count of singular values of A above the absolute ``tol`` (the one factorisation: a
    pick of a loop block's columns keeps its hubs)."""
    return _factorise(A, DEFAULT_RTOL, tol=tol, vectors=False).r


def auto_eliminate(J, rtol: float | None = None, *, equilibrate: bool = True) -> list[int]:
    """Equations an automatic elimination removes: the complement of ``independent_columns``,
    sorted, 0-based (``m - rank`` of them)."""
    fz = _factored(J, rtol, equilibrate)
    m = fz.shape[1] if fz is not None else _as_matrix(J).shape[1]
    keep = set(independent_columns(J if fz is not None else _as_matrix(J), rtol, equilibrate=equilibrate))
    return [c for c in range(m) if c not in keep]


# --------------------------------------------------------------------------- the one factorisation


#: Peeling looks at rows with at most this many live columns (a spatial body has 6 coordinates).
_PEEL_WIDTH = 6
#: Entries of the left inverse held at once when bounding ||L||_F (8 bytes each: 64 MB), and of
#: a stack of small matrices and its factors (:func:`_batches`).
_CHUNK = 1 << 23


def _batches(keys: list, cost) -> list[tuple[object, list]]:
    """[(key, positions)]: the positions of ``keys`` that share a key (a shape; None: left out),
    in order of the key's first appearance, cut into runs of at most max(1, _CHUNK // cost(key))
    positions (``cost``: the entries one item adds to a stack and its factors). The batches of
    every stacked SVD, QR, product and gather of the pre-check: LAPACK factorises each matrix of a
    stack as it does one alone, so batching changes the cost, not the numbers."""
    by: dict = {}
    for k, key in enumerate(keys):
        if key is not None:
            by.setdefault(key, []).append(k)
    out = []
    for key, idx in by.items():
        size = max(1, _CHUNK // cost(key))
        out.extend((key, idx[lo:lo + size]) for lo in range(0, len(idx), size))
    return out
#: Lanczos steps of the lower bound on ||A||_2 when something was peeled (:func:`_sigma1_bounds`).
_LANCZOS_STEPS = 100


@dataclass(frozen=True, eq=False)
class _Factorisation:
    """The one factorisation of a decision matrix A (n, m): see :func:`_factorise`.

    sigma1   ||A||_2                   tol      absolute rank threshold
    r        rank of A                 N        (m, m - r) orthonormal null basis
    sigma    the singular values computed (those of the diagonal blocks; all of A's when nothing
             was peeled or the dense route ran), descending
    kappa    sigma1 / (smallest computed singular value above tol), 1.0 if none
    peeled   columns whose null-space component is zero (coloops), in peeling order
    blocks   [(rows, cols)] of the decoupled blocks left after peeling, with each block's rank
             ``ranks`` and its right singular vectors' V^T ``vhs`` (dense route: one block, A)
    route    "blocks" or "dense" (the peeling certificate failed: one SVD of A)
    """

    sigma1: float
    tol: float
    r: int
    N: np.ndarray
    sigma: np.ndarray
    kappa: float
    peeled: tuple
    blocks: tuple
    ranks: tuple
    route: str


def _peel(A: np.ndarray, rows_of: list, cols_of: list, floor: float):
    """Peel coloops off A (n, m), given its nonzero pattern (``rows_of[c]``: rows of column c;
    ``cols_of[i]``: columns of row i).

    One step: a live row i with at most :data:`_PEEL_WIDTH` live columns C; R = the live rows
    whose live columns all lie in C; if |R| >= |C| and the smallest singular value of D = A[R, C]
    exceeds ``floor``, rows R and columns C are peeled. Repeated until no row qualifies (rows
    are visited smallest-support first, then by index: deterministic). Returns the steps
    [(R, C, D^+)] and the live row and column masks.

    Why it is exact (exact arithmetic): R's rows have nonzeros only in C and in earlier peeled
    columns, so for nu in null(A) the rows R of A nu = 0 read D nu_C + (earlier terms) = 0; the
    earlier steps' columns have nu = 0 already (induction), so D nu_C = 0, and D has full column
    rank, so nu_C = 0. Hence null(A) = {nu: nu_peeled = 0, A' nu_live = 0}, A' = A[live, live]
    (the peeled rows have no live column: a row with a live column outside C is not in R)."""
    n, m = A.shape
    order = _peel_order(n, m, rows_of, cols_of, None)  # the steps if every D has full rank
    pinvs, smallest = _pinvs(A, order, floor)
    if not all(s > floor for s in smallest):  # walk again, skipping the leaves that fail
        known = {(tuple(R), tuple(C)): (P, s) for (R, C), P, s in zip(order, pinvs, smallest)}

        def full_rank(R: list, C: list) -> bool:
            key = (tuple(R), tuple(C))
            if key not in known:
                P, s = _pinvs(A, [(R, C)], floor)
                known[key] = (P[0], s[0])
            return bool(known[key][1] > floor)

        order = _peel_order(n, m, rows_of, cols_of, full_rank)
        pinvs = [known[(tuple(R), tuple(C))][0] for R, C in order]
    live_r = np.ones(n, dtype=bool)
    live_c = np.ones(m, dtype=bool)
    for R, C in order:
        live_r[R] = False
        live_c[C] = False
    return [(R, C, P) for (R, C), P in zip(order, pinvs)], live_r, live_c


def _pinvs(A, pieces: list, floor: float) -> tuple[list, list]:
    """(D^+, the smallest singular value of D) of each D = A[R, C] of the pieces [(R, C)] (every
    D at least as tall as wide), from thin SVDs stacked by shape (:func:`_svds`); D^+ = V S^-1
    U^T, D's left inverse, made only when the smallest singular value exceeds ``floor`` (else
    None: that D is not peeled)."""
    got = _svds(A, pieces, full=False, index=True)
    pinvs, smallest = [], []
    for k in range(len(pieces)):
        u, sv, vt = got(k)
        pinvs.append((vt.T / sv) @ u.T if sv[-1] > floor else None)
        smallest.append(sv[-1])
    return pinvs, smallest


def _peel_order(n: int, m: int, rows_of: list, cols_of: list, full_rank) -> list:
    """The steps [(R, C)] of :func:`_peel` in order, from the pattern alone: a step is taken when
    ``full_rank(R, C)`` says D = A[R, C] has full column rank above the floor (None: taken;
    :func:`_peel` then checks them all at once and walks again only when one fails)."""
    import heapq

    live_r = bytearray(b"\x01") * n
    live_c = bytearray(b"\x01") * m
    count = [len(c) for c in cols_of]
    heap = [(k, i) for i, k in enumerate(count) if 0 < k <= _PEEL_WIDTH]
    heapq.heapify(heap)
    order = []
    while heap:
        k, i = heapq.heappop(heap)
        if not live_r[i] or count[i] != k:
            continue  # stale entry
        C = [c for c in cols_of[i] if live_c[c]]
        cand = sorted({j for c in C for j in rows_of[c] if live_r[j]})
        Cs = set(C)
        R = [j for j in cand if all(c in Cs for c in cols_of[j] if live_c[c])]
        if len(R) < len(C) or (full_rank is not None and not full_rank(R, C)):
            continue
        order.append((R, C))
        for j in R:
            live_r[j] = 0
        for c in C:
            live_c[c] = 0
        for c in C:
            for j in rows_of[c]:
                if live_r[j]:
                    count[j] -= 1
                    if 0 < count[j] <= _PEEL_WIDTH:
                        heapq.heappush(heap, (count[j], j))
    return order


def _svds(A, pieces, full: bool, vectors: bool = True, index: bool = False):
    """{(tuple(rows), tuple(cols)): np.linalg.svd(A[rows, cols])} for the pieces [(rows, cols)],
    one stacked (batched) SVD per shape: LAPACK factorises each matrix of a stack as it does one
    alone, so the factors are those of one SVD per piece, at the cost of one call per shape.
    ``full``: V^T square (``full_matrices`` when the piece is wider than tall, as
    :func:`_svd_full` takes it), else the thin SVD; ``vectors=False``: (None, s, None), the
    singular values alone (as :func:`_svdvals`). Pieces with no rows or columns are left out.
    ``index``: a function of the piece's position in ``pieces`` instead of the dict (no entry
    per piece held: the peeling of a long chain has one piece per body)."""
    keys = [(len(rows), len(cols)) if len(rows) and len(cols) else None for rows, cols in pieces]
    stacks, where = [], [None] * len(pieces)
    for (nr, nc), part in _batches(keys, lambda key: key[0] * key[1] + key[0] ** 2 + key[1] ** 2):
        stack = _gather(A, [pieces[k][0] for k in part], [pieces[k][1] for k in part])
        if vectors:
            stacks.append(np.linalg.svd(stack, full_matrices=full and nc > nr))
        else:
            stacks.append((None, np.linalg.svd(stack, compute_uv=False), None))
        for j, k in enumerate(part):
            where[k] = (len(stacks) - 1, j)

    def at(k: int) -> tuple:
        g, j = where[k]
        u, s, vh = stacks[g]
        return (None if u is None else u[j], s[j], None if vh is None else vh[j])

    if index:
        return at
    return {(tuple(rows), tuple(cols)): at(k) for k, (rows, cols) in enumerate(pieces) if where[k] is not None}


def _left_inverse_bound(A: np.ndarray, steps: list, cols_of: list) -> float:
    """An upper bound of ||L||_F (L: :func:`_left_inverse_norm`) from row norms, in one pass: row
    k of a step's block of L is row k of D^+ E minus sum_p (D^+ X)_kp times the rows of the
    earlier columns p it touches, so its norm is at most ||(D^+)_k|| + sum_p |(D^+ X)_kp| l_p,
    l_p the earlier rows' bounds (triangle inequality). Exact for a single step; on a chain of
    equal links it grows like the chain's length, where the exact norm costs p_r x p_c."""
    prevs = []
    for R, C, _ in steps:
        Cs = set(C)
        prevs.append(sorted({c for i in R for c in cols_of[i] if c not in Cs}))
    # what does not depend on the earlier bounds, batched by shape: ||(D^+)_k|| and |D^+ X|
    norms: list = [None] * len(steps)
    px: list = [None] * len(steps)
    keys = [(P.shape, len(prevs[k])) for k, (_, _, P) in enumerate(steps)]
    for ((nc, nr), npv), part in _batches(keys, lambda key: key[0][0] * key[0][1] + sum(key[0]) * key[1]):
        P = np.stack([steps[k][2] for k in part])
        rows = np.sqrt(np.sum(P * P, axis=2))
        PX = np.abs(P @ _gather(A, [steps[k][0] for k in part], [prevs[k] for k in part])) if npv else None
        for j, k in enumerate(part):
            norms[k] = rows[j]
            px[k] = PX[j] if npv else None
    bound: dict[int, float] = {}
    for k, (_, C, _) in enumerate(steps):
        rows = norms[k]
        if prevs[k]:
            rows = rows + px[k] @ np.array([bound[c] for c in prevs[k]])
        for c, b in zip(C, rows.tolist()):
            bound[c] = b
    return float(np.sqrt(sum(b * b for b in bound.values())))


def _left_inverse_norm(A: np.ndarray, steps: list, cols_of: list) -> float:
    """||L||_F of the left inverse L of B = A[peeled rows, peeled columns] by block forward
    substitution: nu_C = D^+ (y_R - A[R, earlier columns] nu_earlier), step by step (B is block
    lower triangular in peeling order and each D has full column rank, so L B = I). Then
    sigma_min(B) >= 1 / ||L||_2 >= 1 / ||L||_F. Applied to the identity, at most :data:`_CHUNK`
    entries of L at once; the columns of a chunk are zero before the step of their row."""
    col_pos: dict[int, int] = {}
    row_pos: dict[int, int] = {}
    for R, C, _ in steps:
        for c in C:
            col_pos[c] = len(col_pos)
        for i in R:
            row_pos[i] = len(row_pos)
    plan = []
    for R, C, P in steps:
        Cs = set(C)
        prev = sorted({c for i in R for c in cols_of[i] if c not in Cs})
        plan.append((np.array([row_pos[i] for i in R]), np.array([col_pos[c] for c in C]), P,
                     [col_pos[c] for c in prev], _sub(A, R, prev) if prev else None))
    p_r, p_c = len(row_pos), len(col_pos)
    width = max(1, min(p_r, _CHUNK // max(p_c, 1)))
    total = 0.0
    for start in range(0, p_r, width):
        w = min(width, p_r - start)
        nu = np.zeros((p_c, w))
        hi = 0  # columns [hi, w) of the chunk are still zero (their rows come in later steps)
        for rpos, cpos, P, prev, X in plan:
            inside = (rpos >= start) & (rpos < start + w)
            if inside.any():
                hi = max(hi, int(rpos[inside].max()) - start + 1)
            if hi == 0:
                continue
            y = np.zeros((len(rpos), hi))
            y[np.flatnonzero(inside), rpos[inside] - start] = 1.0
            if X is not None:
                y -= X @ nu[prev, :hi]
            nu[cpos, :hi] = P @ y
        total += float(np.sum(nu * nu))
    return float(np.sqrt(total))


def _sigma1_bounds(A, rr: np.ndarray, cc: np.ndarray) -> tuple[float, float]:
    """Bounds lo <= ||A||_2 <= hi from A's nonzeros (rows rr, columns cc). lo = ||A y|| for the
    unit Ritz vector y of the largest Ritz value of :data:`_LANCZOS_STEPS` Lanczos steps on
    A^T A from (1, ..., 1) (full reorthogonalisation; any unit y gives a lower bound, the Ritz
    vector a close one even when the top of the spectrum is clustered, as in a chain of equal
    links); hi = min(||A||_F, sqrt(||A||_1 ||A||_inf)) (both are upper bounds)."""
    import scipy.sparse

    n, m = A.shape
    vals = _values(A, rr, cc)
    S = scipy.sparse.csr_matrix((vals, (rr, cc)), shape=(n, m))
    St = S.T.tocsr()
    k = min(m, _LANCZOS_STEPS)
    Q = np.zeros((m, k))
    alpha, beta = np.zeros(k), np.zeros(k)
    q = np.ones(m) / np.sqrt(m)
    used = 0
    for j in range(k):
        Q[:, j] = q
        used = j + 1
        w = St @ (S @ q)
        alpha[j] = float(q @ w)
        for _ in range(2):  # full reorthogonalisation, twice is enough
            w -= Q[:, :used] @ (Q[:, :used].T @ w)
        beta[j] = float(np.linalg.norm(w))
        if beta[j] <= EPS * max(abs(alpha[j]), 1.0) or used == k:
            break
        q = w / beta[j]
    T = np.diag(alpha[:used]) + np.diag(beta[:used - 1], 1) + np.diag(beta[:used - 1], -1)
    _, vecs = np.linalg.eigh(T)
    y = Q[:, :used] @ vecs[:, -1]
    lo = float(np.linalg.norm(S @ y)) / float(np.linalg.norm(y))
    a = np.abs(vals)
    norm1 = float(np.bincount(cc, a, minlength=m).max())
    norminf = float(np.bincount(rr, a, minlength=n).max())
    hi = min(float(np.sqrt(np.sum(a * a))), float(np.sqrt(norm1 * norminf)))
    return lo, max(lo, hi)


def _factorise(A: np.ndarray, rtol: float, tol: float | None = None, vectors: bool = True,
               nonzeros: tuple | None = None) -> _Factorisation:
    """Rank, null basis and singular values of A (n, m) from its structure, exactly as one dense
    SVD of A decides them (the SVD test, B.11), at the cost of the structure's blocks.

    1. Peel (:func:`_peel`): columns whose null-space component is zero in exact arithmetic (a
       leaf body held by a joint of full rank on its coordinates, and everything that becomes a
       leaf when it is gone; a tree mechanism peels whole).
    2. Split what is left, A' = A[live rows, live columns], into the connected components of its
       row-column graph (two equations are coupled when they share a coordinate). A' is block
       diagonal after permutation, so its singular values are the union of the blocks' and its
       null space the direct sum of theirs. One dense SVD per block (LAPACK gesdd, full V), but
       a block with hub rows goes through them (:func:`_hub`, :meth:`_Hub.finish`).
    3. The threshold is the SVD test's, ``tol = max(rtol, max(n, m) * eps) * ||A||_2``, with
       ||A||_2 of the whole A (when anything was peeled or went through hubs, the lower bound lo
       of :func:`_sigma1_bounds`, 7e-5 low at worst on a long chain of equal links, else exactly
       the largest block singular value), applied to every block: the rank is the number of
       peeled columns plus the blocks' ranks; the null basis is the blocks' (:func:`_assemble`),
       zero on the peeled columns.

    The certificate (why the verdicts are those of one SVD of A, with the tolerance): write
    A = [[B, 0], [X, A']] (peeled rows and columns first). A null-ish vector of A'
    (||A' v|| <= tol ||v||) padded with zeros is one of A, so A has at least as many singular
    values <= tol as A'. Conversely, if ||A nu|| <= tol ||nu||, then ||nu_B|| <= tol ||nu|| /
    beta (beta = sigma_min(B)) and ||A' nu'|| <= c tol ||nu'|| with c = (1 + ||X|| / beta) / (1 -
    tol / beta), so A has at most as many as A' has <= c tol. Both counts agree unless A' has a
    singular value in (tol, c tol], or beta <= tol. With ||A||_2 known only within [lo, hi],
    the dense tolerance lies in [tol_lo, tol_hi] and the certificate is: beta > tol_hi and no
    singular value of A' in (tol_lo, T], T = c(tol_hi) tol_hi (through hubs: :meth:`_Hub.finish`).
    beta >= 1 / ||L||_F (:func:`_left_inverse_bound`, else the exact :func:`_left_inverse_norm`)
    and ||X||_2 <= ||X||_F make c computable; when the certificate fails, the dense route runs:
    one SVD of the whole A (the previous method). With ranks equal, the two null spaces are the
    same in exact arithmetic; numerically each is accurate to its own round-off bound (``kappa``
    here is that of the computed blocks, Wedin's bound for the basis computed). ``A``: dense or
    :class:`_Sparse`; ``nonzeros``: ``np.nonzero(A)`` when the caller has it."""
    n, m = A.shape
    rr, cc = _nonzeros(A) if nonzeros is None else nonzeros  # row-major order
    if rr.size == 0:
        return _Factorisation(sigma1=0.0, tol=0.0 if tol is None else float(tol), r=0, N=np.eye(m),
                              sigma=np.zeros(min(n, m)), kappa=1.0, peeled=(), blocks=(), ranks=(),
                              route="blocks")
    rtol_eff = max(rtol, max(n, m) * EPS)
    rows_of, cols_of = _pattern(rr, cc, n, m)
    # ||A||_F >= ||A||_2, so this floor is at least tol: a peeled D is of full rank above tol
    floor = float(tol) if tol is not None else rtol_eff * float(np.sqrt(np.sum(_values(A, rr, cc) ** 2)))
    steps, live_r, live_c = _peel(A, rows_of, cols_of, floor)
    blocks = _blocks(A, live_r, live_c, rr, cc)
    parts = _block_parts(A, blocks, rows_of, cols_of, live_c, vectors)
    hubs = [b for b, p in enumerate(parts) if isinstance(p, _Hub)]
    top = max((float(s[0]) for p in parts for s in (p.sigmas() if isinstance(p, _Hub) else [p[0]]) if s.size),
              default=0.0)
    if tol is None:
        lo, hi = _sigma1_bounds(A, rr, cc) if steps or hubs else (top, top)
        sigma1 = max(lo, top)
        t, t_hi = rtol_eff * sigma1, rtol_eff * max(hi, top)
    else:
        sigma1, t = float("nan"), float(tol)
        t_hi = t
    T = _peel_margin(A, rr, cc, steps, cols_of, t_hi) if steps else t_hi
    if T is not None:
        for b in hubs:
            parts[b] = parts[b].finish(A, blocks[b][1], t, T) or _block_svd(A, *blocks[b], vectors)
    dense = [p for p in parts if not isinstance(p, _HubFactors)]
    route = "blocks" if T is not None and not any(np.any((s > t) & (s <= T)) for s, _ in dense) else "dense"
    if route == "dense":
        s, vh = _svd_full(_full(A)) if vectors else (_svdvals(_full(A)), None)
        if tol is None:
            sigma1 = float(s[0]) if s.size else 0.0
            t = rtol_eff * sigma1
        blocks = ((tuple(range(n)), tuple(range(m))),)
        parts, steps = [(s, vh)], []
    peeled = tuple(c for _, C, _ in steps for c in C)
    ranks, N, sigma = _assemble(blocks, parts, t, m, vectors)
    r = len(peeled) + sum(ranks)
    above = sigma[sigma > t]
    kappa = float(sigma1 / above[-1]) if above.size and np.isfinite(sigma1) else 1.0
    return _Factorisation(sigma1=sigma1, tol=t, r=r, N=N, sigma=sigma, kappa=kappa, peeled=peeled,
                          blocks=tuple(blocks), ranks=tuple(ranks), route=route)


def _block_parts(A, blocks: list, rows_of: list, cols_of: list, live_c: np.ndarray, vectors: bool) -> list:
    """Per block: a :class:`_Hub` (:func:`_hub`), or its dense SVD (s, V^T or None), the dense
    SVDs stacked by shape (:func:`_block_svds`)."""
    parts = [_hub(A, rows, cols, rows_of, cols_of, live_c) for rows, cols in blocks]
    dense = iter(_block_svds(A, [b for b, p in zip(blocks, parts) if p is None], vectors))
    return [p if p is not None else next(dense) for p in parts]


def _assemble(blocks, parts, t: float, m: int, vectors: bool):
    """(each block's rank, the null basis (m, m - r) on the blocks' columns, the singular values
    computed, descending) from the blocks' factors: a dense SVD (s, V^T) or :class:`_HubFactors`."""
    ranks, nulls, sigmas = [], [], []
    for (_, cols), p in zip(blocks, parts):
        if isinstance(p, _HubFactors):
            rk, null, s = p.rank, p.N, p.sigma
        else:
            s, vh = p
            rk = int(np.count_nonzero(s > t))
            null = vh.T[:, rk:] if vectors and len(cols) > rk else None
        ranks.append(rk)
        sigmas.append(s)
        if vectors and len(cols) > rk:
            part = np.zeros((m, len(cols) - rk))
            part[list(cols), :] = null
            nulls.append(part)
    N = np.hstack(nulls) if nulls else np.zeros((m, 0))
    return ranks, N, np.sort(np.concatenate([np.zeros(0)] + sigmas))[::-1]


def _pattern(rr: np.ndarray, cc: np.ndarray, n: int, m: int) -> tuple[list, list]:
    """(rows of each column, columns of each row) of the nonzeros at (rr, cc), each list in the
    order the nonzeros come."""
    rr, cc = np.asarray(rr, dtype=np.intp), np.asarray(cc, dtype=np.intp)

    def split(key: np.ndarray, other: np.ndarray, size: int) -> list:
        order = np.argsort(key, kind="stable")
        ptr = np.concatenate([[0], np.cumsum(np.bincount(key, minlength=size))]).tolist()
        vals = other[order].tolist()
        return [vals[ptr[k]:ptr[k + 1]] for k in range(size)]

    return split(cc, rr, m), split(rr, cc, n)


def _peel_margin(A, rr, cc, steps, cols_of, t_hi) -> float | None:
    """T = c t_hi of the certificate of :func:`_factorise`, c = (1 + ||X||_F / beta) / (1 - t_hi
    / beta), beta = 1 / (a bound of ||L||_F); None when beta <= t_hi (the certificate fails)."""
    n, m = A.shape
    beta = 1.0 / _left_inverse_bound(A, steps, cols_of)
    if not beta > 2.0 * t_hi:  # the one-pass bound is too loose here: the exact ||L||_F
        beta = 1.0 / _left_inverse_norm(A, steps, cols_of)
    if not beta > t_hi:
        return None
    peeled_c = np.zeros(m, dtype=bool)
    peeled_r = np.zeros(n, dtype=bool)
    for R, C, _ in steps:
        peeled_c[C] = True
        peeled_r[R] = True
    sel = peeled_c[cc] & ~peeled_r[rr]  # X = A[rows left, peeled columns]
    x_f = float(np.sqrt(np.sum(_values(A, rr, cc)[sel] ** 2)))
    return (1.0 + x_f / beta) / (1.0 - t_hi / beta) * t_hi


def _blocks(A: np.ndarray, live_r: np.ndarray, live_c: np.ndarray, rr: np.ndarray, cc: np.ndarray) -> list:
    """Connected components [(rows, cols)] of the live rows and columns of A (an edge per
    nonzero, at rows rr and columns cc), in order of their smallest column; a live column with no
    live row is a block of its own (0 rows)."""
    n, m = A.shape
    cols = np.flatnonzero(live_c)
    if cols.size == 0:
        return []
    edge = live_c[cc] & live_r[rr]
    label = _components(n + m, rr[edge], n + cc[edge]).tolist()
    groups: dict[int, tuple[list, list]] = {}
    for c in cols.tolist():
        groups.setdefault(label[n + c], ([], []))[1].append(c)
    for i in np.flatnonzero(live_r).tolist():
        if label[i] in groups:
            groups[label[i]][0].append(i)
    return [(tuple(rows), tuple(bcols)) for rows, bcols in groups.values()]


def _components(nodes: int, a, b) -> np.ndarray:
    """The connected component label of each of ``nodes`` nodes joined by the edges (a[k], b[k])."""
    import scipy.sparse
    import scipy.sparse.csgraph

    a, b = np.asarray(a, dtype=int), np.asarray(b, dtype=int)
    g = scipy.sparse.coo_matrix((np.ones(a.size), (a, b)), shape=(nodes, nodes))
    return scipy.sparse.csgraph.connected_components(g, directed=False)[1]


def _block_svd(A: np.ndarray, rows, cols, vectors: bool = True) -> tuple:
    """The dense SVD of A[rows, cols]: singular values, and V^T if ``vectors`` (else None)."""
    return _block_svds(A, [(rows, cols)], vectors)[0]


def _block_svds(A: np.ndarray, pieces: list, vectors: bool = True) -> list:
    """:func:`_block_svd` of each piece (rows, cols), the SVDs batched by shape (:func:`_svds`)."""
    got = _svds(A, pieces, full=True, vectors=vectors)
    out = []
    for rows, cols in pieces:
        if not len(rows):
            out.append((np.zeros(0), np.eye(len(cols))))
        elif not len(cols):
            out.append((np.zeros(0), np.eye(0) if vectors else None))
        else:
            _, s, vh = got[(tuple(rows), tuple(cols))]
            out.append((s, vh))
    return out


#: A row (coordinate) of a block touched by more than this many equations is a hub: a body that
#: many joints share (the coupler on k planar cranks: 2k equations), set aside by :func:`_hub`.
#: 12 is two full spatial joints: a body of an ordinary loop (two or three joints) is no hub.
_HUB_DEGREE = 12


@dataclass(frozen=True, eq=False)
class _HubFactors:
    """A block factorised through its hubs (:meth:`_Hub.finish`): rank, null basis (the block's
    columns x its nullity) and the singular values computed (its parts' above tol, the hub
    rows' matrix G's)."""

    rank: int
    N: np.ndarray
    sigma: np.ndarray


@dataclass(frozen=True, eq=False)
class _Hub:
    """A block with hub rows S (:func:`_hub`): the parts [(rows_k, cols_k)] the block falls into
    without S, each with its dense SVD (s_k, V_k^T)."""

    S: tuple
    parts: tuple
    svds: tuple

    def sigmas(self) -> list:
        return [s for s, _ in self.svds]

    def finish(self, A: np.ndarray, cols: tuple, t: float, T: float) -> _HubFactors | None:
        """The block's rank and null basis at the threshold t, or None when the certificate
        cannot show them to be one dense SVD's of the block for every threshold in [t, T].

        With V = diag(V_k) (orthogonal), A_b V = [[D, E], [F, G]] (rows: the parts', then S;
        columns: each part's right singular vectors above t, then those at or below): D =
        diag(U_k Sigma_k) of full column rank, beta = sigma_min(D) its parts' smallest singular
        value above t; E the parts' singular values at or below t, ||E||_2 = e; F, G = A[S, C_k]
        V_k. In exact arithmetic with E = 0, null(A_b) = diag(V_k null) null(G) (D x = 0 forces
        x = 0) and rank = sum rank_k + rank(G). Numerically (Weyl, then the argument of
        :func:`_factorise` with B = D, X = F, A' = G): for tau in [t, T] the count of singular
        values of A_b <= tau lies between G's count <= t - e and G's count <= c (T + e), c = (1
        + ||F|| / beta) / (1 - (T + e) / beta); the certificate is beta > T + e and no singular
        value of G in (t - e, c (T + e)]. ||F||_2 <= ||A[S, block]||_F."""
        pos = {c: p for p, c in enumerate(cols)}
        rank, e, beta, nulls, g_parts = 0, 0.0, np.inf, [], []
        S = list(self.S)
        for (_, cols_k), (s, vh) in zip(self.parts, self.svds):
            rk = int(np.count_nonzero(s > t))
            rank += rk
            if rk:
                beta = min(beta, float(s[rk - 1]))
            if s.size > rk:
                e = max(e, float(s[rk]))
            vn = vh.T[:, rk:]
            nulls.append(vn)
            g_parts.append(_sub(A, S, cols_k) @ vn)
        G = np.hstack(g_parts)
        s_g, vh_g = _svd_full(G)
        r_g = int(np.count_nonzero(s_g > t))
        if not beta > T + e:
            return None
        c = 1.0 if np.isinf(beta) else (1.0 + _frobenius(A, S, cols) / beta) / (1.0 - (T + e) / beta)
        if np.any((s_g > t - e) & (s_g <= c * (T + e))):
            return None
        n_g = vh_g.T[:, r_g:]
        N = np.zeros((len(cols), n_g.shape[1]))
        at = 0
        for (_, cols_k), vn in zip(self.parts, nulls):
            N[[pos[c] for c in cols_k], :] = vn @ n_g[at:at + vn.shape[1]]
            at += vn.shape[1]
        above = [s[s > t] for s, _ in self.svds]
        return _HubFactors(rank=rank + r_g, N=N, sigma=np.concatenate(above + [s_g]))


def _frobenius(A: np.ndarray, rows: list, cols) -> float:
    return float(np.sqrt(np.sum(_sub(A, rows, cols) ** 2)))


def _hub(A: np.ndarray, rows: tuple, cols: tuple, rows_of: list, cols_of: list, live_c: np.ndarray) -> _Hub | None:
    """The block (rows, cols) as a :class:`_Hub`: S = its rows with more than :data:`_HUB_DEGREE`
    live columns, and the parts its other rows and its columns fall into without S (a column
    touching S alone is a part of its own, with no rows), each with its dense SVD; None when no
    row is a hub or some part keeps more than half the block's columns (nothing to gain)."""
    S = [i for i in rows if sum(1 for c in cols_of[i] if live_c[c]) > _HUB_DEGREE]
    if not S or len(cols) < 4:
        return None
    hub_rows = set(S)
    rest = [i for i in rows if i not in hub_rows]
    rpos = {i: k for k, i in enumerate(rest)}
    base = len(rest)
    edges = [(rpos[i], base + k) for k, c in enumerate(cols) for i in rows_of[c] if i in rpos]
    label = _components(base + len(cols), [a for a, _ in edges], [b for _, b in edges])
    groups: dict[int, tuple[list, list]] = {}
    for k, c in enumerate(cols):
        groups.setdefault(int(label[base + k]), ([], []))[1].append(c)
    for i in rest:
        groups[int(label[rpos[i]])][0].append(i)  # every row of the block has a column in it
    parts = tuple((tuple(r), tuple(c)) for r, c in groups.values())
    if len(parts) < 2 or max(len(c) for _, c in parts) > len(cols) // 2:
        return None
    return _Hub(S=tuple(S), parts=parts, svds=tuple(_block_svds(A, list(parts))))


# --------------------------------------------------------------------------- verdict types


@dataclass(frozen=True, eq=False)
class JointVerdict:
    """Uniqueness of one joint's generalized reaction ``f_P = J_P lam_P``.

    unique        agreed verdict; follows the rank method if the methods disagree (the SVD test
                  when it ran alone)
    methods       {"rank": bool, "svd": bool, "qr": bool} (True = unique): the tests that ran
                  (``methods="svd"``: the SVD test only)
    rank_defect   rank(J_P) + rank(J_-P) - rank(J) (B.10); > 0 means not unique (without the
                  rank test: the same number from the one factorisation, :func:`_b_defect`)
    B_svd         (n, m - r) ``J_P V_P[:, r:]`` from the raw J (B.11), in J's units (None
                  unless ``methods="all"``: it needs a second SVD)
    B_qr          (n, m - r) ``J_P Q_P[:, r:]`` from the raw J (B.12) (None unless "all")
    agree         all three methods give the same answer
    columns       the joint's columns, as given
    rank_P        rank(J_P); ``lam_P`` itself is unique only if unique and rank_P == len(columns)
    b_ratio_svd   max row norm of the decision B_P / (b_rtol * sigma_1); <= 1 means B_P == 0
    b_ratio_qr    the same for the QR basis
    """

    unique: bool
    methods: dict
    rank_defect: int
    B_svd: np.ndarray | None = field(repr=False)
    B_qr: np.ndarray | None = field(repr=False)
    agree: bool
    columns: tuple = ()
    rank_P: int = 0
    b_ratio_svd: float = 0.0
    b_ratio_qr: float = 0.0


@dataclass(frozen=True, eq=False)
class SetVerdict:
    """Uniqueness of the reactions of a set K of joints (Eq. 17).

    unique        agreed verdict (follows the rank form of Eq. 17 on disagreement)
    methods       {"rank": Eq. 17 by ranks, "svd": every member's B_svd == 0, "qr": every B_qr == 0}
    rank_defect   sum_i rank(J_Pi) + rank(J_Y) - rank(J)
    agree         the three agree (they are mathematically equivalent)
    names         the members, in the order given
    """

    unique: bool
    methods: dict
    rank_defect: int
    agree: bool
    names: tuple = ()


@dataclass(frozen=True, eq=False)
class _Context:
    J: object  # raw, for the reported B matrices (dense with the cross-check, else sparse: its shape)
    A: object  # matrix the decisions are made on (equilibrated J, or J): dense, or _Sparse without the cross-check
    sigma: np.ndarray  # singular values of A reported (all of them with the cross-check)
    tol: float  # absolute rank threshold on A
    r: int  # rank of A (the rank test's, from one SVD of A, with the cross-check)
    b_rtol: float  # the B_P == 0 threshold of the SVD test, relative to sigma1
    N_svd: np.ndarray  # null basis of A from the one factorisation (the SVD test)
    sigma1: float = 0.0  # ||A||_2
    qr_b_rtol: float = 0.0  # the QR test's threshold (from the dense SVD's kappa)
    route: str = "blocks"  # the one factorisation's route (_Factorisation.route)
    methods: tuple = _METHODS  # the tests run (METHOD_SETS)
    _lazy: dict = field(default_factory=dict)  # the other bases, computed once when a method needs them

    def block(self, cols) -> np.ndarray:
        """A[:, cols] without its zero rows (the rows no column of ``cols`` touches): the same
        singular values, R factor and B row norms, at the size of the joint, not of the mechanism."""
        return self.blocks([cols])[0]

    def blocks(self, groups: Sequence) -> list:
        """:meth:`block` of each group of columns in ``groups``, the rows of all groups found at
        once from the column-sorted nonzeros."""
        if "col_rows" not in self._lazy:
            rr, cc = self._lazy["nonzeros"] if "nonzeros" in self._lazy else np.nonzero(self.A)
            order = np.argsort(cc, kind="stable")
            self._lazy["col_rows"] = (rr[order], np.searchsorted(cc[order], np.arange(self.A.shape[1] + 1)))
        rows_sorted, ptr = self._lazy["col_rows"]
        n = self.A.shape[0]
        cols = [np.asarray(list(g), dtype=np.intp) for g in groups]
        flat = np.concatenate([np.zeros(0, np.intp)] + cols)
        owner = np.repeat(np.arange(len(cols)), [c.size for c in cols])
        lens = ptr[flat + 1] - ptr[flat]
        at = np.repeat(ptr[flat] - np.cumsum(lens) + lens, lens) + np.arange(int(lens.sum()))
        key = np.unique(np.repeat(owner, lens) * n + rows_sorted[at])  # (group, row) pairs, sorted
        split = np.searchsorted(key // n if key.size else key, np.arange(len(cols) + 1))
        rows = key % n if key.size else key
        pieces = [(rows[split[g]:split[g + 1]], cols[g]) for g in range(len(cols))]
        out: list = [None] * len(pieces)
        keys = [(r.size, c.size) for r, c in pieces]
        for (nr, nc), part in _batches(keys, lambda key: max(1, key[0] * key[1])):  # a joint's block is small
            if nr * nc > _CHUNK:  # a block too large to stack (a group of many columns): one at a time
                out[part[0]] = _sub(self.A, *pieces[part[0]])
                continue
            stack = _gather(self.A, [pieces[g][0] for g in part], [pieces[g][1] for g in part])
            for g, b in zip(part, stack):
                out[g] = b
        return out

    @property
    def cross_check(self) -> bool:
        """The rank and QR tests run too (``methods="all"``)."""
        return "rank" in self.methods

    def basis(self, key: str) -> np.ndarray:
        """``"qr"``: the QR null basis of A; ``"svd_raw"``/``"qr_raw"``: those of the raw J (reports)."""
        if key not in self._lazy:
            matrix = self.A if key == "qr" else self.J
            self._lazy[key] = _null_basis(matrix, self.r, key.removesuffix("_raw"))
        return self._lazy[key]


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _method_set(methods: str) -> tuple:
    if methods not in METHOD_SETS:
        raise ValueError(f"methods must be one of {sorted(METHOD_SETS)}, got {methods!r}")
    return METHOD_SETS[methods]


def _b_rtol(rt: float, shape: tuple[int, int], kappa: float) -> float:
    return max(rt, B_NOISE_FACTOR * max(shape) * EPS * kappa)


def _context(J, rtol, b_rtol, use_equilibration: bool, methods: str = "all") -> _Context:
    """The one factorisation of the decision matrix (:func:`_factorise`: the SVD test's null
    basis; ``J`` may be its :class:`Factored`), and with the cross-check (``methods="all"``) one
    dense SVD of it for the rank and QR tests' rank, tolerance and kappa."""
    run = _method_set(methods)
    fz = _factored(J, rtol, use_equilibration)
    if fz is None:
        J = _as_matrix(J)
        # the raw J is read again only by the cross-check's reports, or as A when not equilibrated
        J = _readonly(J.copy() if "rank" in run or not use_equilibration else J.view())
        rt = _rtol(rtol)
        A, nonzeros, f = _decide(J, rt, use_equilibration)
        A = _readonly(A)  # a new array, or the read-only J itself
    else:
        rt, f, nonzeros = fz.rtol, fz.f, fz.nonzeros()
        # dense only for the cross-check (its dense SVDs and reports); the SVD test gathers
        J = _readonly(fz.J.toarray()) if "rank" in run else fz.J
        A = J if not use_equilibration else _readonly(fz.A.toarray()) if "rank" in run else fz.A
    brt = _b_rtol(rt, A.shape, f.kappa) if b_rtol is None else _rtol(b_rtol, "b_rtol")
    sigma, tol, r, qr_brt = f.sigma, f.tol, f.r, brt
    if "rank" in run:
        sigma = _svdvals(A)
        tol = _tol_from(sigma, A.shape, rt)
        r = int(np.count_nonzero(sigma > tol))
        if b_rtol is None:
            qr_brt = _b_rtol(rt, A.shape, float(sigma[0] / sigma[r - 1]) if r > 0 else 1.0)
    return _Context(J=J, A=A, sigma=_readonly(np.array(sigma, dtype=float)), tol=tol, r=r, b_rtol=brt,
                    N_svd=_readonly(f.N), sigma1=f.sigma1, qr_b_rtol=qr_brt, route=f.route, methods=run,
                    _lazy={"nonzeros": nonzeros})


def _svd_full(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Singular values and V^T (m, m) of A from one dense SVD (a block of the one factorisation,
    or the whole A on its dense route)."""
    n, m = A.shape
    if A.size == 0:
        return np.zeros(0), np.eye(m)
    _, s, vh = np.linalg.svd(A, full_matrices=m > n)  # V is complete either way; U only as wide as needed
    return s, vh


def _check_columns(columns: Iterable[int], m: int, what: str = "columns") -> tuple[int, ...]:
    if isinstance(columns, (str, bytes)):
        raise TypeError(f"{what}: expected a sequence of column indices, got {columns!r}")
    cols = []
    for c in columns:
        if isinstance(c, (bool, np.bool_)) or not isinstance(c, (int, np.integer)):
            raise TypeError(f"{what}: column indices must be integers, got {c!r}")
        c = int(c)
        if not 0 <= c < m:
            raise ValueError(f"{what}: column index {c} out of range for {m} equations")
        cols.append(c)
    if len(set(cols)) != len(cols):
        raise ValueError(f"{what}: duplicate column indices {cols}")
    return tuple(cols)


def _B(M: np.ndarray, N: np.ndarray, cols: tuple[int, ...]) -> np.ndarray:
    idx = list(cols)
    if not idx:
        return _readonly(np.zeros((M.shape[0], N.shape[1])))
    return _readonly(M[:, idx] @ N[idx, :])


def _peak(B: np.ndarray) -> float:
    """The largest row 2-norm of B (0.0 for an empty B)."""
    return float(np.linalg.norm(B, axis=1).max()) if B.size else 0.0


def _b_ratio(ctx: _Context, peak: float, test: str = "svd") -> float:
    """B's largest row norm ``peak`` (:func:`_peak`) over the B_P == 0 threshold of ``test``."""
    limit = ctx.b_rtol * ctx.sigma1 if test == "svd" else ctx.qr_b_rtol * (float(ctx.sigma[0]) if ctx.sigma.size else 0.0)
    if peak == 0.0:
        return 0.0
    return peak / limit if limit > 0.0 else float("inf")


def _rank_defect(ctx: _Context, member_columns: Sequence[tuple[int, ...]]) -> int:
    """sum_i rank(A_Pi) + rank(A_rest) - rank(A), all with the same absolute tolerance."""
    m = ctx.A.shape[1]
    in_k = np.zeros(m, dtype=bool)
    total = 0
    for cols in member_columns:
        in_k[list(cols)] = True
        total += _rank_abs(ctx.block(cols), ctx.tol)
    return total + _rank_abs(ctx.A[:, ~in_k], ctx.tol) - ctx.r


def _b_defect(ctx: _Context, cols: tuple[int, ...], unique: bool) -> int:
    """rank_defect from the one factorisation (:func:`_b_defects` of one group of columns)."""
    return _b_defects(ctx, [cols], [unique])[0]


def _b_defects(ctx: _Context, groups: Sequence, unique: Sequence[bool], blocks: list | None = None) -> list:
    """rank_defect from the one factorisation, for each group of columns in ``groups``:
    rank(A_P N) = rank(A_P) + rank(A_-P) - rank(A) in exact arithmetic (both are
    dim(span(A_P) & span(A_-P)): a null vector nu gives A_P nu_P in it, and one whose A_P nu_P =
    0 also has A_-P nu_-P = 0). Numerically: 0 when the B test says unique, else the count of B =
    A_P N_P's singular values above its threshold (at least 1), taken from R N_P with A_P = Q R
    (thin QR: Q has orthonormal columns, so the singular values are B's; the SVD is of a |P| x
    (m - r) matrix, not of n x (m - r), which keeps the pre-check one factorisation of J plus
    small work per joint). The QRs and SVDs are batched by shape (each matrix of a stack is
    factorised as it is alone); ``blocks``: the groups' :meth:`_Context.block` when the caller
    has them."""
    out = [0] * len(groups)
    todo = [g for g, u in enumerate(unique) if not u]
    if not todo:
        return out
    limit = ctx.b_rtol * ctx.sigma1
    got = ctx.blocks([groups[g] for g in todo]) if blocks is None else [blocks[g] for g in todo]
    k_null = ctx.N_svd.shape[1]
    def cost(shape):  # a stack's entries: the blocks and their R N_P
        return max(1, shape[0] * shape[1] + shape[1] * max(k_null, shape[1]))

    for _, part in _batches([b.shape for b in got], cost):
        R = np.linalg.qr(_stacked([got[k] for k in part]), mode="r")
        N = ctx.N_svd[np.array([list(groups[todo[k]]) for k in part], dtype=np.intp)]
        s = _svdvals(R @ N) if k_null else np.zeros((len(part), 0))
        for k, sv in zip(part, s):
            out[todo[k]] = max(1, int(np.count_nonzero(sv > limit)))
    return out


def _stacked(arrays: list) -> np.ndarray:
    """The arrays (of one shape) as one stack; one alone is viewed as a stack, not copied (the
    block of a large set of joints)."""
    return arrays[0][None] if len(arrays) == 1 else np.stack(arrays)


def _joints(ctx: _Context, checked: Mapping[str, tuple[int, ...]]) -> dict:
    """{name: JointVerdict} of the joints (name -> columns): the SVD test for all joints at once
    (each joint's block A_P, its B_P = A_P N_P row norms and rank(A_P) batched by shape), the
    rank comparison and QR test joint by joint with the cross-check."""
    names = list(checked)
    blocks = ctx.blocks([checked[nm] for nm in names])
    peak = [0.0] * len(names)
    rank_p = [0] * len(names)
    k_null = ctx.N_svd.shape[1]
    keys = [b.shape if b.size else None for b in blocks]
    for _, part in _batches(keys, lambda shape: max(1, shape[0] * max(k_null, shape[1]))):  # the stacked B's entries
        stack = _stacked([blocks[k] for k in part])
        for k, sv in zip(part, _svdvals(stack)):
            rank_p[k] = int(np.count_nonzero(sv > ctx.tol))
        if k_null:
            N = ctx.N_svd[np.array([list(checked[names[k]]) for k in part], dtype=np.intp)]
            for k, row_norms in zip(part, np.linalg.norm(stack @ N, axis=2)):
                peak[k] = float(row_norms.max())
    ratios = [_b_ratio(ctx, p) for p in peak]
    defects = [0] * len(names)
    if not ctx.cross_check:
        defects = _b_defects(ctx, [checked[nm] for nm in names], [r <= 1.0 for r in ratios], blocks)
    out = {}
    for k, name in enumerate(names):
        cols = checked[name]
        methods = {"svd": ratios[k] <= 1.0}
        ratio_qr, defect = 0.0, defects[k]
        if ctx.cross_check:
            defect = _rank_defect(ctx, [cols])
            ratio_qr = _b_ratio(ctx, _peak(_B(ctx.A, ctx.basis("qr"), cols)), "qr")
            methods = {"rank": defect <= 0, "svd": methods["svd"], "qr": ratio_qr <= 1.0}
        methods = {key: bool(v) for key, v in methods.items()}
        out[name] = JointVerdict(
            unique=methods["rank"] if ctx.cross_check else methods["svd"],
            methods=methods,
            rank_defect=int(defect),
            B_svd=_B(ctx.J, ctx.basis("svd_raw"), cols) if ctx.cross_check else None,
            B_qr=_B(ctx.J, ctx.basis("qr_raw"), cols) if ctx.cross_check else None,
            agree=len(set(methods.values())) == 1,
            columns=cols,
            rank_P=rank_p[k],
            b_ratio_svd=ratios[k],
            b_ratio_qr=ratio_qr,
        )
    return out


def joint_uniqueness(
    J,
    columns: Sequence[int],
    *,
    rtol: float | None = None,
    b_rtol: float | None = None,
    equilibrate: bool = True,
) -> JointVerdict:
    """Is the reaction ``f_P = J_P lam_P`` of the joint owning ``columns`` of ``J`` unique?

    ``J`` (n, m) = ``Phi_q.T``; ``columns`` are 0-based column indices.  Runs the rank
    comparison (B.10), SVD (B.11) and QR (B.12) tests with the tolerances of the module docstring.
    ``unique`` follows the rank method; ``agree`` is False if any method disagrees.
    """
    ctx = _context(J, rtol, b_rtol, equilibrate)
    cols = _check_columns(columns, ctx.J.shape[1])
    return _joints(ctx, {"": cols})[""]


# --------------------------------------------------------------------------- whole analysis


@dataclass(frozen=True, eq=False)
class Analysis:
    """Result of ``analyse``.

    n_coordinates  n (rows of J: velocity coordinates, 3 per planar and 6 per spatial body,
                   whatever the rotation coordinates)
                                          n_equations  m (columns of J)
    rank           r = rank(J)            dof          n - r
    redundant      m - r                  joints       name -> JointVerdict, in insertion order
    singular_values  of the decision matrix (equilibrated J unless equilibrate=False), descending;
                   with ``methods="svd"`` those the one factorisation computed (its blocks'; all
                   of them when nothing was peeled)
    rank_tol       absolute rank threshold on that matrix
    b_rtol         threshold of the ``B_P == 0`` test (relative to its sigma_1)
    """

    n_coordinates: int
    n_equations: int
    rank: int
    dof: int
    redundant: int
    joints: dict
    singular_values: np.ndarray = field(repr=False)
    rank_tol: float = 0.0
    b_rtol: float = 0.0
    _ctx: _Context = field(repr=False, default=None)
    _groups: dict = field(repr=False, default_factory=dict)

    @property
    def agree(self) -> bool:
        """True if every joint's three methods agree."""
        return all(v.agree for v in self.joints.values())

    def set_unique(self, names: Iterable[str]) -> SetVerdict:
        """Are the reactions of all joints in ``names`` uniquely determined (Eq. 17)?

        Rank form: ``sum_i rank(J_Pi) + rank(J_Y) - rank(J) == 0``, Y = columns of no member (same
        absolute rank tolerance as everywhere).  SVD/QR form: every member's ``B_P == 0``.  They
        are mathematically equivalent; ``agree`` flags a numerical split, in which case ``unique``
        follows the rank form.  The empty set is trivially unique.
        """
        names = (names,) if isinstance(names, str) else tuple(names)
        unknown = [nm for nm in names if nm not in self._groups]
        if unknown:
            raise KeyError(f"unknown joint name(s) {unknown}; known: {list(self._groups)}")
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate joint names in {names}")
        svd = all(self.joints[nm].methods["svd"] for nm in names)
        if not self._ctx.cross_check:
            cols = tuple(c for nm in names for c in self._groups[nm])
            defect = _b_defect(self._ctx, cols, svd)  # rank(stacked A_Pi N) is Eq. 17's defect too
            return SetVerdict(unique=svd, methods={"svd": svd}, rank_defect=int(defect), agree=True, names=names)
        defect = _rank_defect(self._ctx, [self._groups[nm] for nm in names])
        methods = {
            "rank": bool(defect <= 0),
            "svd": svd,
            "qr": all(self.joints[nm].methods["qr"] for nm in names),
        }
        return SetVerdict(
            unique=methods["rank"],
            methods=methods,
            rank_defect=int(defect),
            agree=len(set(methods.values())) == 1,
            names=names,
        )


def analyse(
    J,
    groups: Mapping[str, Sequence[int]],
    *,
    rtol: float | None = None,
    b_rtol: float | None = None,
    equilibrate: bool = True,
    methods: str = "all",
) -> Analysis:
    """Rank, DOF, redundancy and per-joint reaction uniqueness of ``J`` (n, m) = ``Phi_q.T``.

    ``groups`` maps joint name -> its 0-based columns of J.  Groups must not overlap; columns in
    no group (e.g. driving constraints) are part of every ``J_-P`` and of Y in ``set_unique``.
    Tolerances and equilibration: see the module docstring. ``methods`` (:data:`METHOD_SETS`):
    ``"all"`` runs the three tests; ``"svd"`` only the one-factorisation test (one SVD per block
    of J left after peeling, :func:`_factorise`, then O(rows of P * len(columns) * (m - r)) per
    joint instead of two SVDs of J per joint).
    """
    ctx = _context(J, rtol, b_rtol, equilibrate, methods)
    n, m = ctx.J.shape
    checked: dict[str, tuple[int, ...]] = {}
    owner: dict[int, str] = {}
    for name, cols in groups.items():
        cols_t = _check_columns(cols, m, what=f"joint {name!r}")
        for c in cols_t:
            if c in owner:
                raise ValueError(f"column {c} belongs to both {owner[c]!r} and {name!r}")
            owner[c] = name
        checked[name] = cols_t
    return Analysis(
        n_coordinates=n,
        n_equations=m,
        rank=ctx.r,
        dof=n - ctx.r,
        redundant=m - ctx.r,
        joints=_joints(ctx, checked),
        singular_values=ctx.sigma,
        rank_tol=ctx.tol,
        b_rtol=ctx.b_rtol,
        _ctx=ctx,
        _groups=checked,
    )


def to_json(analysis: Analysis) -> dict:
    """JSON-ready dict (plain Python types) of an ``Analysis``."""
    return {
        "n_coordinates": int(analysis.n_coordinates),
        "n_equations": int(analysis.n_equations),
        "rank": int(analysis.rank),
        "dof": int(analysis.dof),
        "redundant": int(analysis.redundant),
        "joints": [
            {
                "name": str(name),
                "unique": bool(v.unique),
                "methods": {k: bool(v.methods[k]) for k in _METHODS if k in v.methods},
                "rank_defect": int(v.rank_defect),
                "agree": bool(v.agree),
            }
            for name, v in analysis.joints.items()
        ],
    }
