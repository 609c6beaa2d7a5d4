/* The singularity watch of a run (sim.c; the retired Python watch's names are kept in the
 * parentheses below, as the messages are): after every accepted step
 * r = sigma_min / sigma_max of the kept Jacobian J_R equilibrated (watch_scale.c: mass-free, as the
 * pre-check's decision matrix; unit-norm rows) and its rate dr/dt
 * (ds_k/dt = u_k^T J' v_k, J' by a forward difference of J along q' = the integrator's
 * derivative); a step that starts with r falling and ends with r rising holds a minimum of r,
 * located by golden section on the dense output; r below ratio_tol is a singular position,
 * judged by the whole Jacobian's numerical rank: the mechanism's (OVK_SINGULAR_POSITION) or only
 * the kept set's (an expired elimination). An expired elimination is chosen again (pivoted QR,
 * unique.c) when the motion does not depend on it (no friction joint with a nonzero law whose
 * reaction is not unique there) and the step is taken anew under it; else the run stops
 * (OVK_ELIMINATION) naming the eliminations valid at the start and there. A degrading elimination
 * (r < 1e-3 with the whole Jacobian 100 times better conditioned) is chosen again at the step's
 * end on the same condition. The uniqueness along the motion (unique.c) is judged where it can
 * change. Messages and events are worded as the Python run's (friction joints as joints[k], named
 * by the bindings), so a stop reads the same from either runtime. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "core.h"

#define DEGRADED_RATIO 1e-3  /* watch.DEGRADED_RATIO */
#define DEGRADED_MARGIN 100.0 /* watch.DEGRADED_MARGIN */
#define SEARCH_REL 1e-9      /* watch.SEARCH_REL */
#define ALONG_RATIO 1e-3     /* watch.ALONG_RATIO: below it the uniqueness along the motion is evaluated */

/* redundancy: the rows the watch judges (SingularityMonitor.rows and full_rows): under "eliminate"
 * the retained rows and every equation; under "min-norm" (every row retained) an independent
 * set of them chosen at the start and every equation; under "compliant" the rigid retained rows
 * and the rigid equations (compliant equations are forces, they cannot lose rank). */
static const int *kept_rows(const ovk_model *M) { return M->redundancy ? M->watch : M->retained; }
static int n_kept(const ovk_model *M) { return M->redundancy ? M->nwatch : M->nR; }
static const int *full_rows(const ovk_model *M) { return M->redundancy ? M->full : NULL; }
static int n_full(const ovk_model *M) { return M->redundancy ? M->nfull : M->m; }

/* A message into msg (OVK_MSG bytes, cut there) and the status. */
#if defined(__GNUC__)
__attribute__((format(printf, 3, 4)))
#endif
static int say(char *msg, int status, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, OVK_MSG, fmt, ap);
    va_end(ap);
    return status;
}

/* Rows `rows` (k of them; NULL: all m) of Phi_h at y, equilibrated as the watch's kept rows are
 * (watch_scale.c: mass-free, invariant to the units of the coordinates), each of unit norm, into
 * out (k x nh). The frames at y stay in the workspace. */
static int weighted(ovk_sim *s, const double *y, const int *rows, int k, double *out, char *msg) {
    int nh = s->nh, status = ovk_rows_in(s->M, s->d, y);
    if (status) return snprintf(msg, OVK_MSG, "%s", ovk_message(s->d)), status;
    const int *body = s->d->al_rows + s->M->m; /* each equation's two bodies */
    for (int i = 0; i < k; i++) {
        int r = rows ? rows[i] : i;
        ovk_row_dense(s->M, s->d->J, r, body[2 * r], body[2 * r + 1], out + (size_t)i * nh);
    }
    ovk_watch_scale(out, k, nh, NULL, s->M->nh_b, nh, s->eig->fscale, s->eig->sscr);
    return OVK_OK;
}

/* The whole Jacobian's weighted rows at y factored (bandsvd.c) into *f. */
static int full_values(ovk_sim *s, const double *y, ovk_bsv *f, char *msg) {
    int status = ovk_sim_dense(s, msg);
    if (!status) status = weighted(s, y, full_rows(s->M), n_full(s->M), s->W2, msg);
    if (!status && (status = ovk_bsv_factor(s->W2, n_full(s->M), s->nh, s->bsv_work, f)))
        snprintf(msg, OVK_MSG, "the singularity watch: a non-finite constraint Jacobian");
    return status;
}

