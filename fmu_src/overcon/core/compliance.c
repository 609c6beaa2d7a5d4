/* Stage: the KKT solve of redundancy "compliant" (and its axis
 * forces). The equations of a compliant joint are not constraints but a spring-damper on
 * their violation: their multipliers are known from the state,
 *   scalar values:   lam = k Phi + d Phi_h h           (per equation: N/m, N.s/m or N.m/rad, N.m.s/rad)
 *   per-axis values: lam = U^T K U Phi + U^T D U Phi_h h, K = F diag(k) F^T, D likewise,
 * F the joint frame in global axes (R_i times the packed frame), U the equations' directions in
 * global axes (translational rows: body b's velocity columns; rotational rows: its angular
 * columns, body axes turned to global; b = body i, or body j when i is the base). With the
 * paper's signs, -Phi_h^T lam pulls the joint together as a constraint's reaction would, so the
 * compliant joints' reactions (outputs.c) come from their deformation and their friction from
 * those reactions: the friction stage reads lam_R at their rows, where W is zero.
 * The rigid retained rows are then the eliminated problem of kkt.c with those forces applied:
 * ovk_kkt_solve and ovk_kkt_friction_columns run on a view of the model and workspace restricted
 * to the rigid rows (packed: rigpos, rigrows, rigbody; their band order d->sb_rigid), so S, its
 * banded Cholesky factor and W have one implementation. h' = M^-1 (Q - J_R^T lam_R) over all
 * retained rows (kkt.c) then holds both. */
#include <math.h>
#include <string.h>

#include "core.h"

size_t ovk_redundancy_doubles(const ovk_model *M) {
    size_t nR = (size_t)M->nR, nh = (size_t)M->nb * (size_t)M->nh_b, nc = (size_t)M->ncols, nrig = (size_t)M->nrig;
    if (M->redundancy == OVK_MIN_NORM) return nR * nh + nR * nR + (nR > nh ? nR : nh); /* T, U, singular values */
    if (M->redundancy == OVK_COMPLIANT) return 2 * nrig + nh + nrig * nc;             /* g_r, lam_r, Q - J_c^T lam_c, W_r */
    return 0;
}

static int in_range(const int *a, int n, int lo, int hi) { /* every a[i] in [lo, hi) */
    for (int i = 0; i < n; i++)
        if (a[i] < lo || a[i] >= hi) return 0;
    return 1;
}

/* The redundancy block of the model, checked before anything is sized from it (ovk_make_data). */
int ovk_check_redundancy(const ovk_model *M, ovk_data *d) {
    if (M->redundancy == OVK_ELIMINATE) return OVK_OK; /* the block is not read */
    if (M->redundancy != OVK_MIN_NORM && M->redundancy != OVK_COMPLIANT)
        return ovk_fail(d, OVK_INVALID, "model: redundancy %d is not eliminate (0), min-norm (1) or compliant (2)",
                        M->redundancy);
    int unpacked = M->nwatch == -1 && M->nfull == -1; /* no watch rows: evaluations only (sim.c refuses a run) */
    if (!unpacked && (M->nwatch < 0 || M->nwatch > M->m || M->nfull < 0 || M->nfull > M->m ||
                      !in_range(M->watch, M->nwatch, 0, M->m) || !in_range(M->full, M->nfull, 0, M->m)))
        return ovk_fail(d, OVK_INVALID, "model: %d watched rows, %d rows of the whole Jacobian: out of range [0, %d]",
                        M->nwatch, M->nfull, M->m);
    if (M->redundancy == OVK_MIN_NORM) return OVK_OK;
    int nh = M->nb * M->nh_b;
    if (M->nrig < 0 || M->nrig > M->nR || M->nax < 0 || M->nax > M->nj || !in_range(M->ckind, M->nR, 0, 3) ||
        !in_range(M->rigpos, M->nrig, 0, M->nR) || !in_range(M->rigrows, M->nrig, 0, M->m) ||
        !in_range(M->rigbody, 2 * M->nrig, -1, M->nb))
        return ovk_fail(d, OVK_INVALID, "model: the compliant block (%d rigid rows, %d per-axis joints) is out of range",
                        M->nrig, M->nax);
    for (int i = 0; i < M->nrig; i++)
        if (M->ckind[M->rigpos[i]] != 0)
            return ovk_fail(d, OVK_INVALID, "model: rigid row %d sits at a compliant retained position %d", i,
                            M->rigpos[i]);
    for (int a = 0; a < M->nax; a++) {
        const int *ai = M->axi + OVK_NAXI * a;
        int ok = ai[0] >= -1 && ai[0] < M->nb && ai[1] >= -1 && ai[1] < M->nb && (ai[0] >= 0 || ai[1] >= 0) &&
                 ai[2] >= 0 && ai[2] <= 3 && ai[3] >= 0 && ai[3] <= 3 && M->nh_b == 6 && nh > 0 &&
                 in_range(ai + 4, ai[2], 0, M->nR) && in_range(ai + 7, ai[3], 0, M->nR);
        if (!ok)
            return ovk_fail(d, OVK_INVALID, "model: per-axis compliant joint %d (bodies %d and %d, %d + %d rows) is "
                            "not one the core takes", a, ai[0], ai[1], ai[2], ai[3]);
    }
    return OVK_OK;
}

