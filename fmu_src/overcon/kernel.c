/* overcon compiled kernel: one evaluation of Eq. 18 (direct dynamics with the chosen elimination
 * and Coulomb joint friction) and the coordinate rates, in C.
 *
 * The optional fast path of overcon.dynamics.evaluate (see overcon/kernel.py, which packs the
 * model, loads this library and documents when it is used). It implements the same formulas, in
 * the same order, as the numpy path:
 *   frames            overcon.evaluation.frames (planar, spatial z-x-z Euler angles)
 *   joints            overcon.joints.revolute, .translational (planar), .spherical (spatial):
 *                     phi, jac_h, gamma, friction_setup, friction, friction_jacobian
 *   loads             overcon.evaluation.applied_forces (gravity, gyroscopic, force, torque, spring)
 *   friction laws     overcon.friction_laws.Law (regularised, stribeck)
 *   solve             overcon.dynamics.evaluate and _newton_reduced (Cholesky of S, Newton on the
 *                     friction multipliers with the analytic Jacobian)
 *   coordinate rates  overcon.evaluation.coordinate_rates (Euler: kinematics.euler_H_rows)
 * Units and signs are those of the Python modules named above (SI; paper conventions).
 *
 * Anything the numpy path handles by a message or a fallback is returned as a status, and the
 * caller repeats the evaluation on the numpy path, which raises or falls back as it always does:
 * OVK_SINGULAR (S not positive definite), OVK_FRICTION (Newton gave up: the Anderson fixed point
 * and the finite-difference Newton live in Python only), OVK_EULER (|sin beta| < SIN_BETA_MIN),
 * OVK_SPRING (spring points coincide), OVK_NONFINITE (a non-finite number on the way).
 * So the kernel never changes what fails or how; it only makes the common case fast.
 *
 * Plain C99 and libm; no BLAS (the matrices are at most a few dozen rows, and a fixed summation
 * order keeps the results independent of the CPU's BLAS dispatch).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define OVK_ABI 3

enum { OVK_OK = 0, OVK_SINGULAR = 1, OVK_FRICTION = 2, OVK_EULER = 3, OVK_NONFINITE = 4, OVK_SPRING = 5,
       OVK_NOMEM = 6 };
enum { J_REVOLUTE = 1, J_TRANSLATIONAL = 2, J_SPHERICAL = 3 };
enum { LAW_NONE = 0, LAW_REGULARISED = 1, LAW_STRIBECK = 2 };
enum { LD_FORCE = 1, LD_TORQUE = 2, LD_SPRING = 3 };

#define NJC 12  /* doubles of constants per joint */
#define NLP 5   /* doubles of friction law per joint: mu, v_reg, size, mu_static, v_stribeck */
#define NLD 11  /* doubles per load: value[3], s_i[3], s_j[3], stiffness, free_length */
#define NEWTON_MAX_ITER 12
#define NEWTON_REFRESH 1e-3
#define SIN_BETA_MIN 1e-3
#define OVK_MAX_FRICTION 32 /* friction joints (and 3 x that multipliers): overcon.kernel.pack checks */

/* The model, packed by overcon.kernel.pack (field order and types mirrored there). */
typedef struct {
    int dim, nb, nq_b, nh_b, m, nR, nj, nl;
    int nx, ncols, nfj, nfg;
    int max_iter;
    double baumgarte, tol;
    const int *retained;   /* nR */
    const double *Minv;    /* nb * nh_b */
    const double *mass;    /* nb */
    const double *inertia; /* nb * 3 (spatial) */
    const double *gravity; /* dim */
    const int *jtype, *jbi, *jbj, *jneq, *jrows; /* nj; jrows nj * 3 (equation indices) */
    const double *jconst;  /* nj * NJC */
    const int *jlaw;       /* nj */
    const double *jlawp;   /* nj * NLP */
    const int *ltype, *lbi, *lbj; /* nl */
    const double *lp;      /* nl * NLD */
    const int *xrows;      /* nx: positions in lam_R of the friction rows */
    const int *cols;       /* ncols: velocity indices the friction forces act on */
    const int *fj;         /* nfj: friction joints, plan order (group by group) */
    const int *fgroup;     /* nfg + 1: start of each friction group in fj */
    const int *fx;         /* nfj * 3: x index per equation (nx = eliminated) */
    const int *fci, *fcj;  /* nfj * 6: index into cols per coordinate of body i, j (ncols = base) */
    const int *rbody;      /* nR * 2: the bodies (-1 base) of each retained row: Phi_h is zero elsewhere */
} ovk_model;

int ovk_abi(void) { return OVK_ABI; }
int ovk_max_friction(void) { return OVK_MAX_FRICTION; }

/* ------------------------------------------------------------------------------ small helpers */

