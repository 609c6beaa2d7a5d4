/* Radau IIA of order 5 (Hairer & Wanner's RADAU5 as SciPy's Radau), integrators.Radau5 in C: each
 * step solves the 3-stage collocation system by simplified Newton iterations with the matrices
 * (mu_real / h) I - J (real LU, linalg.c) and (mu_complex / h) I - J (complex LU, lu.c), kept while
 * h and J stay; J is a forward-difference Jacobian of the right-hand side, recomputed only when
 * Newton converges slowly or fails; the embedded 3rd-order error estimate, Hairer & Wanner's
 * predictive step-size control and the collocation polynomial as dense output (no evaluations).
 * rtol = atol = tolerance; max_step caps the step. The constants, the control and the order of the
 * decisions are those of integrators.Radau5; the arithmetic is summed in index order (Radau5 goes
 * through numpy's BLAS and LAPACK's LU), so a run here agrees with the Python run within the
 * integration tolerance, not bit for bit (tests/test_core_integrators.py).
 *
 * A right-hand side that fails at a Newton iterate with a status the Python run counts as an
 * ArithmeticError (a singular position, the friction solve, an Euler singularity, a spring's
 * coincident points) is a failed Newton iteration: the step is retried smaller, and the last such
 * message is named when the step size collapses. An exactly singular Newton matrix is a failed
 * iteration too (scipy's lu_factor would warn and go on into NaN). Any other failure stops the step
 * with its status. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "core.h"

#define NEWTON_MAXITER 6
#define MIN_FACTOR 0.2
#define MAX_FACTOR 10.0

/* The constants of integrators.Radau5 (SciPy's radau module formulas), bit for bit. */
static const double RD_C[3] = {0.15505102572168222, 0.6449489742783178, 1.0};
static const double RD_E[3] = {-10.048809399827414, 1.382142733160748, -0.3333333333333333};
static const double RD_T[3][3] = {
    {0.09443876248897524, -0.1412552950209542, 0.03002919410514742},
    {0.2502131229653333, 0.20412935229379994, -0.3829421127572619},
    {1.0, 1.0, 0.0},
};
static const double RD_TI[3][3] = {
    {4.178718591551904, 0.32768282076106237, 0.5233764454994495},
    {-4.178718591551904, -0.32768282076106237, 0.47662355450055044},
    {0.5028726349457868, -2.571926949855605, 0.5960392048282249},
};
static const double RD_P[3][3] = {
    {10.048809399827414, -25.62959144707664, 15.580782047249224},
    {-1.382142733160748, 10.296258113743303, -8.914115380582556},
    {0.3333333333333333, -2.6666666666666665, 3.3333333333333335},
};
/* mu_real; Re and Im of mu_complex: the eigenvalues of the inverse of the collocation matrix */
static const double RD_MU[3] = {3.637834252744496, 2.6810828736277523, -3.050430199247411};

int ovk_radau_constants(const char *name, const double **data, int *rows, int *cols) {
    struct { const char *name; const double *p; int r, c; } table[] = {
        {"C", RD_C, 1, 3}, {"E", RD_E, 1, 3}, {"T", &RD_T[0][0], 3, 3}, {"TI", &RD_TI[0][0], 3, 3},
        {"P", &RD_P[0][0], 3, 3}, {"MU", RD_MU, 1, 3}};
    for (size_t i = 0; i < sizeof table / sizeof table[0]; i++)
        if (!strcmp(table[i].name, name)) {
            *data = table[i].p, *rows = table[i].r, *cols = table[i].c;
            return OVK_OK;
        }
    return OVK_INVALID;
}

/* Doubles of radau's arrays after the common ones: J, LU (n n each), LUc (2 n n), Zs, Z0, Z, W, dW,
 * F (3 n each), cw (2 n), err, scale (n each), then the pivots (2 n ints). */
size_t ovk_radau_doubles(int n) {
    size_t un = (size_t)n;
    return 4 * un * un + 18 * un + 2 * un + 2 * un + (2 * un * sizeof(int) + sizeof(double) - 1) / sizeof(double);
}

