/* The robust path of the friction solve, after Newton and
 * damped Newton gave up (friction.c returned OVK_FRICTION, its reduced problem still in the
 * workspace): the Anderson-accelerated fixed point x <- lam0x + Wx qf(x) (depth 3, least squares
 * by a small Jacobi SVD with the relative cut-off 1e-12 of numpy's lstsq), then Newton with a
 * finite-difference Jacobian and backtracking on the residual's 2-norm. */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

#define DEPTH 3
#define LSTSQ_RCOND 1e-12

/* g = lam0x + Wx qf(x) (the fixed-point map on the friction multipliers; qf into q). */
static void G(const ovk_model *M, ovk_data *d, const double *lam0x, const double *Wx, const double *x, double *q,
              double *g) {
    int nx = M->nx, nc = M->ncols;
    ovk_forces_reduced(M, d, x, q);
    for (int a = 0; a < nx; a++) {
        double t = 0.0;
        for (int c = 0; c < nc; c++) t += Wx[a * nc + c] * q[c];
        g[a] = lam0x[a] + t;
    }
}

/* The least-squares coefficients (k <= DEPTH) of the columns F (k vectors of length n, kept) for
 * b: the minimum-norm solution with singular values below LSTSQ_RCOND sigma_max cut off. */
static void lstsq_small(const double *F, int k, int n, const double *b, double *coef, double *B) {
    double V[DEPTH * DEPTH] = {0};
    memcpy(B, F, (size_t)k * n * sizeof(double));
    for (int i = 0; i < k; i++) V[i * k + i] = 1.0;
    for (int sweep = 0; sweep < 60; sweep++) { /* one-sided Jacobi with V: B = F V */
        int rotated = 0;
        for (int p = 0; p < k - 1; p++)
            for (int q = p + 1; q < k; q++) {
                double *u = B + (size_t)p * n, *w = B + (size_t)q * n, al = 0.0, be = 0.0, ga = 0.0;
                for (int i = 0; i < n; i++) al += u[i] * u[i], be += w[i] * w[i], ga += u[i] * w[i];
                if (!(fabs(ga) > 1e-15 * sqrt(al * be))) continue;
                double zeta = (be - al) / (2.0 * ga), t = (zeta >= 0.0 ? 1.0 : -1.0) / (fabs(zeta) + sqrt(1.0 + zeta * zeta));
                double c = 1.0 / sqrt(1.0 + t * t), s = c * t;
                for (int i = 0; i < n; i++) {
                    double x = u[i], y = w[i];
                    u[i] = c * x - s * y, w[i] = s * x + c * y;
                }
                for (int i = 0; i < k; i++) {
                    double x = V[i * k + p], y = V[i * k + q];
                    V[i * k + p] = c * x - s * y, V[i * k + q] = s * x + c * y;
                }
                rotated = 1;
            }
        if (!rotated) break;
    }
    double sv[DEPTH], smax = 0.0;
    for (int p = 0; p < k; p++) {
        double s2 = 0.0;
        for (int i = 0; i < n; i++) s2 += B[(size_t)p * n + i] * B[(size_t)p * n + i];
        sv[p] = sqrt(s2);
        if (sv[p] > smax) smax = sv[p];
    }
    for (int i = 0; i < k; i++) coef[i] = 0.0;
    for (int p = 0; p < k; p++) { /* coef += V_p (u_p . b) / sigma_p, u_p = B_p / sigma_p */
        if (!(sv[p] > LSTSQ_RCOND * smax)) continue;
        double ub = 0.0;
        for (int i = 0; i < n; i++) ub += B[(size_t)p * n + i] * b[i];
        for (int i = 0; i < k; i++) coef[i] += V[i * k + p] * ub / (sv[p] * sv[p]);
    }
}

/* The accelerated fixed point from x; g ends as the map at the
 * last iterate. Returns 1 when converged; *its counts the iterations. */
