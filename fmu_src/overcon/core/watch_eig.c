/* The watch's r = sigma_min / sigma_max (watch.c) without a full SVD: the extreme singular values
 * of the weighted kept rows W (nR x nh: the rows of Phi_h equilibrated by watch_scale.c, each scaled
 * to unit norm)
 * are tracked from one check to the next as the extreme eigenvalues of G = W W^T (nR x nR):
 *   sigma_max^2: inverse iteration on s I - G with s just above the largest Rayleigh quotient seen
 *                (s = rho (1 + SHIFT_REL), raised until s I - G admits a Cholesky factor, at last
 *                to Gershgorin's bound on G), which converges at the rate (s - l_1) / (s - l_2)
 *                also where the largest eigenvalues cluster (the many equal loops of the N-four-bar);
 *   sigma_min^2: inverse iteration on G - s I with s = rho (1 - SHIFT_REL) below the smallest
 *                quotient, or, when G - s I has no Cholesky factor (l_min < s), s = -TAU l_max.
 * Each starts from the left singular vector the last estimate left (umin, umax: part of the run's
 * state, saved by sim_state.c, so a restored run repeats the same bits), else from a fixed vector.
 * sigma itself is never read off G (whose eigenvalues below eps l_max are lost to round-off): it is
 * |W^T u| for the iterate u, which keeps r's digits down to about eps / (the relative gap). An
 * estimate stops after at least one iteration that moved sigma by at most EIG_REL sigma + EIG_FLOOR
 * sigma_max (the quotient settled), when the pair (u, v = W^T u / sigma) has |W v - sigma u| <= EIG_REL sigma +
 * EIG_FLOOR sigma_max + EIG_ROUND sigma_max^2 / sigma (the last term: the round-off of the residual
 * itself, eps sigma_max in W^T u divided by sigma in v): G u - sigma^2 u = sigma (W v - sigma u), so
 * G has an eigenvalue within sigma |W v - sigma u| of sigma^2, and W a singular value within
 * |W v - sigma u| of sigma. Stated accuracy, in r: |dr| <= 1e-9 r + 1e-13 + 1e-14 / r (1e-9 relative
 * for r >= 1e-2, 1e-5 relative at r = 1e-4; below r = 1e-6 only that r is that small). Below r =
 * 1e-7 (G_RES) one iteration is all: G's own round-off (eps sigma_max^2) mixes the singular vectors
 * of values that small when several fall to 0 together (a rank drop of N), and r is then an upper
 * bound (a Rayleigh quotient) that lies among those small values; the minimum search inside a step
 * locates an instant where r falls that low to about 1e-8 / |dr/dt|. That the
 * pair is the extreme one is certified by one more Cholesky factor: of s I - G with s = sigma^2 (1 +
 * 2e-9) (then sigma_max is within 1e-9 of the largest), of G - s I with s = sigma^2 - max(2e-9
 * sigma^2, CERT_FLOOR sigma_max^2) (no singular value lies below that); else it iterates on.
 * The iteration count is bounded (EIG_MAX_ITER); an estimate that reaches the bound without that
 * accuracy is used as it is and counted (ovk_sim_info: watch_capped). When even G + TAU l_max I has
 * no Cholesky factor (only a non-finite W does that), sigma_min is reported as 0 (r = 0, below any
 * ratio_tol > 0), so the watch's judge and its whole-Jacobian SVD decide what the instant is.
 *
 * Structure: a row of Phi_h is nonzero on its joint's two bodies only (each body's nh_b columns),
 * so W is kept as nR rows of 2 nh_b values with their bodies, and G_ab is nonzero only when rows a
 * and b share a body. The rows are put in band order (by their lower, then higher body index; the
 * base does not count), in which G is banded with half bandwidth p = the largest distance between
 * two rows sharing a body: a chain numbered along itself (the N-four-bar) gives a p of a few rows,
 * whatever N; a mechanism without that structure gives p up to nR - 1, the dense case, in the same
 * banded Cholesky (linalg.c). A check costs O(nR p^2) for the factors and O(nR (p + nh_b)) an
 * iteration, against O(nR^2 nh) a sweep of the Jacobi SVD it replaces. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"

#define EIG_REL 1e-9      /* relative accuracy of sigma_min and sigma_max (file header) */
#define EIG_FLOOR 1e-13   /* absolute accuracy floor, relative to sigma_max */
#define G_RES 1e-14       /* sigma_min^2 / sigma_max^2 below which G's round-off (eps) hides sigma_min */
#define EIG_ROUND 1e-14   /* the residual's round-off: W^T u's (eps sigma_max) through v = W^T u / sigma */
#define EIG_MAX_ITER 60   /* inverse iterations per extreme and check at most */
#define SHIFT_REL 1e-4    /* the shift's distance from the last Rayleigh quotient, relative */
#define TAU 1e-13         /* sigma_min's last shift: G + TAU l_max I, factored whatever the rank */
#define LADDER 7          /* shifts tried at SHIFT_REL 4^k from the quotient before the last one */
#define CLOSE 6           /* a settled quotient whose vector is not yet accurate: the ladder starts at 4^-CLOSE */
#define CERT_FLOOR 1e-12  /* sigma_min is certified the smallest down to l_min = CERT_FLOOR l_max */
#define CERT_ROUND 1e-13  /* G's round-off taken off the certified bounds, relative to l_max (many eps) */