/* The whole Jacobian's numerical rank at y (watch.numerical_rank with ratio_tol): the singular
 * values at or above ratio_tol sigma_1. */
static int full_rank(ovk_sim *s, const double *y, int *rank, char *msg) {
    ovk_bsv f;
    int status = full_values(s, y, &f, msg);
    *rank = 0;
    if (!status) {
        double smax = ovk_bsv_value(&f, 0);
        *rank = smax > 0.0 ? n_full(s->M) - ovk_bsv_below(&f, s->o.ratio_tol * smax) : 0;
    }
    return status;
}

/* (r, dr/dt) at y (watch.ratio_and_rate): r from the tracked extremes (watch_eig.c), and dr/dt
 * from d sigma/dt = u^T J' v of each (J' by a forward difference of the weighted rows along q');
 * qdot the coordinate rates (NULL: computed at y). */
static int ratio_and_rate(ovk_sim *s, const double *y, const double *qdot, double *r, double *rate, char *msg) {
    const ovk_model *M = s->M;
    int n = s->n;
    double smin = 1.0, smax = 1.0;
    int status = ovk_eig_rows(s, y, kept_rows(M), s->eig->w, 1, msg);
    if (!status && !qdot) {
        if ((status = ovk_rates(M, s->d, y, y + n, s->qwatch)))
            return snprintf(msg, OVK_MSG, "%s", ovk_message(s->d)), status;
        qdot = s->qwatch;
    }
    if (status || (status = ovk_eig_extremes(s, s->eig->w, &smin, &smax))) return status;
    double most = 0.0;
    for (int i = 0; i < n; i++) most = fabs(qdot[i]) > most ? fabs(qdot[i]) : most;
    double dt = 1e-7 / (most > 1.0 ? most : 1.0);
    memcpy(s->ywatch, y, (size_t)s->ny * sizeof(double));
    for (int i = 0; i < n; i++) s->ywatch[i] = y[i] + dt * qdot[i];
    if ((status = ovk_eig_rows(s, s->ywatch, kept_rows(M), s->eig->w2, 0, msg))) return status;
    double ds_min = ovk_eig_rate(s, s->eig->umin, smin, dt), ds_max = ovk_eig_rate(s, s->eig->umax, smax, dt);
    *r = smax > 0.0 ? smin / smax : 0.0;
    *rate = smax > 0.0 ? (ds_min - *r * ds_max) / smax : 0.0;
    return OVK_OK;
}

/* r of the kept equations at tau on the last step's dense output (the state into s->ywatch),
 * weighted by the scaling of the step's end (watch_scale.c: one scaling along the search). */
static int ratio_at(ovk_sim *s, double tau, double *r, char *msg) {
    double smin = 1.0, smax = 1.0;
    ovk_rk_dense(&s->rk, tau, s->ywatch);
    int status = ovk_eig_rows(s, s->ywatch, kept_rows(s->M), s->eig->w, 0, msg);
    if (!status) status = ovk_eig_extremes(s, s->eig->w, &smin, &smax);
    if (!status) *r = smax > 0.0 ? smin / smax : 0.0;
    return status;
}

/* The minimum of r on [a, b] along the dense output by golden section (watch._minimum). */
static int minimum(ovk_sim *s, double a, double b, double *t_min, double *r_min, char *msg) {
    const double golden = (sqrt(5.0) - 1.0) / 2.0, eps = 2.220446049250313e-16;
    double c = b - golden * (b - a), d = a + golden * (b - a), fc = 0.0, fd = 0.0;
    int status = ratio_at(s, c, &fc, msg);
    if (!status) status = ratio_at(s, d, &fd, msg);
    double wide = fabs(a) > fabs(b) ? fabs(a) : fabs(b), stop = SEARCH_REL * (b - a);
    if (8.0 * eps * wide > stop) stop = 8.0 * eps * wide;
    while (!status && b - a > stop) {
        if (fc < fd) {
            b = d, d = c, fd = fc;
            c = b - golden * (b - a);
            status = ratio_at(s, c, &fc, msg);
        } else {
            a = c, c = d, fc = fd;
            d = a + golden * (b - a);
            status = ratio_at(s, d, &fd, msg);
        }
    }
    *t_min = fc < fd ? c : d;
    *r_min = fc < fd ? fc : fd;
    return status;
}

