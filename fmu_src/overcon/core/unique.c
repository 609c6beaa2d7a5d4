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
 * The factorisation is bandsvd.c's: A's columns (the equations) each touch their joint's two
 * bodies, so with the bodies listed along a chain a windowed QR keeps a narrow band, the singular
 * values come from its bidiagonal by bisection (an absolute accuracy of a few eps sigma_1, what
 * the thresholds above need) and N by inverse iteration, at O(m w^2 + m^2 w) for a band w
 * instead of a dense SVD's O(m^2 nh) a sweep; the equilibration visits each row's two bodies
 * only. The decisions are the same as numpy's LAPACK SVD wherever a verdict is not a tie at the
 * thresholds (tests/test_uniqueness_along.py holds them equal on every mechanism of the
 * repository and on random linkages; tests/test_bandsvd.py the values and bases themselves).
 * Dimensionless. ovk_unique_rows works in the caller's buffer (ovk_unique_doubles); ovk_unique,
 * for a caller without one, allocates it per call. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"

#define UNIQUE_RTOL 1e-9       /* analysis.DEFAULT_RTOL */
#define UNIQUE_NOISE 100.0     /* analysis.NOISE_FACTOR and analysis.B_NOISE_FACTOR */
#define RUIZ_SWEEPS 50         /* analysis._RUIZ_SWEEPS */
#define RUIZ_TOL 1e-3          /* analysis._RUIZ_TOL */
#define EPS 2.220446049250313e-16

/* The equilibrated A^T (m x nh: kept for ovk_choose_kept), the factorisation's scratch (also
 * ovk_choose_kept's m x nh, and first the rows by their nonzeros), the null basis (m x m at most),
 * the Ruiz scratch (m + nh). ovk_unique_certified needs ovk_unique_cert_doubles only. */
size_t ovk_unique_doubles(int m, int nh) {
    size_t M = (size_t)m, n = (size_t)nh, f = ovk_bsv_doubles(m, nh), s = f > M * n ? f : M * n;
    s = s > 2 * 6 * M ? s : 2 * 6 * M; /* also the rows by their nonzeros (2 nh_b <= 12 each) */
    return M * n + s + M * M + M + n + 1;
}

/* B = A^T (m rows, each by its nonzeros: 2 kh entries, OVK_JROW's layout): round-off rows and
 * columns of A zeroed, then Ruiz. Row e is nonzero only in the columns of its joint's bodies
 * blk[2e], blk[2e + 1] (kh each, slots 0 and 1; -1: none, the ground), so only those are stored
 * and visited (BE: the entry of row e at column c inside IN_BLOCKS). cn (m) and rn (nh): scratch for the max-norms of A's columns (B's
 * rows) and A's rows (B's columns). Returns the round-off floor (0 for A = 0): every entry of a
 * zeroed row or column was at most that. */
#define IN_BLOCKS(e, c, body)                                                                           \
    for (int t_ = 0; t_ < 2; t_++)                                                                     \
        if ((body = blk[2 * (e) + t_]) >= 0 && !(t_ == 1 && body == blk[2 * (e)]))                      \
            for (int c = body * kh; c < (body + 1) * kh; c++)
