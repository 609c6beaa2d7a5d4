/* Stage (formulation AL, solver.singular = "pass"): the acceleration solve of the kept rows R by
 * the augmented Lagrangian method (Bayo & Ledesma 1996; the index-3 AL of the multibody benchmark
 * library, Gonzalez et al. 2006, at the acceleration level). It solves the same equations as
 * kkt.c, M h' + J_R^T lam_R = Q, J_R h' = g (the paper's signs, g = gamma_R with Baumgarte), as
 *     (M + alpha J_R^T J_R) h'_k = Q - J_R^T lam_k + alpha J_R^T g,
 *     lam_{k+1} = lam_k + alpha (J_R h'_k - g),            lam_0 = 0,
 * until the acceleration residual |J_R h'_k - g| is below AL_TOL of its scale. The leading matrix
 * stays positive definite where J_R loses rank (M is), so the solve goes through a singular
 * position. Where J_R has full row rank the fixed point is the eliminated form's lam_R = S^-1 (J_R
 * M^-1 Q - g) (S = J_R M^-1 J_R^T): the friction of the paper is unchanged. Where it does not,
 * lam_0 = 0 keeps lam in the range of J_R, so the iteration tends to the minimum-norm multipliers
 * S^+ (J_R M^-1 Q - g); its error there contracts by 1 / (1 + alpha s) per iteration on a
 * direction of S with eigenvalue s, slowly where s is near 0, so it stops on stagnation (the
 * residual left is in the directions that lose rank, where no acceleration can satisfy it: the
 * step-end projections of project.c take the state back onto the constraints).
 *
 * alpha (decided here): alpha_rel times max_k M_kk / max_k (J^T J)_kk, with M's scale (kg,
 * kg m^2) and the rows' (1 or m): alpha J^T J then outweighs M by about alpha_rel. A direction of
 * S whose eigenvalue is a fraction f of the largest contracts by 1 / (1 + alpha_rel f) an
 * iteration, while the leading matrix's condition number (about alpha_rel) costs digits of the
 * result. The acceleration solve takes AL_ALPHA_DYN = 1e5: its result is the evaluation's y', so
 * its round-off matters (measured on six friction scenes: lam within about 1e-11 of the eliminated
 * form's, relative; with 1e6 it was 2e-10, and the round-off of y' showed as energy noise that kept
 * dopri5 at tolerance 1e-12 from converging); it only stalls near a singular position, where a
 * run interpolates instead (sim_pass.c) and the iteration is the fallback. The projections
 * (project.c) take OVK_AL_ALPHA_PROJ = 1e6: they solve for small corrections, whose round-off is
 * relative to the correction; a larger alpha corrects the directions that lose rank harder, which
 * measured worse (N-four-bar N = 2 at tolerance 1e-12: B0's x 5e-5 m off the 1-DOF motion after
 * 4 s with 1e8, 3e-7 m with 1e6), a smaller one (1e5) leaves the positions short of the
 * constraints there.
 *
 * Structure: M is diagonal and each kept row touches at most two bodies (rbody), so the leading
 * matrix is banded in body order with half bandwidth (max |b_i - b_j| + 1) nh_b - 1 (ovk_al_half_band):
 * it is factored by a banded Cholesky, O(nh p^2) with p the half bandwidth (linear in the number of
 * bodies for a chain numbered along itself, such as the N-four-bar of mechanisms/examples). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"

#define AL_ALPHA_DYN 1e5  /* alpha of the acceleration solve, relative (file header) */
#define AL_TOL 1e-13      /* residual / scale at which the iteration stops */
#define AL_MAX_ITER 100   /* iterations at most (a regular position needs 3-10) */
#define AL_STALL 0.5      /* after 3 iterations, a residual that falls by less than this factor has stalled */

/* The half bandwidth of M + alpha J^T J for any set of rows: every joint's two bodies (a row
 * touches the bodies of its joint only), so the kept rows and all rows share one band. */
