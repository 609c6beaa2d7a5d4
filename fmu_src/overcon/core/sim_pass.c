/* Stage (formulation AL under redundancy "eliminate", solver.singular = "pass"): the right-hand
 * side of a run near a singular position, by interpolation along the motion.
 *
 * Why: near a singular position the kept rows lose rank along a few right singular vectors v
 * (singular value s). On the branch the motion follows, the acceleration is a smooth function of
 * the state, but every formula that resolves it from the rows divides by s: a state on the
 * constraints to round-off is off the branch by about 1e-16 / s along v, and the direct solve's
 * acceleration is off by about 1e-16 / s^3 (measured on the N-four-bar, docs/benchmarks.md, "Error
 * against tolerance through the singular positions"). The AL iteration does not divide by s, but it
 * stalls there, and its acceleration along v then follows the unconstrained dynamics; the step-end
 * projections took that velocity out again, and each passage lost about 1e-7 J whatever the
 * tolerance. Either way the error after a passage did not fall with the tolerance.
 *
 * What: the acceleration at a state y near the position is taken from states along the motion where
 * the direct solve is accurate, and interpolated back to y:
 *   g(s) = h'(Y(s)),   Y(s) = P(y) with q shifted by s q' and projected onto the constraints
 *                      (project.c, positions then velocities, at time t + s; P(y) is y projected
 *                      so, and q' its coordinate rates: the nodes start off the constraints by
 *                      their shift's curvature only),
 *   h'(y) := sum_k w_k g(s_k),  nodes s_k = +-a, +-2a, +-3a, +-4a, Lagrange weights at 0
 *                      w = 4/5, -2/5, 4/35, -1/70 (exact for polynomials of degree 7 in s),
 * with the smallest spacing a = PASS_SPACING_MIN PASS_GROW^k at which the direct solve accepts every
 * node (S's squared pivots spread by at most 1 / OVK_PASS_REGULAR). Y(s) is a smooth curve on the
 * branch through the projection of y (the branch is smooth through the singular position, where
 * the union of the branches is not), so g is smooth and the interpolation's error falls as a^8.
 * Where the projection of y itself is regular enough (spread at least OVK_PASS_AT_STATE), its own
 * direct solve is taken instead: the same value to the interpolation's error, at one node's cost.
 * q' is y's own; the multipliers are interpolated alike (the reactions at such a state are not
 * unique: these are those of the nearby regular states).
 *
 * The result depends on y only through its projection, so it is the same at states that differ off
 * the constraints: every stage of a step near the position takes this form (sim.c: a step whose
 * stage refuses the direct solve is taken again so), and the step-end projection does the rest.
 *
 * Decided here, measured on the N-four-bar N = 2 over 20 s (docs/benchmarks.md): the nodes from
 * P(y), not from y (from y, a stage state's own distance from the constraints entered each node's
 * projection: dopri5 at tolerance 1e-12 spread from 1.2e-9 to 1.8e-8 m, from P(y) 6.3e-9 to
 * 8.9e-9 m, and its nodes cost half as much); a fine ladder of
 * spacings (PASS_GROW = 2^(1/4); doubling changed y' in larger jumps between neighbouring states,
 * and the error at tolerance 1e-12 with them), 8 nodes (6 gave errors growing with the spacing as
 * a^6 at the spacings needed), OVK_PASS_REGULAR 2e-5 (5e-6 let the direct solve's error stop
 * dop853 at 1e-12; 5e-5 and 1e-4 give the same errors, at up to 1.2 times the cost on N = 40),
 * OVK_PASS_AT_STATE 1e-4 (the ladder everywhere costs N = 40 at 1e-7 about 40% more).
 * Where y's own projection or the first node's failed, the spreads that start the doublings are
 * taken at the unprojected positions (probe): without them the ladder climbed from
 * PASS_SPACING_MIN in 10 to 14 refused attempts at most passages of the N-four-bar N = 40, each a
 * projection that failed after PASS_PROJ_MAX_ITER corrections. The probes only start the ladder
 * nearer the spacing it accepts: the runs are the same to the bit where the acceptance grows with
 * the spacing. A lower PASS_PROJ_MAX_ITER (6: a node whose Gauss-Newton does not converge
 * quadratically refused as too near) saved as much again on N = 40, but it moved the accepted
 * spacings, and N = 10 under dop853 at 1e-11 went from 7.8e-9 to 2.5e-7 m (docs/benchmarks.md).
 *
 * Where no spacing up to PASS_SPACING_MAX is accepted (a mechanism at rest at a singular position,
 * or one that stays singular), or a node's projection or solve fails otherwise, the caller falls
 * back to the AL iteration at y, as before this stage. Units: s (the spacing), y in SI. */
