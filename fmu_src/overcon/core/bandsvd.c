/* Singular values and the trailing right singular vectors of a set of k rows of length n whose
 * nonzeros lie in a narrow window each (rows of a constraint Jacobian: each touches its joint's two
 * bodies, so with the bodies listed along a chain every row's window is a few bodies wide). It
 * replaces a dense SVD wherever the core needs the rank of such rows or the basis of their
 * dependencies (unique.c, watch.c), at O(k w (w + n_w)) instead of O(k^2 n) a Jacobi sweep, w the
 * band the rows' windows give (w = k for rows without that structure: the dense case, the same
 * steps). Dimensionless: the singular values are those of the rows as given.
 *
 *   1. The rows, sorted by their first then last nonzero column, are the columns of A (n x k; with
 *      k > n, zero rows pad A to k x k, which adds the k - n zero singular values the rank
 *      implies). Householder QR A = Q R, each reflection over the rows the columns so far reach
 *      and applied to the columns that start within them: R (k x k, upper triangular) keeps a
 *      band of width w. R has A's singular values and right singular vectors.
 *   2. R is reduced to upper bidiagonal form by Givens rotations chasing each bulge down the band
 *      (the band-to-bidiagonal reduction of LAPACK's dgbbrd), O(k^2 w).
 *   3. Counts of the singular values below x by Sturm sequences of the Golub-Kahan tridiagonal
 *      matrix of the bidiagonal (zero diagonal, off-diagonal d1 e1 d2 e2 ...; eigenvalues +-sigma):
 *      the count of its eigenvalues below x > 0 is k + #{sigma < x}. Bisection on counts gives
 *      any singular value to an absolute accuracy of a few eps sigma_1 (the reduction's
 *      backward error), which is what a rank decision at 1e-9 sigma_1 needs.
 *   4. The right singular vectors of the p smallest values (the dependencies among the rows) by
 *      subspace inverse iteration with R_mu, the triangular factor of [R; mu I] (R_mu^T R_mu =
 *      R^T R + mu^2 I: the same eigenvectors, and no division by R's zero pivots at an exact
 *      dependency), mu a tenth of the caller's threshold, on a block of b >= p vectors that reaches
 *      every singular value up to NULL_GAP times the p-th, then a Rayleigh-Ritz step (Jacobi on the
 *      b x b projection) that picks the p least. The block makes the convergence independent of the
 *      gap at p: a rank cut inside a cluster of small values (a mechanism near a flat position)
 *      takes the same few iterations as a clear one (block_size).
 * Fixed order of every sum and rotation: the results do not depend on the CPU. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"

#define EPS 2.220446049250313e-16
#define BISECT_STEPS 80   /* halvings of [0, bound]: past the double's resolution of any value */
#define NULL_GAP 30.0    /* the block reaches the singular values up to 30 times the p-th (block_size) */
#define JACOBI_SWEEPS 60  /* a bound never reached: cyclic Jacobi converges quadratically */

/* Doubles for k rows of length n: A (max(n, k) x k), R_mu (k x k), the bidiagonal, the basis and
 * its last iterate (2 k^2), vectors; the ints (order, windows) ride in doubles at the end. */
size_t ovk_bsv_doubles(int k, int n) {
    size_t K = (size_t)k, rows = (size_t)(n > k ? n : k);
    return rows * K + K * K + 2 * K + 2 * K * K + rows + 4 * K + 8;
}

/* The rows' window order: by first, then last nonzero column, then index (a total order). */
typedef struct {
    int lo, hi, index;
} window;
static int by_window(const void *a, const void *b) {
    const window *x = a, *y = b;
    if (x->lo != y->lo) return x->lo < y->lo ? -1 : 1;
    if (x->hi != y->hi) return x->hi < y->hi ? -1 : 1;
    return (x->index > y->index) - (x->index < y->index);
}