/* The half bandwidth of the band order of all m equations (linalg.c), or -1 out of memory. */
static int band_bound(const ovk_model *M) {
    int m = M->m, *bodies = malloc((5 * (size_t)m + 2 * (size_t)M->nb + 1) * sizeof(int));
    long long *key = malloc(((size_t)m + 1) * sizeof(long long));
    int band = -1;
    if (bodies && key) {
        int *order = bodies + 2 * (size_t)m, *obody = order + m, *span = obody + 2 * (size_t)m;
        for (int r = 0; r < 2 * m; r++) bodies[r] = -1;
        for (int j = 0; j < M->nj; j++)
            for (int k = 0; k < M->jneq[j]; k++) {
                int r = M->jrows[OVK_MAXEQ * j + k];
                bodies[2 * r] = M->jbi[j], bodies[2 * r + 1] = M->jbj[j];
            }
        band = ovk_band_order(m, M->nb, bodies, NULL, 0, order, obody, key, span);
    }
    free(bodies);
    free(key);
    return band;
}

int ovk_eig_make(ovk_sim *s) {
    const ovk_model *M = s->M;
    int nR = M->redundancy ? M->nwatch : M->nR, kh = M->nh_b, nb = M->nb, m = M->m, nh = nb * kh;
    ovk_watch_eig *e = calloc(1, sizeof *e);
    if (!e) return OVK_NOMEM;
    s->eig = e;
    e->nR = nR, e->kh = kh, e->nb = nb;
    /* G and its factor F in band storage, nR x (p + 1): p at most the band order's half bandwidth of
     * every equation (a set of kept rows, in its own band order, is no wider: the order sorts by the
     * rows' bodies, so the rows between two that share a body are among the whole set's between
     * them), so that the kept rows chosen again during the run fit too: O(nR p), not nR^2 */
    int pmax = band_bound(M);
    if (pmax < 0) return OVK_NOMEM;
    pmax = pmax < nR - 1 ? pmax : (nR > 0 ? nR - 1 : 0);
    size_t nd = 2 * (size_t)nR * 2 * kh + 4 * (size_t)nR + 6 * (size_t)nh + (size_t)m + 2 * (size_t)nR * (size_t)(pmax + 1) + 1;
    size_t ni = 4 * (size_t)nR + 2 * (size_t)m + 2 * (size_t)nb + 1;
    e->mem = malloc(nd * sizeof(double));
    e->imem = malloc(ni * sizeof(int));
    e->key = malloc(((size_t)nR + 1) * sizeof(long long));
    if (!e->mem || !e->imem || !e->key) return ovk_eig_free(e), s->eig = NULL, OVK_NOMEM;
    double *p = e->mem;
    e->w = p, p += (size_t)nR * 2 * kh;
    e->w2 = p, p += (size_t)nR * 2 * kh;
    e->umin = p, p += nR;
    e->umax = p, p += nR;
    e->x = p, p += 2 * (size_t)nR; /* x and the Gershgorin sums */
    e->scale = p, p += nh;
    e->scale_y = p, p += nh;
    e->fscale = p, p += nh;
    e->sscr = p, p += nh + (size_t)m;
    e->z = p, p += nh;
    e->G = p, p += (size_t)nR * (size_t)(pmax + 1);
    e->F = p;
    int *q = e->imem;
    e->order = q, q += nR;
    e->rows = q, q += nR;
    e->body = q, q += 2 * (size_t)nR;
    e->eqbody = q, q += 2 * (size_t)m;
    e->span = q;
    for (int c = 0; c < nh; c++) e->scale[c] = e->scale_y[c] = 1.0;
    for (int r = 0; r < 2 * m; r++) e->eqbody[r] = -1;
    for (int j = 0; j < M->nj; j++)
        for (int k = 0; k < M->jneq[j]; k++) {
            int r = M->jrows[OVK_MAXEQ * j + k];
            e->eqbody[2 * r] = M->jbi[j], e->eqbody[2 * r + 1] = M->jbj[j];
        }
    for (int i = 0; i < nR; i++) e->rows[i] = -1; /* no order made yet */
    return OVK_OK;
}