void ovk_radau_layout(ovk_rk *rk, double *p) {
    size_t n = (size_t)rk->n;
    rk->J = p; p += n * n;
    rk->LU = p; p += n * n;
    rk->LUc = p; p += 2 * n * n;
    rk->Zs = p; p += 3 * n;
    rk->Z0 = p; p += 3 * n;
    rk->Z = p; p += 3 * n;
    rk->W = p; p += 3 * n;
    rk->dW = p; p += 3 * n;
    rk->F = p; p += 3 * n;
    rk->cw = p; p += 2 * n;
    rk->err = p; p += n;
    rk->scale = p; p += n;
    rk->piv = (int *)p; /* the last part of the block: ints only */
    rk->pivc = rk->piv + n;
}

/* The right-hand side statuses that integrators.Radau5 counts as a failed Newton iteration (its
 * ArithmeticError and LinAlgError). */
static int recoverable(int status) {
    return status == OVK_SINGULAR || status == OVK_FRICTION || status == OVK_EULER || status == OVK_SPRING;
}

/* sqrt(sum x_i^2) / sqrt(size) of x_i = a_i / scale_(i mod n) (Radau5._norm), in index order. */
static double norm(const double *a, const double *scale, int rows, int n) {
    double sum = 0.0;
    for (int r = 0; r < rows; r++)
        for (int i = 0; i < n; i++) {
            double x = a[(size_t)r * n + i] / scale[i];
            sum += x * x;
        }
    return sqrt(sum) / sqrt((double)rows * n);
}

/* J = forward differences of fun at (t, y) with f = fun(t, y) (Radau5._jacobian): the step
 * sqrt(eps) max(|y_k|, 1) in the units of y_k. */
static int jacobian(ovk_rk *rk, double t, const double *y, const double *f, ovk_rhs_fn fun, void *ctx) {
    int n = rk->n;
    const double sqrt_eps = 1.4901161193847656e-08; /* sqrt(2^-52) = 2^-26 */
    memcpy(rk->ystage, y, (size_t)n * sizeof(double));
    for (int k = 0; k < n; k++) {
        double a = fabs(y[k]);
        rk->ystage[k] = y[k] + sqrt_eps * (a > 1.0 ? a : 1.0);
        double dk = rk->ystage[k] - y[k];
        int status = fun(ctx, t, rk->ystage, rk->err);
        if (status) return status;
        for (int i = 0; i < n; i++) rk->J[(size_t)i * n + k] = (rk->err[i] - f[i]) / dk;
        rk->ystage[k] = y[k];
    }
    rk->nfev += n;
    rk->njev++;
    return OVK_OK;
}

/* The LU factors of (mu_real / h) I - J and (mu_complex / h) I - J (Radau5._factor); nonzero when
 * one is exactly singular. */
static int factor(ovk_rk *rk, double h) {
    int n = rk->n;
    double mr = RD_MU[0] / h, cr = RD_MU[1] / h, ci = RD_MU[2] / h;
    for (int i = 0; i < n; i++)
        for (int k = 0; k < n; k++) {
            double j = rk->J[(size_t)i * n + k];
            rk->LU[(size_t)i * n + k] = (i == k ? mr : 0.0) - j;
            rk->LUc[2 * ((size_t)i * n + k)] = (i == k ? cr : 0.0) - j;
            rk->LUc[2 * ((size_t)i * n + k) + 1] = i == k ? ci : 0.0;
        }
    rk->nlu += 2;
    rk->has_lu = 0;
    int bad = ovk_lu_factor(rk->LU, n, rk->piv) || ovk_zlu_factor(rk->LUc, n, rk->pivc);
    if (!bad) {
        rk->has_lu = 1;
        rk->lu_h = h;
    }
    return bad;
}

/* The collocation polynomial of the last step at t (Radau5._dense_poly): y_old + sum_c Q[c] x^(c+1),
 * Q = Zs^T P, x = (t - t_old) / (t_now - t_old). */