/* r for a message (watch.shown_ratio). */
static void shown(double r, char *out, size_t size) {
    if (r >= 1e-9)
        snprintf(out, size, "%.2g", r);
    else
        snprintf(out, size, "< 1e-09");
}

/* The eliminated equations as "Phi3, Phi7" (1-based; "none"). */
static void eliminated(const ovk_model *M, char *out, size_t size) {
    size_t used = 0;
    out[0] = '\0';
    for (int row = 0, k = 0; row < M->m; row++) {
        if (k < M->nR && M->retained[k] == row) {
            k++;
            continue;
        }
        int w = snprintf(out + used, size - used, "%sPhi%d", used ? ", " : "", row + 1);
        if (w < 0 || (size_t)w >= size - used) break;
        used += (size_t)w;
    }
    if (!used) snprintf(out, size, "none");
}

/* r at t (the state y) judged (watch._judge): nothing when r >= ratio_tol; else a singular
 * position of the mechanism when the whole Jacobian lost rank too, or the kept set's expiry.
 * passed: the located minimum lies strictly inside the step (a, b). */
static int judge(ovk_sim *s, double t, double r, const double *y, int passed, double a, double b, char *msg) {
    if (r < s->min_ratio) s->min_ratio = r;
    if (r >= s->o.ratio_tol) return OVK_OK;
    char where[160], rs[24];
    if (passed)
        snprintf(where, sizeof where, "t = %.9g s: the motion passed a singular position (between the steps at "
                 "t = %.9g s and %.9g s)", t, a, b);
    else
        snprintf(where, sizeof where, "t = %.9g s: singular position", t);
    int full = 0, nR = n_kept(s->M), status = full_rank(s, y, &full, msg);
    if (status) return status;
    shown(r, rs, sizeof rs);
    if (full < nR && (status = ovk_sim_along(s, t, y, 0, 0.0, INFINITY, msg))) return status; /* the events at that instant */
    if (full < nR)
        return snprintf(msg, OVK_MSG, "%s: the mechanism's constraint Jacobian is rank deficient (rank %d < %d; "
                        "kept equations' sigma_min/sigma_max %s, below %g); to go on through it, run with "
                        "--singular pass (scene: [solver] singular = \"pass\"), which solves the kept equations in "
                        "the augmented Lagrangian form and projects the state back onto the constraints after every "
                        "step", where, full, nR, rs, s->o.ratio_tol),
               OVK_SINGULAR_POSITION;
    if (s->M->redundancy == OVK_MIN_NORM) /* the watched set is chosen at the start only (checks.watch_rows) */
        return say(msg, OVK_ELIMINATION, "%s: the equations watched under redundancy 'min-norm' are no longer "
                        "independent (their sigma_min/sigma_max %s, below %g), while the mechanism is regular there "
                        "(all equations keep rank %d): the run does not choose the watched equations again; "
                        "redundancy 'eliminate' (eliminate = \"auto\") chooses the kept equations again and goes on",
                        where, rs, s->o.ratio_tol, full);
    s->expired_t = t;
    memmove(s->ystar, y, (size_t)s->ny * sizeof(double));
    return say(msg, OVK_ELIMINATION, "%s: the kept equations are no longer independent (their sigma_min/sigma_max %s, "
                    "below %g), while the mechanism is regular there (all equations keep rank %d): the elimination "
                    "chosen at the start has expired", where, rs, s->o.ratio_tol, full);
}

/* After the check at (t, y) with kept ratio r: the elimination degrades
 * (watch.SingularityMonitor._degrading) when r < 1e-3 while the whole Jacobian's rank-th singular
 * value ratio is at least 100 r; then sim.c chooses it again after the step (ovk_sim_degraded).
 * Never under min-norm, which keeps every equation. */
