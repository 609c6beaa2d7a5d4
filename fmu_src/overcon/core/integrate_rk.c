/* Explicit integrators of overcon.integrators in C: Dormand-Prince 5(4) with its 4th-order dense
 * output and the step-size control of SciPy's RungeKutta loop, and the classical Runge-Kutta 4
 * with the fixed step, its stability guard and cubic Hermite dense output. The constants, the
 * control and the order of the arithmetic are those of integrators.Dopri5 and integrators.RK4, so
 * that a run here equals the Python run on the same right-hand side to round-off (the same steps,
 * the same accept and reject decisions); tests/test_core_integrate.py checks it.
 *
 * The right-hand side is a callback (ovk_rhs_fn) with its own context; a status it returns stops
 * the step with that status (its message already written). The whole state is the ovk_rk record
 * and its arrays, so a copy of them is an exact save (sim_state.c). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"

#define SAFETY 0.9
#define MIN_FACTOR 0.2
#define MAX_FACTOR 10.0
#define STIFF_STEPS 15
#define STIFF_STEP_FRACTION 0.01
#define STABILITY_LIMITED 0.6
#define DOPRI5_STIFF_H_RHO 3.25
#define RK4_STABILITY 2.785

/* The Butcher tableau of SciPy's RK45 (integrators.Dopri5 reads it there), bit for bit. */
static const double DP_C[6] = {0.0, 0.2, 0.3, 0.8, 0.8888888888888888, 1.0};
static const double DP_A[6][5] = {
    {0.0, 0.0, 0.0, 0.0, 0.0},
    {0.2, 0.0, 0.0, 0.0, 0.0},
    {0.075, 0.225, 0.0, 0.0, 0.0},
    {0.9777777777777777, -3.7333333333333334, 3.5555555555555554, 0.0, 0.0},
    {2.9525986892242035, -11.595793324188385, 9.822892851699436, -0.2908093278463649, 0.0},
    {2.8462752525252526, -10.757575757575758, 8.906422717743473, 0.2784090909090909, -0.2735313036020583}};
static const double DP_B[6] = {0.09114583333333333, 0.0, 0.44923629829290207, 0.6510416666666666,
                               -0.322376179245283, 0.13095238095238096};
static const double DP_E[7] = {-0.0012326388888888888, 0.0, 0.0042527702905061394, -0.03697916666666667,
                               0.05086379716981132, -0.0419047619047619, 0.025};
static const double DP_P[7][4] = {
    {1.0, -2.8535800653862835, 3.0717434641059005, -1.1270175653862835},
    {0.0, 0.0, 0.0, 0.0},
    {0.0, 4.023133379230305, -6.249321565289, 2.675424484351598},
    {0.0, -3.7324019615885042, 10.068970589843675, -5.685526961588504},
    {0.0, 2.5548038301849423, -6.399112377351017, 3.5219323679207912},
    {0.0, -1.3744241142186024, 3.272657752246729, -1.7672812570757455},
    {0.0, 1.3824689317781436, -3.764937863556287, 2.382468931778144}};

static int rk_msg(char *msg, int status, const char *fmt, double a, double b, double c) {
    snprintf(msg, OVK_MSG, fmt, a, b, c);
    return status;
}

size_t ovk_rk_doubles(int n) { return (size_t)n * 17; }

