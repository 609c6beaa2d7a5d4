/* Stage: frames. Positions r, rotations R, velocities v and angular velocities w of every body from
 * q and h: planar (x, y, phi), spatial z-x-z Euler angles (nq_b 6) or
 * quaternions (nq_b 7, R of e / |e|: kinematics.quat_R_rows); slot nb is the base (at rest at the
 * origin). Euler bodies also keep sin/cos of beta and gamma (rates.c). */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

int ovk_slot(const ovk_model *M, int b) { return b < 0 ? M->nb : b; }

/* R of every quaternion body from e / |e| (the base: the identity), as kinematics.quat_R_rows. */
static void quat_frames(const ovk_model *M, const double *q, ovk_frames *f) {
    int nb = M->nb;
    for (int b = 0; b < nb; b++) {
        const double *e = q + 7 * b + 3;
        double n = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3]);
        double e0 = e[0] / n, e1 = e[1] / n, e2 = e[2] / n, e3 = e[3] / n;
        double *R = f->R + 9 * b;
        R[0] = e0 * e0 + e1 * e1 - e2 * e2 - e3 * e3;
        R[1] = 2.0 * (e1 * e2 - e0 * e3);
        R[2] = 2.0 * (e1 * e3 + e0 * e2);
        R[3] = 2.0 * (e1 * e2 + e0 * e3);
        R[4] = e0 * e0 - e1 * e1 + e2 * e2 - e3 * e3;
        R[5] = 2.0 * (e2 * e3 - e0 * e1);
        R[6] = 2.0 * (e1 * e3 - e0 * e2);
        R[7] = 2.0 * (e2 * e3 + e0 * e1);
        R[8] = e0 * e0 - e1 * e1 - e2 * e2 + e3 * e3;
    }
    double *R = f->R + 9 * nb;
    for (int k = 0; k < 9; k++) R[k] = k % 4 == 0 ? 1.0 : 0.0;
}

void ovk_frames_build(const ovk_model *M, const double *q, const double *h, ovk_frames *f) {
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
    if (kq == 7) {
        quat_frames(M, q, f);
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