static void mat3mul(const double *A, const double *B, double *C) {
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            C[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
}
static void mat3vec(const double *A, const double *x, double *y) {
    for (int i = 0; i < 3; i++) y[i] = A[3 * i] * x[0] + A[3 * i + 1] * x[1] + A[3 * i + 2] * x[2];
}
static void mat3tvec(const double *A, const double *x, double *y) { /* A^T x */
    for (int i = 0; i < 3; i++) y[i] = A[i] * x[0] + A[3 + i] * x[1] + A[6 + i] * x[2];
}
static void cross3(const double *a, const double *b, double *c) {
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}
static void skew3(const double *a, double *S) {
    S[0] = 0.0;   S[1] = -a[2]; S[2] = a[1];
    S[3] = a[2];  S[4] = 0.0;   S[5] = -a[0];
    S[6] = -a[1]; S[7] = a[0];  S[8] = 0.0;
}
static double dot3(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static void mat2vec(const double *A, const double *x, double *y) {
    y[0] = A[0] * x[0] + A[1] * x[1];
    y[1] = A[2] * x[0] + A[3] * x[1];
}
static double sgn(double x) { return (double)((x > 0.0) - (x < 0.0)); }

/* ------------------------------------------------------------------------------ friction laws */

static double law_magnitude(const double *lp, int law, double speed) {
    if (law == LAW_STRIBECK) {
        double x = speed / lp[4];
        return lp[0] + (lp[3] - lp[0]) * exp(-(x * x));
    }
    return lp[0];
}
static double law_coefficient(const double *lp, int law, double v) {
    double r = v / lp[1];
    r = r < -1.0 ? -1.0 : (r > 1.0 ? 1.0 : r);
    return r * law_magnitude(lp, law, fabs(v));
}
static double law_mu_over_speed(const double *lp, int law, double s) {
    return law_magnitude(lp, law, s) / (s > lp[1] ? s : lp[1]);
}
static double law_mu_over_speed_slope(const double *lp, int law, double s) {
    double slope = 0.0;
    if (law == LAW_STRIBECK) {
        double x = s / lp[4];
        slope = -2.0 * x / lp[4] * (lp[3] - lp[0]) * exp(-x * x);
    }
    if (s < lp[1]) return slope / lp[1];
    return (slope - law_magnitude(lp, law, s) / s) / s;
}

/* ------------------------------------------------------------------------------ frames */

typedef struct {
    double *r, *R, *v, *w; /* (nb + 1) slots: r, v dim; R dim*dim; w 1 (planar) or 3 */
    double *sb, *cb, *sg, *cg; /* spatial: sin/cos of beta and gamma per body (rates) */
} frames_t;

static int slot(const ovk_model *M, int b) { return b < 0 ? M->nb : b; }

static void build_frames(const ovk_model *M, const double *q, const double *h, frames_t *f) {
    int nb = M->nb, d = M->dim, kq = M->nq_b, kh = M->nh_b, wd = d == 2 ? 1 : 3;
    memset(f->r, 0, sizeof(double) * (nb + 1) * d);
    memset(f->v, 0, sizeof(double) * (nb + 1) * d);
    memset(f->w, 0, sizeof(double) * (nb + 1) * wd);
    for (int b = 0; b < nb; b++) {
        for (int i = 0; i < d; i++) {
            f->r[b * d + i] = q[b * kq + i];
            f->v[b * d + i] = h[b * kh + i];
        }
        for (int i = 0; i < wd; i++) f->w[b * wd + i] = h[b * kh + d + i];
    }
    if (d == 2) {
        for (int b = 0; b <= nb; b++) {
            double phi = b < nb ? q[b * kq + 2] : 0.0, c = cos(phi), s = sin(phi);
            double *R = f->R + 4 * b;
            R[0] = c; R[1] = -s; R[2] = s; R[3] = c;
        }
        return;
    }
    for (int b = 0; b <= nb; b++) {
        double *R = f->R + 9 * b;
        double a = 0.0, be = 0.0, g = 0.0;
        if (b < nb) { a = q[b * kq + 3]; be = q[b * kq + 4]; g = q[b * kq + 5]; }
        double ca = cos(a), sa = sin(a), cb = cos(be), sb = sin(be), cg = cos(g), sg = sin(g);
        double za[9] = {ca, -sa, 0.0, sa, ca, 0.0, 0.0, 0.0, 1.0};
        double xb[9] = {1.0, 0.0, 0.0, 0.0, cb, -sb, 0.0, sb, cb};
        double zg[9] = {cg, -sg, 0.0, sg, cg, 0.0, 0.0, 0.0, 1.0};
        double t[9];
        mat3mul(za, xb, t);
        mat3mul(t, zg, R);
        if (b < nb) { f->sb[b] = sb; f->cb[b] = cb; f->sg[b] = sg; f->cg[b] = cg; }
    }
}

/* ------------------------------------------------------------------------------ joint rows */

/* Phi, Jacobian blocks and gamma of joint j; Ji, Jj are (neq, nh_b) row-major. */
static void joint_rows(const ovk_model *M, const frames_t *f, int j, double *phi, double *Ji, double *Jj,
                       double *gam) {
    const double *c = M->jconst + NJC * j;
    int bi = slot(M, M->jbi[j]), bj = slot(M, M->jbj[j]);
    if (M->jtype[j] == J_REVOLUTE) {
        const double *Ri = f->R + 4 * bi, *Rj = f->R + 4 * bj;
        double ai[2], aj[2];
        mat2vec(Ri, c, ai);
        mat2vec(Rj, c + 2, aj);
        const double *ri = f->r + 2 * bi, *rj = f->r + 2 * bj;
        for (int k = 0; k < 2; k++) phi[k] = ri[k] + ai[k] - rj[k] - aj[k];
        double ti[2] = {-ai[1], ai[0]}, tj[2] = {-aj[1], aj[0]};
        memset(Ji, 0, 6 * sizeof(double));
        memset(Jj, 0, 6 * sizeof(double));
        Ji[0] = Ji[4] = 1.0;
        Jj[0] = Jj[4] = -1.0;
        Ji[2] = ti[0]; Ji[5] = ti[1];
        Jj[2] = -tj[0]; Jj[5] = -tj[1];
        double wi = f->w[bi], wj = f->w[bj], wi2 = wi * wi, wj2 = wj * wj;
        for (int k = 0; k < 2; k++) gam[k] = ai[k] * wi2 - aj[k] * wj2;
    } else if (M->jtype[j] == J_TRANSLATIONAL) {
        const double *sA = c, *sB = c + 2, *v = c + 4;
        const double *Ri = f->R + 4 * bi, *Rj = f->R + 4 * bj;
        const double *ri = f->r + 2 * bi, *rj = f->r + 2 * bj;
        double ai[2], bjv[2], dd[2], u[2];
        mat2vec(Ri, sA, ai);
        mat2vec(Rj, sB, bjv);
        for (int k = 0; k < 2; k++) dd[k] = ri[k] + ai[k] - rj[k] - bjv[k];
        mat2vec(Rj, v, u);
        phi[0] = dd[0] * u[0] + dd[1] * u[1];
        phi[1] = 0.0; /* filled by the caller from the angles in q (minus psi) */
        double oai[2] = {-ai[1], ai[0]}, obj[2] = {-bjv[1], bjv[0]}, ou[2] = {-u[1], u[0]};
        memset(Ji, 0, 6 * sizeof(double));
        memset(Jj, 0, 6 * sizeof(double));
        Ji[0] = u[0]; Ji[1] = u[1];
        Ji[2] = oai[0] * u[0] + oai[1] * u[1];
        Ji[5] = 1.0;
        Jj[0] = -u[0]; Jj[1] = -u[1];
        Jj[2] = (-obj[0] * u[0] + -obj[1] * u[1]) + (dd[0] * ou[0] + dd[1] * ou[1]);
        Jj[5] = -1.0;
        double wi = f->w[bi], wj = f->w[bj];
        const double *vi = f->v + 2 * bi, *vj = f->v + 2 * bj;
        double ddot[2], udot[2];
        for (int k = 0; k < 2; k++) {
            ddot[k] = vi[k] + oai[k] * wi - vj[k] - obj[k] * wj;
            udot[k] = ou[k] * wj;
        }
        double wi2 = wi * wi, wj2 = wj * wj;
        double t1[2] = {-ai[0] * wi2 + bjv[0] * wj2, -ai[1] * wi2 + bjv[1] * wj2};
        double quad = (t1[0] * u[0] + t1[1] * u[1]) + ((2.0 * ddot[0]) * udot[0] + (2.0 * ddot[1]) * udot[1])
                      - (dd[0] * u[0] + dd[1] * u[1]) * wj2;
        gam[0] = -quad;
        gam[1] = 0.0;
    } else { /* J_SPHERICAL */
        const double *si = c, *sj = c + 3;
        const double *Ri = f->R + 9 * bi, *Rj = f->R + 9 * bj;
        const double *ri = f->r + 3 * bi, *rj = f->r + 3 * bj;
        double ai[3], aj[3];
        mat3vec(Ri, si, ai);
        mat3vec(Rj, sj, aj);
        for (int k = 0; k < 3; k++) phi[k] = ri[k] + ai[k] - rj[k] - aj[k];
        double Si[9], Sj[9], nRi[9], Ai[9], Aj[9];
        skew3(si, Si);
        skew3(sj, Sj);
        for (int k = 0; k < 9; k++) nRi[k] = -Ri[k];
        mat3mul(nRi, Si, Ai);
        mat3mul(Rj, Sj, Aj);
        for (int r = 0; r < 3; r++) {
            for (int k = 0; k < 3; k++) {
                Ji[6 * r + k] = r == k ? 1.0 : 0.0;
                Jj[6 * r + k] = r == k ? -1.0 : 0.0;
                Ji[6 * r + 3 + k] = Ai[3 * r + k];
                Jj[6 * r + 3 + k] = Aj[3 * r + k];
            }
        }
        const double *wi = f->w + 3 * bi, *wj = f->w + 3 * bj;
        double t[3], ti[3], tj[3], gi[3], gj[3];
        cross3(wi, si, t);
        cross3(wi, t, ti);
        cross3(wj, sj, t);
        cross3(wj, t, tj);
        mat3vec(nRi, ti, gi);
        mat3vec(Rj, tj, gj);
        for (int k = 0; k < 3; k++) gam[k] = gi[k] + gj[k];
    }
}

/* ------------------------------------------------------------------------------ friction */

/* Per-evaluation constants of one friction joint (friction_setup of its type). */
typedef struct {
    double P[3 * 3];     /* planar: A_i (J_X)_i^T (3 x neq), row-major 3 x 2 used */
    double A[9], JiT[6]; /* planar */
    double e[2], arm_i[2], arm_j[2], coef; /* translational: guide, arms, mu(v); revolute: size*mu */
    double Ri[9], RiT[9], omega[3], Rji[9]; /* spherical */
} fctx_t;

static void friction_setup(const ovk_model *M, const frames_t *f, int j, const double *Ji, fctx_t *cx) {
    const double *c = M->jconst + NJC * j, *lp = M->jlawp + NLP * j;
    int law = M->jlaw[j], bi = slot(M, M->jbi[j]), bj = slot(M, M->jbj[j]);
    if (M->jtype[j] == J_SPHERICAL) {
        const double *Ri = f->R + 9 * bi, *Rj = f->R + 9 * bj;
        double t[3], u[3], RjT[9];
        memcpy(cx->Ri, Ri, sizeof cx->Ri);
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) { cx->RiT[3 * a + b] = Ri[3 * b + a]; RjT[3 * a + b] = Rj[3 * b + a]; }
        mat3vec(Rj, f->w + 3 * bj, t);
        mat3vec(cx->RiT, t, u);
        for (int k = 0; k < 3; k++) cx->omega[k] = u[k] - f->w[3 * bi + k];
        mat3mul(RjT, Ri, cx->Rji);
        return;
    }
    /* planar: JiT = (J_X)_i^T (3 x 2), A_i (3 x 3) */
    const double *Ri = f->R + 4 * bi;
    for (int a = 0; a < 3; a++)
        for (int e = 0; e < 2; e++) cx->JiT[2 * a + e] = Ji[3 * e + a];
    double ai[2];
    memset(cx->A, 0, sizeof cx->A);
    if (M->jtype[j] == J_REVOLUTE) {
        mat2vec(Ri, c, ai);
        cx->A[0] = Ri[0]; cx->A[1] = Ri[2]; cx->A[3] = Ri[1]; cx->A[4] = Ri[3];
        cx->coef = law == LAW_NONE ? 0.0 : lp[2] * law_coefficient(lp, law, f->w[bj] - f->w[bi]);
    } else {
        const double *B = c + 7; /* 2 x 2 row-major, column 0 = guide in body i axes */
        mat2vec(Ri, c, ai);
        /* A[:2,:2] = B^T R_i^T */
        for (int a = 0; a < 2; a++)
            for (int b = 0; b < 2; b++) cx->A[3 * a + b] = B[a] * Ri[2 * b] + B[2 + a] * Ri[2 * b + 1];
        const double *ri = f->r + 2 * bi, *rj = f->r + 2 * bj;
        double point[2] = {ri[0] + ai[0], ri[1] + ai[1]};
        double bcol[2] = {B[0], B[2]};
        mat2vec(Ri, bcol, cx->e);
        double pj[2] = {point[0] - rj[0], point[1] - rj[1]}, pi[2] = {point[0] - ri[0], point[1] - ri[1]};
        double wj = f->w[bj], wi = f->w[bi];
        double velj[2] = {f->v[2 * bj] + -pj[1] * wj, f->v[2 * bj + 1] + pj[0] * wj};
        double veli[2] = {f->v[2 * bi] + -pi[1] * wi, f->v[2 * bi + 1] + pi[0] * wi};
        double speed = (velj[0] - veli[0]) * cx->e[0] + (velj[1] - veli[1]) * cx->e[1];
        cx->arm_i[0] = pi[0]; cx->arm_i[1] = pi[1];
        cx->arm_j[0] = pj[0]; cx->arm_j[1] = pj[1];
        cx->coef = law == LAW_NONE ? 0.0 : law_coefficient(lp, law, speed);
    }
    cx->A[6] = ai[1]; cx->A[7] = -ai[0]; cx->A[8] = 1.0; /* -OMEGA a_i */
}

/* p' = A_i (J_X)_i^T lam (planar) */
static void planar_paux(const fctx_t *cx, const double *lam, double *p) {
    double fi[3];
    for (int a = 0; a < 3; a++) fi[a] = cx->JiT[2 * a] * lam[0] + cx->JiT[2 * a + 1] * lam[1];
    for (int a = 0; a < 3; a++) p[a] = cx->A[3 * a] * fi[0] + cx->A[3 * a + 1] * fi[1] + cx->A[3 * a + 2] * fi[2];
}

/* Friction forces of joint j: Qi, Qj (nh_b each) at its multipliers lam (neq). */
static void friction_forces(const ovk_model *M, int j, const fctx_t *cx, const double *lam, double *Qi,
                            double *Qj) {
    const double *c = M->jconst + NJC * j, *lp = M->jlawp + NLP * j;
    int law = M->jlaw[j];
    if (M->jtype[j] == J_REVOLUTE) {
        double p[3];
        planar_paux(cx, lam, p);
        double torque = cx->coef * hypot(p[0], p[1]);
        Qi[0] = Qi[1] = Qj[0] = Qj[1] = 0.0;
        Qi[2] = torque;
        Qj[2] = -torque;
    } else if (M->jtype[j] == J_TRANSLATIONAL) {
        double p[3];
        planar_paux(cx, lam, p);
        double l = lp[2], N = p[1], T = p[2];
        double F = cx->coef * (fabs(N - T / l) + fabs(T / l));
        double Fx = F * cx->e[0], Fy = F * cx->e[1];
        Qi[0] = Fx; Qi[1] = Fy; Qi[2] = cx->arm_i[0] * Fy - cx->arm_i[1] * Fx;
        Qj[0] = -Fx; Qj[1] = -Fy; Qj[2] = -(cx->arm_j[0] * Fy - cx->arm_j[1] * Fx);
    } else {
        const double *si = c, *sj = c + 3;
        double F[3];
        mat3vec(cx->RiT, lam, F);
        double norm = sqrt(dot3(F, F));
        if (norm == 0.0) {
            for (int k = 0; k < 6; k++) Qi[k] = Qj[k] = 0.0;
            return;
        }
        double sC[3], v[3], Ffr[3], RiF[3], t[3], u[3], a1[3], a2[3];
        double nr = -lp[2];
        for (int k = 0; k < 3; k++) sC[k] = nr * F[k] / norm;
        cross3(cx->omega, sC, v);
        double speed = sqrt(dot3(v, v));
        double mn = law_mu_over_speed(lp, law, speed) * norm;
        for (int k = 0; k < 3; k++) Ffr[k] = mn * v[k];
        mat3vec(cx->Ri, Ffr, RiF);
        double arm[3] = {si[0] + sC[0], si[1] + sC[1], si[2] + sC[2]};
        cross3(arm, Ffr, t);
        for (int k = 0; k < 3; k++) { Qi[k] = RiF[k]; Qi[3 + k] = t[k]; }
        mat3vec(cx->Rji, Ffr, u);
        cross3(sj, u, a1);
        cross3(sC, Ffr, t);
        mat3vec(cx->Rji, t, a2);
        for (int k = 0; k < 3; k++) { Qj[k] = -RiF[k]; Qj[3 + k] = -(a1[k] + a2[k]); }
    }
}

/* d(Qi, Qj)/d lam of joint j: dQi, dQj (nh_b x neq, row-major). */
static void friction_jac(const ovk_model *M, int j, const fctx_t *cx, const double *lam, double *dQi,
                         double *dQj) {
    const double *c = M->jconst + NJC * j, *lp = M->jlawp + NLP * j;
    int law = M->jlaw[j];
    if (M->jtype[j] != J_SPHERICAL) {
        double P[6]; /* A JiT, 3 x 2 */
        for (int a = 0; a < 3; a++)
            for (int e = 0; e < 2; e++)
                P[2 * a + e] = cx->A[3 * a] * cx->JiT[e] + cx->A[3 * a + 1] * cx->JiT[2 + e]
                               + cx->A[3 * a + 2] * cx->JiT[4 + e];
        double p[3];
        for (int a = 0; a < 3; a++) p[a] = P[2 * a] * lam[0] + P[2 * a + 1] * lam[1];
        memset(dQi, 0, 6 * sizeof(double));
        memset(dQj, 0, 6 * sizeof(double));
        if (M->jtype[j] == J_REVOLUTE) {
            double norm = hypot(p[0], p[1]);
            double scale = norm > 0.0 ? cx->coef / norm : 0.0;
            for (int e = 0; e < 2; e++) {
                double dT = scale * (p[0] * P[e] + p[1] * P[2 + e]);
                dQi[4 + e] = dT;
                dQj[4 + e] = -dT;
            }
        } else {
            double l = lp[2], N = p[1], T = p[2] / l;
            double sNT = sgn(N - T), sT = sgn(T);
            double ci[3] = {cx->e[0], cx->e[1], cx->arm_i[0] * cx->e[1] - cx->arm_i[1] * cx->e[0]};
            double cj[3] = {cx->e[0], cx->e[1], cx->arm_j[0] * cx->e[1] - cx->arm_j[1] * cx->e[0]};
            for (int e = 0; e < 2; e++) {
                double PN = P[2 + e], PT = P[4 + e] / l;
                double dF = cx->coef * (sNT * (PN - PT) + sT * PT);
                for (int a = 0; a < 3; a++) {
                    dQi[2 * a + e] = ci[a] * dF;
                    dQj[2 * a + e] = -cj[a] * dF;
                }
            }
        }
        return;
    }
    const double *si = c, *sj = c + 3;
    double F[3];
    mat3vec(cx->RiT, lam, F);
    double norm = sqrt(dot3(F, F));
    if (norm == 0.0) {
        memset(dQi, 0, 18 * sizeof(double));
        memset(dQj, 0, 18 * sizeof(double));
        return;
    }
    double u[3], sC[3], proj[9], dsC[9], W[9], v[3], dv[9];
    double nr = -lp[2];
    for (int k = 0; k < 3; k++) { u[k] = F[k] / norm; sC[k] = nr * u[k]; }
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) {
            proj[3 * a + b] = ((a == b ? 1.0 : 0.0) - u[a] * u[b]) / norm;
            dsC[3 * a + b] = nr * proj[3 * a + b];
        }
    skew3(cx->omega, W);
    cross3(cx->omega, sC, v);
    mat3mul(W, dsC, dv);
    double speed = sqrt(dot3(v, v));
    double mm = law_mu_over_speed(lp, law, speed);
    double slope = speed > 0.0 ? law_mu_over_speed_slope(lp, law, speed) : 0.0;
    double vs = speed > 0.0 ? speed : 1.0, dspeed[3];
    for (int b = 0; b < 3; b++) dspeed[b] = (v[0] / vs) * dv[b] + (v[1] / vs) * dv[3 + b] + (v[2] / vs) * dv[6 + b];
    double Ffr[3], dFfr[9], mn = mm * norm, sn = slope * norm;
    for (int k = 0; k < 3; k++) Ffr[k] = mn * v[k];
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++)
            dFfr[3 * a + b] = sn * v[a] * dspeed[b] + mm * v[a] * u[b] + mn * dv[3 * a + b];
    double SF[9], darm[9], top[9], Sa[9], arm[3], bot_i[9], t1[9], t2[9], SC[9], Sj[9], t3[9], t4[9];
    skew3(Ffr, SF);
    mat3mul(SF, dsC, darm);
    for (int k = 0; k < 9; k++) darm[k] = -darm[k];
    mat3mul(cx->Ri, dFfr, top);
    for (int k = 0; k < 3; k++) arm[k] = si[k] + sC[k];
    skew3(arm, Sa);
    mat3mul(Sa, dFfr, t1);
    for (int k = 0; k < 9; k++) bot_i[k] = darm[k] + t1[k];
    /* dQj = -[top; skew(s_j) Rji dFfr + Rji (darm + skew(s_C) dFfr)] */
    skew3(sj, Sj);
    mat3mul(cx->Rji, dFfr, t1);
    mat3mul(Sj, t1, t2);
    skew3(sC, SC);
    mat3mul(SC, dFfr, t3);
    for (int k = 0; k < 9; k++) t3[k] = darm[k] + t3[k];
    mat3mul(cx->Rji, t3, t4);
    double Gi[18], Gj[18];
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) {
            Gi[3 * a + b] = top[3 * a + b];
            Gi[9 + 3 * a + b] = bot_i[3 * a + b];
            Gj[3 * a + b] = -top[3 * a + b];
            Gj[9 + 3 * a + b] = -(t2[3 * a + b] + t4[3 * a + b]);
        }
    /* times d F'/d lam = R_i^T */
    for (int a = 0; a < 6; a++)
        for (int b = 0; b < 3; b++) {
            dQi[3 * a + b] = Gi[3 * a] * cx->RiT[b] + Gi[3 * a + 1] * cx->RiT[3 + b] + Gi[3 * a + 2] * cx->RiT[6 + b];
            dQj[3 * a + b] = Gj[3 * a] * cx->RiT[b] + Gj[3 * a + 1] * cx->RiT[3 + b] + Gj[3 * a + 2] * cx->RiT[6 + b];
        }
}

