/* The explicit integrators of a run (sim.c): Dormand-Prince 5(4) with its 4th-order dense
 * output and Dormand-Prince 8(5,3) (Hairer's DOP853) with its 7th-order dense output, both with the
 * step-size control of SciPy's RungeKutta loop and Hairer's stiffness test, and the classical
 * Runge-Kutta 4 with the fixed step, its stability guard and cubic Hermite dense output. The
 * constants, the control and the order of the arithmetic are those of integrators.Dopri5,
 * integrators.Dop853 and integrators.RK4, so that a run here equals the Python run on the same
 * right-hand side to round-off (the same steps, the same accept and reject decisions);
 * tests/test_core_integrate.py and tests/test_core_integrators.py check it.
 *
 * dop853's dense output needs three more stages per step. They are evaluated only when an output
 * falls inside the step (the first ovk_rk_dense of the step), with rk->dense_fun, a right-hand side
 * that must leave the run's state alone, so reading outputs never alters the trajectory; a failure
 * there is kept in rk->dense_status (the caller stops the run).
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
#define DOP853_STIFF_H_RHO 6.1
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

/* The tableau of SciPy's DOP853 (scipy.integrate._ivp.dop853_coefficients, as integrators.Dop853
 * reads it from scipy.integrate.DOP853), bit for bit: 12 stages, then f(y_new) as row 12 of K. */
static const double D8_C[12] = {0.0, 0.05260015195876773, 0.0789002279381516, 0.1183503419072274, 0.2816496580927726, 0.3333333333333333, 0.25, 0.3076923076923077, 0.6512820512820513, 0.6, 0.8571428571428571, 1.0};
static const double D8_A[12][12] = {
    {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.05260015195876773, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.0197250569845379, 0.0591751709536137, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.02958758547680685, 0.0, 0.08876275643042054, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.037037037037037035, 0.0, 0.0, 0.17082860872947386, 0.12546768756682242, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.037109375, 0.0, 0.0, 0.17025221101954405, 0.06021653898045596, -0.017578125, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.03709200011850479, 0.0, 0.0, 0.17038392571223998, 0.10726203044637328, -0.015319437748624402, 0.008273789163814023, 0.0, 0.0, 0.0, 0.0, 0.0},
    {0.6241109587160757, 0.0, 0.0, -3.3608926294469414, -0.868219346841726, 27.59209969944671, 20.154067550477894, -43.48988418106996, 0.0, 0.0, 0.0, 0.0},
    {0.47766253643826434, 0.0, 0.0, -2.4881146199716677, -0.590290826836843, 21.230051448181193, 15.279233632882423, -33.28821096898486, -0.020331201708508627, 0.0, 0.0, 0.0},
    {-0.9371424300859873, 0.0, 0.0, 5.186372428844064, 1.0914373489967295, -8.149787010746927, -18.52006565999696, 22.739487099350505, 2.4936055526796523, -3.0467644718982196, 0.0, 0.0},
    {2.273310147516538, 0.0, 0.0, -10.53449546673725, -2.0008720582248625, -17.9589318631188, 27.94888452941996, -2.8589982771350235, -8.87285693353063, 12.360567175794303, 0.6433927460157636, 0.0},
};
static const double D8_B[12] = {0.054293734116568765, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, 0.3111643669578199, -0.1521609496625161, 0.20136540080403034, 0.04471061572777259};
static const double D8_E3[13] = {-0.18980075407240762, 0.0, 0.0, 0.0, 0.0, 4.450312892752409, 1.8915178993145003, -5.801203960010585, -0.4226823213237919, -0.1521609496625161, 0.20136540080403034, 0.02265179219836082, 0.0};
static const double D8_E5[13] = {0.01312004499419488, 0.0, 0.0, 0.0, 0.0, -1.2251564463762044, -0.4957589496572502, 1.6643771824549864, -0.35032884874997366, 0.3341791187130175, 0.08192320648511571, -0.022355307863886294, 0.0};
static const double D8_D[4][16] = {
    {-8.428938276109013, 0.0, 0.0, 0.0, 0.0, 0.5667149535193777, -3.0689499459498917, 2.38466765651207, 2.117034582445028, -0.871391583777973, 2.2404374302607883, 0.6315787787694688, -0.08899033645133331, 18.148505520854727, -9.194632392478356, -4.436036387594894},
    {10.427508642579134, 0.0, 0.0, 0.0, 0.0, 242.28349177525817, 165.20045171727028, -374.5467547226902, -22.113666853125306, 7.733432668472264, -30.674084731089398, -9.332130526430229, 15.697238121770845, -31.139403219565178, -9.35292435884448, 35.81684148639408},
    {19.985053242002433, 0.0, 0.0, 0.0, 0.0, -387.0373087493518, -189.17813819516758, 527.8081592054236, -11.57390253995963, 6.8812326946963, -1.0006050966910838, 0.7777137798053443, -2.778205752353508, -60.19669523126412, 84.32040550667716, 11.99229113618279},
    {-25.69393346270375, 0.0, 0.0, 0.0, 0.0, -154.18974869023643, -231.5293791760455, 357.6391179106141, 93.40532418362432, -37.45832313645163, 104.0996495089623, 29.8402934266605, -43.53345659001114, 96.32455395918828, -39.17726167561544, -149.72683625798564},
};
static const double D8_A_EXTRA[3][16] = {
    {0.056167502283047954, 0.0, 0.0, 0.0, 0.0, 0.0, 0.25350021021662483, -0.2462390374708025, -0.12419142326381637, 0.15329179827876568, 0.00820105229563469, 0.007567897660545699, -0.008298, 0.0, 0.0, 0.0},
    {0.03183464816350214, 0.0, 0.0, 0.0, 0.0, 0.028300909672366776, 0.053541988307438566, -0.05492374857139099, 0.0, 0.0, -0.00010834732869724932, 0.0003825710908356584, -0.00034046500868740456, 0.1413124436746325, 0.0, 0.0},
    {-0.42889630158379194, 0.0, 0.0, 0.0, 0.0, -4.697621415361164, 7.683421196062599, 4.06898981839711, 0.3567271874552811, 0.0, 0.0, 0.0, -0.0013990241651590145, 2.9475147891527724, -9.15095847217987, 0.0},
};
static const double D8_C_EXTRA[3] = {0.1, 0.2, 0.7777777777777778};

