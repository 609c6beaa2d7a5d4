/* The singularity monitor's step-end check (overcon.simulate.SingularityMonitor._check_ratio):
 * sigma_min / sigma_max of the kept Jacobian J_R M^-1/2 with unit-norm rows, by a one-sided
 * Jacobi SVD (Hestenes): rotations of pairs of vectors until every pair is orthogonal to working
 * precision; the vectors' norms are then the singular values. Small matrices (tens of rows), so
 * the cyclic sweep is cheap and needs no workspace beyond the matrix. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "core.h"

#define JACOBI_SWEEPS 60 /* quadratic convergence: a handful of sweeps at these sizes */

static double dotn(const double *a, const double *b, int r) {
    double s = 0.0;
    for (int i = 0; i < r; i++) s += a[i] * b[i];
    return s;
}

/* One rotation making vectors a and b (length r) orthogonal; returns 1 if it rotated. */
static int rotate_pair(double *a, double *b, int r) {
    double alpha = dotn(a, a, r), beta = dotn(b, b, r), gamma = dotn(a, b, r);
    if (!(fabs(gamma) > 1e-15 * sqrt(alpha * beta))) return 0;
    double zeta = (beta - alpha) / (2.0 * gamma);
    double t = (zeta >= 0.0 ? 1.0 : -1.0) / (fabs(zeta) + sqrt(1.0 + zeta * zeta));
    double c = 1.0 / sqrt(1.0 + t * t), s = c * t;
    for (int i = 0; i < r; i++) {
        double x = a[i], y = b[i];
        a[i] = c * x - s * y;
        b[i] = s * x + c * y;
    }
    return 1;
}

/* sigma_min / sigma_max of the c vectors of length r in B (c x r, row-major, c <= r; overwritten).
 * Returns 1 if the sweeps did not converge (the ratio is then that of the last sweep). */
int ovk_sv_ratio(double *B, int c, int r, double *ratio) {
    int converged = 0;
    for (int sweep = 0; sweep < JACOBI_SWEEPS && !converged; sweep++) {
        int rotated = 0;
        for (int p = 0; p < c - 1; p++)
            for (int q = p + 1; q < c; q++) rotated += rotate_pair(B + (size_t)p * r, B + (size_t)q * r, r);
        converged = !rotated;
    }
    double lo = INFINITY, hi = 0.0;
    for (int p = 0; p < c; p++) {
        double sv = sqrt(dotn(B + (size_t)p * r, B + (size_t)p * r, r));
        if (sv < lo) lo = sv;
        if (sv > hi) hi = sv;
    }
    *ratio = c ? (hi > 0.0 ? lo / hi : 0.0) : 1.0;
    if (isnan(lo) || isnan(hi)) *ratio = 0.0;
    return !converged;
}

/* r minus its components along the count unit vectors V (length nh each), twice (modified
 * Gram-Schmidt with one re-orthogonalisation: orthogonal to working precision). */
static void project_out(double *r, const double *V, int count, int nh) {
    for (int pass = 0; pass < 2; pass++)
        for (int i = 0; i < count; i++) {
            const double *v = V + (size_t)i * nh;
            double c = dotn(v, r, nh);
            for (int j = 0; j < nh; j++) r[j] -= c * v[j];
        }
}

/* Column a of the null-space basis N (k x nh, unit rows orthogonal to the nR rows of U): the
 * previous basis's row a projected onto the complement when it has a part there (so the basis
 * follows the previous one, in its order: the orientation stays continuous, as the polar
 * alignment of SingularityMonitor._null), else the unit vector e_j with the largest part there. */
static void null_row(const double *U, int nR, const double *Nprev, double *N, int a, int nh) {
    double *r = N + (size_t)a * nh;
    double norm = 0.0;
    if (Nprev) {
        memcpy(r, Nprev + (size_t)a * nh, (size_t)nh * sizeof(double));
        project_out(r, U, nR, nh);
        project_out(r, N, a, nh);
        norm = sqrt(dotn(r, r, nh));
    }
    if (!(norm > 1e-8)) {
        int best = 0;
        double most = -1.0;
        for (int j = 0; j < nh; j++) {
            double part = 1.0;
            for (int i = 0; i < nR; i++) part -= U[(size_t)i * nh + j] * U[(size_t)i * nh + j];
            for (int b = 0; b < a; b++) part -= N[(size_t)b * nh + j] * N[(size_t)b * nh + j];
            if (part > most) most = part, best = j;
        }
        memset(r, 0, (size_t)nh * sizeof(double));
        r[best] = 1.0;
        project_out(r, U, nR, nh);
        project_out(r, N, a, nh);
        norm = sqrt(dotn(r, r, nh));
    }
    for (int j = 0; j < nh; j++) r[j] /= norm;
}

