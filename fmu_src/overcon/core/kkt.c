/* Stage: the KKT solve with the scene's elimination (overcon.dynamics.evaluate). Only the retained
 * rows R of Phi_h enter: S = J_R M^-1 J_R^T (M diagonal, kept as Minv), lam_R = S^-1 (J_R M^-1 Q -
 * gamma_R), h' = M^-1 (Q - J_R^T lam_R). Each retained row touches at most two bodies (rbody), so
 * the products run over those bodies' coordinates only. */
#include <math.h>
#include <string.h>

#include "core.h"

/* d->g: gamma of the retained rows, with Baumgarte stabilisation (-2 a Phi_h h - a^2 Phi) for a > 0. */
void ovk_kkt_rhs(const ovk_model *M, ovk_data *d, const double *h) {
    int nh = M->nb * M->nh_b, kh = M->nh_b;
    const int *rb = M->rbody;
    double a = M->baumgarte;
    for (int i = 0; i < M->nR; i++) {
        int row = M->retained[i];
        d->g[i] = d->gam[row];
        if (a > 0.0) {
            double ph_h = 0.0;
            for (int s2 = 0; s2 < 2; s2++) {
                int b = rb[2 * i + s2];
                if (b < 0) continue;
                for (int k = b * kh; k < (b + 1) * kh; k++) ph_h += d->J[(size_t)row * nh + k] * h[k];
            }
            d->g[i] = d->g[i] - 2.0 * a * ph_h - a * a * d->phi[row];
        }
    }
}

/* S, its Cholesky factor (in d->S) and lam_R without friction (d->lamR). OVK_SINGULAR when S is not
 * positive definite (a singular position), OVK_NONFINITE on a non-finite S or right-hand side. */
int ovk_kkt_solve(const ovk_model *M, ovk_data *d) {
    int nR = M->nR, nh = M->nb * M->nh_b, kh = M->nh_b;
    const int *rb = M->rbody;
    const double *J = d->J;
    double *S = d->S;
    for (int i = 0; i < nR; i++) {
        const double *Ji = J + (size_t)M->retained[i] * nh;
        for (int k2 = 0; k2 <= i; k2++) {
            const double *Jk = J + (size_t)M->retained[k2] * nh;
            double s = 0.0;
            for (int s2 = 0; s2 < 2; s2++) { /* bodies shared by the two rows */
                int b = rb[2 * i + s2];
                if (b < 0 || (s2 == 1 && b == rb[2 * i])) continue;
                if (b != rb[2 * k2] && b != rb[2 * k2 + 1]) continue;
                for (int k = b * kh; k < (b + 1) * kh; k++) s += Ji[k] * (M->Minv[k] * Jk[k]);
            }
            S[i * nR + k2] = S[k2 * nR + i] = s;
        }
    }
    for (int i = 0; i < nR * nR; i++)
        if (!isfinite(S[i]))
            return ovk_fail(d, OVK_NONFINITE, "non-finite number in S = Phi_h M^-1 Phi_h^T (row %d)", i / nR);
    int col = M->redundancy == OVK_MIN_NORM ? 0 : ovk_cholesky(S, nR), status; /* redundancy: min-norm */
    if (col)
        return ovk_fail(d, OVK_SINGULAR, "singular position: S = Phi_h M^-1 Phi_h^T is not positive definite "
                        "(Cholesky pivot %d of %d, retained row %d)", col - 1, nR, M->retained[col - 1]);
    if (M->redundancy == OVK_MIN_NORM && (status = ovk_minnorm_factor(M, d))) return status; /* S^+ in d->S */
    for (int i = 0; i < nR; i++) {
        const double *Ji = J + (size_t)M->retained[i] * nh;
        double s = 0.0;
        for (int s2 = 0; s2 < 2; s2++) {
            int b = rb[2 * i + s2];
            if (b < 0 || (s2 == 1 && b == rb[2 * i])) continue;
            for (int k = b * kh; k < (b + 1) * kh; k++) s += M->Minv[k] * Ji[k] * d->Q[k];
        }
        d->lamR[i] = s - d->g[i];
    }
    for (int i = 0; i < nR; i++)
        if (!isfinite(d->lamR[i]))
            return ovk_fail(d, OVK_NONFINITE, "non-finite number in the multipliers' right-hand side (row %d)",
                            M->retained[i]);
    if (M->redundancy == OVK_MIN_NORM)
        ovk_minnorm_solve_many(M, d, d->lamR, 1);
    else
        ovk_cho_solve(S, nR, d->lamR);
    return OVK_OK;
}

/* d->W = S^-1 J_R M^-1 [:, cols]: how the retained multipliers answer a unit friction force on
 * each friction velocity (one column per entry of cols). */
void ovk_kkt_friction_columns(const ovk_model *M, ovk_data *d) {
    if (M->formulation == OVK_FORM_AL) { /* kkt_al.c: the same columns by the AL solve */
        ovk_kkt_al_columns(M, d);
        return;
    }
    int nR = M->nR, nc = M->ncols, nh = M->nb * M->nh_b;
    if (M->redundancy == OVK_COMPLIANT) { /* redundancy: the rigid rows' columns (compliance.c) */
        ovk_compliant_columns(M, d);
        return;
    }
    for (int i = 0; i < nR; i++)
        for (int c = 0; c < nc; c++) {
            int k = M->cols[c];
            d->W[i * nc + c] = M->Minv[k] * d->J[(size_t)M->retained[i] * nh + k];
        }
    if (M->redundancy == OVK_MIN_NORM)
        ovk_minnorm_solve_many(M, d, d->W, nc);
    else
        ovk_cho_solve_many(d->S, nR, d->W, nc);
}

/* lam (m: lam_R at the retained rows, zeros at the eliminated ones) and h' = M^-1 (Q - J_R^T lam_R). */
void ovk_kkt_accelerations(const ovk_model *M, ovk_data *d, double *lam, double *hdot) {
    int nR = M->nR, nh = M->nb * M->nh_b, kh = M->nh_b;
    const int *rb = M->rbody;
    memset(lam, 0, sizeof(double) * M->m);
    for (int i = 0; i < nR; i++) lam[M->retained[i]] = d->lamR[i];
    memset(hdot, 0, sizeof(double) * nh); /* J_R lam_R first */
    for (int i = 0; i < nR; i++) {
        const double *Ji = d->J + (size_t)M->retained[i] * nh;
        for (int s2 = 0; s2 < 2; s2++) {
            int b = rb[2 * i + s2];
            if (b < 0 || (s2 == 1 && b == rb[2 * i])) continue;
            for (int k = b * kh; k < (b + 1) * kh; k++) hdot[k] += Ji[k] * d->lamR[i];
        }
    }
    for (int k = 0; k < nh; k++) hdot[k] = M->Minv[k] * (d->Q[k] - hdot[k]);
}