/* An embedded explicit pair: its stages, tableau (A row-major, lda columns) and control. */
typedef struct {
    const char *name;
    int stages, lda;
    const double *C, *A, *B;
    double exponent, stiff_h_rho; /* -1 / (error order + 1); Hairer's stiffness threshold of h rho */
} erk_tableau;

static const erk_tableau DOPRI5 = {"dopri5", 6, 5, DP_C, &DP_A[0][0], DP_B, -1.0 / 5.0, DOPRI5_STIFF_H_RHO};
static const erk_tableau DOP853 = {"dop853", 12, 12, D8_C, &D8_A[0][0], D8_B, -1.0 / 8.0, DOP853_STIFF_H_RHO};

int ovk_integrator_constants(int method, const char *name, const double **data, int *rows, int *cols) {
    struct { int method; const char *name; const double *p; int r, c; } table[] = {
        {OVK_METHOD_DOPRI5, "C", DP_C, 1, 6}, {OVK_METHOD_DOPRI5, "A", &DP_A[0][0], 6, 5},
        {OVK_METHOD_DOPRI5, "B", DP_B, 1, 6}, {OVK_METHOD_DOPRI5, "E", DP_E, 1, 7},
        {OVK_METHOD_DOPRI5, "P", &DP_P[0][0], 7, 4},
        {OVK_METHOD_DOP853, "C", D8_C, 1, 12}, {OVK_METHOD_DOP853, "A", &D8_A[0][0], 12, 12},
        {OVK_METHOD_DOP853, "B", D8_B, 1, 12}, {OVK_METHOD_DOP853, "E3", D8_E3, 1, 13},
        {OVK_METHOD_DOP853, "E5", D8_E5, 1, 13}, {OVK_METHOD_DOP853, "D", &D8_D[0][0], 4, 16},
        {OVK_METHOD_DOP853, "A_EXTRA", &D8_A_EXTRA[0][0], 3, 16}, {OVK_METHOD_DOP853, "C_EXTRA", D8_C_EXTRA, 1, 3}};
    if (!name || !data || !rows || !cols) return OVK_INVALID;
    if (method == OVK_METHOD_RADAU) return ovk_radau_constants(name, data, rows, cols);
    for (size_t i = 0; i < sizeof table / sizeof table[0]; i++)
        if (table[i].method == method && !strcmp(table[i].name, name)) {
            *data = table[i].p, *rows = table[i].r, *cols = table[i].c;
            return OVK_OK;
        }
    return OVK_INVALID;
}