/* Lays the arrays out in mem (ovk_rk_doubles(n) doubles) and evaluates f(t0, y0). */
int ovk_rk_start(ovk_rk *rk, const ovk_rk_opts *o, int n, double *mem, double t0, const double *y0, ovk_rhs_fn fun,
                 void *ctx, char *msg) {
    memset(rk, 0, sizeof *rk);
    rk->method = o->method;
    rk->n = n;
    rk->rtol = o->tolerance;
    rk->max_step = o->max_step;
    rk->step = o->step;
    rk->detect_stiffness = o->detect_stiffness;
    double *p = mem;
    rk->y = p; p += n;
    rk->f = p; p += n;
    rk->y_old = p; p += n;
    rk->f_old = p; p += n;
    rk->K = p; p += 7 * (size_t)n;
    rk->ynew = p; p += n;
    rk->ystage = p; p += n;
    rk->Q = p; p += 4 * (size_t)n;
    rk->t = rk->t0 = rk->t_old = t0;
    for (int i = 0; i < n; i++) rk->y[i] = y0[i];
    int status = fun(ctx, t0, rk->y, rk->f);
    if (status) return status;
    rk->nfev = 1;
    rk->h = o->first_step > 0.0 ? o->first_step : 1e-4;
    if (rk->max_step < rk->h) rk->h = rk->max_step;
    for (int i = 0; i < n; i++) {
        rk->y_old[i] = rk->y[i];
        rk->f_old[i] = rk->f[i];
    }
    (void)msg;
    return OVK_OK;
}

/* The stages 1..5 and y_new, f_new of one dopri5 attempt with step h (K[0] = f). */
static int dopri5_stages(ovk_rk *rk, double h, ovk_rhs_fn fun, void *ctx) {
    int n = rk->n;
    double *K = rk->K, t = rk->t;
    for (int i = 0; i < n; i++) K[i] = rk->f[i];
    for (int s = 1; s < 6; s++) {
        for (int i = 0; i < n; i++) {
            double acc = 0.0;
            for (int j = 0; j < s; j++) acc += K[(size_t)j * n + i] * DP_A[s][j];
            rk->ystage[i] = rk->y[i] + acc * h;
        }
        int status = fun(ctx, t + DP_C[s] * h, rk->ystage, K + (size_t)s * n);
        if (status) return status;
    }
    for (int i = 0; i < n; i++) {
        double acc = 0.0;
        for (int j = 0; j < 6; j++) acc += K[(size_t)j * n + i] * DP_B[j];
        rk->ynew[i] = rk->y[i] + h * acc;
    }
    int status = fun(ctx, t + h, rk->ynew, K + (size_t)6 * n);
    rk->nfev += 6;
    return status;
}

/* The RMS error norm of integrators.Dopri5._error_norm, scale = atol + max(|y|, |y_new|) rtol. */
static double dopri5_error(const ovk_rk *rk, double h) {
    int n = rk->n;
    double sum = 0.0;
    for (int i = 0; i < n; i++) {
        double e = 0.0;
        for (int j = 0; j < 7; j++) e += rk->K[(size_t)j * n + i] * DP_E[j];
        double a = fabs(rk->y[i]), b = fabs(rk->ynew[i]);
        double scale = rk->rtol + (a > b ? a : b) * rk->rtol;
        double r = e * h / scale;
        sum += r * r;
    }
    return sqrt(sum / n);
}

/* Hairer's stiffness test after an accepted step (integrators.AdaptiveRK._stiffness_test). */
static int stiffness_test(ovk_rk *rk, double h, char *msg) {
    int n = rk->n;
    const double *k6 = rk->K + (size_t)6 * n, *k5 = rk->K + (size_t)5 * n;
    double num = 0.0, den = 0.0;
    for (int i = 0; i < n; i++) {
        double dy = rk->y[i] - rk->ystage[i];
        den += dy * dy;
    }
    for (int i = 0; i < n; i++) {
        double df = k6[i] - k5[i];
        num += df * df;
    }
    double h_rho = den > 0.0 ? h * sqrt(num / den) : 0.0;
    if (h_rho > DOPRI5_STIFF_H_RHO) {
        rk->n_stiff++;
        rk->n_nonstiff = 0;
    } else if (++rk->n_nonstiff >= 6) {
        rk->n_stiff = 0;
    }
    if (rk->n_stiff >= STIFF_STEPS) rk->stiff_steps++;
    rk->n_limited = h_rho > STABILITY_LIMITED * DOPRI5_STIFF_H_RHO ? rk->n_limited + 1 : 0;
    int limited = rk->n_stiff >= STIFF_STEPS || rk->n_limited >= 10 * STIFF_STEPS;
    if (limited && rk->detect_stiffness && h < STIFF_STEP_FRACTION * rk->max_step) {
        double count = rk->n_stiff > rk->n_limited ? rk->n_stiff : rk->n_limited;
        return rk_msg(msg, OVK_STIFF,
                      "t = %.9g s: the problem is stiff for dopri5 (step %.3g s limited by stability on %.0f steps "
                      "in a row); e.g. a small friction regularisation velocity: increase v_reg or use the method "
                      "for stiff problems, radau", rk->t, h, count);
    }
    return OVK_OK;
}