/* ------------------------------------------------------------------------------ linear algebra */

/* Cholesky S = U^T U in place (upper triangle, row-major n x n); 0 on success. */
static int cholesky(double *S, int n) {
    for (int j = 0; j < n; j++) {
        double s = S[j * n + j];
        for (int k = 0; k < j; k++) s -= S[k * n + j] * S[k * n + j];
        if (!(s > 0.0)) return 1;
        double ujj = sqrt(s);
        S[j * n + j] = ujj;
        for (int i = j + 1; i < n; i++) {
            double t = S[j * n + i];
            for (int k = 0; k < j; k++) t -= S[k * n + j] * S[k * n + i];
            S[j * n + i] = t / ujj;
        }
    }
    return 0;
}
static void cho_solve(const double *U, int n, double *b) {
    for (int i = 0; i < n; i++) { /* U^T y = b */
        double t = b[i];
        for (int k = 0; k < i; k++) t -= U[k * n + i] * b[k];
        b[i] = t / U[i * n + i];
    }
    for (int i = n - 1; i >= 0; i--) { /* U x = y */
        double t = b[i];
        for (int k = i + 1; k < n; k++) t -= U[i * n + k] * b[k];
        b[i] = t / U[i * n + i];
    }
}
/* S X = B for nc columns at once (B row-major nR x nc, overwritten): the columns are the inner loop. */
static void cho_solve_many(const double *U, int n, double *B, int nc) {
    for (int i = 0; i < n; i++) {
        double *Bi = B + (size_t)i * nc;
        for (int k = 0; k < i; k++) {
            double u = U[k * n + i];
            const double *Bk = B + (size_t)k * nc;
            for (int c = 0; c < nc; c++) Bi[c] -= u * Bk[c];
        }
        double d = U[i * n + i];
        for (int c = 0; c < nc; c++) Bi[c] /= d;
    }
    for (int i = n - 1; i >= 0; i--) {
        double *Bi = B + (size_t)i * nc;
        for (int k = i + 1; k < n; k++) {
            double u = U[i * n + k];
            const double *Bk = B + (size_t)k * nc;
            for (int c = 0; c < nc; c++) Bi[c] -= u * Bk[c];
        }
        double d = U[i * n + i];
        for (int c = 0; c < nc; c++) Bi[c] /= d;
    }
}

