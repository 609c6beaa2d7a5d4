/* Uniqueness along the motion: from one rank-revealing factorisation of the whole constraint
 * Jacobian at a state (every equation, not only the kept ones), its rank and, per joint, whether
 * its reaction is unique. The rule is the pre-check's one-factorisation test
 * (overcon.analysis.analyse with methods = "svd", the paper's App. B.11), with its equilibration
 * and tolerances, so that a verdict along the run reads as the pre-check's at t = 0:
 *   A = Phi_h^T (n = nh coordinates x m equations), round-off rows and columns
 *       (max-norm <= 100 max(n, m) eps max|A|) set to zero, then Ruiz-equilibrated (rows and
 *       columns to unit max-norm within 1e-3, at most 50 sweeps) (analysis.equilibrate);
 *   A = U S V^T; rank r = #{sigma > max(1e-9, max(n, m) eps) sigma_1} (analysis.DEFAULT_RTOL);
 *   N = the right singular vectors of the m - r other singular values (a basis of null(A));
 *   joint P unique iff max_i ||(A_P N_P)[i, :]||_2 <= b_rtol sigma_1 with
 *   b_rtol = max(1e-9, 100 max(n, m) eps sigma_1 / sigma_r) (analysis.B_NOISE_FACTOR).
 * The SVD is one-sided Jacobi on the rows of A^T (svd.c) with the rotations accumulated: the
 * rows of the rotation are V's columns, the norms of the rotated rows the singular values. The
 * decisions are the same as numpy's LAPACK SVD wherever a verdict is not a tie at the
 * thresholds (tests/test_uniqueness_along.py holds them equal on every mechanism of the
 * repository and on random linkages). Dimensionless. ovk_unique_rows works in the caller's
 * buffer (ovk_unique_doubles); ovk_unique, for a caller without one, allocates it per call. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"

#define UNIQUE_RTOL 1e-9       /* analysis.DEFAULT_RTOL */
#define UNIQUE_NOISE 100.0     /* analysis.NOISE_FACTOR and analysis.B_NOISE_FACTOR */
#define RUIZ_SWEEPS 50         /* analysis._RUIZ_SWEEPS */
#define RUIZ_TOL 1e-3          /* analysis._RUIZ_TOL */
#define EPS 2.220446049250313e-16

size_t ovk_unique_doubles(int m, int nh) {
    size_t M = (size_t)m, n = (size_t)nh;
    return 2 * M * n + M * M + 2 * M + n;
}

/* B = A^T (m rows of nh): round-off rows and columns of A zeroed, then Ruiz. cn (m) and rn (nh):
 * scratch for the max-norms of A's columns (B's rows) and A's rows (B's columns). */
static void equilibrate(double *B, int m, int nh, double *cn, double *rn) {
    double amax = 0.0;
    for (size_t i = 0; i < (size_t)m * nh; i++) amax = fabs(B[i]) > amax ? fabs(B[i]) : amax;
    if (amax == 0.0) return;
    double floor = UNIQUE_NOISE * (m > nh ? m : nh) * EPS * amax;
    for (int c = 0; c < nh; c++) { /* A's rows: coordinates */
        double x = 0.0;
        for (int e = 0; e < m; e++) x = fabs(B[(size_t)e * nh + c]) > x ? fabs(B[(size_t)e * nh + c]) : x;
        if (x <= floor)
            for (int e = 0; e < m; e++) B[(size_t)e * nh + c] = 0.0;
    }
    for (int e = 0; e < m; e++) { /* A's columns: equations */
        double x = 0.0, *row = B + (size_t)e * nh;
        for (int c = 0; c < nh; c++) x = fabs(row[c]) > x ? fabs(row[c]) : x;
        if (x <= floor) memset(row, 0, (size_t)nh * sizeof(double));
    }
    for (int sweep = 0; sweep < RUIZ_SWEEPS; sweep++) {
        double dev = 0.0;
        for (int c = 0; c < nh; c++) rn[c] = 0.0;
        for (int e = 0; e < m; e++) {
            const double *row = B + (size_t)e * nh;
            cn[e] = 0.0;
            for (int c = 0; c < nh; c++) {
                double a = fabs(row[c]);
                cn[e] = a > cn[e] ? a : cn[e];
                rn[c] = a > rn[c] ? a : rn[c];
            }
        }
        for (int c = 0; c < nh; c++)
            if (rn[c] > 0.0 && fabs(1.0 - rn[c]) > dev) dev = fabs(1.0 - rn[c]);
        for (int e = 0; e < m; e++)
            if (cn[e] > 0.0 && fabs(1.0 - cn[e]) > dev) dev = fabs(1.0 - cn[e]);
        if (dev <= RUIZ_TOL) break;
        for (int c = 0; c < nh; c++) rn[c] = rn[c] > 0.0 ? 1.0 / sqrt(rn[c]) : 1.0;
        for (int e = 0; e < m; e++) cn[e] = cn[e] > 0.0 ? 1.0 / sqrt(cn[e]) : 1.0;
        for (int e = 0; e < m; e++) {
            double *row = B + (size_t)e * nh;
            for (int c = 0; c < nh; c++) row[c] = rn[c] * row[c] * cn[e];
        }
    }
}

