/* Stage: friction. The friction laws (overcon.friction_laws.Law: regularised, stribeck) and the
 * solve of the friction multipliers (Newton, then damped Newton, on the reduced problem):
 * with lam0x the frictionless multipliers of the friction rows and Wx their answer to unit
 * friction forces, find x = lam0x + Wx qf(x). Newton with the analytic Jacobian first (the LU kept
 * while the residual falls fast); if it gives up, damped Newton from the same start (a fresh
 * Jacobian every step, backtracking on the residual's max norm). If that gives up too the status
 * is OVK_FRICTION and friction_robust.c's fallback takes over (ovk_evaluate_robust). */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

/* ------------------------------------------------------------------------------ friction laws */

double ovk_law_magnitude(const double *lp, int law, double speed) {
    if (law == LAW_STRIBECK) {
        double x = speed / lp[4];
        return lp[0] + (lp[3] - lp[0]) * exp(-(x * x));
    }
    return lp[0];
}

/* The signed coefficient at relative speed v: mu(|v|) clip(v / v_reg, -1, 1). */
double ovk_law_coefficient(const double *lp, int law, double v) {
    double r = v / lp[1];
    r = r < -1.0 ? -1.0 : (r > 1.0 ? 1.0 : r);
    return r * ovk_law_magnitude(lp, law, fabs(v));
}

/* mu(s) / max(s, v_reg): the factor of the slip velocity vector. */
double ovk_law_mu_over_speed(const double *lp, int law, double s) {
    return ovk_law_magnitude(lp, law, s) / (s > lp[1] ? s : lp[1]);
}

/* d/ds of ovk_law_mu_over_speed. */
double ovk_law_mu_over_speed_slope(const double *lp, int law, double s) {
    double slope = 0.0;
    if (law == LAW_STRIBECK) {
        double x = s / lp[4];
        slope = -2.0 * x / lp[4] * (lp[3] - lp[0]) * exp(-x * x);
    }
    if (s < lp[1]) return slope / lp[1];
    return (slope - ovk_law_magnitude(lp, law, s) / s) / s;
}

/* The law's mu(s) / max(s, v_reg) and its slope d/ds at the slip speed s >= 0 (lp: NLP doubles), as
 * the spherical joint's Newton uses them: the entry point that lets them be checked on their own.
 * OVK_INVALID (outputs untouched) for a law other than regularised or stribeck, a negative or
 * non-finite s, or a null pointer. */
int ovk_law_eval(const double *lp, int law, double s, double *mu_over_s, double *slope) {
    if (!lp || !mu_over_s || !slope || (law != LAW_REGULARISED && law != LAW_STRIBECK) || !(s >= 0.0) || !isfinite(s))
        return OVK_INVALID;
    *mu_over_s = ovk_law_mu_over_speed(lp, law, s);
    *slope = ovk_law_mu_over_speed_slope(lp, law, s);
    return OVK_OK;
}

/* ------------------------------------------------------------------------------ the reduced problem */

/* qf (ncols): the friction forces at the friction multipliers x (nx), group by group; each joint's
 * multipliers and forces are kept in d->flam, d->Qi, d->Qj for the Jacobian. */
void ovk_forces_reduced(const ovk_model *M, ovk_data *d, const double *x, double *qf) {
    int nx = M->nx;
    memset(qf, 0, sizeof(double) * M->ncols);
    for (int g = 0; g < M->nfg; g++) {
        for (int n = M->fgroup[g]; n < M->fgroup[g + 1]; n++) {
            int j = M->fj[n];
            double *lam = d->flam + OVK_MAXEQ * n;
            for (int e = 0; e < M->jneq[j]; e++) {
                int xi = M->fx[OVK_MAXEQ * n + e];
                lam[e] = xi < nx ? x[xi] : 0.0;
            }
            ovk_joint_friction_forces(M, j, d->ctx + n, lam, d->Qi + 6 * n, d->Qj + 6 * n);
        }
        for (int n = M->fgroup[g]; n < M->fgroup[g + 1]; n++)
            for (int k = 0; k < M->nh_b; k++) {
                int ci = M->fci[6 * n + k];
                if (ci < M->ncols) qf[ci] += d->Qi[6 * n + k];
            }
        for (int n = M->fgroup[g]; n < M->fgroup[g + 1]; n++)
            for (int k = 0; k < M->nh_b; k++) {
                int cj = M->fcj[6 * n + k];
                if (cj < M->ncols) qf[cj] += d->Qj[6 * n + k];
            }
    }
}