static int rk_msg(char *msg, int status, const char *fmt, double a, double b, double c) {
    snprintf(msg, OVK_MSG, fmt, a, b, c);
    return status;
}

/* Rows of K and Q per method: the stages kept for the dense output, its coefficients. */
static int k_rows(int method) {
    return method == OVK_METHOD_DOP853 ? 16 : method == OVK_METHOD_RADAU ? 0 : 7;
}
static int q_rows(int method) {
    return method == OVK_METHOD_DOP853 ? 7 : method == OVK_METHOD_DOPRI5 ? 4 : 0;
}

size_t ovk_rk_doubles(int method, int n) {
    size_t common = 6 * (size_t)n + (size_t)(k_rows(method) + q_rows(method)) * (size_t)n;
    return method == OVK_METHOD_RADAU ? common + ovk_radau_doubles(n) : common;
}

/* The integrator's scalars set anew for the options o and its arrays laid out in mem
 * (ovk_rk_doubles(o->method, n) doubles; their contents are left as they are); dense_fun and
 * dense_ctx stay. */
static void reset(ovk_rk *rk, const ovk_rk_opts *o, int n, double *mem) {
    ovk_rhs_fn dense_fun = rk->dense_fun; /* the dense stages' right-hand side stays */
    void *dense_ctx = rk->dense_ctx;
    memset(rk, 0, sizeof *rk);
    rk->dense_fun = dense_fun, rk->dense_ctx = dense_ctx;
    rk->method = o->method;
    rk->n = n;
    rk->rtol = o->tolerance;
    rk->max_step = o->max_step;
    rk->step = o->step;
    rk->detect_stiffness = o->detect_stiffness;
    rk->nK = k_rows(o->method);
    rk->nQ = q_rows(o->method);
    double *p = mem;
    rk->y = p; p += n;
    rk->f = p; p += n;
    rk->y_old = p; p += n;
    rk->f_old = p; p += n;
    rk->ynew = p; p += n;
    rk->ystage = p; p += n;
    rk->K = p; p += (size_t)rk->nK * n;
    rk->Q = p; p += (size_t)rk->nQ * n;
    if (rk->method == OVK_METHOD_RADAU) ovk_radau_layout(rk, p);
    rk->t_bound = INFINITY;
}

/* f(t, y) into rk->f, the first step size, and radau's Jacobian there. */
static int first_evaluation(ovk_rk *rk, const ovk_rk_opts *o, ovk_rhs_fn fun, void *ctx) {
    int status = fun(ctx, rk->t, rk->y, rk->f);
    if (status) return status;
    rk->nfev = 1;
    rk->h = o->first_step > 0.0 ? o->first_step : 1e-4;
    if (rk->max_step < rk->h) rk->h = rk->max_step;
    return OVK_OK;
}

/* Lays the arrays out in mem (ovk_rk_doubles(o->method, n) doubles) and evaluates f(t0, y0)
 * (radau: and its Jacobian there). */