/* The sign of det([J_R; N^T]) (nh x nh): nonzero while J_R keeps full rank, and it changes when
 * J_R passes through a rank loss (SingularityMonitor's crossing test). */
static double det_sign(ovk_sim *s, const double *N) {
    int nR = s->M->nR, nh = s->nh;
    memcpy(s->sq, s->JR, (size_t)nR * nh * sizeof(double));
    memcpy(s->sq + (size_t)nR * nh, N, (size_t)(nh - nR) * nh * sizeof(double));
    if (ovk_lu_factor(s->sq, nh, s->piv)) return 0.0;
    double sign = 1.0;
    for (int k = 0; k < nh; k++) {
        if (s->piv[k] != k) sign = -sign;
        if (s->sq[(size_t)k * nh + k] < 0.0) sign = -sign;
    }
    return sign;
}

/* J_R M^-1/2 with unit-norm rows (SingularityMonitor._jac) into s->JR, from the rows at y. */
static int kept_rows(ovk_sim *s, const double *y, char *msg) {
    const ovk_model *M = s->M;
    int nh = s->nh, status = ovk_rows(M, s->d, y, s->phi, s->J, s->gam);
    if (status) return snprintf(msg, OVK_MSG, "%s", ovk_message(s->d)), status;
    for (int k = 0; k < M->nR; k++) {
        const double *row = s->J + (size_t)M->retained[k] * nh;
        double *out = s->JR + (size_t)k * nh, norm2 = 0.0;
        for (int c = 0; c < nh; c++) {
            out[c] = row[c] * sqrt(M->Minv[c]);
            norm2 += out[c] * out[c];
        }
        double norm = sqrt(norm2);
        for (int c = 0; c < nh; c++) out[c] /= norm;
    }
    return OVK_OK;
}

/* The singular values of J_R (ratio) and the new null-space basis into s->N2 (k x nh). */
static double decompose(ovk_sim *s, int have_prev) {
    int nR = s->M->nR, nh = s->nh, k = nh - nR;
    memcpy(s->svd, s->JR, (size_t)nR * nh * sizeof(double));
    double ratio = 1.0;
    ovk_sv_ratio(s->svd, nR, nh, &ratio); /* the rows become U_i sigma_i */
    for (int i = 0; i < nR; i++) {
        double *u = s->svd + (size_t)i * nh, sv = sqrt(dotn(u, u, nh));
        for (int j = 0; j < nh; j++) u[j] = sv > 0.0 ? u[j] / sv : 0.0;
    }
    for (int a = 0; a < k; a++) null_row(s->svd, nR, have_prev ? s->N : NULL, s->N2, a, nh);
    return ratio;
}

/* The monitor at (t, y) after a step (SingularityMonitor.check), or at the start (first = 1:
 * no previous basis, no crossing test): a sign change of det([J_R; N^T]) with the previous
 * basis N is a crossing; then sigma_min / sigma_max below the tolerance is a singular position
 * (OVK_SINGULAR_POSITION both); else the basis, the sign and the smallest ratio are kept. */
int ovk_sim_monitor(ovk_sim *s, double t, const double *y, int first, char *msg) {
    int nR = s->M->nR, nh = s->nh, k = nh - nR;
    if (!nR) return OVK_OK;
    int status = kept_rows(s, y, msg);
    if (status) return status;
    if (!first && k > 0 && det_sign(s, s->N) != s->sign)
        return snprintf(msg, OVK_MSG, "the motion passed a singular position between t = %.9g s and t = %.9g s "
                        "(the kept constraint Jacobian lost rank on the way)", s->t_prev, t), OVK_SINGULAR_POSITION;
    double ratio = decompose(s, !first);
    if (k > 0) memcpy(s->N, s->N2, (size_t)k * nh * sizeof(double));
    if (ratio < s->min_ratio) s->min_ratio = ratio;
    if (ratio < s->o.ratio_tol)
        return snprintf(msg, OVK_MSG, "t = %.9g s: singular position: the kept constraint Jacobian is rank deficient "
                        "(sigma_min/sigma_max = %.3g < %g)", t, ratio, s->o.ratio_tol), OVK_SINGULAR_POSITION;
    s->sign = det_sign(s, s->N);
    s->t_prev = t;
    return OVK_OK;
}
