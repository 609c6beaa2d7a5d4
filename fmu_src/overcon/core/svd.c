/* Singular values and the accumulated rotations (kkt_minnorm.c's pseudo-inverse) of the small
 * matrices of the core, by a one-sided Jacobi SVD (Hestenes): rotations of pairs of
 * vectors until every pair is orthogonal to working precision; the vectors' norms are then the
 * singular values. Tens of rows: the cyclic sweep is cheap and needs no LAPACK. */
#include <math.h>
#include <string.h>

#include "core.h"

#define JACOBI_SWEEPS 60 /* quadratic convergence: a handful of sweeps at these sizes */

static double dotn(const double *a, const double *b, int r) {
    double s = 0.0;
    for (int i = 0; i < r; i++) s += a[i] * b[i];
    return s;
}

static void apply(double *a, double *b, int r, double c, double s) {
    for (int i = 0; i < r; i++) {
        double x = a[i], y = b[i];
        a[i] = c * x - s * y;
        b[i] = s * x + c * y;
    }
}

/* One rotation making vectors a and b (length r) orthogonal, also applied to the rows qa, qb
 * (length k) of the accumulated rotation when they are given; returns 1 if it rotated. */
static int rotate_pair(double *a, double *b, int r, double *qa, double *qb, int k) {
    double alpha = dotn(a, a, r), beta = dotn(b, b, r), gamma = dotn(a, b, r);
    if (!(fabs(gamma) > 1e-15 * sqrt(alpha * beta))) return 0;
    double zeta = (beta - alpha) / (2.0 * gamma);
    double t = (zeta >= 0.0 ? 1.0 : -1.0) / (fabs(zeta) + sqrt(1.0 + zeta * zeta));
    double c = 1.0 / sqrt(1.0 + t * t), s = c * t;
    apply(a, b, r, c, s);
    if (qa) apply(qa, qb, k, c, s);
    return 1;
}

/* Orthogonalises the k rows (length r) of B in place: B becomes Q B with Q orthogonal (k x k,
 * into Q when not NULL, its rows the left singular vectors u_i of the original B when k <= r);
 * row i of the result is sigma_i v_i^T. Returns 1 if the sweeps did not converge. */
int ovk_jacobi_rows(double *B, int k, int r, double *Q) {
    if (Q) {
        memset(Q, 0, (size_t)k * (size_t)k * sizeof(double));
        for (int i = 0; i < k; i++) Q[(size_t)i * k + i] = 1.0;
    }
    int converged = 0;
    for (int sweep = 0; sweep < JACOBI_SWEEPS && !converged; sweep++) {
        int rotated = 0;
        for (int p = 0; p < k - 1; p++)
            for (int q = p + 1; q < k; q++)
                rotated += rotate_pair(B + (size_t)p * r, B + (size_t)q * r, r, Q ? Q + (size_t)p * k : NULL,
                                       Q ? Q + (size_t)q * k : NULL, k);
        converged = !rotated;
    }
    return !converged;
}
