/* Stage: inputs and joint sensors (scene [[inputs]], [outputs] joints; overcon.model.CompiledInput).
 *
 * An input is a named slot of the packed model (ukind, uidx, up): what it pushes and where. Its
 * value is the run's (ovk_data.u: the values at u_t and their slopes), so that a host can set it
 * between steps: u(t) = u + du (t - u_t), held (du = 0) or linear within a communication step.
 *   joint_torque  about the axis of a revolute (planar, spatial) or cylindrical joint: +u on body i,
 *                 -u on body j (the axis a_i of body i, in global axes R_i a_i)
 *   joint_force   along a translational (planar), prismatic or cylindrical joint: +u along the axis
 *                 on body i at its joint point P_i, -u on body j at the same point
 *   force         on body i at the point up[3:6] (body i axes), along the unit direction (global, or
 *                 body i axes turning with the body)
 *   torque        on body i about the unit direction (global, or body i axes)
 * The direction up[0:3] is in global axes (frame 0), body i's (1) or body j's (2).
 *
 * Sensors: the rotation of body i relative to body j about a joint's axis and its rate, the
 * displacement along it and its speed, from their values at q0. */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

/* The direction of input k in global axes (dim entries). */
static void input_direction(const ovk_model *M, const ovk_frames *f, int k, double *out) {
    const double *p = M->up + OVK_NUP * k;
    int frame = (int)p[6], b = frame == 2 ? M->uidx[3 * k + 2] : M->uidx[3 * k + 1];
    int sl = ovk_slot(M, frame == 0 ? -1 : b);
    if (M->dim == 2) mat2vec(f->R + 4 * sl, p, out);
    else mat3vec(f->R + 9 * sl, p, out);
}

/* Adds the force F (global) at the point P (global) to body b's generalized forces (not the base). */
static void add_force(const ovk_model *M, const ovk_frames *f, int b, const double *F, const double *P, double *Q) {
    if (b < 0) return;
    int kh = M->nh_b;
    if (M->dim == 2) {
        double arm[2] = {P[0] - f->r[2 * b], P[1] - f->r[2 * b + 1]};
        Q[b * kh] += F[0];
        Q[b * kh + 1] += F[1];
        Q[b * kh + 2] += arm[0] * F[1] - arm[1] * F[0];
        return;
    }
    double arm[3], c[3], cb[3];
    for (int i = 0; i < 3; i++) arm[i] = P[i] - f->r[3 * b + i];
    cross3(arm, F, c);
    mat3tvec(f->R + 9 * b, c, cb);
    for (int i = 0; i < 3; i++) {
        Q[b * kh + i] += F[i];
        Q[b * kh + 3 + i] += cb[i];
    }
}

/* Adds the torque T (global; planar: T[0] about z) to body b (not the base). */
static void add_torque(const ovk_model *M, const ovk_frames *f, int b, const double *T, double *Q) {
    if (b < 0) return;
    int kh = M->nh_b;
    if (M->dim == 2) {
        Q[b * kh + 2] += T[0];
        return;
    }
    double tb[3];
    mat3tvec(f->R + 9 * b, T, tb);
    for (int i = 0; i < 3; i++) Q[b * kh + 3 + i] += tb[i];
}

void ovk_input_forces(const ovk_model *M, const ovk_data *d, double t, double *Q) {
    const ovk_frames *f = &d->f;
    int dim = M->dim;
    for (int k = 0; k < M->nu; k++) {
        double u = d->u[k] + d->u[M->nu + k] * (t - d->u[2 * M->nu]);
        const double *p = M->up + OVK_NUP * k;
        int bi = M->uidx[3 * k + 1], bj = M->uidx[3 * k + 2];
        double dir[3] = {0.0, 0.0, 1.0}, V[3], P[3] = {0.0, 0.0, 0.0}, pt[3];
        if (!(M->ukind[k] == OVK_IN_JOINT_TORQUE && dim == 2)) input_direction(M, f, k, dir);
        for (int i = 0; i < 3; i++) V[i] = u * dir[i];
        if (dim == 2 && M->ukind[k] != OVK_IN_JOINT_FORCE && M->ukind[k] != OVK_IN_FORCE) V[0] = u; /* about z */
        if (M->ukind[k] == OVK_IN_JOINT_TORQUE || M->ukind[k] == OVK_IN_TORQUE) {
            add_torque(M, f, bi, V, Q);
            if (M->ukind[k] == OVK_IN_JOINT_TORQUE) {
                for (int i = 0; i < 3; i++) V[i] = -V[i];
                add_torque(M, f, bj, V, Q);
            }
            continue;
        }
        int si = ovk_slot(M, bi);
        if (dim == 2) mat2vec(f->R + 4 * si, p + 3, pt);
        else mat3vec(f->R + 9 * si, p + 3, pt);
        for (int i = 0; i < dim; i++) P[i] = f->r[dim * si + i] + pt[i];
        add_force(M, f, bi, V, P, Q);
        if (M->ukind[k] == OVK_IN_JOINT_FORCE) {
            for (int i = 0; i < 3; i++) V[i] = -V[i];
            add_force(M, f, bj, V, P, Q);
        }
    }
}