/* One accepted dopri5 step (integrators.AdaptiveRK.step). */
static int dopri5_step(ovk_rk *rk, ovk_rhs_fn fun, void *ctx, char *msg) {
    int n = rk->n;
    double t = rk->t, min_step = 10.0 * fabs(nextafter(t, INFINITY) - t);
    double h = rk->h < rk->max_step ? rk->h : rk->max_step;
    const double exponent = -1.0 / 5.0;
    for (;;) {
        if (!(h >= min_step))
            return rk_msg(msg, OVK_STEP_SMALL, "t = %.9g s: step size %.3g s below the minimum", t, h, 0.0);
        int status = dopri5_stages(rk, h, fun, ctx);
        if (status) return status;
        double err = dopri5_error(rk, h);
        if (err < 1.0) {
            double factor = MAX_FACTOR;
            if (err != 0.0) {
                double g = SAFETY * pow(err, exponent);
                factor = g < MAX_FACTOR ? g : MAX_FACTOR;
            }
            memcpy(rk->y_old, rk->y, (size_t)n * sizeof(double));
            memcpy(rk->y, rk->ynew, (size_t)n * sizeof(double));
            memcpy(rk->f, rk->K + (size_t)6 * n, (size_t)n * sizeof(double));
            rk->t_old = t;
            rk->h_old = h;
            rk->has_K = 1;
            rk->dense_ready = 0;
            rk->t = t + h;
            rk->h = h * factor;
            rk->nsteps++;
            return stiffness_test(rk, h, msg);
        }
        double g = SAFETY * pow(err, exponent);
        h *= g > MIN_FACTOR ? g : MIN_FACTOR;
    }
}

/* The rk4 stability guard (integrators.RK4._check_stability): h rho from stages 1 to 3. */
static int rk4_stability(ovk_rk *rk, double h, const double *k1, const double *k2, const double *k3, char *msg) {
    int n = rk->n;
    double s2 = 0.0, s3 = 0.0;
    for (int i = 0; i < n; i++) {
        double d = k2[i] - k1[i];
        s2 += d * d;
    }
    double den = 0.5 * h * sqrt(s2);
    if (den == 0.0) return OVK_OK;
    for (int i = 0; i < n; i++) {
        double d = k3[i] - k2[i];
        s3 += d * d;
    }
    double h_rho = h * sqrt(s3) / den;
    if (!(h_rho > RK4_STABILITY)) return OVK_OK;
    double rho = h_rho / h;
    rk->stable_step = 2.0 / rho;
    int len = snprintf(msg, OVK_MSG, "t = %.9g s: rk4 is unstable with the fixed step %g s (h*rho = %.3g > %g, ",
                       rk->t, h, h_rho, RK4_STABILITY);
    if (len > 0 && len < OVK_MSG)
        snprintf(msg + len, (size_t)(OVK_MSG - len), "rho = %.3g 1/s the fastest rate of the right-hand side, e.g. "
                 "friction sticking inside its regularisation band): a step of at most %.2g s is stable; or use the "
                 "method for stiff problems, radau", rho, 2.0 / rho);
    return OVK_UNSTABLE;
}

