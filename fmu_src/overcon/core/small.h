/* Small fixed-size vector and matrix helpers of the core (row-major), inlined into each stage. */
#ifndef OVERCON_CORE_SMALL_H
#define OVERCON_CORE_SMALL_H

#include <math.h>

static inline void mat3mul(const double *A, const double *B, double *C) {
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            C[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
}
static inline void mat3vec(const double *A, const double *x, double *y) {
    for (int i = 0; i < 3; i++) y[i] = A[3 * i] * x[0] + A[3 * i + 1] * x[1] + A[3 * i + 2] * x[2];
}
static inline void mat3tvec(const double *A, const double *x, double *y) { /* A^T x */
    for (int i = 0; i < 3; i++) y[i] = A[i] * x[0] + A[3 + i] * x[1] + A[6 + i] * x[2];
}
static inline void cross3(const double *a, const double *b, double *c) {
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}
static inline void skew3(const double *a, double *S) {
    S[0] = 0.0;   S[1] = -a[2]; S[2] = a[1];
    S[3] = a[2];  S[4] = 0.0;   S[5] = -a[0];
    S[6] = -a[1]; S[7] = a[0];  S[8] = 0.0;
}
static inline double dot3(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static inline void mat2vec(const double *A, const double *x, double *y) {
    y[0] = A[0] * x[0] + A[1] * x[1];
    y[1] = A[2] * x[0] + A[3] * x[1];
}
static inline double sgn(double x) { return (double)((x > 0.0) - (x < 0.0)); }
static inline double maxabs(const double *a, int n) { /* max |a_i|, NaN if any is NaN (numpy's max) */
    double m = 0.0;
    for (int i = 0; i < n; i++) {
        double v = fabs(a[i]);
        if (v != v) return v;
        if (v > m) m = v;
    }
    return m;
}

#endif
