/* Stage: the KKT solve with the scene's elimination. Only the retained
 * rows R of Phi_h enter: S = J_R M^-1 J_R^T (M diagonal, kept as Minv), lam_R = S^-1 (J_R M^-1 Q -
 * gamma_R), h' = M^-1 (Q - J_R^T lam_R). Each retained row touches at most two bodies (rbody), so
 * the products run over those bodies' coordinates only, and S_ab is nonzero only when rows a and
 * b share a body: S is built and factored in the band order of the workspace (d->sb, made once
 * per model by linalg.c ovk_band_order), where it is banded with half bandwidth p (a few rows for
 * a chain whose bodies are numbered along it, up to nR - 1 otherwise): O(nR p) entries, a banded
 * Cholesky in O(nR p^2), and O(nR p) a solve. The right-hand sides go into band order and the
 * solutions back (d->Sx); lam_R, W and the messages keep the retained order. A model whose
 * retained order is no wider keeps it (ovk_band_order's keep): then the entries (each summed as
 * row b's bodies in rbody's order, b the later row), the factor and the solves are those of a
 * dense Cholesky in that order to the bit, the terms outside the band being exact zeros. */
#include <math.h>
#include <string.h>

#include "core.h"

/* d->g: gamma of the retained rows, with Baumgarte stabilisation (-2 a Phi_h h - a^2 Phi) for a > 0. */
void ovk_kkt_rhs(const ovk_model *M, ovk_data *d, const double *h) {
    int kh = M->nh_b;
    const int *rb = M->rbody;
    double a = M->baumgarte;
    for (int i = 0; i < M->nR; i++) {
        int row = M->retained[i];
        d->g[i] = d->gam[row];
        if (a > 0.0) {
            double ph_h = 0.0;
            const double *Jr = OVK_JROW(M, d->J, row);
            for (int s2 = 0; s2 < 2; s2++) {
                int b = rb[2 * i + s2];
                if (b < 0 || (s2 == 1 && b == rb[2 * i])) continue;
                for (int k = 0; k < kh; k++) ph_h += Jr[s2 * kh + k] * h[b * kh + k];
            }
            if (d->phit[row] != 0.0) ph_h += d->phit[row]; /* a driver: Phi' = Phi_h h + Phi_t */
            d->g[i] = d->g[i] - 2.0 * a * ph_h - a * a * d->phi[row];
        }
    }
}

/* B (nR x nc, retained order) := S^-1 B with the band factor in d->S: gathered into band order in
 * d->Sx, solved, scattered back. */
static void band_solve(const ovk_model *M, ovk_data *d, double *B, int nc) {
    int nR = M->nR;
    const int *order = d->sb.order;
    for (int a = 0; a < nR; a++)
        memcpy(d->Sx + (size_t)a * nc, B + (size_t)order[a] * nc, sizeof(double) * nc);
    ovk_band_solve_many(d->S, nR, d->sb.band, d->Sx, nc);
    for (int a = 0; a < nR; a++)
        memcpy(B + (size_t)order[a] * nc, d->Sx + (size_t)a * nc, sizeof(double) * nc);
}

/* S in band order, its banded Cholesky factor (in d->S) and lam_R without friction (d->lamR).
 * OVK_SINGULAR when S is not positive definite (a singular position), OVK_NONFINITE on a
 * non-finite S or right-hand side; both name the retained row (its equation) where it showed. */