static int fixed_point(const ovk_model *M, ovk_data *d, const double *lam0x, const double *Wx, double *x, double *g,
                       double *w, int *its) {
    int nx = M->nx, nc = M->ncols, nd = 0;
    double *q = w, *f = q + nc, *fp = f + nx, *gp = fp + nx, *dF = gp + nx, *dG = dF + DEPTH * nx;
    double *B = dG + DEPTH * nx, coef[DEPTH], prev = INFINITY;
    int growth = 0, have_prev = 0;
    G(M, d, lam0x, Wx, x, q, g);
    for (int it = 1; it <= M->max_iter; it++) {
        *its = it;
        for (int a = 0; a < nx; a++) f[a] = g[a] - x[a];
        double res = maxabs(f, nx);
        if (!isfinite(res)) return 0;
        if (res <= M->tol * (1.0 + maxabs(x, nx))) return 1;
        growth = res > prev ? growth + 1 : 0;
        if (growth >= 3) return 0;
        prev = res;
        if (have_prev) { /* the differences, the oldest dropped beyond DEPTH */
            if (nd == DEPTH) {
                memmove(dF, dF + nx, (size_t)(DEPTH - 1) * nx * sizeof(double));
                memmove(dG, dG + nx, (size_t)(DEPTH - 1) * nx * sizeof(double));
                nd--;
            }
            for (int a = 0; a < nx; a++) dF[nd * nx + a] = f[a] - fp[a], dG[nd * nx + a] = g[a] - gp[a];
            nd++;
        }
        memcpy(fp, f, (size_t)nx * sizeof(double));
        memcpy(gp, g, (size_t)nx * sizeof(double));
        have_prev = 1;
        if (nd) lstsq_small(dF, nd, nx, f, coef, B);
        for (int a = 0; a < nx; a++) {
            double t = 0.0;
            for (int i = 0; i < nd; i++) t += dG[i * nx + a] * coef[i];
            x[a] = g[a] - t;
        }
        G(M, d, lam0x, Wx, x, q, g);
    }
    return 0;
}

static double norm2(const double *a, int n) {
    double s = 0.0;
    for (int i = 0; i < n; i++) s += a[i] * a[i];
    return sqrt(s);
}

/* F(x) = x - G(x) into Fx (the map into g). */
static void F(const ovk_model *M, ovk_data *d, const double *lam0x, const double *Wx, const double *x, double *q,
              double *g, double *Fx) {
    G(M, d, lam0x, Wx, x, q, g);
    for (int a = 0; a < M->nx; a++) Fx[a] = x[a] - g[a];
}

/* Newton with a finite-difference Jacobian from x. Returns 1 when
 * converged; *its counts the iterations. */
static int fd_newton(const ovk_model *M, ovk_data *d, const double *lam0x, const double *Wx, double *x, double *w,
                     int *its) {
    int nx = M->nx, nc = M->ncols, *piv = d->piv;
    double *q = w, *g = q + nc, *Fx = g + nx, *xp = Fx + nx, *Fp = xp + nx, *dx = Fp + nx, *Jac = dx + nx;
    F(M, d, lam0x, Wx, x, q, g, Fx);
    for (int it = 1; it <= M->max_iter; it++) {
        *its = it;
        if (!isfinite(maxabs(Fx, nx))) return 0;
        if (maxabs(Fx, nx) <= M->tol * (1.0 + maxabs(x, nx))) return 1;
        for (int k = 0; k < nx; k++) {
            double step = 1e-7 * (fabs(x[k]) > 1.0 ? fabs(x[k]) : 1.0);
            memcpy(xp, x, (size_t)nx * sizeof(double));
            xp[k] += step;
            F(M, d, lam0x, Wx, xp, q, g, Fp);
            for (int a = 0; a < nx; a++) Jac[a * nx + k] = (Fp[a] - Fx[a]) / step;
        }
        for (int a = 0; a < nx; a++) dx[a] = -Fx[a];
        if (ovk_lu_factor(Jac, nx, piv)) return 0;
        ovk_lu_solve(Jac, nx, piv, dx);
        double norm0 = norm2(Fx, nx), alpha = 1.0;
        for (;;) {
            if (!(alpha > 1e-4)) return 0;
            for (int a = 0; a < nx; a++) xp[a] = x[a] + alpha * dx[a];
            F(M, d, lam0x, Wx, xp, q, g, Fp);
            if (norm2(Fp, nx) < (1.0 - 1e-4 * alpha) * norm0) break;
            alpha *= 0.5;
        }
        memcpy(x, xp, (size_t)nx * sizeof(double));
        memcpy(Fx, Fp, (size_t)nx * sizeof(double));
    }
    return 0;
}

