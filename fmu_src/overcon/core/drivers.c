/* Stage: drivers (scene [[drivers]]; overcon.model's driver joints): one rheonomic equation per
 * driver, a joint's relative coordinate prescribed as a function of time,
 *     Phi = theta(q) - f(t),  Phi_h h = theta',  Phi_h h' = gamma = f''(t) - (Phi_h)' h,
 *     Phi_t = -f'(t) (Baumgarte's Phi' = Phi_h h + Phi_t, kkt.c),
 * its multiplier lam giving the effort -lam (the torque or force the motor exerts on body i of the
 * driven joint, about or along its axis; reported by outputs.c).
 * theta (from q0, as the sensors of inputs.c): a revolute's (planar, spatial) or cylindrical joint's
 * rotation of body i relative to body j about the axis (spatial: atan2 of the lock vectors, zero at
 * q0; Phi wrapped into (-pi, pi] so that turns never jump), or a translational, prismatic or
 * cylindrical joint's displacement along the axis.
 * Constants (jconst of the driver, packed by overcon.kernel): [0] driven joint, [1] coordinate
 * (0 rotation, 1 displacement), [2] motion (1 constant_speed, 2 ramp, 3 harmonic), [3:8] its
 * parameters (constant_speed: speed, start time; ramp: from, to, t0, t1; harmonic: amplitude,
 * frequency (Hz), phase, offset), [8] theta's raw value at q0 (planar rotations, displacements). */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

#define PI 3.14159265358979323846

/* f(t), f'(t), f''(t) of driver constants c into out[3]. The ramp is the quintic of smooth
 * start and stop (zero velocity and acceleration at t0 and t1): from + (to - from) s^3 (10 - 15 s +
 * 6 s^2), s = (t - t0) / (t1 - t0), held outside [t0, t1]. */
void ovk_driver_motion(const double *c, double t, double *out) {
    const double *p = c + 3;
    out[0] = out[1] = out[2] = 0.0;
    if (c[2] == 1.0) {
        out[0] = p[0] * (t - p[1]);
        out[1] = p[0];
    } else if (c[2] == 2.0) {
        double span = p[3] - p[2], s = (t - p[2]) / span, dv = p[1] - p[0];
        if (s <= 0.0) out[0] = p[0];
        else if (s >= 1.0) out[0] = p[1];
        else {
            double s2 = s * s, s3 = s2 * s;
            out[0] = p[0] + dv * s3 * (10.0 - 15.0 * s + 6.0 * s2);
            out[1] = dv * 30.0 * s2 * (1.0 - 2.0 * s + s2) / span;
            out[2] = dv * 60.0 * s * (1.0 - 3.0 * s + 2.0 * s2) / (span * span);
        }
    } else if (c[2] == 3.0) {
        double w = 2.0 * PI * p[1], x = w * t + p[2];
        out[0] = p[3] + p[0] * sin(x);
        out[1] = p[0] * w * cos(x);
        out[2] = -p[0] * w * w * sin(x);
    }
}

void ovk_planar_slide(const ovk_model *M, const ovk_frames *f, int j, ovk_slide *s) {
    int si = ovk_slot(M, M->jbi[j]), sj = ovk_slot(M, M->jbj[j]);
    const double *c = M->jconst + NJC * j, *sA = c, *sB = c + 2, *v = c + 4;
    double nv = sqrt(v[0] * v[0] + v[1] * v[1]), g[2] = {v[1] / nv, -v[0] / nv}; /* OMEGA^T v / |v| */
    mat2vec(f->R + 4 * si, sA, s->ai);
    mat2vec(f->R + 4 * sj, sB, s->bv);
    mat2vec(f->R + 4 * sj, g, s->u);
    s->wi = f->w[si], s->wj = f->w[sj];
    for (int e = 0; e < 2; e++) s->dd[e] = f->r[2 * si + e] + s->ai[e] - f->r[2 * sj + e] - s->bv[e];
    s->ddot[0] = f->v[2 * si] - s->wi * s->ai[1] - f->v[2 * sj] + s->wj * s->bv[1];
    s->ddot[1] = f->v[2 * si + 1] + s->wi * s->ai[0] - f->v[2 * sj + 1] - s->wj * s->bv[0];
    s->udot[0] = -s->wj * s->u[1], s->udot[1] = s->wj * s->u[0];
}

/* The driven coordinate's raw value and its equation's Jacobian blocks (body i, body j: nh_b
 * each) and velocity remainder (Phi_h)' h at the frames f. */