static void dense_poly(const ovk_rk *rk, double t, double *out) {
    int n = rk->n;
    double x = (t - rk->t_old) / (rk->t - rk->t_old), p[3];
    p[0] = x, p[1] = x * x, p[2] = p[1] * x;
    for (int i = 0; i < n; i++) {
        double acc = 0.0;
        for (int c = 0; c < 3; c++) {
            double q = 0.0;
            for (int j = 0; j < 3; j++) q += rk->Zs[(size_t)j * n + i] * RD_P[j][c];
            acc += q * p[c];
        }
        out[i] = rk->y_old[i] + acc;
    }
}

void ovk_radau_dense(const ovk_rk *rk, double t, double *out) {
    if (t == rk->t || (!rk->has_K && !rk->dense_kept)) {
        memcpy(out, rk->y, (size_t)rk->n * sizeof(double));
        return;
    }
    dense_poly(rk, t, out);
}

int ovk_radau_start(ovk_rk *rk, ovk_rhs_fn fun, void *ctx, char *msg) {
    (void)msg;
    const double eps = 2.220446049250313e-16;
    double a = 10.0 * eps / rk->rtol, b = pow(rk->rtol, 0.5);
    if (b > 0.03) b = 0.03;
    rk->newton_tol = b > a ? b : a;
    int status = jacobian(rk, rk->t, rk->y, rk->f, fun, ctx);
    if (status) return status;
    rk->current_jac = 1;
    return OVK_OK;
}

/* The outcome of the simplified Newton iterations on the collocation system (Radau5._collocation). */
typedef struct {
    int converged, iterations, has_rate;
    double rate;
} newton;

/* Simplified Newton from Z0 (3 n) with the current factors; the iterate into rk->Z. Returns OVK_OK
 * (converged or not, in *out) or a status that stops the step; a recoverable failure of the
 * right-hand side is kept in why. */
static int collocation(ovk_rk *rk, double t, const double *y, double h, ovk_rhs_fn fun, void *ctx, char *msg,
                       char *why, newton *out) {
    int n = rk->n;
    double mr = RD_MU[0] / h, cr = RD_MU[1] / h, ci = RD_MU[2] / h;
    double *W = rk->W, *Z = rk->Z, *dW = rk->dW, *F = rk->F, dW_norm_old = 0.0;
    int has_old = 0;
    out->converged = 0, out->has_rate = 0, out->rate = 0.0;
    for (int r = 0; r < 3; r++) /* W = TI Z0 */
        for (int i = 0; i < n; i++) {
            double acc = 0.0;
            for (int j = 0; j < 3; j++) acc += RD_TI[r][j] * rk->Z0[(size_t)j * n + i];
            W[(size_t)r * n + i] = acc;
        }
    memcpy(Z, rk->Z0, 3 * (size_t)n * sizeof(double));
    for (int k = 0; k < NEWTON_MAXITER; k++) {
        out->iterations = k + 1;
        for (int s = 0; s < 3; s++) {
            for (int i = 0; i < n; i++) rk->ystage[i] = y[i] + Z[(size_t)s * n + i];
            int status = fun(ctx, t + RD_C[s] * h, rk->ystage, F + (size_t)s * n);
            rk->nfev++;
            if (status && !recoverable(status)) return status;
            if (status) {
                snprintf(why, OVK_MSG, "%s", msg);
                return OVK_OK;
            }
        }
        for (int i = 0; i < n; i++) {
            double fr = 0.0, fc = 0.0, fi = 0.0;
            for (int j = 0; j < 3; j++) fr += F[(size_t)j * n + i] * RD_TI[0][j];
            for (int j = 0; j < 3; j++) fc += F[(size_t)j * n + i] * RD_TI[1][j];
            for (int j = 0; j < 3; j++) fi += F[(size_t)j * n + i] * RD_TI[2][j];
            double w0 = W[i], w1 = W[(size_t)n + i], w2 = W[2 * (size_t)n + i];
            dW[i] = fr - mr * w0;
            rk->cw[2 * i] = fc - (cr * w1 - ci * w2);
            rk->cw[2 * i + 1] = fi - (cr * w2 + ci * w1);
        }
        ovk_zlu_solve(rk->LUc, n, rk->pivc, rk->cw);
        ovk_lu_solve(rk->LU, n, rk->piv, dW);
        for (int i = 0; i < n; i++) {
            dW[(size_t)n + i] = rk->cw[2 * i];
            dW[2 * (size_t)n + i] = rk->cw[2 * i + 1];
        }
        double dW_norm = norm(dW, rk->scale, 3, n);
        if (has_old) {
            out->rate = dW_norm / dW_norm_old;
            out->has_rate = 1;
        }
        double rate = out->rate;
        if (out->has_rate && (rate >= 1.0 || pow(rate, NEWTON_MAXITER - k) / (1.0 - rate) * dW_norm > rk->newton_tol))
            return OVK_OK;
        for (size_t i = 0; i < 3 * (size_t)n; i++) W[i] = W[i] + dW[i];
        for (int r = 0; r < 3; r++) /* Z = T W */
            for (int i = 0; i < n; i++) {
                double acc = 0.0;
                for (int j = 0; j < 3; j++) acc += RD_T[r][j] * W[(size_t)j * n + i];
                Z[(size_t)r * n + i] = acc;
            }
        if (dW_norm == 0.0 || (out->has_rate && rate / (1.0 - rate) * dW_norm < rk->newton_tol)) {
            out->converged = 1;
            return OVK_OK;
        }
        dW_norm_old = dW_norm;
        has_old = 1;
    }
    return OVK_OK;
}