int ovk_set_inputs(const ovk_model *M, ovk_data *d, const double *u, const double *du, double t_ref) {
    if (!d) return OVK_NOMEM;
    if (d->status) return d->status;
    if (!M->nu) return OVK_OK;
    if (!u || !isfinite(t_ref)) return ovk_fail(d, OVK_INVALID, "inputs: no values, or a non-finite time");
    for (int k = 0; k < M->nu; k++)
        if (!isfinite(u[k]) || (du && !isfinite(du[k])))
            return ovk_fail(d, OVK_NONFINITE, "inputs: input %d is %g (slope %g): not finite", k, u[k],
                            du ? du[k] : 0.0);
    for (int k = 0; k < M->nu; k++) {
        d->u[k] = u[k];
        d->u[M->nu + k] = du ? du[k] : 0.0;
    }
    d->u[2 * M->nu] = t_ref;
    return OVK_OK;
}

/* A spatial axis joint's rotation angle of body i about the axis relative to body j and its rate,
 * displacement along the axis (raw: not from q0) and its speed, at the frames f. */
static void axis_sensor(const ovk_model *M, const ovk_frames *f, int j, double *out) {
    const double *c = M->jconst + NJC * j;
    int bi = ovk_slot(M, M->jbi[j]), bj = ovk_slot(M, M->jbj[j]);
    const double *Ri = f->R + 9 * bi, *Rj = f->R + 9 * bj, *wi = f->w + 3 * bi, *wj = f->w + 3 * bj;
    double ci[3], b1[3], b2[3], a[3], aj[3], Pi[3], Pj[3], si[3], sj[3], u[3];
    mat3vec(Ri, c + 18, ci);
    mat3vec(Rj, c + 12, b1);
    mat3vec(Rj, c + 15, b2);
    mat3vec(Ri, c + 6, a);
    mat3tvec(Rj, a, aj);
    out[0] = atan2(dot3(ci, b2), dot3(ci, b1)); /* zero at q0: R_i c_i = R_j b1_j there */
    out[1] = dot3(wi, c + 6) - dot3(wj, aj);
    mat3vec(Ri, c, si);
    mat3vec(Rj, c + 3, sj);
    mat3vec(Rj, c + 9, u);
    double dd[3], vi[3], vj[3], t[3], wu[3], wjg[3], wig[3];
    mat3vec(Ri, wi, wig);
    mat3vec(Rj, wj, wjg);
    cross3(wig, si, t);
    for (int i = 0; i < 3; i++) vi[i] = f->v[3 * bi + i] + t[i];
    cross3(wjg, sj, t);
    for (int i = 0; i < 3; i++) vj[i] = f->v[3 * bj + i] + t[i];
    for (int i = 0; i < 3; i++) {
        Pi[i] = f->r[3 * bi + i] + si[i];
        Pj[i] = f->r[3 * bj + i] + sj[i];
        dd[i] = Pi[i] - Pj[i];
        t[i] = vi[i] - vj[i];
    }
    cross3(wjg, u, wu);
    out[2] = dot3(dd, u);
    out[3] = dot3(t, u) + dot3(dd, wu);
}

/* A planar joint's relative angle and rate, the displacement along a translational joint's guide
 * and its speed (raw: not from q0), at the frames f and the coordinates q, h. */
static void planar_sensor(const ovk_model *M, const ovk_frames *f, const double *q, const double *h, int j,
                          double *out) {
    int bi = M->jbi[j], bj = M->jbj[j], kq = M->nq_b, kh = M->nh_b;
    out[0] = (bi >= 0 ? q[bi * kq + 2] : 0.0) - (bj >= 0 ? q[bj * kq + 2] : 0.0);
    out[1] = (bi >= 0 ? h[bi * kh + 2] : 0.0) - (bj >= 0 ? h[bj * kh + 2] : 0.0);
    out[2] = out[3] = 0.0;
    if (M->jtype[j] != J_TRANSLATIONAL) return;
    ovk_slide s; /* drivers.c: the one slide formula */
    ovk_planar_slide(M, f, j, &s);
    out[2] = s.dd[0] * s.u[0] + s.dd[1] * s.u[1];
    out[3] = s.ddot[0] * s.u[0] + s.ddot[1] * s.u[1] + s.dd[0] * s.udot[0] + s.dd[1] * s.udot[1];
}

/* Joint j's sensors at y from their values at y0 (NULL: raw) into out[4]: angle (rad), rate (rad/s),
 * displacement (m), speed (m/s); the spatial angle is in (-pi, pi] (atan2 of the lock vectors). */
int ovk_sensors(const ovk_model *M, ovk_data *d, const double *y, const double *y0, int j, double *out) {
    if (!d) return OVK_NOMEM;
    if (d->status) return d->status;
    if (j < 0 || j >= M->nj) return ovk_fail(d, OVK_INVALID, "sensors: joint %d of %d", j, M->nj);
    int n = M->nb * M->nq_b;
    double ref[4] = {0.0, 0.0, 0.0, 0.0};
    for (int pass = y0 ? 0 : 1; pass < 2; pass++) { /* y0 NULL: the raw values (drivers' references) */
        const double *x = pass ? y : y0;
        double *o = pass ? out : ref;
        ovk_frames_build(M, x, x + n, &d->f);
        if (M->dim == 2) planar_sensor(M, &d->f, x, x + n, j, o);
        else axis_sensor(M, &d->f, j, o);
    }
    if (M->dim == 2) out[0] -= ref[0];
    out[2] -= ref[2];
    return OVK_OK;
}