/* LU with partial pivoting (dgetrf semantics: fails only on an exact zero pivot). */
static int lu_factor(double *A, int n, int *piv) {
    for (int k = 0; k < n; k++) {
        int p = k;
        double best = fabs(A[k * n + k]);
        for (int i = k + 1; i < n; i++)
            if (fabs(A[i * n + k]) > best) { best = fabs(A[i * n + k]); p = i; }
        piv[k] = p;
        if (A[p * n + k] == 0.0) return 1;
        if (p != k)
            for (int c = 0; c < n; c++) { double t = A[k * n + c]; A[k * n + c] = A[p * n + c]; A[p * n + c] = t; }
        for (int i = k + 1; i < n; i++) {
            double l = A[i * n + k] / A[k * n + k];
            A[i * n + k] = l;
            for (int c = k + 1; c < n; c++) A[i * n + c] -= l * A[k * n + c];
        }
    }
    return 0;
}
static void lu_solve(const double *A, int n, const int *piv, double *b) {
    for (int k = 0; k < n; k++)
        if (piv[k] != k) { double t = b[k]; b[k] = b[piv[k]]; b[piv[k]] = t; }
    for (int i = 0; i < n; i++)
        for (int k = 0; k < i; k++) b[i] -= A[i * n + k] * b[k];
    for (int i = n - 1; i >= 0; i--) {
        for (int k = i + 1; k < n; k++) b[i] -= A[i * n + k] * b[k];
        b[i] /= A[i * n + i];
    }
}