/* c, s with [c s; -s c] [a; b] = [r; 0]. */
static void givens(double a, double b, double *c, double *s) {
    double r = sqrt(a * a + b * b); /* not hypot: libm's may differ between machines, sqrt may not */
    if (r < 1e-150) { /* the squares may have underflowed: scaled */
        double big = fabs(a) > fabs(b) ? fabs(a) : fabs(b);
        r = big > 0.0 ? big * sqrt((a / big) * (a / big) + (b / big) * (b / big)) : 0.0;
    }
    if (r == 0.0) {
        *c = 1.0, *s = 0.0;
    } else {
        *c = a / r, *s = b / r;
    }
}

/* X (k x k, row-major): columns p, q = p + 1 rotated over rows [r0, r1] so that X[zr][q] = 0. */
static void col_rot(double *X, int k, int p, int zr, int r0, int r1) {
    double c, s;
    givens(X[(size_t)zr * k + p], X[(size_t)zr * k + p + 1], &c, &s);
    for (int r = r0; r <= r1; r++) {
        double a = X[(size_t)r * k + p], b = X[(size_t)r * k + p + 1];
        X[(size_t)r * k + p] = c * a + s * b;
        X[(size_t)r * k + p + 1] = -s * a + c * b;
    }
    X[(size_t)zr * k + p + 1] = 0.0;
}

/* X: rows p, p + 1 rotated over columns [c0, c1] so that X[p + 1][p] = 0. */
static void row_rot(double *X, int k, int p, int c0, int c1) {
    double c, s, *u = X + (size_t)p * k, *v = u + k;
    givens(u[p], v[p], &c, &s);
    for (int j = c0; j <= c1; j++) {
        double a = u[j], b = v[j];
        u[j] = c * a + s * b;
        v[j] = -s * a + c * b;
    }
    v[p] = 0.0;
}

/* Upper triangular X (k x k) with upper band w to bidiagonal: d (k), e (k - 1). */
static void bidiagonal(double *X, int k, int w, double *d, double *e) {
    for (int i = 0; i + 2 < k; i++)
        for (int j = i + w < k - 1 ? i + w : k - 1; j >= i + 2; j--) {
            if (X[(size_t)i * k + j] == 0.0) continue;
            col_rot(X, k, j - 1, i, i, j); /* a bulge at (j, j - 1) */
            for (int c = j;;) {
                row_rot(X, k, c - 1, c - 1, c + w < k - 1 ? c + w : k - 1); /* fill at (c - 1, c + w) */
                int nc = c + w;
                if (nc > k - 1 || X[(size_t)(c - 1) * k + nc] == 0.0) break;
                col_rot(X, k, nc - 1, c - 1, c - 1, nc); /* a bulge at (nc, nc - 1) */
                c = nc;
            }
        }
    for (int i = 0; i < k; i++) {
        d[i] = X[(size_t)i * k + i];
        if (i + 1 < k) e[i] = X[(size_t)i * k + i + 1];
    }
}