int ovk_al_half_band(const ovk_model *M) {
    int kh = M->nh_b, w = 0, nh = M->nb * kh;
    for (int j = 0; j < M->nj; j++) {
        int a = M->jbi[j], b = M->jbj[j];
        if (a >= 0 && b >= 0 && abs(a - b) > w) w = abs(a - b);
    }
    int p = (w + 1) * kh - 1;
    return p < nh ? p : (nh ? nh - 1 : 0);
}

ovk_rowset ovk_al_kept(const ovk_model *M) {
    ovk_rowset rs = {M->nR, M->retained, M->rbody};
    return rs;
}

/* Every equation with its joint's bodies, in d->al_rows (made by ovk_al_make_rows). */
ovk_rowset ovk_al_all(const ovk_model *M, const ovk_data *d) {
    ovk_rowset rs = {M->m, d->al_rows, d->al_rows + M->m};
    return rs;
}

/* d->al_rows: the m equations in order, then each one's two bodies (from the joint table). */
void ovk_al_make_rows(const ovk_model *M, ovk_data *d) {
    int *rows = d->al_rows, *bodies = d->al_rows + M->m;
    for (int r = 0; r < M->m; r++) {
        rows[r] = r;
        bodies[2 * r] = bodies[2 * r + 1] = -1;
    }
    for (int j = 0; j < M->nj; j++)
        for (int e = 0; e < M->jneq[j]; e++) {
            int r = M->jrows[OVK_MAXEQ * j + e];
            bodies[2 * r] = M->jbi[j];
            bodies[2 * r + 1] = M->jbj[j];
        }
}

/* d->al: the band (nh (p + 1)), then the vectors of OVK_AL_SLOT_* in order: BASE, RHS, X, UNIT
 * (nh each), RES, LAMC, ZERO (m each), then the projections' P1, P2, P3 (n = nb nq_b each) and
 * PR1, PR2 (m each). */
static size_t slot_size(const ovk_model *M, int k) {
    if (k < OVK_AL_SLOT_RES) return (size_t)M->nb * (size_t)M->nh_b;
    if (k < OVK_AL_SLOT_P1 || k >= OVK_AL_SLOT_PR1) return (size_t)M->m;
    return (size_t)M->nb * (size_t)M->nq_b;
}
double *ovk_al_slot(const ovk_model *M, const ovk_data *d, int which) {
    size_t at = (size_t)M->nb * (size_t)M->nh_b * ((size_t)d->al_band + 1);
    for (int k = 0; k < which; k++) at += slot_size(M, k);
    return d->al + at;
}
#define slot ovk_al_slot
#define SLOT_BASE OVK_AL_SLOT_BASE
#define SLOT_RHS OVK_AL_SLOT_RHS
#define SLOT_X OVK_AL_SLOT_X
#define SLOT_UNIT OVK_AL_SLOT_UNIT
#define SLOT_RES OVK_AL_SLOT_RES
#define SLOT_LAMC OVK_AL_SLOT_LAMC
#define SLOT_ZERO OVK_AL_SLOT_ZERO
size_t ovk_al_doubles(const ovk_model *M) {
    size_t n = (size_t)M->nb * (size_t)M->nh_b * ((size_t)ovk_al_half_band(M) + 1) + 1;
    for (int k = 0; k < OVK_AL_SLOT_END; k++) n += slot_size(M, k);
    return n;
}

/* y = J v (rs->n) and v += c J^T u (nh): the rows of rs over their two bodies' coordinates. */
static void rows_times(const ovk_model *M, const ovk_data *d, const ovk_rowset *rs, const double *v, double *y) {
    int kh = M->nh_b;
    for (int i = 0; i < rs->n; i++) {
        const double *Ji = OVK_JROW(M, d->J, rs->rows[i]);
        double s = 0.0;
        for (int s2 = 0; s2 < 2; s2++) {
            int b = rs->rbody[2 * i + s2];
            if (b < 0 || (s2 == 1 && b == rs->rbody[2 * i])) continue;
            for (int k = 0; k < kh; k++) s += Ji[s2 * kh + k] * v[b * kh + k];
        }
        y[i] = s;
    }
}
void ovk_rowset_times(const ovk_model *M, const ovk_data *d, const ovk_rowset *rs, const double *v, double *y) {
    rows_times(M, d, rs, v, y);
}
static void rows_t_add(const ovk_model *M, const ovk_data *d, const ovk_rowset *rs, const double *u, double c,
                       double *v) {
    int kh = M->nh_b;
    for (int i = 0; i < rs->n; i++) {
        const double *Ji = OVK_JROW(M, d->J, rs->rows[i]);
        for (int s2 = 0; s2 < 2; s2++) {
            int b = rs->rbody[2 * i + s2];
            if (b < 0 || (s2 == 1 && b == rs->rbody[2 * i])) continue;
            for (int k = 0; k < kh; k++) v[b * kh + k] += c * Ji[s2 * kh + k] * u[i];
        }
    }
}