size_t ovk_robust_doubles(int nx, int nc) { return (size_t)nc + (size_t)(6 + 3 * DEPTH) * nx + (size_t)nx * nx; }

/* The robust path after ovk_friction returned OVK_FRICTION in this workspace: start (m, or NULL:
 * the frictionless multipliers) as the first guess of the multipliers. On success the
 * friction forces (qf, ncols) are added to d->Q and their answer to d->lamR, as ovk_friction does;
 * *iterations counts the fixed-point and Newton iterations. */
int ovk_friction_robust(const ovk_model *M, ovk_data *d, const double *start, double *qf, int *iterations) {
    int nx = M->nx, nc = M->ncols, nR = M->nR, its_fp = 0, its_nt = 0;
    double *lam0x = d->work, *Wx = lam0x + nx, *x = d->robust, *g = x + nx, *w = g + nx;
    for (int a = 0; a < nx; a++) x[a] = start ? start[M->retained[M->xrows[a]]] : lam0x[a];
    int ok = fixed_point(M, d, lam0x, Wx, x, g, w, &its_fp), newton = 0;
    if (!ok) { /* Newton from the fixed point's last map value */
        memcpy(x, g, (size_t)nx * sizeof(double));
        ok = newton = fd_newton(M, d, lam0x, Wx, x, w, &its_nt);
    }
    *iterations = its_fp + its_nt;
    if (!ok) { /* the residual at the last iterate, for the message */
        double *q = w, *r = w + nc;
        G(M, d, lam0x, Wx, x, q, r);
        for (int a = 0; a < nx; a++) r[a] -= x[a];
        char names[160];
        ovk_friction_joint_list(M, names, sizeof names);
        return ovk_fail(d, OVK_FRICTION, "friction solve did not converge (residual %.3g N after %d iterations of the "
                        "robust path: fixed point, then Newton with a finite-difference Jacobian, after Newton and "
                        "damped Newton; %d friction multipliers of %s)", maxabs(r, nx), *iterations, nx, names);
    }
    /* lam_R: the map at the last iterate (the fixed point) or the Newton iterate on the friction
     * rows; the forces at lam_R's friction rows (what the path returns) */
    if (!newton) ovk_forces_reduced(M, d, x, qf); /* qf(x): lam_R = lam0 + W qf(x) */
    double *lr = w;                               /* the friction rows of lam_R */
    for (int a = 0; a < nx; a++) lr[a] = newton ? x[a] : g[a];
    if (!newton)
        for (int i = 0; i < nR; i++) {
            double acc = 0.0;
            for (int c = 0; c < nc; c++) acc += d->W[i * nc + c] * qf[c];
            d->lamR[i] += acc;
        }
    else {
        ovk_forces_reduced(M, d, x, qf); /* lam_R = G's full vector with x on the friction rows */
        for (int i = 0; i < nR; i++) {
            double acc = 0.0;
            for (int c = 0; c < nc; c++) acc += d->W[i * nc + c] * qf[c];
            d->lamR[i] += acc;
        }
        for (int a = 0; a < nx; a++) d->lamR[M->xrows[a]] = x[a];
    }
    ovk_forces_reduced(M, d, lr, qf); /* reads lr, writes qf and the per-joint buffers only */
    for (int c = 0; c < nc; c++) d->Q[M->cols[c]] += qf[c];
    return OVK_OK;
}