/* Phi_h h of the retained row at position p (the row's bodies only: it is zero elsewhere). */
double ovk_row_rate(const ovk_model *M, const ovk_data *d, int p, const double *h) {
    int kh = M->nh_b, row = M->retained[p];
    const double *Jr = OVK_JROW(M, d->J, row);
    double s = 0.0;
    for (int s2 = 0; s2 < 2; s2++) {
        int b = M->rbody[2 * p + s2];
        if (b < 0 || (s2 == 1 && b == M->rbody[2 * p])) continue;
        for (int k = 0; k < kh; k++) s += Jr[s2 * kh + k] * h[b * kh + k];
    }
    return s;
}

/* Group rot (0 translational, 1 rotational) of per-axis compliant joint a at the rows of d: its
 * row count n (<= 3), FU = F^T U (joint-frame components of each row's direction: FU[x][e]),
 * and each row's Phi and Phi_h h (module docstring). The force law below and the energy outputs
 * (energy.c: 1/2 sum_x k_x (FU Phi)_x^2, damper power sum_x d_x (FU Phi_h h)_x^2) read it. */
int ovk_axis_group(const ovk_model *M, const ovk_data *d, int a, int rot, const double *h, double FU[3][3],
                   double *phi, double *rate) {
    const int *ai = M->axi + OVK_NAXI * a;
    const double *ap = M->axp + OVK_NAXP * a, *Ri = d->f.R + 9 * ovk_slot(M, ai[0]);
    int b = ai[0] >= 0 ? ai[0] : ai[1], n = ai[2 + rot];
    const int *pos = ai + 4 + 3 * rot;
    const double *Rb = d->f.R + 9 * b;
    double F[9];
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) F[3 * r + c] = Ri[3 * r] * ap[c] + Ri[3 * r + 1] * ap[3 + c] + Ri[3 * r + 2] * ap[6 + c];
    for (int e = 0; e < n; e++) {
        int row = M->retained[pos[e]], slot = M->rbody[2 * pos[e]] == b ? 0 : 1; /* body b's slot of the row */
        const double *Je = OVK_JROW(M, d->J, row) + (size_t)slot * M->nh_b + 3 * rot;
        double u[3];
        for (int x = 0; x < 3; x++) u[x] = rot ? Rb[3 * x] * Je[0] + Rb[3 * x + 1] * Je[1] + Rb[3 * x + 2] * Je[2] : Je[x];
        for (int x = 0; x < 3; x++) FU[x][e] = F[x] * u[0] + F[3 + x] * u[1] + F[6 + x] * u[2];
        phi[e] = d->phi[M->retained[pos[e]]];
        rate[e] = ovk_row_rate(M, d, pos[e], h);
    }
    return n;
}