/* The band factor of M + alpha J^T J of the rows rs in d->J (band row k holds columns k..k+p,
 * then its Cholesky factor U, A = U^T U). OVK_NONFINITE on a non-finite entry; OVK_SINGULAR if a
 * pivot is not positive (M is positive definite, so only round-off beyond repair does that). */
int ovk_al_factor(const ovk_model *M, ovk_data *d, const ovk_rowset *rs, double alpha_rel) {
    int nh = M->nb * M->nh_b, kh = M->nh_b, p = ovk_al_half_band(M), w = p + 1;
    double *A = d->al;
    d->al_band = p;
    double mmax = 0.0, jmax = 0.0;
    for (int k = 0; k < nh; k++)
        if (1.0 / M->Minv[k] > mmax) mmax = 1.0 / M->Minv[k];
    memset(A, 0, sizeof(double) * (size_t)nh * (size_t)w);
    for (int i = 0; i < rs->n; i++) { /* J^T J, its upper band; the diagonal gives alpha's scale */
        const double *Ji = OVK_JROW(M, d->J, rs->rows[i]);
        int b0 = rs->rbody[2 * i], b1 = rs->rbody[2 * i + 1];
        for (int s2 = 0; s2 < 2; s2++) {
            int a = s2 ? b1 : b0;
            if (a < 0 || (s2 == 1 && a == b0)) continue;
            for (int t2 = 0; t2 < 2; t2++) {
                int b = t2 ? b1 : b0;
                if (b < 0 || (t2 == 1 && b == b0) || b < a) continue;
                for (int k = a * kh; k < (a + 1) * kh; k++)
                    for (int l = b * kh; l < (b + 1) * kh; l++)
                        if (l >= k) A[(size_t)k * w + (l - k)] += Ji[s2 * kh + k - a * kh] * Ji[t2 * kh + l - b * kh];
            }
        }
    }
    for (int k = 0; k < nh; k++)
        if (A[(size_t)k * w] > jmax) jmax = A[(size_t)k * w];
    d->al_alpha = jmax > 0.0 ? alpha_rel * mmax / jmax : 0.0;
    for (size_t e = 0; e < (size_t)nh * w; e++) A[e] *= d->al_alpha;
    for (int k = 0; k < nh; k++) A[(size_t)k * w] += 1.0 / M->Minv[k];
    for (size_t e = 0; e < (size_t)nh * w; e++)
        if (!isfinite(A[e]))
            return ovk_fail(d, OVK_NONFINITE, "non-finite number in M + alpha Phi_h^T Phi_h (coordinate %d)",
                            (int)(e / w));
    int bad = ovk_band_cholesky(A, nh, p);
    if (bad)
        return ovk_fail(d, OVK_SINGULAR, "M + alpha Phi_h^T Phi_h is not positive definite (pivot %d of %d)", bad - 1,
                        nh);
    return OVK_OK;
}

/* (U^T U) x = b in place, with the band factor of ovk_al_factor. */
static void band_solve(const ovk_data *d, int nh, double *b) { ovk_band_solve(d->al, nh, d->al_band, b); }

/* The acceleration residual of x: res := J_R x - g (rs->n) and its largest entry, with the scale
 * it is judged against, max_i max(|g_i|, |(J_R x)_i|): the AL iteration's stopping test, also the
 * direct solve's (below). */