int ovk_rk_start(ovk_rk *rk, const ovk_rk_opts *o, int n, double *mem, double t0, const double *y0, ovk_rhs_fn fun,
                 void *ctx, char *msg) {
    reset(rk, o, n, mem);
    rk->t = rk->t0 = rk->t_old = t0;
    for (int i = 0; i < n; i++) rk->y[i] = y0[i];
    int status = first_evaluation(rk, o, fun, ctx);
    if (status) return status;
    for (int i = 0; i < n; i++) {
        rk->y_old[i] = rk->y[i];
        rk->f_old[i] = rk->f[i];
    }
    if (rk->method == OVK_METHOD_RADAU) return ovk_radau_start(rk, fun, ctx, msg);
    return OVK_OK;
}

/* Goes on from the end (t, y) of the last accepted step as ovk_rk_start there would (a new step
 * control and f(t, y) of fun, which may differ from the step's right-hand side), but keeps that
 * step's dense output: ovk_rk_dense still answers on [t_old, t] from the step that was accepted
 * (a run whose kept equations are chosen again at a step's end, sim.c). ovk_rk_dense_prepare
 * must have run while the step's right-hand side was still in force. The counters start anew. */
int ovk_rk_restart(ovk_rk *rk, const ovk_rk_opts *o, ovk_rhs_fn fun, void *ctx, char *msg) {
    double t = rk->t, t_old = rk->t_old, h_old = rk->h_old, t_bound = rk->t_bound; /* a bound of the advance in course */
    int kept = t_old < t && (rk->method == OVK_METHOD_RK4 || rk->has_K || rk->dense_kept) &&
               (rk->method == OVK_METHOD_RK4 || rk->method == OVK_METHOD_RADAU || rk->dense_ready);
    reset(rk, o, rk->n, rk->y);
    rk->t_bound = t_bound;
    rk->t = rk->t0 = t;
    rk->t_old = kept ? t_old : t, rk->h_old = kept ? h_old : 0.0;
    rk->dense_kept = kept, rk->dense_ready = kept;
    int status = first_evaluation(rk, o, fun, ctx);
    if (status) return status;
    if (!kept)
        for (int i = 0; i < rk->n; i++) {
            rk->y_old[i] = rk->y[i];
            rk->f_old[i] = rk->f[i];
        }
    if (rk->method == OVK_METHOD_RADAU) return ovk_radau_start(rk, fun, ctx, msg);
    return OVK_OK;
}

/* y0 + (sum_{j < s} K[j] a[j]) h, the sum in index order from zero (integrators._combine). */
static void stage_state(const ovk_rk *rk, const double *y0, const double *a, int s, double h, double *out) {
    int n = rk->n;
    for (int i = 0; i < n; i++) {
        double acc = 0.0;
        for (int j = 0; j < s; j++) acc += rk->K[(size_t)j * n + i] * a[j];
        out[i] = y0[i] + acc * h;
    }
}

/* The stages 1..s-1 and y_new, f_new (row s of K) of one attempt with step h (K[0] = f). */
static int erk_stages(ovk_rk *rk, const erk_tableau *tb, double h, ovk_rhs_fn fun, void *ctx) {
    int n = rk->n, ns = tb->stages;
    double *K = rk->K, t = rk->t;
    for (int i = 0; i < n; i++) K[i] = rk->f[i];
    for (int s = 1; s < ns; s++) {
        stage_state(rk, rk->y, tb->A + (size_t)s * tb->lda, s, h, rk->ystage);
        int status = fun(ctx, t + tb->C[s] * h, rk->ystage, K + (size_t)s * n);
        if (status) return status;
    }
    for (int i = 0; i < n; i++) {
        double acc = 0.0;
        for (int j = 0; j < ns; j++) acc += K[(size_t)j * n + i] * tb->B[j];
        rk->ynew[i] = rk->y[i] + h * acc;
    }
    int status = fun(ctx, t + h, rk->ynew, K + (size_t)ns * n);
    rk->nfev += ns;
    return status;
}

/* The scale of the error norms: atol + max(|y|, |y_new|) rtol (atol = rtol). */
static double err_scale(const ovk_rk *rk, int i) {
    double a = fabs(rk->y[i]), b = fabs(rk->ynew[i]);
    return rk->rtol + (a > b ? a : b) * rk->rtol;
}