void ovk_eig_free(ovk_watch_eig *e) {
    if (!e) return;
    free(e->mem);
    free(e->imem);
    free(e->key);
    free(e);
}

/* The band order of the kept rows `rows` and its half bandwidth (file header; linalg.c). */
static void make_order(ovk_watch_eig *e, const int *rows) {
    e->band = ovk_band_order(e->nR, e->nb, e->eqbody, rows, 0, e->order, e->body, e->key, e->span);
    memcpy(e->rows, rows, (size_t)e->nR * sizeof(int));
}

/* The order for the kept rows `rows` (a restored state's), the tracked vectors kept: they were
 * saved in that order. */
void ovk_eig_order(ovk_watch_eig *e, const int *rows) {
    if (memcmp(rows, e->rows, (size_t)e->nR * sizeof(int))) make_order(e, rows);
}

/* The kept rows `rows` (k = e->nR of them) of Phi_h at y, equilibrated (watch_scale.c: fresh, a
 * new column scaling into e->scale) or weighted by the last one (fresh = 0: the rate's rows at a
 * nearby state), of unit norm, on their bodies' columns in band order, into w (nR x 2 nh_b). The
 * frames at y stay in the workspace. */
int ovk_eig_rows(ovk_sim *s, const double *y, const int *rows, double *w, int fresh, char *msg) {
    ovk_watch_eig *e = s->eig;
    int nR = e->nR, kh = e->kh, nh = s->nh, status = ovk_rows_in(s->M, s->d, y);
    if (status) return snprintf(msg, OVK_MSG, "%s", ovk_message(s->d)), status;
    if (memcmp(rows, e->rows, (size_t)nR * sizeof(int))) /* other kept rows: their order, a cold start */
        make_order(e, rows), e->have = 0, fresh = 1;
    const int *rbody = s->d->al_rows + s->M->m; /* each equation's two bodies: its slots of d->J */
    for (int k = 0; k < nR; k++) {
        int r = rows[e->order[k]];
        const double *row = OVK_JROW(s->M, s->d->J, r);
        double *o = w + (size_t)k * 2 * kh;
        for (int t = 0; t < 2; t++) {
            int b = e->body[2 * k + t], slot = b == rbody[2 * r] ? 0 : 1;
            for (int c = 0; c < kh; c++) o[t * kh + c] = b < 0 ? 0.0 : row[slot * kh + c];
        }
    }
    if (fresh)
        ovk_watch_scale(w, nR, 2 * kh, e->body, kh, nh, e->scale, e->sscr);
    else
        ovk_watch_apply(w, nR, 2 * kh, e->body, kh, e->scale);
    return OVK_OK;
}

/* z = W^T u (nh) and sigma = |z|; *res = |W z / sigma - sigma u| (0 when sigma = 0: u is then an
 * exact null vector of W^T). */
static double pair(const ovk_watch_eig *e, const double *w, const double *u, int nh, double *res) {
    int nR = e->nR, kh = e->kh;
    double *z = e->z, ss = 0.0, rr = 0.0;
    memset(z, 0, (size_t)nh * sizeof(double));
    for (int k = 0; k < nR; k++)
        for (int t = 0; t < 2; t++) {
            int b = e->body[2 * k + t];
            if (b < 0) continue;
            for (int c = 0; c < kh; c++) z[b * kh + c] += w[(size_t)k * 2 * kh + t * kh + c] * u[k];
        }
    for (int c = 0; c < nh; c++) ss += z[c] * z[c];
    double sigma = sqrt(ss);
    for (int k = 0; sigma > 0.0 && k < nR; k++) {
        double t2 = 0.0;
        for (int t = 0; t < 2; t++) {
            int b = e->body[2 * k + t];
            if (b < 0) continue;
            for (int c = 0; c < kh; c++) t2 += w[(size_t)k * 2 * kh + t * kh + c] * z[b * kh + c];
        }
        double d = t2 / sigma - sigma * u[k];
        rr += d * d;
    }
    *res = sqrt(rr);
    return sigma;
}