#include <math.h>
#include <string.h>

#include "core.h"

#define PASS_NODES 8
static const double NODE[PASS_NODES] = {1.0, -1.0, 2.0, -2.0, 3.0, -3.0, 4.0, -4.0};
static const double WEIGHT[PASS_NODES] = {0.8, 0.8, -0.4, -0.4, 4.0 / 35.0, 4.0 / 35.0, -1.0 / 70.0, -1.0 / 70.0};
#define PASS_SPACING_MIN 1e-5 /* s: the first spacing tried */
#define PASS_SPACING_MAX 0.1  /* s: the last (nodes at most 0.3 s along the motion) */
#define PASS_PROJ_TOL 1e-14   /* m or rad: max |Phi| of a node's projection */
#define PASS_PROJ_MAX_ITER 60
#define PASS_GROW 1.189207115002721 /* 2^(1/4): the ratio of neighbouring spacings (spacing) */

/* y's positions shifted by sk s->pass_qd, into s->pass_y (returned). */
static double *shifted(ovk_sim *s, const double *y, double sk) {
    double *yn = s->pass_y;
    memcpy(yn, y, (size_t)s->ny * sizeof(double));
    for (int k = 0; k < s->n; k++) yn[k] += sk * s->pass_qd[k];
    return yn;
}

/* The direct solve at (t, s->pass_y), refused where S's squared pivots spread by more than 1 / piv:
 * y' into s->pass_f, multipliers into s->ev_lam, the spread into d->al_spread. OVK_OK, OVK_SINGULAR
 * with d->al_refused where refused, or another failure. */
static int direct_at(ovk_sim *s, double t, double piv) {
    ovk_data *d = s->d;
    int its = 0, damped = 0;
    d->al_pivot_min = piv;
    int status = ovk_evaluate(s->M, d, t, s->pass_y, 0, NULL, s->pass_f, s->ev_lam, s->ev_qf, &its, &damped);
    d->al_pivot_min = 0.0;
    return status;
}

/* The direct solve (direct_at) at the projection of y's positions shifted by sk s->pass_qd, at
 * time t + sk; that state in s->pass_y. A failed projection's status otherwise. */
static int node(ovk_sim *s, double t, const double *y, double sk, double piv) {
    double drift = 0.0;
    int status = ovk_project(s->M, s->d, t + sk, shifted(s, y, sk), PASS_PROJ_TOL, PASS_PROJ_MAX_ITER, &drift);
    return status ? status : direct_at(s, t + sk, piv);
}

/* The interpolation at spacing a into s->pass_acc (nh) and s->pass_lam (m); OVK_OK or the first
 * node's failure (the nodes nearest to y first: they are the likeliest to be refused). */
static int interpolate(ovk_sim *s, double t, const double *y, double a) {
    int n = s->n, nh = s->nh, m = s->m, status;
    memset(s->pass_acc, 0, (size_t)nh * sizeof(double));
    memset(s->pass_lam, 0, (size_t)m * sizeof(double));
    for (int j = 0; j < PASS_NODES; j++) {
        if ((status = node(s, t, y, NODE[j] * a, OVK_PASS_REGULAR))) return status;
        for (int k = 0; k < nh; k++) s->pass_acc[k] += WEIGHT[j] * s->pass_f[n + k];
        for (int k = 0; k < m; k++) s->pass_lam[k] += WEIGHT[j] * s->ev_lam[k];
    }
    return OVK_OK;
}

/* The spread of S's squared pivots at y's positions shifted by sk s->pass_qd, not projected: the
 * hint of spacing where a projection failed (near the constraints the spread is its projection's to
 * first order); 0 where the solve failed otherwise. */
static double probe(ovk_sim *s, double t, const double *y, double sk) {
    shifted(s, y, sk);
    int status = direct_at(s, t + sk, OVK_PASS_REGULAR);
    return !status || (status == OVK_SINGULAR && s->d->al_refused) ? s->d->al_spread : 0.0;
}

/* Whether a node's failure only means "too near the singular position there": a wider spacing may do. */
static int too_near(const ovk_data *d, int status) {
    return (status == OVK_SINGULAR && d->al_refused) || status == OVK_PROJECTION;
}

