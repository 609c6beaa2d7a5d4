/* The library's entry points: the ABI number, the workspace (made from a model, checked on the
 * way), one evaluation (the stages in order) and the reported outputs. Only these symbols are
 * exported; every failure is a status with its message in the workspace (ovk_message). */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "core.h"

int ovk_abi(void) { return OVK_ABI; }

int ovk_fail(ovk_data *d, int status, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(d->msg, sizeof d->msg, fmt, ap);
    va_end(ap);
    return status;
}

void ovk_friction_joint_list(const ovk_model *M, char *out, size_t size) {
    size_t used = 0;
    if (size) out[0] = '\0';
    for (int k = 0; k < M->nfj && used < size; k++) {
        int w = snprintf(out + used, size - used, "%sjoints[%d]", k ? ", " : "", M->fj[k]);
        if (w < 0) break;
        used += (size_t)w;
    }
}

#define OVK_MAX_COUNT (1 << 20) /* any count of the model: far above any mechanism, far below overflow */

static int in_range(const int *a, int n, int lo, int hi) { /* every a[i] in [lo, hi) */
    for (int i = 0; i < n; i++)
        if (a[i] < lo || a[i] >= hi) return 0;
    return 1;
}

/* The equations of a joint type in dimension dim (overcon.joints.TYPES n_equations), 0 for an
 * unknown type; the point-on-line joint has dim - 1 (its line's normals). */
static int joint_equations(int type, int dim) {
    static const int n[] = {0, 2, 2, 3, 5, 5, 4, 4, 6, 1, 1}; /* by J_* */
    if (type == J_POINT_LINE) return dim - 1;
    return type >= 0 && type <= J_DISTANCE ? n[type] : 0;
}

/* A driver's constants (drivers.c): a driven joint of a type its coordinate has, on the same
 * bodies, a known motion with finite parameters (a ramp's t1 after its t0). */
static int driver_ok(const ovk_model *M, int j) {
    const double *c = M->jconst + NJC * j;
    for (int k = 0; k < 9; k++)
        if (!isfinite(c[k])) return 0;
    int jd = (int)c[0];
    if (c[0] != (double)jd || jd < 0 || jd >= M->nj || !(c[1] == 0.0 || c[1] == 1.0) ||
        !(c[2] == 1.0 || c[2] == 2.0 || c[2] == 3.0) || M->jlaw[j] != LAW_NONE)
        return 0;
    int t = M->jtype[jd], rot = c[1] == 0.0;
    int ok = rot ? t == J_REVOLUTE || t == J_SREVOLUTE || t == J_CYLINDRICAL
                 : t == J_TRANSLATIONAL || t == J_PRISMATIC || t == J_CYLINDRICAL;
    return ok && M->jbi[j] == M->jbi[jd] && M->jbj[j] == M->jbj[jd] && (c[2] != 2.0 || c[6] > c[5]);
}

/* The model's counts, types and indices, checked before anything is sized from them: a model that
 * is not what overcon.kernel packs is refused with a message instead of read out of bounds. */