/* The band of G = W W^T (upper, band storage of linalg.c: row a holds columns a..a+p) into e->G. */
static void gram(ovk_watch_eig *e, const double *w) {
    int nR = e->nR, kh = e->kh, p = e->band, wd = p + 1;
    for (int a = 0; a < nR; a++) {
        int last = a + p < nR - 1 ? a + p : nR - 1;
        for (int b = a; b <= last; b++) {
            double g = 0.0;
            for (int t = 0; t < 2; t++)
                for (int t2 = 0; t2 < 2; t2++) {
                    int body = e->body[2 * a + t];
                    if (body < 0 || body != e->body[2 * b + t2]) continue;
                    for (int c = 0; c < kh; c++)
                        g += w[(size_t)a * 2 * kh + t * kh + c] * w[(size_t)b * 2 * kh + t2 * kh + c];
                }
            e->G[(size_t)a * wd + (b - a)] = g;
        }
        for (int b = last + 1; b < a + wd; b++) e->G[(size_t)a * wd + (b - a)] = 0.0;
    }
}

/* Gershgorin's bound on G's largest eigenvalue: the largest absolute row sum. */
static double gershgorin(ovk_watch_eig *e) {
    int nR = e->nR, wd = e->band + 1;
    double *sum = e->x + nR, most = 0.0;
    memset(sum, 0, (size_t)nR * sizeof(double));
    for (int a = 0; a < nR; a++)
        for (int d = 0; d < wd && a + d < nR; d++) {
            double g = fabs(e->G[(size_t)a * wd + d]);
            sum[a] += g;
            if (d) sum[a + d] += g;
        }
    for (int a = 0; a < nR; a++) most = sum[a] > most ? sum[a] : most;
    return most;
}

/* e->F = sign G + shift I (band storage) and its Cholesky factor; 1 when it has one: for sign -1
 * that proves G's eigenvalues below shift, for sign 1 above -shift (to G's round-off). */
static int shifted(ovk_watch_eig *e, double sign, double shift) {
    size_t n = (size_t)e->nR * (size_t)(e->band + 1);
    for (size_t k = 0; k < n; k++) e->F[k] = sign * e->G[k];
    for (int a = 0; a < e->nR; a++) e->F[(size_t)a * (e->band + 1)] += shift;
    return !ovk_band_cholesky(e->F, e->nR, e->band);
}

/* The fixed start of a cold estimate: unit, with no symmetry a mechanism's rows could share. */
static void cold_start(double *u, int n) {
    double ss = 0.0;
    for (int k = 0; k < n; k++) u[k] = 1.5 + cos(1.0 + 2.399963229728653 * k), ss += u[k] * u[k];
    for (int k = 0; k < n; k++) u[k] /= sqrt(ss);
}

/* One extreme from u (unit, nR; in place) by the inverse iteration of the file header: top the
 * largest, else the smallest (lmax: G's largest eigenvalue, for its last shift and the floor).
 * *sigma the estimate; 0 when it met the accuracy and the certificate, 1 at the iteration bound,
 * -1 when no shifted matrix could be factored (sigma: u's quotient as it is). */
static int track(ovk_watch_eig *e, const double *w, double *u, int nh, int top, double lmax, double *sigma,
                 double *bound) {
    int nR = e->nR, factored = 0;
    double s = 0.0, sign = top ? -1.0 : 1.0, dir = top ? 1.0 : -1.0, before = 0.0; /* F = sign (G - s I) */
    for (int it = 0;; it++) {
        double res = 0.0, sg = pair(e, w, u, nh, &res), rho = sg * sg;
        *sigma = sg;
        double big = top ? rho : lmax, tol = EIG_REL * sg + EIG_FLOOR * sqrt(big); /* big: sigma_max^2 */
        /* at least one iteration, which moved sigma by no more than tol: where the residual's
         * round-off hides it (a tiny sigma_min), the quotient still settles to its digits */
        int settled = fabs(sg - before) <= tol || (!top && rho <= G_RES * big); /* below G_RES: G cannot say more */
        if (it > 0 && settled && res <= tol + (sg > 0.0 ? EIG_ROUND * big / sg : 0.0)) {
            /* an eigenpair to the accuracy stated: is it the extreme? */
            double margin = top ? 2.0 * EIG_REL * rho : fmax(2.0 * EIG_REL * rho, CERT_FLOOR * lmax);
            double cert = rho + dir * margin;
            if (!top && cert <= 0.0) return 0;                  /* l_min in [0, rho]: nothing to certify */
            if ((factored && dir * (cert - s) >= 0.0) || shifted(e, sign, -sign * cert)) {
                *bound = cert;                                  /* l_max < cert, or l_min > cert */
                return 0;                                       /* (the factor at hand, or a new one) */
            }
            factored = 0;                                       /* the extreme lies beyond: on */
        }
        if (it == EIG_MAX_ITER) return 1;
        /* the quotient settled while the residual did not: the extreme lies in a cluster of values
         * closer than SHIFT_REL (the equal loops of the N-four-bar, equilibrated), where a shift at
         * SHIFT_REL converges at 1 - gap / SHIFT_REL an iteration; shifts from SHIFT_REL 4^-CLOSE on
         * separate the cluster (a shift inside the spectrum has no Cholesky factor: the next one) */
        int first = it > 0 && settled ? -CLOSE : 0;
        if (factored && dir * (s - rho) > 10.0 * SHIFT_REL * pow(4.0, first) * rho) factored = 0; /* the shift far behind */
        for (int k = first; !factored && k <= LADDER; k++) {
            if (k < LADDER)
                s = rho * (1.0 + dir * SHIFT_REL * pow(4.0, k));
            else
                s = top ? gershgorin(e) * (1.0 + SHIFT_REL) + 1e-300 : -TAU * lmax;
            factored = shifted(e, sign, -sign * s);
        }
        if (!factored) return -1;
        before = sg;
        double *x = e->x, ss = 0.0;
        memcpy(x, u, (size_t)nR * sizeof(double));
        ovk_band_solve(e->F, nR, e->band, x);
        for (int k = 0; k < nR; k++) ss += x[k] * x[k];
        double norm = sqrt(ss);
        if (!(norm > 0.0) || !isfinite(norm)) return -1;
        for (int k = 0; k < nR; k++) u[k] = x[k] / norm;
    }
}

