/* Complex LU with partial pivoting: radau's complex Newton matrix (mu_complex / h) I - J
 * (integrate_radau.c); the real one is linalg.c's ovk_lu_factor. Entries are (re, im) pairs of
 * doubles, row-major, so the core needs no <complex.h> and its complex arithmetic is written out
 * here in one fixed order. The pivot of a column is its first entry of largest |re| + |im|, the
 * choice of LAPACK's zgetrf (izamax), which scipy.linalg.lu_factor calls in integrators.Radau5. */
#include <math.h>
#include <stddef.h>

#include "core.h"

/* (ar + i ai) / (br + i bi) by Smith's algorithm (no overflow of |b|^2). */
static void cdiv(double ar, double ai, double br, double bi, double *re, double *im) {
    if (fabs(br) >= fabs(bi)) {
        double r = bi / br, d = br + bi * r;
        *re = (ar + ai * r) / d;
        *im = (ai - ar * r) / d;
    } else {
        double r = br / bi, d = bi + br * r;
        *re = (ar * r + ai) / d;
        *im = (ai * r - ar) / d;
    }
}

/* A = P L U in place (L unit lower, U upper; piv[k]: the row exchanged with row k). Returns 0, or
 * 1 + the column whose pivot is exactly zero (dgetrf's semantics: A is left part-factored). */
int ovk_zlu_factor(double *A, int n, int *piv) {
    for (int k = 0; k < n; k++) {
        int p = k;
        double best = fabs(A[2 * ((size_t)k * n + k)]) + fabs(A[2 * ((size_t)k * n + k) + 1]);
        for (int i = k + 1; i < n; i++) {
            double a = fabs(A[2 * ((size_t)i * n + k)]) + fabs(A[2 * ((size_t)i * n + k) + 1]);
            if (a > best) best = a, p = i;
        }
        piv[k] = p;
        if (!(best > 0.0)) return k + 1;
        if (p != k)
            for (int c = 0; c < 2 * n; c++) {
                double t = A[2 * (size_t)k * n + c];
                A[2 * (size_t)k * n + c] = A[2 * (size_t)p * n + c];
                A[2 * (size_t)p * n + c] = t;
            }
        const double *rk = A + 2 * (size_t)k * n;
        for (int i = k + 1; i < n; i++) {
            double *ri = A + 2 * (size_t)i * n, lr, li;
            cdiv(ri[2 * k], ri[2 * k + 1], rk[2 * k], rk[2 * k + 1], &lr, &li);
            ri[2 * k] = lr, ri[2 * k + 1] = li;
            for (int c = k + 1; c < n; c++) {
                double ur = rk[2 * c], ui = rk[2 * c + 1];
                ri[2 * c] -= lr * ur - li * ui;
                ri[2 * c + 1] -= lr * ui + li * ur;
            }
        }
    }
    return 0;
}

/* Solves A x = b with the factors of ovk_zlu_factor; b (n pairs) is overwritten by x. */
void ovk_zlu_solve(const double *A, int n, const int *piv, double *b) {
    for (int k = 0; k < n; k++)
        if (piv[k] != k) {
            int p = piv[k];
            double tr = b[2 * k], ti = b[2 * k + 1];
            b[2 * k] = b[2 * p], b[2 * k + 1] = b[2 * p + 1];
            b[2 * p] = tr, b[2 * p + 1] = ti;
        }
    for (int i = 0; i < n; i++) { /* L y = P b */
        const double *ri = A + 2 * (size_t)i * n;
        for (int k = 0; k < i; k++) {
            double lr = ri[2 * k], li = ri[2 * k + 1], xr = b[2 * k], xi = b[2 * k + 1];
            b[2 * i] -= lr * xr - li * xi;
            b[2 * i + 1] -= lr * xi + li * xr;
        }
    }
    for (int i = n - 1; i >= 0; i--) { /* U x = y */
        const double *ri = A + 2 * (size_t)i * n;
        for (int k = i + 1; k < n; k++) {
            double ur = ri[2 * k], ui = ri[2 * k + 1], xr = b[2 * k], xi = b[2 * k + 1];
            b[2 * i] -= ur * xr - ui * xi;
            b[2 * i + 1] -= ur * xi + ui * xr;
        }
        cdiv(b[2 * i], b[2 * i + 1], ri[2 * i], ri[2 * i + 1], &b[2 * i], &b[2 * i + 1]);
    }
}