static int check_model(const ovk_model *M, ovk_data *d) {
    const int counts[] = {M->nb, M->m, M->nR, M->nj, M->nl, M->nx, M->ncols, M->nfj, M->nfg};
    const char *names[] = {"nb", "m", "nR", "nj", "nl", "nx", "ncols", "nfj", "nfg"};
    for (size_t i = 0; i < sizeof counts / sizeof counts[0]; i++)
        if (counts[i] < 0 || counts[i] > OVK_MAX_COUNT)
            return ovk_fail(d, OVK_INVALID, "model: %s = %d is out of range [0, %d]", names[i], counts[i],
                            OVK_MAX_COUNT);
    if (!((M->dim == 2 && M->nq_b == 3 && M->nh_b == 3) ||
          (M->dim == 3 && (M->nq_b == 6 || M->nq_b == 7) && M->nh_b == 6)))
        return ovk_fail(d, OVK_INVALID, "model: dim %d with %d coordinates and %d velocities per body "
                        "(planar: 2, 3, 3; spatial: 3, 6 or 7, 6)", M->dim, M->nq_b, M->nh_b);
    if (M->nx > OVK_MAXEQ * M->nfj)
        return ovk_fail(d, OVK_INVALID, "model: %d friction multipliers for %d friction joints (at most %d each)",
                        M->nx, M->nfj, OVK_MAXEQ);
    if (M->formulation != OVK_FORM_ELIMINATED && M->formulation != OVK_FORM_AL)
        return ovk_fail(d, OVK_INVALID, "model: formulation %d (0 eliminated, 1 augmented Lagrangian)",
                        M->formulation);
    if (M->nR > M->m || M->ncols > M->nb * M->nh_b || M->max_iter < 1 || !(M->tol > 0.0) ||
        !(M->baumgarte >= 0.0))
        return ovk_fail(d, OVK_INVALID, "model: nR %d of m %d rows, %d friction columns of %d velocities, "
                        "max_iter %d, tol %g, baumgarte %g", M->nR, M->m, M->ncols, M->nb * M->nh_b, M->max_iter,
                        M->tol, M->baumgarte);
    int nh = M->nb * M->nh_b;
    for (int j = 0; j < M->nj; j++) {
        int t = M->jtype[j], planar = t == J_REVOLUTE || t == J_TRANSLATIONAL || t == J_DISTANCE || t == J_POINT_LINE;
        int spatial = t == J_SPHERICAL || (t >= J_SREVOLUTE && t <= J_FIXED) || t == J_DISTANCE || t == J_POINT_LINE;
        if (t == J_DRIVER && !driver_ok(M, j)) return ovk_fail(d, OVK_INVALID, "model: driver %d is not one the core takes", j);
        if (!((M->dim == 2 && planar) || (M->dim == 3 && spatial) || t == J_DRIVER) || M->jneq[j] != joint_equations(t, M->dim) ||
            M->jbi[j] < -1 || M->jbi[j] >= M->nb || M->jbj[j] < -1 || M->jbj[j] >= M->nb ||
            !in_range(M->jrows + OVK_MAXEQ * j, M->jneq[j], 0, M->m) || M->jlaw[j] < LAW_NONE ||
            M->jlaw[j] > LAW_STRIBECK || (t == J_DISTANCE && M->jlaw[j] != LAW_NONE))
            return ovk_fail(d, OVK_INVALID, "model: joint %d (type %d, %d rows, bodies %d and %d, law %d) is not "
                            "one the core takes in dimension %d", j, t, M->jneq[j], M->jbi[j], M->jbj[j], M->jlaw[j],
                            M->dim);
    }
    for (int l = 0; l < M->nl; l++) {
        int t = M->ltype[l];
        if (t < LD_FORCE || t > LD_SPRING || M->lbi[l] < (t == LD_SPRING ? -1 : 0) || M->lbi[l] >= M->nb ||
            (t == LD_SPRING && (M->lbj[l] < -1 || M->lbj[l] >= M->nb)))
            return ovk_fail(d, OVK_INVALID, "model: load %d (type %d, bodies %d and %d) is not one the core takes",
                            l, t, M->lbi[l], M->lbj[l]);
    }
    if (!in_range(M->retained, M->nR, 0, M->m) || !in_range(M->rbody, 2 * M->nR, -1, M->nb) ||
        !in_range(M->xrows, M->nx, 0, M->nR) || !in_range(M->cols, M->ncols, 0, nh) ||
        !in_range(M->fj, M->nfj, 0, M->nj) || !in_range(M->fgroup, M->nfg + 1, 0, M->nfj + 1) ||
        (M->nfg >= 0 && M->fgroup[M->nfg] != M->nfj) || !in_range(M->fx, OVK_MAXEQ * M->nfj, 0, M->nx + 1) ||
        !in_range(M->fci, 6 * M->nfj, 0, M->ncols + 1) || !in_range(M->fcj, 6 * M->nfj, 0, M->ncols + 1))
        return ovk_fail(d, OVK_INVALID, "model: an index of the elimination or the friction plan is out of range");
    if (M->nu < 0 || M->nu > OVK_MAX_COUNT)
        return ovk_fail(d, OVK_INVALID, "model: nu = %d is out of range [0, %d]", M->nu, OVK_MAX_COUNT);
    for (int k = 0; k < M->nu; k++) {
        int kind = M->ukind[k], j = M->uidx[3 * k], bi = M->uidx[3 * k + 1], bj = M->uidx[3 * k + 2];
        int joint = kind == OVK_IN_JOINT_TORQUE || kind == OVK_IN_JOINT_FORCE;
        double frame = M->up[OVK_NUP * k + 6];
        if (!isfinite(M->up[OVK_NUP * k + 7]) || kind < OVK_IN_JOINT_TORQUE || kind > OVK_IN_TORQUE || bi < 0 || bi >= M->nb || bj < -1 || bj >= M->nb ||
            (joint ? j < 0 || j >= M->nj : j != -1) || !(frame == 0.0 || frame == 1.0 || frame == 2.0))
            return ovk_fail(d, OVK_INVALID, "model: input %d (kind %d, joint %d, bodies %d and %d, frame %g) is not "
                            "one the core takes", k, kind, j, bi, bj, frame);
    }
    for (int p = 1; p < M->nR; p++)
        if (M->retained[p] <= M->retained[p - 1])
            return ovk_fail(d, OVK_INVALID, "model: the retained rows are not ascending (position %d: %d after %d)", p,
                            M->retained[p], M->retained[p - 1]);
    /* the joints' rows are the m equations, each once (unique.c and watch.c fill per-row tables from them) */
    unsigned char *seen = calloc((size_t)M->m + 1, 1);
    if (!seen) return ovk_fail(d, OVK_NOMEM, "out of memory: %d row flags", M->m);
    int covered = 0, twice = -1;
    for (int j = 0; j < M->nj; j++)
        for (int e = 0; e < M->jneq[j]; e++) {
            int r = M->jrows[(size_t)j * OVK_MAXEQ + e];
            if (seen[r]++) twice = r;
            else covered++;
        }
    free(seen);
    if (twice >= 0 || covered != M->m)
        return ovk_fail(d, OVK_INVALID, "model: the joints' rows are not the %d equations once each (%d covered%s)",
                        M->m, covered, twice >= 0 ? ", one twice" : "");
    for (int g = 0; g < M->nfg; g++)
        if (M->fgroup[g] > M->fgroup[g + 1])
            return ovk_fail(d, OVK_INVALID, "model: friction group %d starts after the next one", g);
    return ovk_check_redundancy(M, d);
}