/* The RMS error norm of integrators.Dopri5._error_norm. */
static double dopri5_error(const ovk_rk *rk, double h) {
    int n = rk->n;
    double sum = 0.0;
    for (int i = 0; i < n; i++) {
        double e = 0.0;
        for (int j = 0; j < 7; j++) e += rk->K[(size_t)j * n + i] * DP_E[j];
        double r = e * h / err_scale(rk, i);
        sum += r * r;
    }
    return sqrt(sum / n);
}

/* The error norm of integrators.Dop853._error_norm (Hairer's, from the 5th- and 3rd-order
 * estimates): |h| e5 / sqrt((e5 + 0.01 e3) n), e5 and e3 the squared norms of the scaled errors. */
static double dop853_error(const ovk_rk *rk, double h) {
    int n = rk->n;
    double e5 = 0.0, e3 = 0.0;
    for (int i = 0; i < n; i++) {
        double a5 = 0.0, a3 = 0.0, sc = err_scale(rk, i);
        for (int j = 0; j < 13; j++) a5 += rk->K[(size_t)j * n + i] * D8_E5[j];
        for (int j = 0; j < 13; j++) a3 += rk->K[(size_t)j * n + i] * D8_E3[j];
        a5 /= sc;
        a3 /= sc;
        e5 += a5 * a5;
        e3 += a3 * a3;
    }
    if (e5 == 0.0 && e3 == 0.0) return 0.0;
    return fabs(h) * e5 / sqrt((e5 + 0.01 * e3) * n);
}

/* Hairer's stiffness test after an accepted step (integrators.AdaptiveRK._stiffness_test), from the
 * last stage and f(y_new) (rows s - 1 and s of K) and the last stage's state (ystage). */
static int stiffness_test(ovk_rk *rk, const erk_tableau *tb, double h, char *msg) {
    int n = rk->n;
    const double *kn = rk->K + (size_t)tb->stages * n, *kl = rk->K + (size_t)(tb->stages - 1) * n;
    double num = 0.0, den = 0.0;
    for (int i = 0; i < n; i++) {
        double dy = rk->y[i] - rk->ystage[i];
        den += dy * dy;
    }
    for (int i = 0; i < n; i++) {
        double df = kn[i] - kl[i];
        num += df * df;
    }
    double h_rho = den > 0.0 ? h * sqrt(num / den) : 0.0;
    if (h_rho > tb->stiff_h_rho) {
        rk->n_stiff++;
        rk->n_nonstiff = 0;
    } else if (++rk->n_nonstiff >= 6) {
        rk->n_stiff = 0;
    }
    if (rk->n_stiff >= STIFF_STEPS) rk->stiff_steps++;
    rk->n_limited = h_rho > STABILITY_LIMITED * tb->stiff_h_rho ? rk->n_limited + 1 : 0;
    int limited = rk->n_stiff >= STIFF_STEPS || rk->n_limited >= 10 * STIFF_STEPS;
    if (limited && rk->detect_stiffness && h < STIFF_STEP_FRACTION * rk->max_step) {
        double count = rk->n_stiff > rk->n_limited ? rk->n_stiff : rk->n_limited;
        int len = snprintf(msg, OVK_MSG, "t = %.9g s: the problem is stiff for %s ", rk->t, tb->name);
        if (len > 0 && len < OVK_MSG)
            rk_msg(msg + len, OVK_STIFF, "(step %.3g s limited by stability on %.0f steps in a row); e.g. a small "
                   "friction regularisation velocity: increase v_reg or use the method for stiff problems, radau",
                   h, count, 0.0);
        return OVK_STIFF;
    }
    return OVK_OK;
}