/* The interpolation at the smallest accepted spacing of PASS_SPACING_MIN PASS_GROW^k, into
 * s->pass_acc and s->pass_lam: doublings (four steps of PASS_GROW each) find the first accepted
 * one of them, then the three steps below it are tried in order. OVK_OK, or the status where none
 * is accepted up to PASS_SPACING_MAX (OVK_INVALID at rest: nothing moves the nodes). spread0: the
 * spread at y's projection (0: unknown). */
static int spacing(ovk_sim *s, double t, const double *y, double spread0) {
    double speed = 0.0, a = PASS_SPACING_MIN;
    for (int k = 0; k < s->n; k++) speed = fmax(speed, fabs(s->pass_qd[k]));
    if (!(speed > 0.0)) return OVK_INVALID;
    int status = interpolate(s, t, y, a), near = too_near(s->d, status);
    double spread1 = s->d->al_spread; /* at the node refused, a away from y */
    if (status == OVK_PROJECTION) { /* the spreads unprojected where the projections failed */
        spread0 = spread0 > 0.0 ? spread0 : probe(s, t, y, 0.0);
        spread1 = probe(s, t, y, a);
    }
    if (near && spread0 > 0.0 && spread1 > 0.0) {
        /* the doublings start near the spacing needed: sqrt(spread) grows about linearly with the
         * distance from the singular instant, at the rate these two spreads give; half of what
         * that rate says, so that the smallest accepted spacing is not passed over */
        double rate = fabs(sqrt(spread1) - sqrt(spread0)) / a;
        double want = rate > 0.0 ? 0.5 * (sqrt(OVK_PASS_REGULAR) + sqrt(spread0)) / rate : 0.0;
        while (2.0 * a <= want && 4.0 * a <= PASS_SPACING_MAX) a *= 2.0;
    }
    while (status && too_near(s->d, status) && a * 2.0 <= PASS_SPACING_MAX) {
        a *= 2.0;
        if ((status = interpolate(s, t, y, a))) continue;
        for (double b = a / 2.0 * PASS_GROW; b < a / PASS_GROW * 1.0001; b *= PASS_GROW) /* the steps below a */
            if (!interpolate(s, t, y, b)) return OVK_OK;
        return interpolate(s, t, y, a);
    }
    return status;
}

/* y' at (t, y) near a singular position (file header) into ydot (ny), its multipliers into
 * s->ev_lam. OVK_OK, or a status (no spacing worked, or a failure on the way) for the caller to
 * fall back on the AL iteration; d's message is then cleared. */
int ovk_sim_passing(ovk_sim *s, double t, const double *y, double *ydot) {
    const ovk_model *M = s->M;
    ovk_data *d = s->d;
    int n = s->n, nh = s->nh, status;
    ovk_frames_build(M, y, y + n, &d->f);
    if ((status = ovk_rates(M, d, y, y + n, s->pass_qd))) return status;
    int allow = d->al_allow_direct;
    d->al_allow_direct = 1, d->al_direct_only = 1;
    status = node(s, t, y, 0.0, OVK_PASS_AT_STATE);
    if (!status) {
        memcpy(s->pass_acc, s->pass_f + n, (size_t)nh * sizeof(double));
        memcpy(s->pass_lam, s->ev_lam, (size_t)s->m * sizeof(double));
    } else if (too_near(d, status)) {
        const double *base = y;
        double spread0 = status == OVK_SINGULAR ? d->al_spread : 0.0; /* at y's projection, if it was reached */
        if (status == OVK_SINGULAR) { /* y's projection stands in pass_y: the nodes start from it (ydot as */
            memcpy(ydot, s->pass_y, (size_t)s->ny * sizeof(double)); /* scratch), off the constraints by */
            base = ydot;                                              /* their shift's curvature only */
            ovk_frames_build(M, base, base + n, &d->f);
            status = ovk_rates(M, d, base, base + n, s->pass_qd);
        }
        if (!status || too_near(d, status)) status = spacing(s, t, base, spread0);
    }
    d->al_allow_direct = allow, d->al_direct_only = 0;
    d->msg[0] = '\0';
    if (status) return status;
    ovk_frames_build(M, y, y + n, &d->f);
    if ((status = ovk_rates(M, d, y, y + n, ydot))) return status;
    memcpy(ydot + n, s->pass_acc, (size_t)nh * sizeof(double));
    memcpy(s->ev_lam, s->pass_lam, (size_t)s->m * sizeof(double));
    for (int k = 0; k < n + nh; k++)
        if (!isfinite(ydot[k])) return OVK_NONFINITE;
    return OVK_OK;
}