/* The band orders of S's rows (kkt.c): the retained rows, and under "compliant" the rigid ones
 * (compliance.c's view), fixed per model. The status. */
static int band_orders(const ovk_model *M, ovk_data *d) {
    size_t nR = (size_t)M->nR, nrig = M->redundancy == OVK_COMPLIANT ? (size_t)M->nrig : 0;
    d->sb_mem = malloc((3 * nR + 3 * nrig + 1) * sizeof(int));
    long long *key = malloc((nR + 1) * sizeof(long long));
    int *span = malloc((2 * (size_t)M->nb + 1) * sizeof(int));
    if (!d->sb_mem || !key || !span) {
        free(key);
        free(span);
        return ovk_fail(d, OVK_NOMEM, "out of memory: the band order of S needs %zu bytes",
                        (3 * nR + 3 * nrig + 1) * sizeof(int) + (nR + 1) * sizeof(long long) +
                        (2 * (size_t)M->nb + 1) * sizeof(int));
    }
    d->sb.order = d->sb_mem, d->sb.body = d->sb.order + nR;
    d->sb_rigid.order = d->sb.body + 2 * nR, d->sb_rigid.body = d->sb_rigid.order + nrig;
    d->sb.band = ovk_band_order(M->nR, M->nb, M->rbody, NULL, 1, d->sb.order, d->sb.body, key, span);
    if (nrig)
        d->sb_rigid.band = ovk_band_order(M->nrig, M->nb, M->rigbody, NULL, 1, d->sb_rigid.order, d->sb_rigid.body,
                                          key, span);
    free(key);
    free(span);
    return OVK_OK;
}