int ovk_unique_rows(const ovk_model *M, const double *J, double *work, int *rank, int *unique) {
    int m = M->m, nh = M->nb * M->nh_b, big = m > nh ? m : nh;
    double *A = work, *B = A + (size_t)m * nh, *Q = B + (size_t)m * nh, *sv = Q + (size_t)m * m, *cn = sv + m;
    double *rn = cn + m;
    for (size_t i = 0; i < (size_t)m * nh; i++)
        if (!isfinite(J[i])) return OVK_NONFINITE;
    memcpy(B, J, (size_t)m * nh * sizeof(double));
    equilibrate(B, m, nh, cn, rn);
    memcpy(A, B, (size_t)m * nh * sizeof(double)); /* A^T equilibrated, kept for the joints' A_P */
    ovk_jacobi_rows(B, m, nh, Q); /* rows of Q B: sigma_k u_k^T; rows of Q: v_k (V's columns) */
    double smax = 0.0;
    for (int k = 0; k < m; k++) {
        double s2 = 0.0;
        for (int c = 0; c < nh; c++) s2 += B[(size_t)k * nh + c] * B[(size_t)k * nh + c];
        sv[k] = sqrt(s2);
        smax = sv[k] > smax ? sv[k] : smax;
    }
    double tol = (UNIQUE_RTOL > big * EPS ? UNIQUE_RTOL : big * EPS) * smax, smin_kept = smax;
    int r = 0;
    for (int k = 0; k < m; k++)
        if (sv[k] > tol) {
            r++;
            smin_kept = sv[k] < smin_kept ? sv[k] : smin_kept;
        }
    double kappa = r > 0 && smin_kept > 0.0 ? smax / smin_kept : 1.0;
    double brt = UNIQUE_NOISE * big * EPS * kappa;
    brt = brt > UNIQUE_RTOL ? brt : UNIQUE_RTOL;
    double limit = brt * smax;
    for (int j = 0; j < M->nj; j++) {
        const int *cols = M->jrows + (size_t)j * OVK_MAXEQ;
        double peak = 0.0;
        for (int i = 0; i < nh; i++) { /* row i of B_P = A_P N_P over the null vectors */
            double norm2 = 0.0;
            for (int k = 0; k < m; k++) {
                if (sv[k] > tol) continue;
                double b = 0.0;
                for (int e = 0; e < M->jneq[j]; e++) b += A[(size_t)cols[e] * nh + i] * Q[(size_t)k * m + cols[e]];
                norm2 += b * b;
            }
            peak = sqrt(norm2) > peak ? sqrt(norm2) : peak;
        }
        unique[j] = peak == 0.0 || (limit > 0.0 && peak <= limit);
    }
    *rank = r;
    return OVK_OK;
}

int ovk_unique(const ovk_model *M, ovk_data *d, const double *y, int *rank, int *unique) {
    if (!M || !d || !y || !rank || !unique) return OVK_INVALID;
    if (d->status) return d->status;
    int m = M->m, nh = M->nb * M->nh_b;
    double *mem = malloc((2 * (size_t)m + (size_t)m * nh + ovk_unique_doubles(m, nh) + 1) * sizeof(double));
    if (!mem) return ovk_fail(d, OVK_NOMEM, "uniqueness: out of memory (%d equations, %d velocities)", m, nh);
    double *phi = mem, *gam = phi + m, *J = gam + m, *work = J + (size_t)m * nh;
    int status = ovk_rows(M, d, y, phi, J, gam);
    if (!status) {
        status = ovk_unique_rows(M, J, work, rank, unique);
        if (status) ovk_fail(d, status, "uniqueness: a non-finite entry in the constraint Jacobian");
    }
    free(mem);
    return status;
}