/* Dq (ncols x nx) = d qf / d x at the multipliers of the last force evaluation. */
static void jacobian_reduced(const ovk_model *M, ovk_data *d, double *Dq) {
    int nx = M->nx;
    double dQi[6 * OVK_MAXEQ], dQj[6 * OVK_MAXEQ];
    memset(Dq, 0, sizeof(double) * M->ncols * nx);
    for (int n = 0; n < M->nfj; n++) {
        int j = M->fj[n], ne = M->jneq[j];
        ovk_joint_friction_jac(M, j, d->ctx + n, d->flam + OVK_MAXEQ * n, dQi, dQj);
        for (int k = 0; k < M->nh_b; k++)
            for (int e = 0; e < ne; e++) {
                int xi = M->fx[OVK_MAXEQ * n + e];
                if (xi >= nx) continue;
                int ci = M->fci[6 * n + k], cj = M->fcj[6 * n + k];
                if (ci < M->ncols) Dq[ci * nx + xi] += dQi[k * ne + e];
                if (cj < M->ncols) Dq[cj * nx + xi] += dQj[k * ne + e];
            }
    }
}

/* r = lam0x + Wx qf - x: the residual of the friction fixed point (nx). */
static void residual(int nx, int nc, const double *lam0x, const double *Wx, const double *qf, const double *x,
                     double *r) {
    for (int a = 0; a < nx; a++) {
        double t = 0.0;
        for (int c = 0; c < nc; c++) t += Wx[a * nc + c] * qf[c];
        r[a] = lam0x[a] + t - x[a];
    }
}

/* The Newton matrix I - Wx dqf/dx at the multipliers of the last force evaluation, LU-factored in
 * Mx (nx x nx) with piv; Dq (ncols x nx) is work space. Returns nonzero on an exact zero pivot. */
static int newton_matrix(const ovk_model *M, ovk_data *d, const double *Wx, double *Dq, double *Mx, int *piv) {
    int nx = M->nx, nc = M->ncols;
    jacobian_reduced(M, d, Dq);
    for (int a = 0; a < nx; a++)
        for (int b = 0; b < nx; b++) {
            double t = 0.0;
            for (int c = 0; c < nc; c++) t += Wx[a * nc + c] * Dq[c * nx + b];
            Mx[a * nx + b] = (a == b ? 1.0 : 0.0) - t;
        }
    return ovk_lu_factor(Mx, nx, piv);
}

/* Newton on x = lam0x + Wx qf(x). Returns 1 when converged; *iters counts force evaluations. */
static int newton_reduced(const ovk_model *M, ovk_data *d, const double *lam0x, const double *Wx, double *x,
                          double *qf, int *iters, double *work) {
    int nx = M->nx, nc = M->ncols;
    int n_max = M->max_iter < NEWTON_MAX_ITER ? M->max_iter : NEWTON_MAX_ITER;
    double *r = work, *Dq = r + nx, *Mx = Dq + nc * nx;
    int *piv = d->piv, have_lu = 0, growth = 0;
    double prev = INFINITY;
    for (int it = 1; it <= n_max; it++) {
        *iters = it;
        ovk_forces_reduced(M, d, x, qf);
        residual(nx, nc, lam0x, Wx, qf, x, r);
        double res = maxabs(r, nx);
        if (!isfinite(res)) return 0;
        if (res <= M->tol * (1.0 + maxabs(x, nx))) return 1;
        growth = res >= prev ? growth + 1 : 0;
        if (growth >= 2 || it == n_max) return 0;
        if (!have_lu || res > NEWTON_REFRESH * prev) {
            if (newton_matrix(M, d, Wx, Dq, Mx, piv)) return 0;
            have_lu = 1;
        }
        prev = res;
        ovk_lu_solve(Mx, nx, piv, r);
        for (int a = 0; a < nx; a++) x[a] += r[a];
    }
    return 0;
}

/* Damped Newton: a fresh Jacobian every step and a backtracking line search on the residual's max
 * norm. Returns 1 when converged; *iters counts its force evaluations. */