/* sigma_min and sigma_max of the rows w (ovk_eig_rows), tracked from the run's vectors (file
 * header); the estimates that missed their accuracy are counted in s->watch_capped. */
int ovk_eig_extremes(ovk_sim *s, const double *w, double *smin, double *smax) {
    ovk_watch_eig *e = s->eig;
    if (!e->nR) return *smin = *smax = 1.0, OVK_OK;
    if (!e->have) {
        cold_start(e->umax, e->nR);
        cold_start(e->umin, e->nR);
    }
    e->have = 1;
    gram(e, w);
    double cmax = INFINITY, cmin = 0.0; /* the certified bounds of l_max and l_min, to G's round-off */
    int top = track(e, w, e->umax, s->nh, 1, 0.0, smax, &cmax);
    double lmax = *smax * *smax;
    int low = track(e, w, e->umin, s->nh, 0, lmax, smin, &cmin);
    if (low < 0) *smin = 0.0;
    /* G's round-off (a few eps l_max for unit rows) off the bounds: what is left holds for W itself */
    /* An estimate that missed its accuracy (a cluster of small eigenvalues, a long chain's, slows
     * the inverse iteration) is no certificate; bounds still follow at little cost: l_max below
     * Gershgorin's bound, and l_min above c = l_est / 4 when G - c I has a Cholesky factor (then
     * G - c I is positive definite): what the uniqueness's certificate (unique.c) needs to skip its
     * dense factorisation on such mechanisms. */
    if (top != 0) cmax = gershgorin(e);
    if (low != 0) {
        double c = 0.25 * *smin * *smin;
        cmin = c > 0.0 && shifted(e, 1.0, -c) ? c : 0.0;
    }
    cmin -= CERT_ROUND * cmax;
    e->smin_low = cmin > 0.0 ? sqrt(cmin) : 0.0;
    e->smax_up = isfinite(cmax) ? sqrt(cmax * (1.0 + CERT_ROUND)) : INFINITY;
    s->watch_capped += (top != 0) + (low != 0);
    return OVK_OK;
}

/* d sigma / dt = u^T W' v (v = W^T u / sigma) with W' = (e->w2 - e->w) / dt, the forward
 * difference of the rows along the motion; 0 for sigma = 0. */
double ovk_eig_rate(const ovk_sim *s, const double *u, double sigma, double dt) {
    const ovk_watch_eig *e = s->eig;
    int nR = e->nR, kh = e->kh;
    double res = 0.0, out = 0.0;
    if (!(sigma > 0.0) || !nR) return 0.0;
    pair(e, e->w, u, s->nh, &res); /* z = W^T u = sigma v */
    for (int k = 0; k < nR; k++) {
        double row = 0.0;
        for (int t = 0; t < 2; t++) {
            int b = e->body[2 * k + t];
            if (b < 0) continue;
            for (int c = 0; c < kh; c++) {
                size_t at = (size_t)k * 2 * kh + t * kh + c;
                row += (e->w2[at] - e->w[at]) / dt * (e->z[b * kh + c] / sigma);
            }
        }
        out += u[k] * row;
    }
    return out;
}