/* ------------------------------------------------------------------------------ the friction solve */

typedef struct {
    const ovk_model *M;
    fctx_t *ctx;     /* nfj */
    double *flam;    /* nfj * 3: multipliers of each friction joint at the last force evaluation */
    double *Qi, *Qj; /* nfj * 6 */
} fsolve_t;

static void forces_reduced(fsolve_t *s, const double *x, double *qf) {
    const ovk_model *M = s->M;
    int nx = M->nx;
    memset(qf, 0, sizeof(double) * M->ncols);
    for (int g = 0; g < M->nfg; g++) {
        for (int n = M->fgroup[g]; n < M->fgroup[g + 1]; n++) {
            int j = M->fj[n];
            double *lam = s->flam + 3 * n;
            for (int e = 0; e < M->jneq[j]; e++) {
                int xi = M->fx[3 * n + e];
                lam[e] = xi < nx ? x[xi] : 0.0;
            }
            friction_forces(M, j, s->ctx + n, lam, s->Qi + 6 * n, s->Qj + 6 * n);
        }
        for (int n = M->fgroup[g]; n < M->fgroup[g + 1]; n++)
            for (int k = 0; k < M->nh_b; k++) {
                int ci = M->fci[6 * n + k];
                if (ci < M->ncols) qf[ci] += s->Qi[6 * n + k];
            }
        for (int n = M->fgroup[g]; n < M->fgroup[g + 1]; n++)
            for (int k = 0; k < M->nh_b; k++) {
                int cj = M->fcj[6 * n + k];
                if (cj < M->ncols) qf[cj] += s->Qj[6 * n + k];
            }
    }
}

static void jacobian_reduced(fsolve_t *s, double *Dq /* ncols x nx */) {
    const ovk_model *M = s->M;
    int nx = M->nx;
    double dQi[18], dQj[18];
    memset(Dq, 0, sizeof(double) * M->ncols * nx);
    for (int n = 0; n < M->nfj; n++) {
        int j = M->fj[n], ne = M->jneq[j];
        friction_jac(M, j, s->ctx + n, s->flam + 3 * n, dQi, dQj);
        for (int k = 0; k < M->nh_b; k++)
            for (int e = 0; e < ne; e++) {
                int xi = M->fx[3 * n + e];
                if (xi >= nx) continue;
                int ci = M->fci[6 * n + k], cj = M->fcj[6 * n + k];
                if (ci < M->ncols) Dq[ci * nx + xi] += dQi[k * ne + e];
                if (cj < M->ncols) Dq[cj * nx + xi] += dQj[k * ne + e];
            }
    }
}