static double coordinate(const ovk_model *M, const ovk_frames *f, int j, const double *c, double *Ji, double *Jj,
                         double *rem) {
    int jd = (int)c[0], kh = M->nh_b, rot = c[1] == 0.0;
    int si = ovk_slot(M, M->jbi[jd]), sj = ovk_slot(M, M->jbj[jd]);
    const double *k = M->jconst + NJC * jd;
    (void)j;
    memset(Ji, 0, sizeof(double) * kh);
    memset(Jj, 0, sizeof(double) * kh);
    if (M->dim == 2) {
        if (rot) { /* the angle itself: ovk_driver_rows */
            Ji[2] = 1.0, Jj[2] = -1.0;
            *rem = 0.0;
            return 0.0;
        }
        ovk_slide sl;
        ovk_planar_slide(M, f, jd, &sl);
        const double *ai = sl.ai, *bv = sl.bv, *u = sl.u, *dd = sl.dd, *ddot = sl.ddot, *udot = sl.udot;
        double wi = sl.wi, wj = sl.wj;
        Ji[0] = u[0], Ji[1] = u[1], Ji[2] = -ai[1] * u[0] + ai[0] * u[1];
        Jj[0] = -u[0], Jj[1] = -u[1];
        Jj[2] = (bv[1] * u[0] - bv[0] * u[1]) + (-dd[0] * u[1] + dd[1] * u[0]);
        double wi2 = wi * wi, wj2 = wj * wj;
        *rem = (-wi2 * ai[0] + wj2 * bv[0]) * u[0] + (-wi2 * ai[1] + wj2 * bv[1]) * u[1] +
               2.0 * (ddot[0] * udot[0] + ddot[1] * udot[1]) - wj2 * (dd[0] * u[0] + dd[1] * u[1]);
        return dd[0] * u[0] + dd[1] * u[1];
    }
    const double *Ri = f->R + 9 * si, *Rj = f->R + 9 * sj;
    double wig[3], wjg[3];
    mat3vec(Ri, f->w + 3 * si, wig);
    mat3vec(Rj, f->w + 3 * sj, wjg);
    if (rot) {
        double a[3], aj[3], ci[3], b1[3], b2[3], t[3];
        mat3vec(Ri, k + 6, a);
        mat3tvec(Rj, a, aj);
        for (int e = 0; e < 3; e++) Ji[3 + e] = k[6 + e], Jj[3 + e] = -aj[e];
        cross3(wig, a, t);
        *rem = -dot3(wjg, t); /* (Phi_h)' h = -w_j . (w_i x a) */
        mat3vec(Ri, k + 18, ci);
        mat3vec(Rj, k + 12, b1);
        mat3vec(Rj, k + 15, b2);
        return atan2(dot3(ci, b2), dot3(ci, b1));
    }
    double si_g[3], sj_g[3], u[3], dd[3], ddot[3], udot[3], t[3], x[3];
    mat3vec(Ri, k, si_g);
    mat3vec(Rj, k + 3, sj_g);
    mat3vec(Rj, k + 9, u);
    for (int e = 0; e < 3; e++) dd[e] = f->r[3 * si + e] + si_g[e] - f->r[3 * sj + e] - sj_g[e];
    double ui[3], uj[3];
    cross3(si_g, u, t); /* w_i . (s_i x u) */
    mat3tvec(Ri, t, ui);
    cross3(u, dd, x);   /* w_j . (u x dd - s_j x u) */
    cross3(sj_g, u, t);
    for (int e = 0; e < 3; e++) x[e] -= t[e];
    mat3tvec(Rj, x, uj);
    for (int e = 0; e < 3; e++) {
        Ji[e] = u[e], Ji[3 + e] = ui[e];
        Jj[e] = -u[e], Jj[3 + e] = uj[e];
    }
    double wsi[3], wsj[3], wwi[3], wwj[3], wwu[3];
    cross3(wig, si_g, wsi);
    cross3(wjg, sj_g, wsj);
    cross3(wig, wsi, wwi);
    cross3(wjg, wsj, wwj);
    cross3(wjg, u, udot);
    cross3(wjg, udot, wwu);
    for (int e = 0; e < 3; e++) ddot[e] = f->v[3 * si + e] + wsi[e] - f->v[3 * sj + e] - wsj[e];
    *rem = (dot3(wwi, u) - dot3(wwj, u)) + 2.0 * dot3(ddot, udot) + dot3(dd, wwu);
    return dot3(dd, u);
}

void ovk_driver_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                     double *gam) {
    const double *c = M->jconst + NJC * j;
    int jd = (int)c[0];
    double rem = 0.0, fm[3];
    double theta = coordinate(M, f, j, c, Ji, Jj, &rem);
    if (M->dim == 2 && c[1] == 0.0) { /* planar rotation: phi_i - phi_j of the coordinates (frames hold R) */
        int si = ovk_slot(M, M->jbi[jd]), sj = ovk_slot(M, M->jbj[jd]);
        double pi = atan2(f->R[4 * si + 2], f->R[4 * si]), pj = atan2(f->R[4 * sj + 2], f->R[4 * sj]);
        theta = pi - pj;
    }
    ovk_driver_motion(c, f->t, fm);
    double err = theta - (c[1] == 0.0 && M->dim == 3 ? 0.0 : c[8]) - fm[0];
    if (c[1] == 0.0) err = remainder(err, 2.0 * PI); /* a rotation: turns never jump */
    phi[0] = err;
    gam[0] = fm[2] - rem;
}

double ovk_driver_phit(const ovk_model *M, int j, double t) {
    double fm[3];
    ovk_driver_motion(M->jconst + NJC * j, t, fm);
    return -fm[1];
}

int ovk_set_time(ovk_data *d, double t) {
    if (!d) return OVK_NOMEM;
    if (d->status) return d->status;
    if (!isfinite(t)) return ovk_fail(d, OVK_INVALID, "set time: %g is not finite", t);
    d->f.t = t;
    return OVK_OK;
}

int ovk_phi_t(const ovk_model *M, const ovk_data *d, double *out) {
    if (!d) return OVK_NOMEM;
    if (d->status) return d->status;
    memcpy(out, d->phit, (size_t)M->m * sizeof(double));
    return OVK_OK;
}