static int degrading(ovk_sim *s, double r, const double *y, char *msg) {
    int nR = n_kept(s->M), k = n_full(s->M) < s->nh ? n_full(s->M) : s->nh;
    /* kept rows that are the whole set (no elimination): its ratio is r itself, never 100 r */
    if (r >= DEGRADED_RATIO || s->M->redundancy == OVK_MIN_NORM || nR == n_full(s->M)) return OVK_OK;
    ovk_bsv f;
    int status = full_values(s, y, &f, msg);
    if (status) return status;
    double s1 = ovk_bsv_value(&f, 0), full = k >= nR && s1 > 0.0 ? ovk_bsv_value(&f, nR - 1) / s1 : 0.0;
    s->degrading = full >= DEGRADED_MARGIN * r;
    return OVK_OK;
}

/* motion_unique from the verdicts u (nj): every friction joint with a nonzero law unique. */
static int motion_of(const ovk_model *M, const int *u) {
    for (int k = 0; k < M->nfj; k++) {
        const double *lp = M->jlawp + (size_t)M->fj[k] * NLP;
        if (!(lp[0] == 0.0 && lp[3] == 0.0) && !u[M->fj[k]]) return 0;
    }
    return 1;
}

/* The uniqueness along the motion at (t, y) (watch.Uniqueness.update): the whole Jacobian's
 * rank and every joint's verdict by the pre-check's rule (unique.c); after the first evaluation
 * (first = 1, at the start: no events), a rank-change event when the rank differs from the last
 * evaluation's and a uniqueness-change event when a friction joint's verdict does (friction
 * joints as "joints[k]", 0-based in model order; the bindings put the names in). */
static int along(ovk_sim *s, double t, const double *y, int first, double wmin_low, double wmax_up, char *msg) {
    const ovk_model *M = s->M;
    int nj = M->nj, rank = 0, *now = s->along_unique + nj, *was = s->along_unique;
    int status = ovk_rows_in(M, s->d, y);
    if (status) return snprintf(msg, OVK_MSG, "%s", ovk_message(s->d)), status;
    const double *J = s->d->J;
    if (n_kept(M) == ovk_unique_judged(M) && ovk_unique_certified(M, J, s->cert_work, wmin_low, wmax_up, s->eig->scale_y)) {
        rank = n_kept(M); /* the kept rows are every judged one and certified regular: no dependency */
        for (int j = 0; j < nj; j++) now[j] = 1;
        s->along_certified++;
    } else if ((status = ovk_sim_dense(s, msg))) {
        return status;
    } else if ((status = ovk_unique_rows(M, J, s->along_work, &rank, now)))
        return say(msg, status, "t = %.9g s: uniqueness along the motion: a non-finite constraint Jacobian", t);
    if (!first && rank != s->along_rank) {
        char text[64];
        snprintf(text, sizeof text, "rank %d -> %d", s->along_rank, rank);
        if ((status = ovk_sim_push_event(s, t, OVK_EV_RANK, text)))
            return say(msg, status, "t = %.9g s: out of memory for the run's events", t);
    }
    char text[OVK_MSG] = "";
    size_t len = 0;
    for (int k = 0; !first && k < M->nfj; k++) {
        int j = M->fj[k];
        if (now[j] == was[j]) continue;
        int w = snprintf(text + len, sizeof text - len, "%sjoints[%d]: %s -> %s", len ? ", " : "", j,
                         was[j] ? "unique" : "not unique", now[j] ? "unique" : "not unique");
        if (w < 0 || (size_t)w >= sizeof text - len) break;
        len += (size_t)w;
    }
    int motion_was = motion_of(M, was), motion_now = motion_of(M, now);
    if (len && motion_was != motion_now && len < sizeof text)
        snprintf(text + len, sizeof text - len, "; motion_unique %s -> %s", motion_was ? "true" : "false",
                 motion_now ? "true" : "false");
    if (len && (status = ovk_sim_push_event(s, t, OVK_EV_UNIQUENESS, text)))
        return say(msg, status, "t = %.9g s: out of memory for the run's events", t);
    s->along_rank = rank;
    memcpy(was, now, (size_t)nj * sizeof(int));
    return OVK_OK;
}

/* along, its wall time counted in s->along_time (ovk_sim_info). */
int ovk_sim_along(ovk_sim *s, double t, const double *y, int first, double wmin_low, double wmax_up, char *msg) {
    double started = ovk_now();
    int status = along(s, t, y, first, wmin_low, wmax_up, msg);
    s->along_time += ovk_now() - started;
    return status;
}