static double maxabs(const double *a, int n) { /* max |a_i|, NaN if any is NaN (numpy's max) */
    double m = 0.0;
    for (int i = 0; i < n; i++) {
        double v = fabs(a[i]);
        if (v != v) return v;
        if (v > m) m = v;
    }
    return m;
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
static int newton_matrix(fsolve_t *s, const double *Wx, double *Dq, double *Mx, int *piv) {
    int nx = s->M->nx, nc = s->M->ncols;
    jacobian_reduced(s, Dq);
    for (int a = 0; a < nx; a++)
        for (int b = 0; b < nx; b++) {
            double t = 0.0;
            for (int c = 0; c < nc; c++) t += Wx[a * nc + c] * Dq[c * nx + b];
            Mx[a * nx + b] = (a == b ? 1.0 : 0.0) - t;
        }
    return lu_factor(Mx, nx, piv);
}

/* Newton on x = lam0x + Wx qf(x) (dynamics._newton_reduced). Returns 1 when converged. */
static int newton_reduced(fsolve_t *s, const double *lam0x, const double *Wx /* nx x ncols */, double *x,
                          double *qf, int *iters, double *work) {
    const ovk_model *M = s->M;
    int nx = M->nx, nc = M->ncols;
    int n_max = M->max_iter < NEWTON_MAX_ITER ? M->max_iter : NEWTON_MAX_ITER;
    double *r = work, *Dq = r + nx, *Mx = Dq + nc * nx;
    int piv[OVK_MAX_FRICTION * 3], have_lu = 0, growth = 0;
    double prev = INFINITY;
    for (int it = 1; it <= n_max; it++) {
        *iters = it;
        forces_reduced(s, x, qf);
        residual(nx, nc, lam0x, Wx, qf, x, r);
        double res = maxabs(r, nx);
        if (!isfinite(res)) return 0;
        if (res <= M->tol * (1.0 + maxabs(x, nx))) return 1;
        growth = res >= prev ? growth + 1 : 0;
        if (growth >= 2 || it == n_max) return 0;
        if (!have_lu || res > NEWTON_REFRESH * prev) {
            if (newton_matrix(s, Wx, Dq, Mx, piv)) return 0;
            have_lu = 1;
        }
        prev = res;
        lu_solve(Mx, nx, piv, r);
        for (int a = 0; a < nx; a++) x[a] += r[a];
    }
    return 0;
}

#define DAMPED_MAX_ITER 30
#define ARMIJO 1e-4

/* The damped Newton solve (dynamics._damped_newton_reduced): a fresh Jacobian every step and a
 * backtracking line search on the residual's max norm. Returns 1 when converged; *iters counts
 * its force evaluations. */
static int damped_newton_reduced(fsolve_t *s, const double *lam0x, const double *Wx, double *x, double *qf,
                                 int *iters, double *work) {
    const ovk_model *M = s->M;
    int nx = M->nx, nc = M->ncols;
    int n_max = M->max_iter < DAMPED_MAX_ITER ? M->max_iter : DAMPED_MAX_ITER;
    double *r = work, *Dq = r + nx, *Mx = Dq + nc * nx, *dx = Mx + nx * nx, *xn = dx + nx, *qn = xn + nx,
           *rn = qn + nc;
    int piv[OVK_MAX_FRICTION * 3];
    forces_reduced(s, x, qf);
    int evals = 1;
    residual(nx, nc, lam0x, Wx, qf, x, r);
    for (;;) {
        *iters = evals;
        double res = maxabs(r, nx);
        if (!isfinite(res)) return 0;
        if (res <= M->tol * (1.0 + maxabs(x, nx))) return 1;
        if (evals >= n_max) return 0;
        /* the Jacobian at x: s->flam holds x's multipliers (the last forces_reduced was at x) */
        if (newton_matrix(s, Wx, Dq, Mx, piv)) return 0;
        memcpy(dx, r, sizeof(double) * nx);
        lu_solve(Mx, nx, piv, dx);
        double step = 1.0;
        for (;;) {
            for (int a = 0; a < nx; a++) xn[a] = x[a] + step * dx[a];
            forces_reduced(s, xn, qn);
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

/* ------------------------------------------------------------------------------ the evaluation */

/* y = [q (nb nq_b), h (nb nh_b)] -> ydot, lam (m; zeros at eliminated rows), qf (ncols; friction
 * forces, the next evaluation's warm start), *iterations (friction force evaluations).
 * guess_mode: 0 none (x0 = lam0), 1 guess = qf of a nearby evaluation (ncols), 2 guess = lam (m). */
int ovk_evaluate(const ovk_model *M, double t, const double *y, int guess_mode, const double *guess,
                 double *ydot, double *lam, double *qf, int *iterations, int *damped) {
    (void)t;
    int nb = M->nb, d = M->dim, kh = M->nh_b, m = M->m, nR = M->nR, nh = nb * kh, n = nb * M->nq_b;
    int wd = d == 2 ? 1 : 3, nx = M->nx, nc = M->ncols;
    const double *q = y, *h = y + n;
    size_t need = (size_t)(nb + 1) * (2 * d + d * d + wd) + 4 * (size_t)nb /* frames */
                  + (size_t)m * (nh + 2) /* J, phi, gamma */ + (size_t)nR * (nR + 2) /* S, g, lamR */
                  + (size_t)nh /* Q */ + (size_t)nR * nc /* W */ + (size_t)nx * (nc + 3)
                  + (size_t)nc * nx + (size_t)nx * nx + 18 * (size_t)M->nj + 5 * (size_t)nx + 2 * (size_t)nc + 64;
    double *mem = malloc(need * sizeof(double));
    fctx_t *ctx = M->nfj ? malloc(sizeof(fctx_t) * M->nfj) : NULL;
    if (!mem || (M->nfj && !ctx)) { free(mem); free(ctx); return OVK_NOMEM; }
    int status = OVK_OK;
    double *p = mem;
    frames_t f;
    f.r = p; p += (nb + 1) * d;
    f.v = p; p += (nb + 1) * d;
    f.R = p; p += (nb + 1) * d * d;
    f.w = p; p += (nb + 1) * wd;
    f.sb = p; p += nb; f.cb = p; p += nb; f.sg = p; p += nb; f.cg = p; p += nb;
    double *J = p; p += (size_t)m * nh;
    double *phi = p; p += m;
    double *gam = p; p += m;
    double *S = p; p += (size_t)nR * nR;
    double *g = p; p += nR;
    double *lamR = p; p += nR;
    double *Q = p; p += nh;
    double *W = p; p += (size_t)nR * nc;
    double *Jblk = p; p += 18 * (size_t)M->nj; /* every joint's (J_X)_i block, for the friction setup */
    const int *rb = M->rbody;
    double *work = p;

    build_frames(M, q, h, &f);
    /* Phi, Phi_h, gamma */
    memset(J, 0, sizeof(double) * m * nh);
    double blkJ[18], ph[3], gm[3];
    for (int j = 0; j < M->nj; j++) {
        int ne = M->jneq[j];
        double *blkI = Jblk + 18 * j;
        joint_rows(M, &f, j, ph, blkI, blkJ, gm);
        if (M->jtype[j] == J_TRANSLATIONAL) {
            double pi = M->jbi[j] >= 0 ? q[M->jbi[j] * M->nq_b + 2] : 0.0;
            double pj = M->jbj[j] >= 0 ? q[M->jbj[j] * M->nq_b + 2] : 0.0;
            ph[1] = pi - pj - M->jconst[NJC * j + 6];
        }
        for (int e = 0; e < ne; e++) {
            int row = M->jrows[3 * j + e];
            phi[row] = ph[e];
            gam[row] = gm[e];
            if (M->jbi[j] >= 0)
                for (int k = 0; k < kh; k++) J[(size_t)row * nh + M->jbi[j] * kh + k] += blkI[e * kh + k];
            if (M->jbj[j] >= 0)
                for (int k = 0; k < kh; k++) J[(size_t)row * nh + M->jbj[j] * kh + k] += blkJ[e * kh + k];
        }
    }
    double a = M->baumgarte;
    for (int i = 0; i < nR; i++) {
        int row = M->retained[i];
        g[i] = gam[row];
        if (a > 0.0) {
            double ph_h = 0.0;
            for (int s2 = 0; s2 < 2; s2++) {
                int b = rb[2 * i + s2];
                if (b < 0) continue;
                for (int k = b * kh; k < (b + 1) * kh; k++) ph_h += J[(size_t)row * nh + k] * h[k];
            }
            g[i] = g[i] - 2.0 * a * ph_h - a * a * phi[row];
        }
    }
    /* applied forces Q */
    memset(Q, 0, sizeof(double) * nh);
    for (int b = 0; b < nb; b++) {
        for (int i = 0; i < d; i++) Q[b * kh + i] = M->mass[b] * M->gravity[i];
        if (d == 3) {
            const double *w = f.w + 3 * b;
            double Jw[3] = {M->inertia[3 * b] * w[0], M->inertia[3 * b + 1] * w[1], M->inertia[3 * b + 2] * w[2]}, c[3];
            cross3(w, Jw, c);
            for (int i = 0; i < 3; i++) Q[b * kh + 3 + i] -= c[i];
        }
    }
    for (int l = 0; l < M->nl; l++) {
        const double *lp = M->lp + NLD * l;
        int bi = M->lbi[l], bj = M->lbj[l];
        if (M->ltype[l] == LD_FORCE) {
            for (int i = 0; i < d; i++) Q[bi * kh + i] += lp[i];
        } else if (M->ltype[l] == LD_TORQUE) {
            if (d == 2) Q[bi * kh + 2] += lp[0];
            else {
                double tb[3];
                mat3tvec(f.R + 9 * bi, lp, tb);
                for (int i = 0; i < 3; i++) Q[bi * kh + 3 + i] += tb[i];
            }
        } else { /* spring */
            int si = slot(M, bi), sj = slot(M, bj);
            double pi[3] = {0}, pj[3] = {0}, dv[3] = {0}, t[3];
            if (d == 2) {
                mat2vec(f.R + 4 * si, lp + 3, t);
                for (int i = 0; i < 2; i++) pi[i] = f.r[2 * si + i] + t[i];
                mat2vec(f.R + 4 * sj, lp + 6, t);
                for (int i = 0; i < 2; i++) pj[i] = f.r[2 * sj + i] + t[i];
            } else {
                mat3vec(f.R + 9 * si, lp + 3, t);
                for (int i = 0; i < 3; i++) pi[i] = f.r[3 * si + i] + t[i];
                mat3vec(f.R + 9 * sj, lp + 6, t);
                for (int i = 0; i < 3; i++) pj[i] = f.r[3 * sj + i] + t[i];
            }
            double len2 = 0.0;
            for (int i = 0; i < d; i++) { dv[i] = pi[i] - pj[i]; len2 += dv[i] * dv[i]; }
            double len = sqrt(len2), L0 = lp[10];
            double F[3] = {0};
            if (L0 == 0.0) { /* -k d: defined at coinciding points too */
                for (int i = 0; i < d; i++) F[i] = -lp[9] * dv[i];
            } else {
                if (len < 1e-12 * L0) { status = OVK_SPRING; goto done; }
                for (int i = 0; i < d; i++) F[i] = -lp[9] * (len - L0) * dv[i] / len;
            }
            for (int side = 0; side < 2; side++) {
                int b = side ? bj : bi, sl = side ? sj : si;
                double sign = side ? -1.0 : 1.0, *pt = side ? pj : pi;
                if (b < 0) continue;
                double Fs[3] = {sign * F[0], sign * F[1], sign * F[2]};
                if (d == 2) {
                    double arm[2] = {pt[0] - f.r[2 * sl], pt[1] - f.r[2 * sl + 1]};
                    Q[b * kh] += Fs[0];
                    Q[b * kh + 1] += Fs[1];
                    Q[b * kh + 2] += arm[0] * Fs[1] - arm[1] * Fs[0];
                } else {
                    double arm[3], ab[3], fb[3], c[3];
                    for (int i = 0; i < 3; i++) arm[i] = pt[i] - f.r[3 * sl + i];
                    mat3tvec(f.R + 9 * sl, arm, ab);
                    mat3tvec(f.R + 9 * sl, Fs, fb);
                    cross3(ab, fb, c);
                    for (int i = 0; i < 3; i++) { Q[b * kh + i] += Fs[i]; Q[b * kh + 3 + i] += c[i]; }
                }
            }
        }
    }
    /* S = J_R^T M^-1 J_R (here J_R is rows of Phi_h: S_ab = sum_k Phi_h[Ra,k] Minv_k Phi_h[Rb,k]) */
    for (int i = 0; i < nR; i++) {
        const double *Ji = J + (size_t)M->retained[i] * nh;
        for (int k2 = 0; k2 <= i; k2++) {
            const double *Jk = J + (size_t)M->retained[k2] * nh;
            double s = 0.0;
            for (int s2 = 0; s2 < 2; s2++) { /* bodies shared by the two rows */
                int b = rb[2 * i + s2];
                if (b < 0 || (s2 == 1 && b == rb[2 * i])) continue;
                if (b != rb[2 * k2] && b != rb[2 * k2 + 1]) continue;
                for (int k = b * kh; k < (b + 1) * kh; k++) s += Ji[k] * (M->Minv[k] * Jk[k]);
            }
            S[i * nR + k2] = S[k2 * nR + i] = s;
        }
    }
    for (int i = 0; i < nR * nR; i++)
        if (!isfinite(S[i])) { status = OVK_NONFINITE; goto done; }
    if (cholesky(S, nR)) { status = OVK_SINGULAR; goto done; }
    for (int i = 0; i < nR; i++) {
        const double *Ji = J + (size_t)M->retained[i] * nh;
        double s = 0.0;
        for (int s2 = 0; s2 < 2; s2++) {
            int b = rb[2 * i + s2];
            if (b < 0 || (s2 == 1 && b == rb[2 * i])) continue;
            for (int k = b * kh; k < (b + 1) * kh; k++) s += M->Minv[k] * Ji[k] * Q[k];
        }
        lamR[i] = s - g[i];
    }
    for (int i = 0; i < nR; i++)
        if (!isfinite(lamR[i])) { status = OVK_NONFINITE; goto done; }
    cho_solve(S, nR, lamR);
    *iterations = 0;
    *damped = 0;
    if (M->nfj) {
        /* W = S^-1 J_R^T M^-1 [:, cols]: one column per friction velocity */
        for (int i = 0; i < nR; i++)
            for (int c = 0; c < nc; c++) {
                int k = M->cols[c];
                W[i * nc + c] = M->Minv[k] * J[(size_t)M->retained[i] * nh + k];
            }
        cho_solve_many(S, nR, W, nc);
        double *lam0x = work, *Wx = lam0x + nx, *x = Wx + (size_t)nx * nc, *nwork = x + nx;
        for (int a = 0; a < nx; a++) {
            lam0x[a] = lamR[M->xrows[a]];
            memcpy(Wx + (size_t)a * nc, W + (size_t)M->xrows[a] * nc, sizeof(double) * nc);
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
        double flam[3 * OVK_MAX_FRICTION], Qib[6 * OVK_MAX_FRICTION], Qjb[6 * OVK_MAX_FRICTION];
        for (int nfr = 0; nfr < M->nfj; nfr++) /* the planar setup needs the joint's (J_X)_i block */
            friction_setup(M, &f, M->fj[nfr], Jblk + 18 * M->fj[nfr], ctx + nfr);
        fsolve_t s = {M, ctx, flam, Qib, Qjb};
        double *x0 = nwork; /* the start, kept for the damped solve */
        nwork += nx;
        memcpy(x0, x, sizeof(double) * nx);
        if (!newton_reduced(&s, lam0x, Wx, x, qf, iterations, nwork)) {
            int first = *iterations, more = 0;
            memcpy(x, x0, sizeof(double) * nx);
            int ok = damped_newton_reduced(&s, lam0x, Wx, x, qf, &more, nwork);
            *iterations = first + more;
            *damped = 1;
            if (!ok) { status = OVK_FRICTION; goto done; }
        }
        for (int i = 0; i < nR; i++) {
            double acc = 0.0;
            for (int c = 0; c < nc; c++) acc += W[i * nc + c] * qf[c];
            lamR[i] += acc;
        }
        for (int c = 0; c < nc; c++) Q[M->cols[c]] += qf[c];
    }
    /* h' = M^-1 (Q - J_R lam_R), lam */
    memset(lam, 0, sizeof(double) * m);
    for (int i = 0; i < nR; i++) lam[M->retained[i]] = lamR[i];
    double *hdot = ydot + n;
    memset(hdot, 0, sizeof(double) * nh); /* J_R lam_R first */
    for (int i = 0; i < nR; i++) {
        const double *Ji = J + (size_t)M->retained[i] * nh;
        for (int s2 = 0; s2 < 2; s2++) {
            int b = rb[2 * i + s2];
            if (b < 0 || (s2 == 1 && b == rb[2 * i])) continue;
            for (int k = b * kh; k < (b + 1) * kh; k++) hdot[k] += Ji[k] * lamR[i];
        }
    }
    for (int k = 0; k < nh; k++) hdot[k] = M->Minv[k] * (Q[k] - hdot[k]);
    /* coordinate rates */
    if (d == 2) {
        memcpy(ydot, h, sizeof(double) * nh);
    } else {
        for (int b = 0; b < nb; b++) {
            double sb = f.sb[b], cb = f.cb[b], sg = f.sg[b], cg = f.cg[b];
            if (fabs(sb) < SIN_BETA_MIN) { status = OVK_EULER; goto done; }
            const double *w = h + b * kh + 3;
            double H[9] = {sg / sb, cg / sb, 0.0, cg, -sg, 0.0, -cb * sg / sb, -cb * cg / sb, 1.0};
            for (int i = 0; i < 3; i++) ydot[b * 6 + i] = h[b * kh + i];
            mat3vec(H, w, ydot + b * 6 + 3);
        }
    }
    for (int k = 0; k < n + nh; k++)
        if (!isfinite(ydot[k])) { status = OVK_NONFINITE; break; }
done:
    free(mem);
    free(ctx);
    return status;
}

/* ------------------------------------------------------------------------------ reported values */

/* The reported reactions and friction forces at y and the multipliers lam (m) (overcon.evaluation
 * physical_reactions and friction_output): per joint j, reac[6 j ...] = -A_i fi in its auxiliary
 * frame (3 components: planar Fx, Fy, T; spherical Fx, Fy, Fz), then -fi[:dim] in the global
 * frame, fi = (J_X)_i^T lam_X; fric[j] = the friction output of a joint with friction (else 0). */
int ovk_outputs(const ovk_model *M, const double *y, const double *lam, double *reac, double *fric) {
    int nb = M->nb, d = M->dim, kh = M->nh_b, wd = d == 2 ? 1 : 3, n = nb * M->nq_b;
    double *mem = malloc(sizeof(double) * ((size_t)(nb + 1) * (2 * d + d * d + wd) + 4 * (size_t)nb + 1));
    if (!mem) return OVK_NOMEM;
    frames_t f;
    double *p = mem;
    f.r = p; p += (nb + 1) * d;
    f.v = p; p += (nb + 1) * d;
    f.R = p; p += (nb + 1) * d * d;
    f.w = p; p += (nb + 1) * wd;
    f.sb = p; p += nb; f.cb = p; p += nb; f.sg = p; p += nb; f.cg = p;
    build_frames(M, y, y + n, &f);
    double blkI[18], blkJ[18], ph[3], gm[3], lj[3], fi[6];
    for (int j = 0; j < M->nj; j++) {
        int ne = M->jneq[j], bi = slot(M, M->jbi[j]);
        double *out = reac + 6 * j;
        joint_rows(M, &f, j, ph, blkI, blkJ, gm);
        for (int e = 0; e < ne; e++) lj[e] = lam[M->jrows[3 * j + e]];
        for (int k = 0; k < kh; k++) {
            double s = 0.0;
            for (int e = 0; e < ne; e++) s += blkI[e * kh + k] * lj[e];
            fi[k] = s;
        }
        for (int k = 0; k < 6; k++) out[k] = 0.0;
        fctx_t cx;
        if (M->jtype[j] == J_SPHERICAL) {
            double t[3];
            mat3tvec(f.R + 9 * bi, fi, t);
            for (int k = 0; k < 3; k++) { out[k] = -t[k]; out[3 + k] = -fi[k]; }
        } else {
            friction_setup(M, &f, j, blkI, &cx); /* A_i (the friction constants are not used without a law) */
            for (int a = 0; a < 3; a++) out[a] = -(cx.A[3 * a] * fi[0] + cx.A[3 * a + 1] * fi[1] + cx.A[3 * a + 2] * fi[2]);
            out[3] = -fi[0];
            out[4] = -fi[1];
        }
        fric[j] = 0.0;
        if (M->jlaw[j] == LAW_NONE) continue;
        if (M->jtype[j] == J_SPHERICAL) friction_setup(M, &f, j, blkI, &cx);
        const double *lp = M->jlawp + NLP * j;
        if (M->jtype[j] == J_REVOLUTE) {
            double pa[3];
            planar_paux(&cx, lj, pa);
            fric[j] = cx.coef * hypot(pa[0], pa[1]);
        } else if (M->jtype[j] == J_TRANSLATIONAL) {
            double pa[3], l = lp[2];
            planar_paux(&cx, lj, pa);
            fric[j] = cx.coef * (fabs(pa[1] - pa[2] / l) + fabs(pa[2] / l));
        } else {
            double F[3];
            mat3vec(cx.RiT, lj, F);
            if (sqrt(dot3(F, F)) == 0.0) continue; /* no contact point: no friction */
            double norm = sqrt(dot3(F, F)), sC[3], v[3], Ffr[3];
            for (int k = 0; k < 3; k++) sC[k] = -lp[2] * F[k] / norm;
            cross3(cx.omega, sC, v);
            double mn = law_mu_over_speed(lp, M->jlaw[j], sqrt(dot3(v, v))) * norm;
            for (int k = 0; k < 3; k++) Ffr[k] = mn * v[k];
            fric[j] = sqrt(dot3(Ffr, Ffr));
        }
    }
    free(mem);
    return OVK_OK;
}