static int damped_newton_reduced(const ovk_model *M, ovk_data *d, const double *lam0x, const double *Wx, double *x,
                                 double *qf, int *iters, double *work) {
    int nx = M->nx, nc = M->ncols;
    int n_max = M->max_iter < DAMPED_MAX_ITER ? M->max_iter : DAMPED_MAX_ITER;
    double *r = work, *Dq = r + nx, *Mx = Dq + nc * nx, *dx = Mx + nx * nx, *xn = dx + nx, *qn = xn + nx,
           *rn = qn + nc;
    int *piv = d->piv;
    ovk_forces_reduced(M, d, x, qf);
    int evals = 1;
    residual(nx, nc, lam0x, Wx, qf, x, r);
    for (;;) {
        *iters = evals;
        double res = maxabs(r, nx);
        if (!isfinite(res)) return 0;
        if (res <= M->tol * (1.0 + maxabs(x, nx))) return 1;
        if (evals >= n_max) return 0;
        /* the Jacobian at x: d->flam holds x's multipliers (the last forces_reduced was at x) */
        if (newton_matrix(M, d, Wx, Dq, Mx, piv)) return 0;
        memcpy(dx, r, sizeof(double) * nx);
        ovk_lu_solve(Mx, nx, piv, dx);
        double step = 1.0;
        for (;;) {
            for (int a = 0; a < nx; a++) xn[a] = x[a] + step * dx[a];
            ovk_forces_reduced(M, d, xn, qn);
            evals++;
            *iters = evals;
            residual(nx, nc, lam0x, Wx, qn, xn, rn);
            if (maxabs(rn, nx) < (1.0 - ARMIJO * step) * res) break;
            step *= 0.5;
            if (step < ARMIJO || evals >= n_max) return 0;
        }
        memcpy(x, xn, sizeof(double) * nx);
        memcpy(qf, qn, sizeof(double) * nc);
        memcpy(r, rn, sizeof(double) * nx);
    }
}

/* The friction stage, after ovk_kkt_solve: solves the friction multipliers, adds the friction
 * forces to d->Q and their answer to d->lamR, and returns the forces in qf (ncols, the next
 * evaluation's warm start). guess_mode: 0 none (x0 = lam0), 1 guess = qf of a nearby evaluation
 * (ncols), 2 guess = lam (m). *iterations: force evaluations; *damped: damped Newton ran. */
int ovk_friction(const ovk_model *M, ovk_data *d, int guess_mode, const double *guess, double *qf, int *iterations,
                 int *damped) {
    int nx = M->nx, nc = M->ncols, nR = M->nR;
    ovk_kkt_friction_columns(M, d);
    double *lam0x = d->work, *Wx = lam0x + nx, *x = Wx + (size_t)nx * nc, *x0 = x + nx, *nwork = x0 + nx;
    for (int a = 0; a < nx; a++) {
        lam0x[a] = d->lamR[M->xrows[a]];
        memcpy(Wx + (size_t)a * nc, d->W + (size_t)M->xrows[a] * nc, sizeof(double) * nc);
    }
    for (int a = 0; a < nx; a++) {
        if (guess_mode == 1) {
            double s = 0.0;
            for (int c = 0; c < nc; c++) s += Wx[a * nc + c] * guess[c];
            x[a] = lam0x[a] + s;
        } else if (guess_mode == 2) {
            x[a] = guess[M->retained[M->xrows[a]]];
        } else {
            x[a] = lam0x[a];
        }
    }
    for (int n = 0; n < M->nfj; n++) /* the planar setup needs the joint's (J_X)_i block */
        ovk_joint_friction_setup(M, &d->f, M->fj[n], d->Jblk + 6 * OVK_MAXEQ * M->fj[n], d->ctx + n);
    memcpy(x0, x, sizeof(double) * nx); /* the start, kept for the damped solve */
    if (!newton_reduced(M, d, lam0x, Wx, x, qf, iterations, nwork)) {
        int first = *iterations, more = 0;
        memcpy(x, x0, sizeof(double) * nx);
        int ok = damped_newton_reduced(M, d, lam0x, Wx, x, qf, &more, nwork);
        *iterations = first + more;
        *damped = 1;
        if (!ok) {
            char names[160];
            ovk_friction_joint_list(M, names, sizeof names);
            return ovk_fail(d, OVK_FRICTION, "friction solve gave up: Newton after %d force evaluations, damped "
                            "Newton after %d more (%d friction multipliers of %s)", first, more, nx, names);
        }
    }
    for (int i = 0; i < nR; i++) {
        double acc = 0.0;
        for (int c = 0; c < nc; c++) acc += d->W[i * nc + c] * qf[c];
        d->lamR[i] += acc;
    }
    for (int c = 0; c < nc; c++) d->Q[M->cols[c]] += qf[c];
    return OVK_OK;
}