/* The uniqueness at the run's start (t0, y0), after the watch's start (monitor, first = 1): with
 * the watch's certified bounds at y0 (no search moved them), so that where the kept rows are every
 * equation and regular the factorisation is skipped (ovk_unique_certified, O(nonzeros): a long
 * chain, whose dense factorisation would cost O(m nh) memory). */
int ovk_sim_along_start(ovk_sim *s, double t0, const double *y0, char *msg) {
    return ovk_sim_along(s, t0, y0, 1, s->eig->smin_low, s->eig->smax_up, msg);
}

/* The watch at (t, y) (SingularityMonitor.check and, first = 1, its start at t0: no minimum
 * search, no degrading test); qdot: the integrator's q' at y (NULL: the coordinate rates). */
static int monitor(ovk_sim *s, double t, const double *y, const double *qdot, int first, char *msg) {
    if (!n_kept(s->M)) return OVK_OK;
    double r = 1.0, rate = 0.0;
    int status = ratio_and_rate(s, y, qdot, &r, &rate, msg);
    if (status) return status;
    double wmin_low = s->eig->smin_low, wmax_up = s->eig->smax_up; /* at y: the searches below move them */
    memcpy(s->eig->scale_y, s->eig->scale, (size_t)s->nh * sizeof(double)); /* the rows' scaling at y, with them */
    s->ratio = r;
    if (!first && s->rate < 0.0 && 0.0 < rate && t > s->t_prev) {
        double t_min = t, r_min = r;
        status = minimum(s, s->t_prev, t, &t_min, &r_min, msg);
        if (!status && r_min < r) {
            ovk_rk_dense(&s->rk, t_min, s->ywatch);
            status = judge(s, t_min, r_min, s->ywatch, 1, s->t_prev, t, msg);
        }
        if (status) return status;
    }
    if ((status = judge(s, t, r, y, 0, 0.0, 0.0, msg))) return status;
    s->t_prev = t;
    s->rate = rate;
    if (!first && r < ALONG_RATIO && (status = ovk_sim_along(s, t, y, 0, wmin_low, wmax_up, msg))) return status;
    return first ? OVK_OK : degrading(s, r, y, msg);
}

/* The watch at (t, y) (monitor), its wall time counted in s->watch_time (ovk_sim_info). */
int ovk_sim_monitor(ovk_sim *s, double t, const double *y, const double *qdot, int first, char *msg) {
    double started = ovk_now();
    int status = monitor(s, t, y, qdot, first, msg);
    s->watch_time += ovk_now() - started;
    return status;
}

/* A restored state's kept rows: the tracked vectors saved with it are in their order. */
void ovk_sim_watch_adopt(ovk_sim *s) {
    if (s->eig) ovk_eig_order(s->eig, kept_rows(s->M));
}

/* sigma_min and sigma_max of the watched rows at y (ovk_sim_watch_extremes in core.h): the run's
 * tracked vectors and its count of capped estimates are put back afterwards. */
int ovk_sim_watch_extremes(ovk_sim *s, const double *y, int cold, double *out) {
    if (!s) return OVK_NOMEM;
    if (!s->eig || !y || !out) return snprintf(s->msg, sizeof s->msg, "watch extremes: no run or no state"), OVK_INVALID;
    ovk_watch_eig *e = s->eig;
    int nR = e->nR, have = e->have;
    long long capped = s->watch_capped;
    double *keep = s->T; /* 2 m >= 2 nR doubles */
    memcpy(keep, e->umin, (size_t)nR * sizeof(double));
    memcpy(keep + nR, e->umax, (size_t)nR * sizeof(double));
    if (cold) e->have = 0;
    char msg[OVK_MSG];
    int status = ovk_eig_rows(s, y, kept_rows(s->M), e->w, 1, msg);
    if (!status) status = ovk_eig_extremes(s, e->w, out, out + 1);
    if (status) snprintf(s->msg, sizeof s->msg, "watch extremes: %.900s", msg);
    memcpy(e->umin, keep, (size_t)nR * sizeof(double));
    memcpy(e->umax, keep + nR, (size_t)nR * sizeof(double));
    e->have = have, s->watch_capped = capped;
    return status;
}

/* After the step from the accepted state failed with status `failed` (its message in msg):
 * OVK_ELIMINATION with the expiry's message when the kept equations were about to lose rank
 * while the mechanism stays regular (SingularityMonitor.expiring, Simulation._recover), else
 * `failed` unchanged. */