ovk_data *ovk_make_data(const ovk_model *M) {
    ovk_data *d = calloc(1, sizeof(ovk_data));
    if (!d) return NULL;
    if (!M) { d->status = ovk_fail(d, OVK_INVALID, "model: a null pointer"); return d; }
    if ((d->status = check_model(M, d))) return d;
    if ((d->status = band_orders(M, d))) return d;
    size_t nb = (size_t)M->nb, dim = (size_t)M->dim, wd = dim == 2 ? 1 : 3, m = (size_t)M->m, nR = (size_t)M->nR;
    size_t nh = nb * (size_t)M->nh_b, nc = (size_t)M->ncols, nx = (size_t)M->nx, nj = (size_t)M->nj;
    size_t nfj = (size_t)M->nfj, nrig = M->redundancy == OVK_COMPLIANT ? (size_t)M->nrig : 0;
    size_t nS = M->redundancy == OVK_MIN_NORM ? nR * nR : nR * (size_t)(d->sb.band + 1); /* S: band storage */
    if (nrig * (size_t)(d->sb_rigid.band + 1) > nS) nS = nrig * (size_t)(d->sb_rigid.band + 1);
    size_t n_frames = (nb + 1) * (2 * dim + dim * dim + wd) + 4 * nb;
    size_t n_work = 4 * nx + nx * nc                          /* lam0x, x, x0, Wx */
                    + 4 * nx + nc * nx + nx * nx + nc + nx;   /* r, Dq, Mx, dx, xn, qn, rn (damped Newton) */
    size_t need = n_frames + m * 2 * (size_t)M->nh_b + 3 * m + nS + nR * (nc ? nc : 1) + 2 * nR + nh + nR * nc
                  + 6 * OVK_MAXEQ * nj + n_work + (OVK_MAXEQ + 12) * nfj + ovk_robust_doubles(M->nx, M->ncols)
                  + ovk_redundancy_doubles(M);
    d->mem = calloc(need ? need : 1, sizeof(double)); /* zeros: Phi_h's unused slots stay so (joints.c) */
    d->ctx = calloc(nfj ? nfj : 1, sizeof(ovk_fctx));
    d->piv = calloc(nx ? nx : 1, sizeof(int));
    if (!d->mem || !d->ctx || !d->piv) {
        free(d->mem);
        free(d->ctx);
        free(d->piv);
        d->mem = NULL;
        d->ctx = NULL;
        d->piv = NULL;
        d->status = ovk_fail(d, OVK_NOMEM, "out of memory: the workspace needs %zu bytes",
                             need * sizeof(double) + nfj * sizeof(ovk_fctx) + nx * sizeof(int));
        return d;
    }
    double *p = d->mem;
    d->f.r = p; p += (nb + 1) * dim;
    d->f.v = p; p += (nb + 1) * dim;
    d->f.R = p; p += (nb + 1) * dim * dim;
    d->f.w = p; p += (nb + 1) * wd;
    d->f.sb = p; p += nb; d->f.cb = p; p += nb; d->f.sg = p; p += nb; d->f.cg = p; p += nb;
    d->J = p; p += m * 2 * (size_t)M->nh_b;
    d->phi = p; p += m;
    d->gam = p; p += m;
    d->phit = p; p += m;
    d->S = p; p += nS;
    d->Sx = p; p += nR * (nc ? nc : 1);
    d->g = p; p += nR;
    d->lamR = p; p += nR;
    d->Q = p; p += nh;
    d->W = p; p += nR * nc;
    d->Jblk = p; p += 6 * OVK_MAXEQ * nj;
    d->flam = p; p += OVK_MAXEQ * nfj;
    d->Qi = p; p += 6 * nfj;
    d->Qj = p; p += 6 * nfj;
    d->robust = p;
    p += ovk_robust_doubles(M->nx, M->ncols);
    d->red = p;
    p += ovk_redundancy_doubles(M);
    d->work = p;
    d->al_band = ovk_al_half_band(M); /* the AL band and vectors: formulation AL and ovk_project */
    d->al = calloc(ovk_al_doubles(M), sizeof(double));
    d->al_rows = calloc(3 * m + 1, sizeof(int));
    d->u = calloc(2 * (size_t)M->nu + 1, sizeof(double)); /* the inputs' values: zero until set */
    if (!d->al || !d->al_rows || !d->u)
        d->status = ovk_fail(d, OVK_NOMEM, "out of memory: the augmented Lagrangian workspace needs %zu bytes",
                             ovk_al_doubles(M) * sizeof(double) + (3 * m + 1) * sizeof(int));
    else
        ovk_al_make_rows(M, d);
    for (int k = 0; d->u && k < M->nu; k++) d->u[k] = M->up[OVK_NUP * k + 7]; /* the start values */
    return d;
}