/* Step-size factor of Hairer & Wanner's predictive controller (Radau5._predict_factor); an error
 * of exactly 0 gives an infinite factor, which the caller caps at MAX_FACTOR. */
static double predict_factor(double h_abs, int has_old, double h_abs_old, double error_norm, double error_norm_old) {
    if (error_norm == 0.0) return INFINITY;
    double multiplier = 1.0;
    if (has_old && error_norm_old != 0.0) multiplier = h_abs / h_abs_old * pow(error_norm_old / error_norm, 0.25);
    return (multiplier < 1.0 ? multiplier : 1.0) * pow(error_norm, -0.25);
}

/* err = LU_real^-1 (g + ZE) and its norm with the scale (rk->scale). */
static double error_estimate(ovk_rk *rk, const double *g, const double *ZE) {
    int n = rk->n;
    for (int i = 0; i < n; i++) rk->err[i] = g[i] + ZE[i];
    ovk_lu_solve(rk->LU, n, rk->piv, rk->err);
    return norm(rk->err, rk->scale, 1, n);
}

/* One accepted step (Radau5.step). */
int ovk_radau_step(ovk_rk *rk, ovk_rhs_fn fun, void *ctx, char *msg) {
    int n = rk->n, rejected = 0, has_old = rk->has_old, status;
    double t = rk->t, min_step = 10.0 * fabs(nextafter(t, INFINITY) - t);
    double h_abs = rk->h, h_abs_old = rk->h_abs_old, error_norm_old = rk->error_norm_old, h = h_abs;
    double error_norm = 0.0, safety = 0.0;
    double *y = rk->y, *Z = rk->Z, *ZE = rk->cw; /* ZE: n of cw (free after the Newton iterations) */
    char why[OVK_MSG] = "";
    newton nt = {0, 0, 0, 0.0};
    if (h_abs > rk->max_step) h_abs = rk->max_step, has_old = 0;
    int bounded = t + h_abs >= rk->t_bound; /* the step ends at t_bound (inputs change there: sim.c) */
    if (bounded) h_abs = rk->t_bound - t, has_old = 0;
    h = h_abs;
    for (;;) {
        if (!(h_abs >= min_step)) {
            int len = snprintf(msg, OVK_MSG, "t = %.9g s: step size %.3g s below the minimum", t, h_abs);
            if (why[0] && len > 0 && len < OVK_MSG) snprintf(msg + len, (size_t)(OVK_MSG - len), " (last failure: %s)", why);
            return OVK_STEP_SMALL;
        }
        if (h != h_abs) bounded = 0; /* a smaller step than the bounded one */
        h = h_abs;
        if (!rk->has_K) {
            memset(rk->Z0, 0, 3 * (size_t)n * sizeof(double));
        } else {
            for (int s = 0; s < 3; s++) {
                double *z = rk->Z0 + (size_t)s * n;
                dense_poly(rk, t + RD_C[s] * h, z);
                for (int i = 0; i < n; i++) z[i] = z[i] - y[i];
            }
        }
        for (int i = 0; i < n; i++) rk->scale[i] = rk->rtol + fabs(y[i]) * rk->rtol;
        for (;;) {
            int singular = (!rk->has_lu || rk->lu_h != h) ? factor(rk, h) : 0;
            if (singular) {
                snprintf(why, OVK_MSG, "t = %.9g s: the Newton matrix mu/h I - J is singular (h = %.3g s)", t, h);
                nt.converged = 0, nt.iterations = 0, nt.has_rate = 0;
            } else if ((status = collocation(rk, t, y, h, fun, ctx, msg, why, &nt))) {
                return status;
            }
            if (nt.converged || rk->current_jac) break;
            if ((status = jacobian(rk, t, y, rk->f, fun, ctx))) return status;
            rk->current_jac = 1;
            rk->has_lu = 0;
        }
        if (!nt.converged) {
            h_abs *= 0.5;
            rk->has_lu = 0;
            continue;
        }
        for (int i = 0; i < n; i++) {
            rk->ynew[i] = y[i] + Z[2 * (size_t)n + i];
            double acc = 0.0;
            for (int j = 0; j < 3; j++) acc += Z[(size_t)j * n + i] * RD_E[j];
            ZE[i] = acc / h;
        }
        for (int i = 0; i < n; i++) {
            double a = fabs(y[i]), b = fabs(rk->ynew[i]);
            rk->scale[i] = rk->rtol + (a > b ? a : b) * rk->rtol;
        }
        error_norm = error_estimate(rk, rk->f, ZE);
        safety = 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + nt.iterations);
        if (rejected && error_norm > 1.0) {
            for (int i = 0; i < n; i++) rk->ystage[i] = y[i] + rk->err[i];
            if ((status = fun(ctx, t, rk->ystage, rk->F))) return status;
            rk->nfev++;
            error_norm = error_estimate(rk, rk->F, ZE);
        }
        if (!isfinite(error_norm)) { /* never accept a non-finite estimate: halve, as on failure */
            snprintf(why, OVK_MSG, "non-finite error estimate");
            h_abs *= 0.5;
            rk->has_lu = 0;
            rejected = 1;
            continue;
        }
        if (error_norm > 1.0) {
            double g = safety * predict_factor(h_abs, has_old, h_abs_old, error_norm, error_norm_old);
            h_abs *= g > MIN_FACTOR ? g : MIN_FACTOR;
            rk->has_lu = 0;
            rejected = 1;
            continue;
        }
        break;
    }
    int recompute_jac = nt.iterations > 2 && nt.has_rate && nt.rate > 1e-3;
    double factor_h = safety * predict_factor(h_abs, has_old, h_abs_old, error_norm, error_norm_old);
    if (!(factor_h < MAX_FACTOR)) factor_h = MAX_FACTOR;
    if (!recompute_jac && factor_h < 1.2)
        factor_h = 1.0;
    else
        rk->has_lu = 0;
    double t_new = bounded ? rk->t_bound : t + h;
    /* the last evaluation of the step, at the accepted state, into F's first row (then f) */
    if ((status = fun(ctx, t_new, rk->ynew, rk->F))) return status;
    rk->nfev++;
    if (recompute_jac) {
        if ((status = jacobian(rk, t_new, rk->ynew, rk->F, fun, ctx))) return status;
        rk->current_jac = 1;
    } else {
        rk->current_jac = 0;
    }
    rk->h_abs_old = h_abs, rk->error_norm_old = error_norm, rk->has_old = 1;
    rk->h = h_abs * factor_h;
    rk->t_old = t;
    memcpy(rk->y_old, y, (size_t)n * sizeof(double));
    memcpy(rk->Zs, Z, 3 * (size_t)n * sizeof(double));
    rk->has_K = 1;
    rk->dense_kept = 0;
    rk->t = t_new;
    memcpy(rk->y, rk->ynew, (size_t)n * sizeof(double));
    memcpy(rk->f, rk->F, (size_t)n * sizeof(double));
    rk->h_old = h;
    rk->nsteps++;
    return OVK_OK;
}