int ovk_bsv_factor(const double *B, int k, int n, double *work, ovk_bsv *f) {
    int rows = n > k ? n : k;
    double *A = work, *X = A + (size_t)rows * k, *d = X + (size_t)k * k, *e = d + k, *v = e + k + (size_t)2 * k * k;
    window *win = (window *)(v + rows); /* 3 k ints in the 4 k doubles left */
    memset(f, 0, sizeof *f);
    f->k = k, f->rows = rows, f->A = A, f->d = d, f->e = e, f->basis = e + k, f->v = v, f->order = (int *)(win + k);
    if (!k) return OVK_OK;
    for (int i = 0; i < k; i++) {
        const double *row = B + (size_t)i * n;
        int lo = 0, hi = n;
        while (lo < n && row[lo] == 0.0) lo++;
        while (hi > lo && row[hi - 1] == 0.0) hi--;
        if (lo == n) lo = hi = rows; /* a zero row: last, it starts nowhere */
        for (int c = 0; c < n; c++)
            if (!isfinite(row[c])) return OVK_NONFINITE;
        win[i].lo = lo, win[i].hi = hi, win[i].index = i;
    }
    qsort(win, (size_t)k, sizeof *win, by_window);
    int *order = f->order; /* after the windows: order[c] = the row that is column c */
    memset(A, 0, (size_t)rows * k * sizeof(double));
    for (int c = 0; c < k; c++) {
        order[c] = win[c].index;
        memcpy(A + (size_t)c * rows, B + (size_t)order[c] * n, (size_t)n * sizeof(double));
    }
    /* 1. Householder QR in the windows: H the rows reached so far, reflections applied to the columns
     * that start above H only (the later ones are zero there) */
    int reach = 0, last = 0;
    for (int j = 0; j < k; j++) {
        double *x = A + (size_t)j * rows;
        reach = win[j].hi > reach ? win[j].hi : reach;
        if (reach < j + 1) reach = j + 1;
        while (last + 1 < k && win[last + 1].lo < reach) last++;
        double norm2 = 0.0;
        for (int i = j; i < reach; i++) norm2 += x[i] * x[i];
        double norm = sqrt(norm2);
        if (norm == 0.0) continue;
        double alpha = x[j] > 0.0 ? -norm : norm, vv = 0.0;
        for (int i = j; i < reach; i++) v[i] = x[i];
        v[j] -= alpha;
        for (int i = j; i < reach; i++) vv += v[i] * v[i];
        for (int c = j + 1; c <= last && vv > 0.0; c++) {
            double *y = A + (size_t)c * rows, dot = 0.0;
            for (int i = j; i < reach; i++) dot += v[i] * y[i];
            double g = 2.0 * dot / vv;
            for (int i = j; i < reach; i++) y[i] -= g * v[i];
        }
        x[j] = alpha;
        for (int i = j + 1; i < reach; i++) x[i] = 0.0;
    }
    /* R (column j of A, rows 0..j) into X row-major; its band w */
    int w = 0;
    memset(X, 0, (size_t)k * k * sizeof(double));
    for (int j = 0; j < k; j++) {
        const double *x = A + (size_t)j * rows;
        int top = j;
        for (int i = 0; i <= j; i++) {
            X[(size_t)i * k + j] = x[i];
            if (x[i] != 0.0 && i < top) top = i;
        }
        w = j - top > w ? j - top : w;
    }
    f->w = w;
    bidiagonal(X, k, w, d, e);
    double bound = 0.0; /* Gershgorin on the Golub-Kahan matrix: sigma_1 <= bound */
    for (int i = 0; i < k; i++) {
        double g = fabs(d[i]) + (i + 1 < k ? fabs(e[i]) : 0.0), h = fabs(d[i]) + (i > 0 ? fabs(e[i - 1]) : 0.0);
        bound = g > bound ? g : bound;
        bound = h > bound ? h : bound;
    }
    f->bound = bound;
    return OVK_OK;
}

int ovk_bsv_below(const ovk_bsv *f, double x) {
    int k = f->k, count = 0;
    if (!k || !(x > 0.0)) return 0;
    double tiny = EPS * (f->bound > 0.0 ? f->bound : 1.0) * 1e-3, q = -x;
    count += q < 0.0;
    for (int t = 0; t < 2 * k - 1; t++) { /* off-diagonal t: d[t / 2] for even t, e[t / 2] for odd */
        double o = t % 2 ? f->e[t / 2] : f->d[t / 2];
        if (q == 0.0) q = -tiny;
        q = -x - o * o / q;
        count += q < 0.0;
    }
    return count > k ? count - k : 0; /* round-off cannot make a count negative */
}

double ovk_bsv_value(const ovk_bsv *f, int i) {
    int want = f->k - i; /* the i-th largest is the want-th smallest */
    double lo = 0.0, hi = f->bound * (1.0 + 4.0 * EPS) + 1e-300;
    if (i < 0 || i >= f->k) return 0.0;
    for (int step = 0; step < BISECT_STEPS && hi - lo > 2.0 * EPS * hi; step++) {
        double mid = 0.5 * (lo + hi);
        if (ovk_bsv_below(f, mid) >= want)
            hi = mid;
        else
            lo = mid;
    }
    return 0.5 * (lo + hi);
}