void ovk_free_data(ovk_data *d) {
    if (!d) return;
    free(d->mem);
    free(d->ctx);
    free(d->piv);
    free(d->al);
    free(d->al_rows);
    free(d->sb_mem);
    free(d->u);
    free(d);
}

const char *ovk_message(const ovk_data *d) { return d ? d->msg : "no workspace (out of memory)"; }
int ovk_data_status(const ovk_data *d) { return d ? d->status : OVK_NOMEM; }

static int finish(const ovk_model *M, ovk_data *d, const double *y, double *ydot, double *lam);

/* y = [q (nb nq_b), h (nb nh_b)] -> ydot, lam (m; zeros at eliminated rows), qf (ncols; friction
 * forces, the next evaluation's warm start), *iterations (friction force evaluations), *damped
 * (the damped Newton ran). guess_mode: 0 none (x0 = lam0), 1 guess = qf of a nearby evaluation
 * (ncols), 2 guess = lam (m). t: the time the inputs' values are taken at (inputs.c). */
int ovk_evaluate(const ovk_model *M, ovk_data *d, double t, const double *y, int guess_mode, const double *guess,
                 double *ydot, double *lam, double *qf, int *iterations, int *damped) {
    if (!d) return OVK_NOMEM;
    if (d->status) return d->status;
    d->msg[0] = '\0';
    d->robust_ready = 0;
    *iterations = 0;
    *damped = 0;
    if (guess_mode < 0 || guess_mode > 2 || (guess_mode && !guess))
        return ovk_fail(d, OVK_INVALID, "evaluate: guess_mode %d %s", guess_mode,
                        guess ? "is not 0, 1 or 2" : "without a guess");
    const double *q = y, *h = y + M->nb * M->nq_b;
    int status;
    ovk_frames_build(M, q, h, &d->f);
    d->f.t = t;
    ovk_constraint_rows(M, d, q);
    ovk_kkt_rhs(M, d, h);
    if ((status = ovk_loads(M, d, t))) return status;
    status = M->redundancy == OVK_COMPLIANT       ? ovk_compliant_solve(M, d, h)
             : M->formulation == OVK_FORM_AL          ? ovk_kkt_al_solve(M, d)
                                                      : ovk_kkt_solve(M, d);
    if (status) return status;
    if (M->nfj && (status = ovk_friction(M, d, guess_mode, guess, qf, iterations, damped))) {
        d->robust_ready = status == OVK_FRICTION;
        return status;
    }
    return finish(M, d, y, ydot, lam);
}

/* The tail of an evaluation after the friction stage: multipliers, accelerations, rates. */
static int finish(const ovk_model *M, ovk_data *d, const double *y, double *ydot, double *lam) {
    int n = M->nb * M->nq_b, nh = M->nb * M->nh_b, status;
    ovk_kkt_accelerations(M, d, lam, ydot + n);
    if ((status = ovk_rates(M, d, y, y + n, ydot))) return status;
    for (int k = 0; k < n + nh; k++)
        if (!isfinite(ydot[k])) return ovk_fail(d, OVK_NONFINITE, "non-finite number in y' (entry %d)", k);
    return OVK_OK;
}

/* The evaluation at y that ovk_evaluate left at OVK_FRICTION (Newton and damped Newton gave up),
 * finished by the robust path (friction_robust.c; start: lam_guess (m) or NULL, the frictionless
 * multipliers). The same outputs as ovk_evaluate; qf: the friction forces, not handed on as the
 * next evaluation's warm start after this path. */
