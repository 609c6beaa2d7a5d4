/* Linear algebra of the core: the banded Cholesky of the eliminated form's S = J_R M^-1 J_R^T
 * (kkt.c), of kkt_al.c's M + alpha J^T J and of the watch's G = W W^T (watch_eig.c), the band
 * order that makes S and G banded, and LU with partial pivoting (the friction Newton matrix).
 * Fixed summation order and no BLAS: the results do not depend on the CPU's BLAS dispatch. */
#include <math.h>
#include <stddef.h>
#include <stdlib.h>

#include "core.h"

static int by_key(const void *a, const void *b) {
    long long x = *(const long long *)a, y = *(const long long *)b;
    return (x > y) - (x < y);
}

/* The half bandwidth of A A^T for the rows of ovk_band_order listed as order says (NULL: as
 * they are): the largest distance between two listed rows that share a body. */
static int half_band(int n, int nb, const int *bodies, const int *rows, const int *order, int *span) {
    for (int b = 0; b < nb; b++) span[2 * b] = n, span[2 * b + 1] = -1;
    for (int k = 0; k < n; k++) {
        int i = order ? order[k] : k, r = rows ? rows[i] : i;
        for (int t = 0; t < 2; t++) {
            int c = bodies[2 * r + t];
            if (c < 0) continue;
            if (k < span[2 * c]) span[2 * c] = k;
            if (k > span[2 * c + 1]) span[2 * c + 1] = k;
        }
    }
    int band = 0;
    for (int b = 0; b < nb; b++)
        if (span[2 * b + 1] - span[2 * b] > band) band = span[2 * b + 1] - span[2 * b];
    return band;
}

/* The band order of n rows each nonzero on two bodies' columns only (row i's bodies at
 * bodies[2 r], bodies[2 r + 1], r = rows ? rows[i] : i; -1 the base, which does not count): the
 * rows sorted by their lower, then higher body index (then their own index, so the order is one
 * whatever qsort does with ties). A product A A^T of such rows (S, G) is nonzero at (a, b) only
 * when rows a and b share a body, so in this order it is banded with half bandwidth p = the
 * largest distance between two rows sharing a body: a few rows for a chain numbered along
 * itself, up to n - 1 for a mechanism without that structure. keep: the rows as they are
 * instead when that is no wider (a small mechanism whose S is dense either way keeps the
 * user's order, and its factor the bits of a dense Cholesky in that order). Into order (n: the
 * row at each position) and obody (2 n: each ordered row's bodies, lower first, -1 none); key
 * (n) and span (2 nb) are scratch. Returns p. */
int ovk_band_order(int n, int nb, const int *bodies, const int *rows, int keep, int *order, int *obody,
                   long long *key, int *span) {
    for (int i = 0; i < n; i++) {
        int r = rows ? rows[i] : i, a = bodies[2 * r], b = bodies[2 * r + 1];
        int lo = a < 0 ? b : b < 0 ? a : a < b ? a : b, hi = a < 0 || b < 0 || a == b ? -1 : a < b ? b : a;
        key[i] = ((long long)(lo + 1) * (nb + 1) + (hi + 1)) * n + i;
    }
    qsort(key, (size_t)n, sizeof *key, by_key);
    for (int k = 0; k < n; k++) order[k] = (int)(key[k] % n);
    int band = half_band(n, nb, bodies, rows, order, span);
    if (keep) {
        int own = half_band(n, nb, bodies, rows, NULL, span);
        if (own <= band)
            for (int k = 0; k < n; k++) order[k] = k;
        band = own <= band ? own : band;
    }
    for (int k = 0; k < n; k++) {
        int r = rows ? rows[order[k]] : order[k], a = bodies[2 * r], b = bodies[2 * r + 1];
        obody[2 * k] = a < 0 ? b : b < 0 ? a : a < b ? a : b;
        obody[2 * k + 1] = a < 0 || b < 0 || a == b ? -1 : a < b ? b : a;
    }
    return band;
}

/* Banded Cholesky A = U^T U in place: A symmetric n x n with half bandwidth p, in band storage
 * (row k holds columns k..k+p at A[k (p + 1) + (l - k)]; U lives in the same places). 0 on
 * success, else 1 + the column whose pivot is not positive (or not a number). O(n p^2). */