/* The multipliers of per-axis compliant joint a into d->lamR (module docstring). */
static void axis_forces(const ovk_model *M, ovk_data *d, int a, const double *h) {
    const int *ai = M->axi + OVK_NAXI * a;
    const double *ap = M->axp + OVK_NAXP * a;
    for (int rot = 0; rot < 2; rot++) {
        const int *pos = ai + 4 + 3 * rot;
        const double *kv = ap + 9 + 6 * rot, *dv = kv + 3;
        double FU[3][3], phi[3], rate[3];
        int n = ovk_axis_group(M, d, a, rot, h, FU, phi, rate);
        for (int e = 0; e < n; e++) {
            double s = 0.0;
            for (int f = 0; f < n; f++) {
                double kk = 0.0, dd = 0.0;
                for (int x = 0; x < 3; x++) {
                    kk += FU[x][e] * kv[x] * FU[x][f];
                    dd += FU[x][e] * dv[x] * FU[x][f];
                }
                s += kk * phi[f] + dd * rate[f];
            }
            d->lamR[pos[e]] = s;
        }
    }
}

/* The view of M and d restricted to the rigid retained rows: the problem of kkt.c, with d's
 * buffers for S, its right-hand sides, J and the frames, the rigid rows' band order, and the
 * scratch g_r, lam_r, Q - J_c^T lam_c, W_r. */
static void rigid_view(const ovk_model *M, ovk_data *d, ovk_model *Mr, ovk_data *dr) {
    int nrig = M->nrig, nh = M->nb * M->nh_b;
    *Mr = *M;
    Mr->nR = nrig;
    Mr->retained = M->rigrows;
    Mr->rbody = M->rigbody;
    Mr->redundancy = OVK_ELIMINATE;
    *dr = *d;
    dr->sb = d->sb_rigid;
    dr->g = d->red;
    dr->lamR = dr->g + nrig;
    dr->Q = dr->lamR + nrig;
    dr->W = dr->Q + nh;
}

/* d->lamR: the compliant rows' spring-damper multipliers and the rigid rows' solve with those
 * forces applied (module docstring); d->S the rigid rows' banded Cholesky factor (in their band
 * order d->sb_rigid). Statuses as
 * ovk_kkt_solve's (a singular position of the rigid rows), with its message. */
int ovk_compliant_solve(const ovk_model *M, ovk_data *d, const double *h) {
    int nR = M->nR, nh = M->nb * M->nh_b, kh = M->nh_b;
    for (int p = 0; p < nR; p++)
        if (M->ckind[p] == 1) {
            int row = M->retained[p];
            d->lamR[p] = M->ck[row] * d->phi[row] + M->cd[row] * ovk_row_rate(M, d, p, h);
        }
    for (int a = 0; a < M->nax; a++) axis_forces(M, d, a, h);
    ovk_model Mr;
    ovk_data dr;
    rigid_view(M, d, &Mr, &dr);
    memcpy(dr.Q, d->Q, sizeof(double) * nh);
    for (int p = 0; p < nR; p++) { /* Q - J_c^T lam_c */
        if (!M->ckind[p]) continue;
        const double *Jp = OVK_JROW(M, d->J, M->retained[p]);
        for (int s2 = 0; s2 < 2; s2++) {
            int b = M->rbody[2 * p + s2];
            if (b < 0 || (s2 == 1 && b == M->rbody[2 * p])) continue;
            for (int k = 0; k < kh; k++) dr.Q[b * kh + k] -= Jp[s2 * kh + k] * d->lamR[p];
        }
    }
    for (int i = 0; i < M->nrig; i++) dr.g[i] = d->g[M->rigpos[i]];
    if (!M->nrig) return OVK_OK;
    int status = ovk_kkt_solve(&Mr, &dr);
    if (status) {
        memcpy(d->msg, dr.msg, sizeof d->msg);
        return status;
    }
    for (int i = 0; i < M->nrig; i++) d->lamR[M->rigpos[i]] = dr.lamR[i];
    return OVK_OK;
}

/* d->W (nR x ncols): the rigid rows' answer to unit friction forces (kkt.c on the view), zero at
 * the compliant rows, whose multipliers the state fixes. After ovk_compliant_solve. */
void ovk_compliant_columns(const ovk_model *M, ovk_data *d) {
    int nc = M->ncols;
    memset(d->W, 0, sizeof(double) * (size_t)M->nR * nc);
    if (!M->nrig) return;
    ovk_model Mr;
    ovk_data dr;
    rigid_view(M, d, &Mr, &dr);
    ovk_kkt_friction_columns(&Mr, &dr);
    for (int i = 0; i < M->nrig; i++)
        memcpy(d->W + (size_t)M->rigpos[i] * nc, dr.W + (size_t)i * nc, sizeof(double) * nc);
}
