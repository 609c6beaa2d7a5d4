/* Stage: the mass-orthogonal projection of a state onto the constraints (formulation AL,
 * solver.singular = "pass"; Bayo & Ledesma 1996), after every accepted step of a run:
 *   positions:  q <- q + G(q) dh, dh = argmin 1/2 dh^T M dh subject to J(q) dh = -Phi(q),
 *               repeated (Gauss-Newton) until max |Phi| <= tol; G(q) dh = q'(q, dh) - q'(q, 0),
 *               the coordinate rates of rates.c without their part that does not depend on h
 *               (a quaternion's norm stabilisation);
 *   velocities: h <- h + dh, dh = argmin 1/2 dh^T M dh subject to J(q) dh = -J(q) h (then J h = 0;
 *               no joint depends on time).
 * Phi and J = Phi_h are every equation's, the eliminated ones too (decided here): away from a
 * singular position they follow from the kept ones, but near it the kept equations alone admit
 * motions off the mechanism's configuration space (measured: 2e-7 m in an eliminated equation of a
 * 10-crank parallelogram after its flat position), which the whole set excludes. Each correction is
 * one augmented Lagrangian solve of kkt_al.c, which takes redundant and rank-deficient rows as they
 * are (M + alpha J^T J stays positive definite): the correction is the minimum-norm one in M's
 * metric, at a singular position too. The branch is kept by the velocity: at a singular position
 * the branches of the configuration space meet, the step that reached the state moved along one of
 * them, and the smallest correction keeps the state on the branch it is closest to. Units: Phi in m
 * or rad (the joints' rows), y = [q, h] in SI. */
#include <math.h>
#include <string.h>

#include "core.h"

/* Positions then velocities of y = [q (nb nq_b), h (nb nh_b)] projected in place (file header):
 * *drift = max |Phi| at the projected positions. OVK_PROJECTION when the positions do not reach
 * tol (or OVK_PROJ_SLACK tol with the corrections stalled) within max_iter corrections; OVK_EULER, OVK_NONFINITE as an evaluation; OVK_INVALID for tol
 * <= 0 or max_iter < 1. t (s) only names the instant in messages. */
int ovk_project(const ovk_model *M, ovk_data *d, double t, double *y, double tol, int max_iter, double *drift) {
    if (!d) return OVK_NOMEM;
    if (d->status) return d->status;
    d->msg[0] = '\0';
    if (!(tol > 0.0) || max_iter < 1)
        return ovk_fail(d, OVK_INVALID, "project: tolerance %g (must be > 0) and max_iter %d (must be >= 1)", tol,
                        max_iter);
    int n = M->nb * M->nq_b, nh = M->nb * M->nh_b, status;
    ovk_rowset all = ovk_al_all(M, d);
    double *q = y, *h = y + n;
    double *dq = ovk_al_slot(M, d, OVK_AL_SLOT_P1), *q0dot = ovk_al_slot(M, d, OVK_AL_SLOT_P2);
    double *dh = ovk_al_slot(M, d, OVK_AL_SLOT_P3), *g = ovk_al_slot(M, d, OVK_AL_SLOT_PR1);
    double *mu = ovk_al_slot(M, d, OVK_AL_SLOT_PR2), *zero = ovk_al_slot(M, d, OVK_AL_SLOT_UNIT);
    double err = 0.0, prev = INFINITY;
    memset(zero, 0, sizeof(double) * (size_t)nh);
    d->f.t = t; /* the drivers' equations at t */
    for (int it = 0;; it++) {
        ovk_frames_build(M, q, h, &d->f);
        ovk_constraint_rows(M, d, q);
        err = 0.0;
        for (int i = 0; i < M->m; i++) {
            g[i] = -d->phi[i];
            if (!isfinite(g[i])) return ovk_fail(d, OVK_NONFINITE, "project: t = %.9g s: non-finite Phi (row %d)", t, i);
            if (fabs(g[i]) > err) err = fabs(g[i]);
        }
        /* done at tol, or within OVK_PROJ_SLACK tol once a correction no longer halves |Phi|: near a
         * singular position the corrections converge linearly along the directions losing rank
         * (the |Phi| left is the run's drift, reported) */
        if (err <= tol || (err <= OVK_PROJ_SLACK * tol && err > 0.5 * prev)) break;
        prev = err;
        if (it == max_iter)
            return ovk_fail(d, OVK_PROJECTION, "t = %.9g s: the projection onto the constraints left max |Phi| = %.3g "
                            "after %d corrections (tolerance %g)", t, err, max_iter, tol);
        if ((status = ovk_al_factor(M, d, &all, OVK_AL_ALPHA_PROJ))) return status;
        ovk_al_solve(M, d, &all, zero, g, dh, mu);
        if ((status = ovk_rates(M, d, q, dh, dq)) || (status = ovk_rates(M, d, q, zero, q0dot))) return status;
        for (int k = 0; k < n; k++) q[k] += dq[k] - q0dot[k];
    }
    /* d->J holds the rows at the projected q (the last pass of the loop); the velocities' correction
     * dh (J dh = -J h, least M-norm) is solved for, not h* itself, so that the round-off is the
     * correction's, not the velocity's */
    if ((status = ovk_al_factor(M, d, &all, OVK_AL_ALPHA_PROJ))) return status;
    {
        ovk_rowset_times(M, d, &all, h, g); /* J h over each row's two bodies, then its negative */
        for (int i = 0; i < M->m; i++) g[i] = -g[i];
    }
    ovk_al_solve(M, d, &all, zero, g, dh, mu);
    for (int k = 0; k < nh; k++) h[k] += dh[k];
    for (int k = 0; k < n + nh; k++)
        if (!isfinite(y[k])) return ovk_fail(d, OVK_NONFINITE, "project: t = %.9g s: non-finite state (entry %d)", t, k);
    *drift = err;
    return OVK_OK;
}