/* One rk4 step (integrators.RK4.step); K rows 1..4 hold k2, k3, k4 and the stage state. */
static int rk4_step(ovk_rk *rk, ovk_rhs_fn fun, void *ctx, char *msg) {
    int n = rk->n, status;
    double h = rk->step, t = rk->t;
    double *k1 = rk->f, *k2 = rk->K + n, *k3 = rk->K + 2 * (size_t)n, *k4 = rk->K + 3 * (size_t)n;
    for (int i = 0; i < n; i++) rk->ystage[i] = rk->y[i] + h / 2 * k1[i];
    if ((status = fun(ctx, t + h / 2, rk->ystage, k2))) return status;
    for (int i = 0; i < n; i++) rk->ystage[i] = rk->y[i] + h / 2 * k2[i];
    if ((status = fun(ctx, t + h / 2, rk->ystage, k3))) return status;
    if ((status = rk4_stability(rk, h, k1, k2, k3, msg))) return status;
    double t_new = rk->t0 + (double)(rk->k + 1) * h;
    for (int i = 0; i < n; i++) rk->ystage[i] = rk->y[i] + h * k3[i];
    if ((status = fun(ctx, t_new, rk->ystage, k4))) return status;
    for (int i = 0; i < n; i++) rk->ynew[i] = rk->y[i] + h / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
    double *f_new = rk->K; /* row 0 is free in rk4 */
    if ((status = fun(ctx, t_new, rk->ynew, f_new))) return status;
    rk->nfev += 4;
    memcpy(rk->y_old, rk->y, (size_t)n * sizeof(double));
    memcpy(rk->f_old, rk->f, (size_t)n * sizeof(double));
    memcpy(rk->y, rk->ynew, (size_t)n * sizeof(double));
    memcpy(rk->f, f_new, (size_t)n * sizeof(double));
    rk->t_old = t;
    rk->k++;
    rk->t = t_new;
    rk->nsteps++;
    return OVK_OK;
}

int ovk_rk_step(ovk_rk *rk, ovk_rhs_fn fun, void *ctx, char *msg) {
    if (rk->method == OVK_METHOD_RK4) return rk4_step(rk, fun, ctx, msg);
    return dopri5_step(rk, fun, ctx, msg);
}

/* The solution at t_old <= t <= t (integrators' dense()), into out (n). */
void ovk_rk_dense(ovk_rk *rk, double t, double *out) {
    int n = rk->n;
    if (t == rk->t) {
        memcpy(out, rk->y, (size_t)n * sizeof(double));
        return;
    }
    if (rk->method == OVK_METHOD_RK4) {
        double h = rk->t - rk->t_old, x = (t - rk->t_old) / h;
        double h00 = 2 * pow(x, 3) - 3 * pow(x, 2) + 1, h10 = pow(x, 3) - 2 * pow(x, 2) + x;
        double h01 = -2 * pow(x, 3) + 3 * pow(x, 2), h11 = pow(x, 3) - pow(x, 2);
        double a = h10 * h, b = h11 * h;
        for (int i = 0; i < n; i++) out[i] = h00 * rk->y_old[i] + a * rk->f_old[i] + h01 * rk->y[i] + b * rk->f[i];
        return;
    }
    if (!rk->has_K) { /* no step yet: t is t0 */
        memcpy(out, rk->y, (size_t)n * sizeof(double));
        return;
    }
    if (!rk->dense_ready) { /* Q = K^T P */
        for (int i = 0; i < n; i++)
            for (int c = 0; c < 4; c++) {
                double acc = 0.0;
                for (int j = 0; j < 7; j++) acc += rk->K[(size_t)j * n + i] * DP_P[j][c];
                rk->Q[(size_t)i * 4 + c] = acc;
            }
        rk->dense_ready = 1;
    }
    double x = (t - rk->t_old) / rk->h_old, p[4];
    p[0] = x;
    for (int c = 1; c < 4; c++) p[c] = p[c - 1] * x;
    for (int i = 0; i < n; i++) {
        const double *q = rk->Q + (size_t)i * 4;
        out[i] = rk->y_old[i] + rk->h_old * (q[0] * p[0] + q[1] * p[1] + q[2] * p[2] + q[3] * p[3]);
    }
}