static void residual(const ovk_model *M, const ovk_data *d, const ovk_rowset *rs, const double *x, const double *g,
                     double *res, double *rmax, double *scale) {
    rows_times(M, d, rs, x, res);
    *rmax = 0.0, *scale = 0.0;
    for (int i = 0; i < rs->n; i++) {
        double gi = fabs(g[i]), ji = fabs(res[i]);
        if (gi > *scale) *scale = gi;
        if (ji > *scale) *scale = ji;
        res[i] -= g[i];
        if (fabs(res[i]) > *rmax) *rmax = fabs(res[i]);
    }
}

/* The AL iteration (file header) with the factor of ovk_al_factor: x (nh) with M x + J_R^T lam =
 * Q, J_R x = g, and lam (nR) from lam_0 = 0. Iterations in d->al_iterations; d->al_stalled = 1 when
 * it stopped on stagnation (the rank is being lost) or at AL_MAX_ITER rather than at AL_TOL. */
void ovk_al_solve(const ovk_model *M, ovk_data *d, const ovk_rowset *rs, const double *Q, const double *g, double *x,
                  double *lam) {
    int nh = M->nb * M->nh_b, nR = rs->n;
    double *base = slot(M, d, SLOT_BASE), *rhs = slot(M, d, SLOT_RHS), *res = slot(M, d, SLOT_RES);
    double a = d->al_alpha, prev = INFINITY;
    memset(lam, 0, sizeof(double) * (size_t)nR);
    memcpy(base, Q, sizeof(double) * (size_t)nh); /* Q + alpha J_R^T g: the part that does not change */
    rows_t_add(M, d, rs, g, a, base);
    d->al_stalled = 0;
    for (int it = 1;; it++) {
        memcpy(rhs, base, sizeof(double) * (size_t)nh);
        rows_t_add(M, d, rs, lam, -1.0, rhs);
        band_solve(d, nh, rhs);
        memcpy(x, rhs, sizeof(double) * (size_t)nh);
        double rmax = 0.0, scale = 0.0;
        residual(M, d, rs, x, g, res, &rmax, &scale);
        for (int i = 0; i < nR; i++) lam[i] += a * res[i];
        d->al_iterations = it;
        if (!(rmax > AL_TOL * scale)) break; /* also nR = 0, and a NaN the caller's check reports */
        if (it >= AL_MAX_ITER || (it > 3 && rmax > AL_STALL * prev)) {
            d->al_stalled = 1;
            break;
        }
        prev = rmax;
    }
}

/* Where the kept rows are regular the AL's fixed point is the eliminated form's lam_R (file
 * header), which kkt.c's banded Cholesky of S gives directly, at a fraction of the iteration's
 * cost on a long chain (the iteration contracts by 1 / (1 + alpha s) a step on S's small
 * eigenvalues s: a dozen band solves at the N-four-bar's regular positions). Refined by at most
 * DIRECT_REFINE solves with the same factor (S d = J_R h' - g, lam_R += d), it is taken when it
 * meets the AL's own stopping test (the residual at most AL_TOL of its scale): 1, with
 * d->al_direct set (the friction columns use the same factor). It is tried only where the run
 * allows it for the whole step (d->al_allow_direct: sim.c, from the watch's r at the step's start,
 * OVK_DIRECT_RATIO); a Kernel outside a run keeps the iteration. 0 when not allowed, when S has no
 * Cholesky factor or its squared pivots spread by more than 1 / d->al_pivot_min (OVK_PASS_REGULAR
 * unless the caller sets another: the direct acceleration's error along the directions losing rank
 * grows as the inverse cube of their singular value, sim_pass.c), or when the test is not met.
 * Only under redundancy "eliminate" (the AL's rows). */
