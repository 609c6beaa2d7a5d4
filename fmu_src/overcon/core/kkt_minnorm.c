/* Stage: the KKT solve of redundancy "min-norm": every
 * equation is kept and S = J_R M^-1 J_R^T is singular by the redundancy, so in place of its
 * Cholesky factor the pseudo-inverse S^+ = sum_i u_i u_i^T / s_i^2 over the singular values s_i of
 * B = J_R M^-1/2 (rows: the retained equations) above MIN_NORM_RTOL s_1 (u_i its left singular
 * vectors). S^+ b is the multiplier vector of least norm among those that give the accelerations:
 * the redundant directions are in null(J_R^T) and exert no force. That choice is not physically
 * justified (real joints share their loads by their compliance: redundancy "compliant").
 * The SVD is the one-sided Jacobi of svd.c, run on the shorter side of B so that no vector is
 * forced to zero by the shape (a rank deficiency still gives zero singular values). */
#include <math.h>
#include <string.h>

#include "core.h"

#define MIN_NORM_RTOL 1e-9 /* dynamics.MIN_NORM_RTOL: the rank threshold relative to s_1 */
#define EPS 2.220446049250313e-16
#define ORTHO_TOL 1e-12   /* the kept singular vectors' orthogonality that counts as converged */

/* d->S := S^+ of the retained rows at this configuration (d->J). OVK_SINGULAR when the Jacobi
 * sweeps do not converge (a number that is not meaningful then). */
int ovk_minnorm_factor(const ovk_model *M, ovk_data *d) {
    int nR = M->nR, nh = M->nb * M->nh_b, rows_short = nR <= nh;
    int k = rows_short ? nR : nh, len = rows_short ? nh : nR; /* Jacobi on k vectors of length len */
    double *T = d->red, *U = T + (size_t)nR * nh, *sv = U + (size_t)nR * nR, *P = d->S;
    for (int i = 0; i < nR; i++) { /* B = J_R M^-1/2, row i written densely from its two bodies' slots */
        if (rows_short) {
            double *Ti = T + (size_t)i * nh;
            ovk_row_dense(M, d->J, M->retained[i], M->rbody[2 * i], M->rbody[2 * i + 1], Ti);
            for (int c = 0; c < nh; c++) Ti[c] = Ti[c] * sqrt(M->Minv[c]);
            continue;
        }
        const double *Ji = OVK_JROW(M, d->J, M->retained[i]);
        int kh = M->nh_b;
        for (int c = 0; c < nh; c++) T[(size_t)c * nR + i] = 0.0;
        for (int s2 = 0; s2 < 2; s2++) {
            int b = M->rbody[2 * i + s2];
            if (b < 0 || (s2 == 1 && b == M->rbody[2 * i])) continue;
            for (int k = 0; k < kh; k++)
                T[(size_t)(b * kh + k) * nR + i] = Ji[s2 * kh + k] * sqrt(M->Minv[b * kh + k]);
        }
    }
    /* rows_short: T := U^T B (rows s_i v_i^T), U's rows u_i; else T := V^T B^T (rows s_i u_i^T). The
     * sweeps' own convergence flag is not used: with redundant rows some vectors end at round-off
     * size and pairs of them rotate on forever without touching the others; the vectors kept
     * below are checked orthogonal instead. */
    ovk_jacobi_rows(T, k, len, rows_short ? U : NULL);
    double s1 = 0.0;
    for (int i = 0; i < k; i++) {
        double s = 0.0;
        for (int c = 0; c < len; c++) s += T[(size_t)i * len + c] * T[(size_t)i * len + c];
        sv[i] = sqrt(s);
        if (sv[i] > s1) s1 = sv[i];
    }
    double rtol = (double)(nR > nh ? nR : nh) * EPS, cut = (rtol > MIN_NORM_RTOL ? rtol : MIN_NORM_RTOL) * s1;
    for (int i = 0; i < k; i++)
        for (int j = i + 1; j < k && sv[i] > cut; j++) {
            if (!(sv[j] > cut)) continue;
            double g = 0.0;
            for (int c = 0; c < len; c++) g += T[(size_t)i * len + c] * T[(size_t)j * len + c];
            if (!(fabs(g) <= ORTHO_TOL * sv[i] * sv[j]))
                return ovk_fail(d, OVK_SINGULAR, "redundancy 'min-norm': the SVD of the %d retained rows did not "
                                "converge (singular vectors %d and %d not orthogonal after the Jacobi sweeps)", nR, i, j);
        }
    memset(P, 0, (size_t)nR * nR * sizeof(double));
    for (int i = 0; i < k; i++) {
        if (!(sv[i] > cut)) continue;
        const double *u = rows_short ? U + (size_t)i * nR : T + (size_t)i * nR;
        double w = rows_short ? 1.0 / (sv[i] * sv[i]) : 1.0 / (sv[i] * sv[i] * sv[i] * sv[i]); /* T rows: s_i u_i */
        for (int a = 0; a < nR; a++)
            for (int b = 0; b < nR; b++) P[(size_t)a * nR + b] += u[a] * u[b] * w;
    }
    return OVK_OK;
}

/* B (nR x nc, row-major) := S^+ B with the factor of ovk_minnorm_factor (d->S). */
void ovk_minnorm_solve_many(const ovk_model *M, ovk_data *d, double *B, int nc) {
    int nR = M->nR;
    double *col = d->red; /* the factor's scratch is free again */
    for (int c = 0; c < nc; c++) {
        for (int a = 0; a < nR; a++) col[a] = B[(size_t)a * nc + c];
        for (int a = 0; a < nR; a++) {
            double s = 0.0;
            for (int b = 0; b < nR; b++) s += d->S[(size_t)a * nR + b] * col[b];
            B[(size_t)a * nc + c] = s;
        }
    }
}