/* One accepted step of an embedded pair (integrators.AdaptiveRK.step). */
static int erk_step(ovk_rk *rk, const erk_tableau *tb, ovk_rhs_fn fun, void *ctx, char *msg) {
    int n = rk->n;
    double t = rk->t, min_step = 10.0 * fabs(nextafter(t, INFINITY) - t);
    double h = rk->h < rk->max_step ? rk->h : rk->max_step;
    int bounded = t + h >= rk->t_bound; /* the step ends at t_bound (inputs change there: sim.c) */
    if (bounded) h = rk->t_bound - t;
    for (;;) {
        if (!(h >= min_step))
            return rk_msg(msg, OVK_STEP_SMALL, "t = %.9g s: step size %.3g s below the minimum", t, h, 0.0);
        int status = erk_stages(rk, tb, h, fun, ctx);
        if (status) return status;
        double err = rk->method == OVK_METHOD_DOP853 ? dop853_error(rk, h) : dopri5_error(rk, h);
        if (err < 1.0) {
            double factor = MAX_FACTOR;
            if (err != 0.0) {
                double g = SAFETY * pow(err, tb->exponent);
                factor = g < MAX_FACTOR ? g : MAX_FACTOR;
            }
            memcpy(rk->y_old, rk->y, (size_t)n * sizeof(double));
            memcpy(rk->y, rk->ynew, (size_t)n * sizeof(double));
            memcpy(rk->f, rk->K + (size_t)tb->stages * n, (size_t)n * sizeof(double));
            rk->t_old = t;
            rk->h_old = h;
            rk->has_K = 1;
            rk->dense_ready = rk->dense_kept = 0;
            rk->dense_status = OVK_OK;
            rk->t = bounded ? rk->t_bound : t + h;
            rk->h = h * factor;
            rk->nsteps++;
            return stiffness_test(rk, tb, h, msg);
        }
        double g = SAFETY * pow(err, tb->exponent);
        h *= g > MIN_FACTOR ? g : MIN_FACTOR;
        bounded = 0;
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
    rk->dense_kept = 0;
    rk->k++;
    rk->t = t_new;
    rk->nsteps++;
    return OVK_OK;
}

int ovk_rk_step(ovk_rk *rk, ovk_rhs_fn fun, void *ctx, char *msg) {
    switch (rk->method) {
    case OVK_METHOD_RK4: return rk4_step(rk, fun, ctx, msg);
    case OVK_METHOD_DOP853: return erk_step(rk, &DOP853, fun, ctx, msg);
    case OVK_METHOD_RADAU: return ovk_radau_step(rk, fun, ctx, msg);
    default: return erk_step(rk, &DOPRI5, fun, ctx, msg);
    }
}

/* dop853's dense output coefficients F (rows of Q) of the last step (integrators.Dop853._dense_setup):
 * the three extra stages (rows 13-15 of K) by dense_fun, then F[0] = y - y_old, F[1] = h K[0] -
 * F[0], F[2] = 2 F[0] - h (f + K[0]), F[3 + r] = h sum_j D[r][j] K[j]. */
static int dop853_dense_setup(ovk_rk *rk) {
    int n = rk->n;
    double h = rk->h_old, *K = rk->K, *F = rk->Q;
    if (!rk->dense_fun)
        return snprintf(rk->dense_msg, OVK_MSG, "dop853's dense output needs a right-hand side (rk->dense_fun)"),
               OVK_INVALID;
    for (int e = 0; e < 3; e++) {
        int s = 13 + e;
        stage_state(rk, rk->y_old, D8_A_EXTRA[e], s, h, rk->ystage);
        int status = rk->dense_fun(rk->dense_ctx, rk->t_old + D8_C_EXTRA[e] * h, rk->ystage, K + (size_t)s * n);
        if (status) return status;
    }
    for (int i = 0; i < n; i++) {
        double delta = rk->y[i] - rk->y_old[i];
        F[i] = delta;
        F[(size_t)n + i] = h * K[i] - delta;
        F[2 * (size_t)n + i] = 2 * delta - h * (rk->f[i] + K[i]);
        for (int r = 0; r < 4; r++) {
            double acc = 0.0;
            for (int j = 0; j < 16; j++) acc += D8_D[r][j] * K[(size_t)j * n + i];
            F[(size_t)(3 + r) * n + i] = h * acc;
        }
    }
    return OVK_OK;
}

/* The dense output coefficients of the last step made ready: dop853's Q (its three dense stages;
 * a failure kept in rk->dense_status until the next step), dopri5's Q = K^T P. */
static int coefficients(ovk_rk *rk) {
    int n = rk->n;
    if (rk->dense_ready) return OVK_OK;
    if (rk->method == OVK_METHOD_DOP853) {
        if (!rk->dense_status) {
            rk->dense_status = dop853_dense_setup(rk);
            rk->dense_ready = !rk->dense_status;
        }
        return rk->dense_status;
    }
    for (int i = 0; i < n; i++)
        for (int c = 0; c < 4; c++) {
            double acc = 0.0;
            for (int j = 0; j < 7; j++) acc += rk->K[(size_t)j * n + i] * DP_P[j][c];
            rk->Q[(size_t)i * 4 + c] = acc;
        }
    rk->dense_ready = 1;
    return OVK_OK;
}

int ovk_rk_dense_prepare(ovk_rk *rk) {
    if (!rk->has_K || rk->method == OVK_METHOD_RK4 || rk->method == OVK_METHOD_RADAU) return OVK_OK;
    return coefficients(rk);
}

/* The solution at t_old <= t <= t (integrators' dense()), into out (n). OVK_OK, or the status of
 * dop853's dense stages (out is then NaN and rk->dense_status keeps the status until the next step). */
int ovk_rk_dense(ovk_rk *rk, double t, double *out) {
    int n = rk->n;
    if (t == rk->t) {
        memcpy(out, rk->y, (size_t)n * sizeof(double));
        return OVK_OK;
    }
    if (rk->method == OVK_METHOD_RADAU) {
        ovk_radau_dense(rk, t, out);
        return OVK_OK;
    }
    if (rk->method == OVK_METHOD_RK4) { /* f at the step's end: row 0 of K (rk->f once a restart evaluated anew) */
        double h = rk->t - rk->t_old, x = (t - rk->t_old) / h;
        double h00 = 2 * pow(x, 3) - 3 * pow(x, 2) + 1, h10 = pow(x, 3) - 2 * pow(x, 2) + x;
        double h01 = -2 * pow(x, 3) + 3 * pow(x, 2), h11 = pow(x, 3) - pow(x, 2);
        double a = h10 * h, b = h11 * h;
        const double *f_end = rk->K;
        for (int i = 0; i < n; i++) out[i] = h00 * rk->y_old[i] + a * rk->f_old[i] + h01 * rk->y[i] + b * f_end[i];
        return OVK_OK;
    }
    if (!rk->has_K && !rk->dense_kept) { /* no step yet: t is t0 */
        memcpy(out, rk->y, (size_t)n * sizeof(double));
        return OVK_OK;
    }
    double x = (t - rk->t_old) / rk->h_old;
    int status = coefficients(rk);
    if (status) {
        for (int i = 0; i < n; i++) out[i] = NAN;
        return status;
    }
    if (rk->method == OVK_METHOD_DOP853) {
        /* y_old + the nested polynomial of Dop853._dense_eval: row r of F weighted by the product of
         * the factors x, 1 - x, x, ... of rows 6 down to r */
        double w[7], p = 1.0;
        for (int r = 0; r < 7; r++) {
            p *= (6 - r) % 2 == 0 ? x : 1 - x;
            w[r] = p;
        }
        for (int i = 0; i < n; i++) {
            double acc = 0.0;
            for (int r = 0; r < 7; r++) acc += w[r] * rk->Q[(size_t)r * n + i];
            out[i] = acc + rk->y_old[i];
        }
        return OVK_OK;
    }
    double p[4];
    p[0] = x;
    for (int c = 1; c < 4; c++) p[c] = p[c - 1] * x;
    for (int i = 0; i < n; i++) {
        const double *q = rk->Q + (size_t)i * 4;
        out[i] = rk->y_old[i] + rk->h_old * (q[0] * p[0] + q[1] * p[1] + q[2] * p[2] + q[3] * p[3]);
    }
    return OVK_OK;
}