/* Modified Gram-Schmidt, twice, on the p columns of Z (k x p, column-major); a column that
 * vanishes is replaced by a fixed vector and orthonormalised again. */
static void orthonormal(double *Z, int k, int p) {
    for (int c = 0; c < p; c++) {
        double *z = Z + (size_t)c * k;
        for (int pass = 0; pass < 3; pass++) {
            for (int b = 0; b < c; b++) {
                const double *y = Z + (size_t)b * k;
                double dot = 0.0;
                for (int i = 0; i < k; i++) dot += y[i] * z[i];
                for (int i = 0; i < k; i++) z[i] -= dot * y[i];
            }
            double n2 = 0.0;
            for (int i = 0; i < k; i++) n2 += z[i] * z[i];
            if (n2 > 0.0 && isfinite(n2)) {
                double inv = 1.0 / sqrt(n2);
                for (int i = 0; i < k; i++) z[i] *= inv;
                if (pass) break;
            } else {
                for (int i = 0; i < k; i++) z[i] = cos(1.0 + 2.399963229728653 * (i + 13 * c + 7 * pass));
            }
        }
    }
}

/* H (b x b, symmetric, row-major) to diagonal by cyclic Jacobi rotations in a fixed order, each
 * accumulated into V (b x b, row-major; V := V G): H = V diag V^T. A pair is left alone once
 * |h_ij| <= eps sqrt(h_ii h_jj) (H positive definite here: its eigenvalues are sigma^2 + mu^2).
 * Not svd.c's one-sided ovk_jacobi_rows on the rows of (U Z)^T, which avoids forming H: it rotates
 * vectors of length k, O(k b^2) a sweep against O(b^3) here (measured: the uniqueness along the
 * N-four-bar N = 40 0.12 -> 0.21 s), and forming H loses nothing that matters: the round-off of U Z
 * itself (eps sigma_1 in each column) already bounds how well the p least are told apart. */