#define BE(e, c) B[(size_t)(e) * 2 * kh + t_ * kh + (c) - body * kh]
static double equilibrate(double *B, int m, int nh, int kh, const int *blk, double *cn, double *rn, double *dc,
                          double *dr) {
    double amax = 0.0;
    int body;
    if (dc) /* the scalings applied so far, B = diag(dc) B_given diag(dr); 0 marks a zeroed row or column */
        for (int e = 0; e < m; e++) dc[e] = 1.0;
    if (dr)
        for (int c = 0; c < nh; c++) dr[c] = 1.0;
    for (int e = 0; e < m; e++) IN_BLOCKS(e, c, body) amax = fabs(BE(e, c)) > amax ? fabs(BE(e, c)) : amax;
    if (amax == 0.0) return 0.0;
    double floor = UNIQUE_NOISE * (m > nh ? m : nh) * EPS * amax;
    for (int c = 0; c < nh; c++) rn[c] = 0.0;
    for (int e = 0; e < m; e++) IN_BLOCKS(e, c, body) rn[c] = fabs(BE(e, c)) > rn[c] ? fabs(BE(e, c)) : rn[c];
    for (int e = 0; e < m; e++) IN_BLOCKS(e, c, body) /* A's rows (coordinates) of round-off only */
        if (rn[c] <= floor) BE(e, c) = 0.0;
    for (int c = 0; dr && c < nh; c++)
        if (rn[c] <= floor) dr[c] = 0.0;
    for (int e = 0; e < m; e++) { /* A's columns (equations) of round-off only */
        double x = 0.0;
        IN_BLOCKS(e, c, body) x = fabs(BE(e, c)) > x ? fabs(BE(e, c)) : x;
        if (x <= floor) IN_BLOCKS(e, c, body) BE(e, c) = 0.0;
        if (x <= floor && dc) dc[e] = 0.0;
    }
    for (int sweep = 0; sweep < RUIZ_SWEEPS; sweep++) {
        double dev = 0.0;
        for (int c = 0; c < nh; c++) rn[c] = 0.0;
        for (int e = 0; e < m; e++) {
            cn[e] = 0.0;
            IN_BLOCKS(e, c, body) {
                double a = fabs(BE(e, c));
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
        for (int e = 0; e < m; e++) IN_BLOCKS(e, c, body) BE(e, c) = rn[c] * BE(e, c) * cn[e];
        for (int e = 0; dc && e < m; e++) dc[e] *= cn[e];
        for (int c = 0; dr && c < nh; c++) dr[c] *= rn[c];
    }
    return floor;
}

/* Under "compliant", whether equation e is a compliant one (its retained position's ckind). */
static int compliant_equation(const ovk_model *M, int e) {
    for (int p = 0; p < M->nR; p++)
        if (M->retained[p] == e) return M->ckind[p] != 0;
    return 0;
}

/* The position of equation e among the rows the uniqueness judges (the rigid equations under
 * "compliant", every equation otherwise), or -1 for a compliant equation. O(m nR) under
 * "compliant" only (its mechanisms are small); e itself otherwise. */
static int judged_position(const ovk_model *M, int e) {
    if (M->redundancy != OVK_COMPLIANT) return e;
    if (compliant_equation(M, e)) return -1;
    int k = 0;
    for (int f = 0; f < e; f++) k += !compliant_equation(M, f);
    return k;
}

/* The number of rows the uniqueness judges. */
int ovk_unique_judged(const ovk_model *M) {
    int k = 0;
    for (int e = 0; e < M->m; e++) k += judged_position(M, e) >= 0;
    return M->redundancy == OVK_COMPLIANT ? k : M->m;
}

/* The judged rows of J (Phi_h by its nonzeros, laid out as ovk_data.J: OVK_JROW) into B (m rows
 * of 2 kh, the same layout, in judged order) and each one's two bodies into blk (2 m); 1 when one
 * is not finite on its bodies' columns (the only ones a row fills). */
static int judged_rows(const ovk_model *M, const double *J, double *B, int *blk) {
    int kh = M->nh_b, body;
    /* under "compliant" the compliant equations are forces, not constraints: the rigid rest is
     * judged (precheck.analyse_model) and a compliant joint's reaction is unique (its deformation) */
    for (int j = 0; j < M->nj; j++)
        for (int e = 0; e < M->jneq[j]; e++) {
            int k = judged_position(M, M->jrows[(size_t)j * OVK_MAXEQ + e]);
            if (k < 0) continue;
            blk[2 * k] = M->jbi[j], blk[2 * k + 1] = M->jbj[j];
            memcpy(B + (size_t)k * 2 * kh, OVK_JROW(M, J, M->jrows[(size_t)j * OVK_MAXEQ + e]),
                   sizeof(double) * 2 * (size_t)kh);
            IN_BLOCKS(k, c, body) if (!isfinite(BE(k, c))) return 1;
        }
    return 0;
}

size_t ovk_unique_cert_doubles(int m, int nh, int kh) {
    return (size_t)m * (2 * (size_t)kh + 4) + 2 * (size_t)nh + 1; /* B (m x 2 kh), cn, dc, wn, blk; rn, dr */
}

/* Whether the rule's answer at J is known without the factorisation: the judged rows are the
 * equations W holds (the watch's kept rows, W = their rows of Phi_h diag(sc) scaled to unit norm, sc
 * the watch's column scaling at that state, watch_scale.c),
 * and W's certified singular value bounds at the same state (wmin_low <= sigma_min(W),
 * wmax_up >= sigma_max(W); watch_eig.c) prove every singular value of the equilibrated A^T above
 * ten times the rank threshold: then the rank is m, null(A) is empty and every reaction is unique,
 * which is what ovk_unique_rows would find. The proof: A^T = diag(L) (W P) diag(R) with L = the
 * equilibration's row scalings times W's row norms, R = its column scalings over sc, P
 * the projection off the columns the equilibration zeroed (each of round-off only), so
 * sigma_min(A^T) >= min L min R (wmin_low - |W (I - P)|_F) and sigma_1(A^T) <= max L max R
 * wmax_up. 1 when proven; 0 when not (then the factorisation decides). O(m nh_b) in all: the rows
 * are copied and equilibrated by their nonzeros (work: ovk_unique_cert_doubles). */
int ovk_unique_certified(const ovk_model *M, const double *J, double *work, double wmin_low, double wmax_up,
                         const double *sc) {
    int nh = M->nb * M->nh_b, kh = M->nh_b, m = ovk_unique_judged(M), big = m > nh ? m : nh, body;
    if (!(wmin_low > 0.0) || !(wmax_up < INFINITY) || m > nh || !m) return 0;
    double *B = work, *cn = B + (size_t)m * 2 * kh, *rn = cn + m, *dc = rn + nh, *dr = dc + m, *wn = dr + nh;
    int *blk = (int *)(wn + m);
    if (judged_rows(M, J, B, blk)) return 0;
    for (int e = 0; e < m; e++) { /* W's row norms |Phi_h,e diag(sc)|, as given */
        double n2 = 0.0;
        IN_BLOCKS(e, c, body) n2 += BE(e, c) * BE(e, c) * (sc[c] * sc[c]);
        wn[e] = sqrt(n2);
        if (!(wn[e] > 0.0)) return 0;
    }
    double floor = equilibrate(B, m, nh, kh, blk, cn, rn, dc, dr); /* a zeroed column's entries are below it */
    double lmin = INFINITY, lmax = 0.0, rmin = INFINITY, rmax = 0.0, zf2 = 0.0;
    for (int e = 0; e < m; e++) {
        if (dc[e] == 0.0) return 0; /* a row of round-off only: the rank is not m */
        double l = dc[e] * wn[e];
        lmin = l < lmin ? l : lmin, lmax = l > lmax ? l : lmax;
        IN_BLOCKS(e, c, body) {
            if (dr[c] == 0.0) { /* W's entry in a zeroed column, bounded by the floor */
                zf2 += floor * floor * (sc[c] * sc[c]) / (wn[e] * wn[e]);
                continue;
            }
            if (sc[c] == 0.0) return 0; /* a column W dropped as round-off: no bound through W */
            double r = dr[c] / sc[c];
            rmin = r < rmin ? r : rmin, rmax = r > rmax ? r : rmax;
        }
    }
    double low = wmin_low - sqrt(zf2), rt = UNIQUE_RTOL > big * EPS ? UNIQUE_RTOL : big * EPS;
    if (!(low > 0.0) || !(rmax > 0.0)) return 0;
    return lmin * rmin * low > 10.0 * rt * (lmax * rmax * wmax_up);
}

int ovk_unique_rows(const ovk_model *M, const double *J, double *work, int *rank, int *unique) {
    int nh = M->nb * M->nh_b;
    int m = ovk_unique_judged(M), big = m > nh ? m : nh;
    size_t fd = ovk_bsv_doubles(m, nh), scratch = fd > (size_t)m * nh ? fd : (size_t)m * nh;
    scratch = scratch > 2 * 6 * (size_t)m ? scratch : 2 * 6 * (size_t)m; /* as ovk_unique_doubles */
    double *A = work, *F = A + (size_t)m * nh, *N = F + scratch, *cn = N + (size_t)m * m, *rn = cn + m;
    int *blk = (int *)N, kh = M->nh_b, body; /* the judged rows' bodies, in N until the null basis */
    double *B = F; /* the rows by their nonzeros (m x 2 kh <= m x nh), equilibrated there, then A dense */
    if (judged_rows(M, J, B, blk)) return OVK_NONFINITE;
    equilibrate(B, m, nh, kh, blk, cn, rn, NULL, NULL); /* A^T equilibrated: its rows are the equations */
    memset(A, 0, sizeof(double) * (size_t)m * nh);
    for (int e = 0; e < m; e++) IN_BLOCKS(e, c, body) A[(size_t)e * nh + c] = BE(e, c);
    ovk_bsv f;
    int status = ovk_bsv_factor(A, m, nh, F, &f);
    if (status) return status;
    double smax = ovk_bsv_value(&f, 0);
    double tol = (UNIQUE_RTOL > big * EPS ? UNIQUE_RTOL : big * EPS) * smax;
    int p = smax > 0.0 ? ovk_bsv_below(&f, tol) : m, r = m - p; /* p: the dependencies (null(A)) */
    double smin_kept = r > 0 ? ovk_bsv_value(&f, r - 1) : smax;
    double kappa = r > 0 && smin_kept > 0.0 ? smax / smin_kept : 1.0;
    double brt = UNIQUE_NOISE * big * EPS * kappa;
    brt = brt > UNIQUE_RTOL ? brt : UNIQUE_RTOL;
    double limit = brt * smax;
    if (p > 0 && smax > 0.0) ovk_bsv_null(&f, p, 0.1 * tol, N); /* N (m x p): a basis of null(A) */
    for (int j = 0; j < M->nj; j++) {
        const int *rows = M->jrows + (size_t)j * OVK_MAXEQ;
        int cols[OVK_MAXEQ], compliant = 0, ne = M->jneq[j];
        for (int e = 0; e < ne; e++) compliant |= (cols[e] = judged_position(M, rows[e])) < 0;
        if (compliant || !p || !(smax > 0.0)) { /* no dependency (or A = 0): every reaction is unique */
            unique[j] = 1;
            continue;
        }
        double peak = 0.0;
        for (int i = 0; i < nh; i++) { /* row i of B_P = A_P N_P, where A_P has an entry */
            int any = 0;
            for (int e = 0; e < ne; e++) any |= A[(size_t)cols[e] * nh + i] != 0.0;
            if (!any) continue;
            double norm2 = 0.0;
            for (int c = 0; c < p; c++) {
                double b = 0.0;
                for (int e = 0; e < ne; e++) b += A[(size_t)cols[e] * nh + i] * N[(size_t)cols[e] * p + c];
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
    double *work = malloc((ovk_unique_doubles(m, nh) + 1) * sizeof(double));
    if (!work) return ovk_fail(d, OVK_NOMEM, "uniqueness: out of memory (%d equations, %d velocities)", m, nh);
    int status = ovk_rows_in(M, d, y); /* Phi_h at y in d->J, by its nonzeros */
    if (!status) {
        status = ovk_unique_rows(M, d->J, work, rank, unique);
        if (status) ovk_fail(d, status, "uniqueness: a non-finite entry in the constraint Jacobian");
    }
    free(work);
    return status;
}

/* The kept set's packed arrays, as overcon.kernel.Kernel packs them from overcon.model.build_plan
 * (one implementation: the Kernel calls this): rbody (2 nR: the bodies of each kept row's joint),
 * xrows (the positions in lam_R of the kept rows of the friction joints, joints in model order)
 * and fx (nfj x OVK_MAXEQ, friction joints in plan order M->fj: each equation's index into
 * xrows, nx for an eliminated one and the padding). iwork: m + nR ints. Returns nx. */
int ovk_pack_kept(const ovk_model *M, const int *retained, int nR, int *xrows, int *fx, int *rbody, int *iwork) {
    int m = M->m, *pos = iwork, *xpos = iwork + m, nx = 0;
    for (int r = 0; r < m; r++) pos[r] = -1;
    for (int p = 0; p < nR; p++) {
        pos[retained[p]] = p;
        xpos[p] = -1;
    }
    for (int j = 0; j < M->nj; j++) {
        int friction = 0;
        for (int k = 0; k < M->nfj; k++) friction |= M->fj[k] == j;
        for (int e = 0; e < M->jneq[j]; e++) {
            int p = pos[M->jrows[(size_t)j * OVK_MAXEQ + e]];
            if (p < 0) continue;
            rbody[2 * p] = M->jbi[j];
            rbody[2 * p + 1] = M->jbj[j];
            if (friction) {
                xpos[p] = nx;
                xrows[nx++] = p;
            }
        }
    }
    for (int k = 0; k < M->nfj; k++) {
        int j = M->fj[k];
        for (int e = 0; e < OVK_MAXEQ; e++) {
            int p = e < M->jneq[j] ? pos[M->jrows[(size_t)j * OVK_MAXEQ + e]] : -1;
            fx[(size_t)k * OVK_MAXEQ + e] = p >= 0 && xpos[p] >= 0 ? xpos[p] : nx;
        }
    }
    return nx;
}

/* The equations an automatic elimination keeps at the rows J (Phi_h by its nonzeros, OVK_JROW), as
 * overcon.analysis.independent_columns: the first r pivots of the column-pivoted Householder QR
 * of the equilibrated A = Phi_h^T (the pivot: the largest remaining column norm, the first of
 * equals, as LAPACK's dgeqp3), r its rank by the rule of ovk_unique_rows. kept: m flags; work:
 * ovk_unique_doubles(m, nh); iwork: nj + m ints. Returns the status; r into *rank. */
int ovk_choose_kept(const ovk_model *M, const double *J, double *work, int *iwork, int *kept, int *rank) {
    int m = M->m, nh = M->nb * M->nh_b, *perm = iwork + M->nj;
    int status = ovk_unique_rows(M, J, work, rank, iwork);
    if (status) return status;
    double *B = work + (size_t)m * nh; /* A's columns (the equations) as rows, equilibrated */
    memcpy(B, work, (size_t)m * nh * sizeof(double));
    for (int e = 0; e < m; e++) perm[e] = e;
    int steps = m < nh ? m : nh;
    for (int k = 0; k < steps && k < *rank; k++) {
        int best = k;
        double most = -1.0;
        for (int e = k; e < m; e++) {
            double n2 = 0.0;
            for (int c = k; c < nh; c++) n2 += B[(size_t)e * nh + c] * B[(size_t)e * nh + c];
            if (n2 > most) most = n2, best = e;
        }
        if (best != k) {
            for (int c = 0; c < nh; c++) {
                double x = B[(size_t)k * nh + c];
                B[(size_t)k * nh + c] = B[(size_t)best * nh + c];
                B[(size_t)best * nh + c] = x;
            }
            int x = perm[k];
            perm[k] = perm[best];
            perm[best] = x;
        }
        double *v = B + (size_t)k * nh, norm = sqrt(most);
        if (!(norm > 0.0)) break;
        double alpha = v[k] > 0.0 ? -norm : norm, vk = v[k] - alpha, vv = vk * vk;
        for (int c = k + 1; c < nh; c++) vv += v[c] * v[c];
        for (int e = k + 1; e < m && vv > 0.0; e++) { /* H = I - 2 u u^T / u^T u, u = (vk, v[k+1:]) */
            double *w = B + (size_t)e * nh, dot = vk * w[k];
            for (int c = k + 1; c < nh; c++) dot += v[c] * w[c];
            double f = 2.0 * dot / vv;
            w[k] -= f * vk;
            for (int c = k + 1; c < nh; c++) w[c] -= f * v[c];
        }
        v[k] = alpha;
        for (int c = k + 1; c < nh; c++) v[c] = 0.0;
    }
    for (int e = 0; e < m; e++) kept[e] = 0;
    for (int k = 0; k < *rank; k++) kept[perm[k]] = 1;
    return OVK_OK;
}