#define DIRECT_REFINE 2
static int direct(const ovk_model *M, ovk_data *d, const ovk_rowset *kept) {
    d->al_direct = 0, d->al_spread = 0.0;
    if (!d->al_allow_direct) return 0;
    if (M->redundancy != OVK_ELIMINATE || ovk_kkt_solve(M, d)) {
        d->msg[0] = '\0'; /* a failed factor is no failure here: the iteration takes over */
        return 0;
    }
    double lo = INFINITY, hi = 0.0; /* S's Cholesky pivots: their spread bounds how far S is from singular */
    for (int a = 0; a < M->nR; a++) {
        double u = d->S[(size_t)a * (d->sb.band + 1)];
        lo = u * u < lo ? u * u : lo, hi = u * u > hi ? u * u : hi;
    }
    d->al_spread = hi > 0.0 ? lo / hi : 0.0;
    if (!(lo >= (d->al_pivot_min > 0.0 ? d->al_pivot_min : OVK_PASS_REGULAR) * hi)) return 0;
    double *x = slot(M, d, SLOT_X), *res = slot(M, d, SLOT_RES), *lam = slot(M, d, SLOT_LAMC), rmax = 0.0,
           scale = 0.0;
    for (int k = 0;; k++) { /* h' of these multipliers (kkt.c), then the stopping test */
        ovk_kkt_accelerations(M, d, lam, x);
        residual(M, d, kept, x, d->g, res, &rmax, &scale);
        if (!isfinite(rmax)) return 0;
        if (!(rmax > AL_TOL * scale)) break;
        if (k == DIRECT_REFINE) return 0;
        ovk_kkt_refine(M, d, res); /* J_R h' - g = J_R M^-1 Q - g - S lam_R: lam_R += S^-1 res */
        for (int i = 0; i < kept->n; i++) d->lamR[i] += res[i];
    }
    d->al_direct = 1, d->al_iterations = 0, d->al_stalled = 0;
    return 1;
}

/* Formulation AL in place of ovk_kkt_solve: the factor and lam_R without friction (d->lamR), from
 * d->Q and d->g (directly where the kept rows are regular: direct above). The same statuses, but
 * never OVK_SINGULAR at a singular position, except under d->al_direct_only (a run's step in pass
 * mode, sim.c): there OVK_SINGULAR with d->al_refused set where the direct solve is refused, so that
 * the run interpolates instead (sim_pass.c). */
int ovk_kkt_al_solve(const ovk_model *M, ovk_data *d) {
    ovk_rowset kept = ovk_al_kept(M);
    d->al_refused = 0;
    if (direct(M, d, &kept)) return OVK_OK;
    if (d->al_direct_only) {
        d->al_refused = 1;
        return ovk_fail(d, OVK_SINGULAR, "the kept rows are too near a singular position for the direct solve");
    }
    int status = ovk_al_factor(M, d, &kept, AL_ALPHA_DYN);
    if (status) return status;
    ovk_al_solve(M, d, &kept, d->Q, d->g, slot(M, d, SLOT_X), d->lamR);
    for (int i = 0; i < M->nR; i++)
        if (!isfinite(d->lamR[i]))
            return ovk_fail(d, OVK_NONFINITE, "non-finite number in the multipliers (AL, row %d)", M->retained[i]);
    return OVK_OK;
}

/* Formulation AL in place of ovk_kkt_friction_columns: d->W (nR x ncols), the answer of lam_R to a
 * unit friction force on each friction velocity (Q = e_c, g = 0), one AL solve per column. */
void ovk_kkt_al_columns(const ovk_model *M, ovk_data *d) {
    int nR = M->nR, nc = M->ncols, nh = M->nb * M->nh_b;
    double *x = slot(M, d, SLOT_X), *unit = slot(M, d, SLOT_UNIT), *lamc = slot(M, d, SLOT_LAMC);
    double *zero = slot(M, d, SLOT_ZERO);
    memset(unit, 0, sizeof(double) * (size_t)nh);
    ovk_rowset kept = ovk_al_kept(M);
    memset(zero, 0, sizeof(double) * (size_t)nR);
    for (int c = 0; c < nc; c++) {
        unit[M->cols[c]] = 1.0;
        ovk_al_solve(M, d, &kept, unit, zero, x, lamc);
        unit[M->cols[c]] = 0.0;
        for (int i = 0; i < nR; i++) d->W[i * nc + c] = lamc[i];
    }
}