int ovk_kkt_solve(const ovk_model *M, ovk_data *d) {
    int nR = M->nR, kh = M->nh_b, p = d->sb.band, w = p + 1;
    const int *rb = M->rbody, *order = d->sb.order, *body = d->sb.body;
    const double *J = d->J;
    double *S = d->S;
    for (int a = 0; a < nR; a++) { /* row a of the band: columns a..a+p */
        int ia = order[a];
        const double *Ja = OVK_JROW(M, J, M->retained[ia]);
        int last = a + p < nR - 1 ? a + p : nR - 1;
        for (int b = a; b <= last; b++) { /* S_ab over the bodies of row b (rbody's order) that row a shares */
            int i = order[b];
            const double *Jb = OVK_JROW(M, J, M->retained[i]);
            double s = 0.0;
            for (int s2 = 0; s2 < 2; s2++) {
                int c = rb[2 * i + s2];
                if (c < 0 || (s2 == 1 && c == rb[2 * i]) || (c != body[2 * a] && c != body[2 * a + 1])) continue;
                int sa = c == rb[2 * ia] ? 0 : 1; /* row a's slot of body c */
                for (int k = 0; k < kh; k++) s += Jb[s2 * kh + k] * (M->Minv[c * kh + k] * Ja[sa * kh + k]);
            }
            if (!isfinite(s))
                return ovk_fail(d, OVK_NONFINITE, "non-finite number in S = Phi_h M^-1 Phi_h^T (row %d)",
                                M->retained[order[a]]);
            S[(size_t)a * w + (b - a)] = s;
        }
    }
    int col = M->redundancy == OVK_MIN_NORM ? 0 : ovk_band_cholesky(S, nR, p), status; /* redundancy: min-norm */
    if (col)
        return ovk_fail(d, OVK_SINGULAR, "singular position: S = Phi_h M^-1 Phi_h^T is not positive definite "
                        "(Cholesky pivot %d of %d, retained row %d)", col - 1, nR, M->retained[order[col - 1]]);
    if (M->redundancy == OVK_MIN_NORM && (status = ovk_minnorm_factor(M, d))) return status; /* S^+ in d->S */
    for (int i = 0; i < nR; i++) {
        const double *Ji = OVK_JROW(M, J, M->retained[i]);
        double s = 0.0;
        for (int s2 = 0; s2 < 2; s2++) {
            int b = rb[2 * i + s2];
            if (b < 0 || (s2 == 1 && b == rb[2 * i])) continue;
            for (int k = 0; k < kh; k++) s += M->Minv[b * kh + k] * Ji[s2 * kh + k] * d->Q[b * kh + k];
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
        band_solve(M, d, d->lamR, 1);
    return OVK_OK;
}

/* r (nR, retained order) := S^-1 r with the band factor of the last ovk_kkt_solve (kkt_al.c's
 * refinement of a direct solve). */
void ovk_kkt_refine(const ovk_model *M, ovk_data *d, double *r) { band_solve(M, d, r, 1); }

/* d->W = S^-1 J_R M^-1 [:, cols]: how the retained multipliers answer a unit friction force on
 * each friction velocity (one column per entry of cols). */
void ovk_kkt_friction_columns(const ovk_model *M, ovk_data *d) {
    if (M->formulation == OVK_FORM_AL && !d->al_direct) { /* kkt_al.c: the same columns by the AL solve */
        ovk_kkt_al_columns(M, d);
        return;
    }
    int nR = M->nR, nc = M->ncols, kh = M->nh_b;
    if (M->redundancy == OVK_COMPLIANT) { /* redundancy: the rigid rows' columns (compliance.c) */
        ovk_compliant_columns(M, d);
        return;
    }
    for (int i = 0; i < nR; i++) {
        const double *Ji = OVK_JROW(M, d->J, M->retained[i]);
        int b0 = M->rbody[2 * i], b1 = M->rbody[2 * i + 1];
        for (int c = 0; c < nc; c++) { /* the row's entry at velocity k: zero off its two bodies */
            int k = M->cols[c], b = k / kh;
            double v = b == b0 ? Ji[k - b * kh] : b == b1 ? Ji[kh + k - b * kh] : 0.0;
            d->W[i * nc + c] = M->Minv[k] * v;
        }
    }
    if (M->redundancy == OVK_MIN_NORM)
        ovk_minnorm_solve_many(M, d, d->W, nc);
    else
        band_solve(M, d, d->W, nc);
}

/* lam (m: lam_R at the retained rows, zeros at the eliminated ones) and h' = M^-1 (Q - J_R^T lam_R). */
void ovk_kkt_accelerations(const ovk_model *M, ovk_data *d, double *lam, double *hdot) {
    int nR = M->nR, nh = M->nb * M->nh_b, kh = M->nh_b;
    const int *rb = M->rbody;
    memset(lam, 0, sizeof(double) * M->m);
    for (int i = 0; i < nR; i++) lam[M->retained[i]] = d->lamR[i];
    memset(hdot, 0, sizeof(double) * nh); /* J_R lam_R first */
    for (int i = 0; i < nR; i++) {
        const double *Ji = OVK_JROW(M, d->J, M->retained[i]);
        for (int s2 = 0; s2 < 2; s2++) {
            int b = rb[2 * i + s2];
            if (b < 0 || (s2 == 1 && b == rb[2 * i])) continue;
            for (int k = 0; k < kh; k++) hdot[b * kh + k] += Ji[s2 * kh + k] * d->lamR[i];
        }
    }
    for (int k = 0; k < nh; k++) hdot[k] = M->Minv[k] * (d->Q[k] - hdot[k]);
}