int ovk_evaluate_robust(const ovk_model *M, ovk_data *d, const double *y, const double *start, double *ydot,
                        double *lam, double *qf, int *iterations) {
    if (!d) return OVK_NOMEM;
    if (d->status) return d->status;
    if (!d->robust_ready)
        return ovk_fail(d, OVK_INVALID, "evaluate_robust: the last evaluation did not stop in the friction solve");
    d->robust_ready = 0;
    d->msg[0] = '\0';
    int status = ovk_friction_robust(M, d, start, qf, iterations);
    return status ? status : finish(M, d, y, ydot, lam);
}

/* The reported reactions (reac, nj x 6) and friction outputs (fric, nj) at y and lam (outputs.c). */
int ovk_outputs(const ovk_model *M, ovk_data *d, const double *y, const double *lam, double *reac, double *fric) {
    if (!d) return OVK_NOMEM;
    if (d->status) return d->status;
    d->msg[0] = '\0';
    ovk_reported(M, d, y, lam, reac, fric);
    return OVK_OK;
}

/* The friction forces of friction joint n (0 <= n < nfj, the plan's order M->fj) at y and its
 * multipliers lam (its equations, in order): Q = [Qi, Qj] (2 nh_b: generalized forces on body i
 * and body j) and their derivatives dQ = d Q / d lam (2 nh_b x neq, row-major), the Jacobian the
 * friction solve's Newton uses (ovk_joint_friction_jac): the entry point that lets each type's
 * Jacobian be checked against differences of its forces. */
int ovk_friction_joint_at(const ovk_model *M, ovk_data *d, const double *y, int n, const double *lam, double *Q,
                          double *dQ) {
    if (!d) return OVK_NOMEM;
    if (d->status) return d->status;
    d->msg[0] = '\0';
    if (n < 0 || n >= M->nfj || !y || !lam || !Q || !dQ)
        return ovk_fail(d, OVK_INVALID, "friction_joint_at: friction joint %d of %d (or a null pointer)", n, M->nfj);
    int j = M->fj[n], ne = M->jneq[j], kh = M->nh_b;
    double blkI[6 * OVK_MAXEQ], blkJ[6 * OVK_MAXEQ], ph[OVK_MAXEQ], gm[OVK_MAXEQ];
    double dQi[6 * OVK_MAXEQ], dQj[6 * OVK_MAXEQ];
    for (int e = 0; e < ne; e++)
        if (!isfinite(lam[e])) return ovk_fail(d, OVK_NONFINITE, "friction_joint_at: lam[%d] is not finite", e);
    ovk_frames_build(M, y, y + M->nb * M->nq_b, &d->f);
    ovk_joint_rows(M, &d->f, j, ph, blkI, blkJ, gm);
    ovk_fctx cx;
    ovk_joint_friction_setup(M, &d->f, j, blkI, &cx);
    ovk_joint_friction_forces(M, j, &cx, lam, Q, Q + kh);
    ovk_joint_friction_jac(M, j, &cx, lam, dQi, dQj);
    for (int k = 0; k < kh * ne; k++) {
        dQ[k] = dQi[k];
        dQ[kh * ne + k] = dQj[k];
    }
    return OVK_OK;
}

/* Phi (m), Phi_h (m x nh, row-major) and gamma (m, without Baumgarte) at y (joints.c): the rows
 * the evaluation solves with, for the pre-check, the initial-state checks and the tests' finite
 * differences. */
int ovk_rows_in(const ovk_model *M, ovk_data *d, const double *y) {
    if (!d) return OVK_NOMEM;
    if (d->status) return d->status;
    d->msg[0] = '\0';
    ovk_frames_build(M, y, y + M->nb * M->nq_b, &d->f);
    ovk_constraint_rows(M, d, y);
    return OVK_OK;
}

int ovk_rows(const ovk_model *M, ovk_data *d, const double *y, double *phi, double *J, double *gam) {
    int status = ovk_rows_in(M, d, y), nh = M->nb * M->nh_b;
    if (status) return status;
    const int *body = d->al_rows + M->m; /* each equation's two bodies (kkt_al.c ovk_al_make_rows) */
    for (int r = 0; r < M->m; r++) {
        phi[r] = d->phi[r];
        gam[r] = d->gam[r];
        ovk_row_dense(M, d->J, r, body[2 * r], body[2 * r + 1], J + (size_t)r * nh);
    }
    return OVK_OK;
}