int ovk_sim_expiring(ovk_sim *s, int failed, char *msg) {
    const ovk_rk *rk = &s->rk;
    double h = rk->t - rk->t_old;
    int n = s->n, recoverable = failed == OVK_FRICTION || failed == OVK_EULER || failed == OVK_STEP_SMALL ||
                                failed == OVK_STIFF || failed == OVK_UNSTABLE;
    if (!recoverable || !n_kept(s->M) || s->M->redundancy == OVK_MIN_NORM || s->rate >= 0.0 || !(h > 0.0) ||
        rk->nsteps == 0)
        return failed;
    double dt = s->ratio / -s->rate;
    if (dt > 2.0 * h) return failed;
    char why[OVK_MSG];
    memcpy(why, msg, OVK_MSG);
    why[OVK_MSG - 1] = '\0';
    if (ovk_sim_dense(s, msg) || ovk_rows(s->M, s->d, rk->y, s->phi, s->J, s->gam) ||
        ovk_rates(s->M, s->d, rk->y, rk->y + n, s->qwatch))
        return failed;
    memcpy(s->ystar, rk->y, (size_t)s->ny * sizeof(double));
    for (int i = 0; i < n; i++) s->ystar[i] = rk->y[i] + dt * s->qwatch[i];
    int full = 0;
    if (full_rank(s, s->ystar, &full, msg)) return snprintf(msg, OVK_MSG, "%s", why), failed;
    if (full < n_kept(s->M)) return snprintf(msg, OVK_MSG, "%s", why), failed;
    s->expired_t = rk->t + dt;
    return say(msg, OVK_ELIMINATION, "t = %.9g s: the kept equations lose rank here while the mechanism stays regular: the "
             "elimination chosen at the start expires (the step from t = %.9g s failed: %.600s)", rk->t + dt, rk->t, why);
}

/* ------------------------------------------------------------------ the elimination chosen again */

/* The numerical rank of the rows `rows` (count k; all m for NULL) of the raw J (m x nh) by
 * analysis.numerical_rank: singular values above max(1e-9, max(k, nh) eps) sigma_1 (s->W and
 * s->bsv_work are scratch). */
static int raw_rank(ovk_sim *s, const double *J, const int *skip_flags, int *count) {
    int nh = s->nh, k = 0;
    for (int r = 0; r < s->m; r++)
        if (!skip_flags || !skip_flags[r]) memcpy(s->W + (size_t)k++ * nh, J + (size_t)r * nh, (size_t)nh * sizeof(double));
    *count = k;
    if (!k) return 0;
    ovk_bsv f;
    if (ovk_bsv_factor(s->W, k, nh, s->bsv_work, &f)) return 0; /* a non-finite J: no rank to match */
    int big = k > nh ? k : nh;
    double rt = 1e-9 > big * 2.220446049250313e-16 ? 1e-9 : big * 2.220446049250313e-16, s1 = ovk_bsv_value(&f, 0);
    return s1 > 0.0 ? k - ovk_bsv_below(&f, rt * s1) : 0;
}

/* "[a, b]": the 1-based equations of the m flags `gone`, into out. */
static void listed(const int *gone, int m, char *out, size_t size) {
    size_t len = (size_t)snprintf(out, size, "[");
    for (int r = 0, first = 1; r < m && len < size; r++)
        if (gone[r]) {
            len += (size_t)snprintf(out + len, size - len, "%s%d", first ? "" : ", ", r + 1);
            first = 0;
        }
    if (len < size) snprintf(out + len, size - len, "]");
}

/* The flags of the eliminated equations of the run's kept set into gone (m). */
static void eliminated_flags(const ovk_sim *s, int *gone) {
    for (int r = 0; r < s->m; r++) gone[r] = 1;
    for (int p = 0; p < s->M->nR; p++) gone[s->M->retained[p]] = 0;
}

/* The flags of the equations an automatic elimination removes at y into gone (m): the complement
 * of ovk_choose_kept at y (watch.reselected). */