static void jacobi(double *H, double *V, int b) {
    for (int sweep = 0; sweep < JACOBI_SWEEPS; sweep++) {
        int rotated = 0;
        for (int i = 0; i < b; i++)
            for (int j = i + 1; j < b; j++) {
                double hij = H[(size_t)i * b + j], hii = H[(size_t)i * b + i], hjj = H[(size_t)j * b + j];
                if (hij == 0.0 || fabs(hij) <= EPS * sqrt(fabs(hii * hjj))) continue;
                rotated = 1;
                double theta = (hjj - hii) / (2.0 * hij), t;
                if (fabs(theta) > 1e150)
                    t = 0.5 / theta;
                else
                    t = (theta >= 0.0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
                for (int r = 0; r < b; r++) {
                    if (r == i || r == j) continue;
                    double hri = H[(size_t)r * b + i], hrj = H[(size_t)r * b + j];
                    H[(size_t)r * b + i] = H[(size_t)i * b + r] = c * hri - s * hrj;
                    H[(size_t)r * b + j] = H[(size_t)j * b + r] = s * hri + c * hrj;
                }
                H[(size_t)i * b + i] = hii - t * hij;
                H[(size_t)j * b + j] = hjj + t * hij;
                H[(size_t)i * b + j] = H[(size_t)j * b + i] = 0.0;
                for (int r = 0; r < b; r++) {
                    double vri = V[(size_t)r * b + i], vrj = V[(size_t)r * b + j];
                    V[(size_t)r * b + i] = c * vri - s * vrj;
                    V[(size_t)r * b + j] = s * vri + c * vrj;
                }
            }
        if (!rotated) return;
    }
}

/* R_mu into U (k x k, row-major, upper band w): the factor of [R; mu I], R from A's upper
 * triangle, each row of mu I rotated in; t: k doubles of scratch. */
static void shifted_factor(const ovk_bsv *f, double mu, double *U, double *t) {
    int k = f->k, rows = f->rows, w = f->w;
    memset(U, 0, (size_t)k * k * sizeof(double));
    for (int j = 0; j < k; j++)
        for (int i = j - w > 0 ? j - w : 0; i <= j; i++) U[(size_t)i * k + j] = f->A[(size_t)j * rows + i];
    for (int i = 0; i < k; i++) {
        memset(t, 0, (size_t)k * sizeof(double));
        t[i] = mu;
        for (int l = i; l < k; l++) {
            if (t[l] == 0.0) continue;
            double c, s, *u = U + (size_t)l * k;
            givens(u[l], t[l], &c, &s);
            int end = l + w < k - 1 ? l + w : k - 1;
            for (int j = l; j <= end; j++) {
                double a = u[j], b = t[j];
                u[j] = c * a + s * b;
                t[j] = -s * a + c * b;
            }
            t[l] = 0.0;
        }
    }
}

/* x := (U^T U)^-1 x, U (k x k) upper triangular with band w. */
static void normal_solve(const double *U, int k, int w, double *x) {
    for (int i = 0; i < k; i++) { /* U^T y = x */
        double s = x[i];
        for (int l = i - w > 0 ? i - w : 0; l < i; l++) s -= U[(size_t)l * k + i] * x[l];
        x[i] = s / U[(size_t)i * k + i];
    }
    for (int i = k - 1; i >= 0; i--) { /* U z = y */
        double s = x[i];
        int end = i + w < k - 1 ? i + w : k - 1;
        for (int l = i + 1; l <= end; l++) s -= U[(size_t)i * k + l] * x[l];
        x[i] = s / U[(size_t)i * k + i];
    }
}

/* The block's size b and its inverse iterations: b the count of singular values below NULL_GAP
 * sqrt(lambda_p) (lambda_i = sigma_i^2 + mu^2, the eigenvalues R_mu^T R_mu has, sigma_p the largest
 * of the p smallest), at least p; each iteration takes the part of the block outside the p
 * smallest vectors' space down by rho = lambda_p / lambda_(b+1) <= 1 / NULL_GAP^2 whatever the
 * gap at p itself (Saad, Numerical Methods for Large Eigenvalue Problems, Thm 5.2), so the
 * iterations that take it to eps, and one more, are enough. */
static int block_size(const ovk_bsv *f, int p, double mu, int *iterations) {
    int k = f->k;
    double sp = ovk_bsv_value(f, k - p), lp = sp * sp + mu * mu;
    int b = ovk_bsv_below(f, NULL_GAP * sqrt(lp));
    b = b < p ? p : b > k ? k : b;
    double rho = 0.0; /* b = k: the block is the whole space, one iteration and the Ritz step are exact */
    if (b < k) {
        double sn = ovk_bsv_value(f, k - b - 1);
        rho = lp / (sn * sn + mu * mu);
        rho = rho < 1.0 / (NULL_GAP * NULL_GAP) ? rho : 1.0 / (NULL_GAP * NULL_GAP);
    }
    int it = 1; /* the least with rho^it <= eps (rho <= 1 / NULL_GAP^2: a few), then one more; by products,
                 * not log (whose libm version would raise the FMU binaries' glibc floor, libm_pins.h) */
    for (double reach = rho; reach > EPS; reach *= rho) it++;
    *iterations = rho > 0.0 ? it + 1 : 1;
    return b;
}

/* N (k x p, row-major, the rows' own order): an orthonormal basis of the right singular vectors of
 * the p smallest values (step 4 above). f's values (d, e) stay; its A and scratch do not. */
void ovk_bsv_null(ovk_bsv *f, int p, double mu, double *N) {
    int k = f->k, w = f->w, iterations;
    if (!p || !k) return;
    if (!(mu > 0.0)) mu = EPS * f->bound + 1e-300;
    int b = block_size(f, p, mu, &iterations);
    /* regions: U (R_mu) in the bidiagonal's scratch after A; Z (k x b) and T = U Z (k x b) in the
     * basis's 2 k^2; H and the rows of Z V in A (free once U is built); V over U after T */
    double *U = f->A + (size_t)f->rows * k, *Z = f->basis, *T = Z + (size_t)k * b, *H = f->A, *V = U, *z = f->v;
    shifted_factor(f, mu, U, T);
    for (int c = 0; c < b; c++)
        for (int i = 0; i < k; i++) Z[(size_t)c * k + i] = 1.5 + cos(1.0 + 2.399963229728653 * (i + 31 * c));
    orthonormal(Z, k, b);
    for (int it = 0; it < iterations; it++) {
        for (int c = 0; c < b; c++) normal_solve(U, k, w, Z + (size_t)c * k);
        orthonormal(Z, k, b);
    }
    /* Rayleigh-Ritz: H = (U Z)^T (U Z) = V diag V^T, the Ritz vectors Z V, the p of least value */
    for (int c = 0; c < b; c++)
        for (int i = 0; i < k; i++) {
            double s = 0.0;
            int end = i + w < k - 1 ? i + w : k - 1;
            for (int l = i; l <= end; l++) s += U[(size_t)i * k + l] * Z[(size_t)c * k + l];
            T[(size_t)c * k + i] = s;
        }
    for (int c = 0; c < b; c++)
        for (int d = c; d < b; d++) {
            double s = 0.0;
            for (int i = 0; i < k; i++) s += T[(size_t)c * k + i] * T[(size_t)d * k + i];
            H[(size_t)c * b + d] = H[(size_t)d * b + c] = s;
        }
    memset(V, 0, (size_t)b * b * sizeof(double));
    for (int c = 0; c < b; c++) V[(size_t)c * b + c] = 1.0;
    jacobi(H, V, b);
    for (int i = 0; i < k; i++) { /* row i of Z := row i of Z V */
        for (int c = 0; c < b; c++) {
            double s = 0.0;
            for (int d = 0; d < b; d++) s += Z[(size_t)d * k + i] * V[(size_t)d * b + c];
            z[c] = s;
        }
        for (int c = 0; c < b; c++) Z[(size_t)c * k + i] = z[c];
    }
    int *pick = (int *)T; /* the p columns of least Ritz value, in a fixed order: T is free */
    for (int c = 0; c < b; c++) pick[c] = c;
    for (int c = 0; c < p; c++)
        for (int d = c + 1; d < b; d++)
            if (H[(size_t)pick[d] * b + pick[d]] < H[(size_t)pick[c] * b + pick[c]]) {
                int x = pick[c];
                pick[c] = pick[d];
                pick[d] = x;
            }
    for (int c = 0; c < p; c++) /* into the rows' own order: N (k x p, row-major) */
        for (int i = 0; i < k; i++) N[(size_t)f->order[i] * p + c] = Z[(size_t)pick[c] * k + i];
}

/* For the tests (tests/test_bandsvd.py): the k singular values of the rows B (k x n, row-major),
 * largest first, into sv, and with p > 0 the basis of ovk_bsv_null (mu) into N (k x p). */
int ovk_band_svd(const double *B, int k, int n, int p, double mu, double *sv, double *N) {
    if (!B || k < 0 || n < 0 || p < 0 || p > k || !sv || (p && !N)) return OVK_INVALID;
    double *work = malloc(ovk_bsv_doubles(k, n) * sizeof(double));
    if (!work) return OVK_NOMEM;
    ovk_bsv f;
    int status = ovk_bsv_factor(B, k, n, work, &f);
    for (int i = 0; !status && i < k; i++) sv[i] = ovk_bsv_value(&f, i);
    if (!status && p) ovk_bsv_null(&f, p, mu, N);
    free(work);
    return status;
}
