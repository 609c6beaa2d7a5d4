/* Dense linear algebra of the core: Cholesky (the KKT matrix S) and LU with partial pivoting (the
 * friction Newton matrix), and the banded Cholesky of kkt_al.c's M + alpha J^T J and of the
 * watch's G = W W^T (watch_eig.c). Fixed summation order and no BLAS: the results do not depend on
 * the CPU's BLAS dispatch. The dense matrices are at most a few dozen rows. */
#include <math.h>
#include <stddef.h>

#include "core.h"

/* Cholesky S = U^T U in place (upper triangle, row-major n x n). 0 on success, else 1 + the
 * column whose pivot is not positive. */
int ovk_cholesky(double *S, int n) {
    for (int j = 0; j < n; j++) {
        double s = S[j * n + j];
        for (int k = 0; k < j; k++) s -= S[k * n + j] * S[k * n + j];
        if (!(s > 0.0)) return j + 1;
        double ujj = sqrt(s);
        S[j * n + j] = ujj;
        for (int i = j + 1; i < n; i++) {
            double t = S[j * n + i];
            for (int k = 0; k < j; k++) t -= S[k * n + j] * S[k * n + i];
            S[j * n + i] = t / ujj;
        }
    }
    return 0;
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

/* (U^T U) x = b in place with the factor of ovk_band_cholesky (n, half bandwidth p). */
void ovk_band_solve(const double *U, int n, int p, double *b) {
    int w = p + 1;
    for (int i = 0; i < n; i++) {
        double t = b[i];
        for (int k = i - p > 0 ? i - p : 0; k < i; k++) t -= U[(size_t)k * w + (i - k)] * b[k];
        b[i] = t / U[(size_t)i * w];
    }
    for (int i = n - 1; i >= 0; i--) {
        double t = b[i];
        int last = i + p < n - 1 ? i + p : n - 1;
        for (int k = i + 1; k <= last; k++) t -= U[(size_t)i * w + (k - i)] * b[k];
        b[i] = t / U[(size_t)i * w];
    }
}

void ovk_cho_solve(const double *U, int n, double *b) {
    for (int i = 0; i < n; i++) { /* U^T y = b */
        double t = b[i];
        for (int k = 0; k < i; k++) t -= U[k * n + i] * b[k];
        b[i] = t / U[i * n + i];
    }
    for (int i = n - 1; i >= 0; i--) { /* U x = y */
        double t = b[i];
        for (int k = i + 1; k < n; k++) t -= U[i * n + k] * b[k];
        b[i] = t / U[i * n + i];
    }
}

/* S X = B for nc columns at once (B row-major n x nc, overwritten): the columns are the inner loop. */
void ovk_cho_solve_many(const double *U, int n, double *B, int nc) {
    for (int i = 0; i < n; i++) {
        double *Bi = B + (size_t)i * nc;
        for (int k = 0; k < i; k++) {
            double u = U[k * n + i];
            const double *Bk = B + (size_t)k * nc;
            for (int c = 0; c < nc; c++) Bi[c] -= u * Bk[c];
        }
        double d = U[i * n + i];
        for (int c = 0; c < nc; c++) Bi[c] /= d;
    }
    for (int i = n - 1; i >= 0; i--) {
        double *Bi = B + (size_t)i * nc;
        for (int k = i + 1; k < n; k++) {
            double u = U[i * n + k];
            const double *Bk = B + (size_t)k * nc;
            for (int c = 0; c < nc; c++) Bi[c] -= u * Bk[c];
        }
        double d = U[i * n + i];
        for (int c = 0; c < nc; c++) Bi[c] /= d;
    }
}

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