static int chosen_gone(ovk_sim *s, const double *y, int *gone, char *msg) {
    int *iwork = s->kept + 7 * s->m + 2 * OVK_MAXEQ * s->Mrun.nfj, rank = 0;
    int status = ovk_sim_dense(s, msg);
    if (status) return status;
    if ((status = ovk_rows_in(s->M, s->d, y))) return snprintf(msg, OVK_MSG, "%s", ovk_message(s->d)), status;
    if ((status = ovk_choose_kept(s->M, s->d->J, s->along_work, iwork, gone, &rank))) return status;
    for (int r = 0; r < s->m; r++) gone[r] = !gone[r];
    return OVK_OK;
}

/* Eliminations valid both at the start and at y as "[a], [b]" (watch.valid_eliminations, at
 * most 10): with one redundant equation every single equation that qualifies, else the set
 * chosen at y if it qualifies at the start too; "none found" when none. */
static int valid_eliminations(ovk_sim *s, const double *y, char *out, size_t size, char *msg) {
    int m = s->m, *gone = s->kept + 5 * m + 2 * OVK_MAXEQ * s->Mrun.nfj, *current = gone + m;
    int status = ovk_sim_dense(s, msg);
    if (status) return status;
    status = ovk_rows(s->M, s->d, s->y0, s->phi, s->W2, s->gam); /* J at the start into W2 */
    if (!status) status = ovk_rows(s->M, s->d, y, s->phi, s->J, s->gam);
    if (status) return snprintf(msg, OVK_MSG, "%s", ovk_message(s->d)), status;
    int count = 0, rank = raw_rank(s, s->W2, NULL, &count), found = 0;
    size_t len = 0;
    out[0] = '\0';
    eliminated_flags(s, current);
    int singles = m - rank == 1, candidates = singles ? m : 1;
    double *J1 = s->J;
    for (int c = 0; c < candidates && found < 10; c++) {
        if (singles) {
            for (int r = 0; r < m; r++) gone[r] = r == c;
        } else if ((status = chosen_gone(s, y, gone, msg))) { /* (s->J keeps the rows at y: J1) */
            return status;
        }
        int same = 1;
        for (int r = 0; r < m; r++) same &= gone[r] == current[r];
        int k0 = 0, k1 = 0, ok = !same && raw_rank(s, s->W2, gone, &k0) == rank && k0 == rank;
        ok = ok && raw_rank(s, J1, gone, &k1) == rank && k1 == rank;
        if (!ok) continue;
        char one[96];
        listed(gone, m, one, sizeof one);
        if (len >= size) break; /* the list is cut at the message's size */
        len += (size_t)snprintf(out + len, size - len, "%s%s", found ? ", " : "", one);
        found++;
    }
    if (!found) snprintf(out, size, "none found");
    return OVK_OK;
}

/* Friction joints with a nonzero law whose reaction is not unique at y, as "joints[k], ..." into
 * out (watch.friction_on_nonunique); returns their count (negative: a status). */
static int nonunique_friction(ovk_sim *s, const double *y, char *out, size_t size, char *msg) {
    const ovk_model *M = s->M;
    int rank = 0, *u = s->along_unique + M->nj, count = 0;
    int status = ovk_sim_dense(s, msg);
    if (status) return -status;
    if (!(status = ovk_rows_in(M, s->d, y))) status = ovk_unique_rows(M, s->d->J, s->along_work, &rank, u);
    if (status) return snprintf(msg, OVK_MSG, "%s", ovk_message(s->d)), -status;
    size_t len = 0;
    out[0] = '\0';
    for (int j = 0; j < M->nj; j++) {
        int friction = 0;
        for (int k = 0; k < M->nfj; k++) friction |= M->fj[k] == j;
        const double *lp = M->jlawp + (size_t)j * NLP;
        if (!friction || (lp[0] == 0.0 && lp[3] == 0.0) || u[j]) continue;
        if (len < size) len += (size_t)snprintf(out + len, size - len, "%sjoints[%d]", count ? ", " : "", j);
        count++;
    }
    return count;
}

/* Chooses the kept equations again at y_at, records the event at t_event ("eliminated [a] ->
 * [b] (why)") and goes on from (t_from, y_from) (Simulation._choose_again); 1 when the choice is
 * the elimination in use (nothing done), 0 when restarted, else minus a status. */