int ovk_band_cholesky(double *A, int n, int p) {
    int w = p + 1;
    for (int j = 0; j < n; j++) { /* U[k][j] lives at A[k w + j - k] for j - p <= k <= j */
        double s = A[(size_t)j * w];
        for (int k = j - p > 0 ? j - p : 0; k < j; k++) s -= A[(size_t)k * w + (j - k)] * A[(size_t)k * w + (j - k)];
        if (!(s > 0.0)) return j + 1;
        double ujj = sqrt(s);
        A[(size_t)j * w] = ujj;
        int last = j + p < n - 1 ? j + p : n - 1;
        for (int i = j + 1; i <= last; i++) {
            double t = A[(size_t)j * w + (i - j)];
            for (int k = i - p > 0 ? i - p : 0; k < j; k++) t -= A[(size_t)k * w + (j - k)] * A[(size_t)k * w + (i - k)];
            A[(size_t)j * w + (i - j)] = t / ujj;
        }
    }
    return 0;
}

/* One column b (entries b[0], b[stride], ...) of ovk_band_solve_many, each sum over k ascending,
 * in a local (a store through b at every term would be kept: b may alias U for the compiler). */
static void band_solve_strided(const double *U, int n, int p, double *b, size_t stride) {
    int w = p + 1;
    for (int i = 0; i < n; i++) { /* U^T y = b */
        double t = b[(size_t)i * stride];
        for (int k = i - p > 0 ? i - p : 0; k < i; k++) t -= U[(size_t)k * w + (i - k)] * b[(size_t)k * stride];
        b[(size_t)i * stride] = t / U[(size_t)i * w];
    }
    for (int i = n - 1; i >= 0; i--) { /* U x = y */
        double t = b[(size_t)i * stride];
        int last = i + p < n - 1 ? i + p : n - 1;
        for (int k = i + 1; k <= last; k++) t -= U[(size_t)i * w + (k - i)] * b[(size_t)k * stride];
        b[(size_t)i * stride] = t / U[(size_t)i * w];
    }
}

/* (U^T U) X = B in place with the factor of ovk_band_cholesky (n, half bandwidth p) for nc
 * columns (B row-major n x nc), one column after the other. */
void ovk_band_solve_many(const double *U, int n, int p, double *B, int nc) {
    for (int c = 0; c < nc; c++) band_solve_strided(U, n, p, B + c, (size_t)nc);
}

/* (U^T U) x = b in place: one column of ovk_band_solve_many. */
void ovk_band_solve(const double *U, int n, int p, double *b) { band_solve_strided(U, n, p, b, 1); }

/* LU with partial pivoting (dgetrf semantics: fails, returning nonzero, only on an exact zero pivot). */
int ovk_lu_factor(double *A, int n, int *piv) {
    for (int k = 0; k < n; k++) {
        int p = k;
        double best = fabs(A[k * n + k]);
        for (int i = k + 1; i < n; i++)
            if (fabs(A[i * n + k]) > best) { best = fabs(A[i * n + k]); p = i; }
        piv[k] = p;
        if (A[p * n + k] == 0.0) return 1;
        if (p != k)
            for (int c = 0; c < n; c++) { double t = A[k * n + c]; A[k * n + c] = A[p * n + c]; A[p * n + c] = t; }
        for (int i = k + 1; i < n; i++) {
            double l = A[i * n + k] / A[k * n + k];
            A[i * n + k] = l;
            for (int c = k + 1; c < n; c++) A[i * n + c] -= l * A[k * n + c];
        }
    }
    return 0;
}

void ovk_lu_solve(const double *A, int n, const int *piv, double *b) {
    for (int k = 0; k < n; k++)
        if (piv[k] != k) { double t = b[k]; b[k] = b[piv[k]]; b[piv[k]] = t; }
    for (int i = 0; i < n; i++)
        for (int k = 0; k < i; k++) b[i] -= A[i * n + k] * b[k];
    for (int i = n - 1; i >= 0; i--) {
        for (int k = i + 1; k < n; k++) b[i] -= A[i * n + k] * b[k];
        b[i] /= A[i * n + i];
    }
}