static int choose_again(ovk_sim *s, const double *y_at, double t_event, const char *why, double t_from,
                        const double *y_from, char *msg) {
    int m = s->m, *gone = s->kept + 6 * m + 2 * OVK_MAXEQ * s->Mrun.nfj;
    int *before = s->kept + 5 * m + 2 * OVK_MAXEQ * s->Mrun.nfj;
    int status = chosen_gone(s, y_at, gone, msg);
    if (status) return -status;
    eliminated_flags(s, before);
    int same = 1;
    for (int r = 0; r < m; r++) same &= gone[r] == before[r];
    if (same) return 1;
    char was[96], now[96], detail[OVK_MSG];
    listed(before, m, was, sizeof was);
    listed(gone, m, now, sizeof now);
    snprintf(detail, sizeof detail, "eliminated %s -> %s (%s)", was, now, why);
    for (int r = 0; r < m; r++) gone[r] = !gone[r]; /* the kept flags */
    if ((status = ovk_sim_push_event(s, t_event, OVK_EV_RESELECTED, detail)))
        return snprintf(msg, OVK_MSG, "t = %.9g s: out of memory for the run's events", t_event), -status;
    if ((status = ovk_sim_restart(s, gone, t_from, y_from))) return -status;
    return 0;
}

/* The kept set expired at s->expired_t (state in s->ystar; the expiry's message in s->msg)
 * (Simulation._expired): with friction on a joint whose reaction is not unique there the run
 * stops, naming the eliminations that stay valid (OVK_ELIMINATION); else the equations are
 * chosen again there and the run goes on from (t_from, y_from), the start of the step (OVK_OK),
 * or, when the choice is the elimination in use, it stops with the expiry. */
int ovk_sim_expired(ovk_sim *s, double t_from, const double *y_from) {
    s->memo = 0; /* another kept set: sim_eval's memo no longer holds */
    char names[OVK_MSG], valid[OVK_MSG], gone[OVK_MSG], why[96], scratch[OVK_MSG];
    double t_event = s->expired_t;
    memcpy(s->yout, y_from, (size_t)s->ny * sizeof(double)); /* the restart's state, apart */
    int count = nonunique_friction(s, s->ystar, names, sizeof names, scratch);
    if (count < 0) return snprintf(s->msg, sizeof s->msg, "%s", scratch), -count;
    if (count > 0) {
        int status = valid_eliminations(s, s->ystar, valid, sizeof valid, scratch);
        if (status) return snprintf(s->msg, sizeof s->msg, "%s", scratch), status;
        eliminated(s->M, gone, sizeof gone);
        size_t len = strlen(s->msg);
        snprintf(s->msg + len, sizeof s->msg - len, "; with friction on %s, whose reaction is not unique, the "
                 "elimination decides the motion, so the run stops (eliminated: %s; other eliminations valid at the "
                 "start and here: %s)", names, gone, valid);
        return OVK_ELIMINATION;
    }
    snprintf(why, sizeof why, "the kept equations lost rank at t = %.9g s", t_event);
    int done = choose_again(s, s->ystar, t_event, why, t_from, s->yout, scratch);
    if (done == 1) return OVK_ELIMINATION; /* the same equations: the expiry stands */
    if (done < 0) return snprintf(s->msg, sizeof s->msg, "%s", scratch), -done;
    return OVK_OK;
}

/* The step just accepted found the elimination degrading (Simulation._degraded): when the motion
 * does not depend on it, the equations are chosen again at the step's end and the run goes on
 * from there; else it keeps them (the run stops if they expire). The status. */
int ovk_sim_degraded(ovk_sim *s) {
    s->memo = 0; /* another kept set: sim_eval's memo no longer holds */
    const ovk_rk *rk = &s->rk;
    char names[OVK_MSG], why[96], rs[24], scratch[OVK_MSG];
    int count = nonunique_friction(s, rk->y, names, sizeof names, scratch);
    if (count < 0) return snprintf(s->msg, sizeof s->msg, "%s", scratch), -count;
    if (count > 0) return OVK_OK;
    shown(s->ratio, rs, sizeof rs);
    snprintf(why, sizeof why, "the kept equations became ill-conditioned: sigma_min/sigma_max %s", rs);
    memcpy(s->yout, rk->y, (size_t)s->ny * sizeof(double));
    int done = choose_again(s, s->yout, rk->t, why, rk->t, s->yout, scratch);
    if (done < 0) return snprintf(s->msg, sizeof s->msg, "%s", scratch), -done;
    return OVK_OK;
}
