/* Stage: coordinate rates q' from the velocities h: planar
 * q' = h; spatial positions' rates are the velocities, the z-x-z Euler angles' rates are
 * H(beta, gamma) w (kinematics.euler_H_rows), singular where sin beta = 0, and a quaternion's
 * e' = 1/2 e (x) (0, w) + QUAT_NORM_RATE / 2 (1 - |e|^2) e (kinematics.quat_rates_rows). */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

/* q' of quaternion bodies (nq_b 7): r' = v and e' (never singular). */
static void quat_rates(const ovk_model *M, const double *q, const double *h, double *qdot) {
    for (int b = 0; b < M->nb; b++) {
        const double *e = q + 7 * b + 3, *w = h + 6 * b + 3;
        double *ed = qdot + 7 * b + 3, c[3];
        for (int i = 0; i < 3; i++) qdot[7 * b + i] = h[6 * b + i];
        cross3(e + 1, w, c);
        ed[0] = -0.5 * (e[1] * w[0] + e[2] * w[1] + e[3] * w[2]);
        for (int i = 0; i < 3; i++) ed[1 + i] = 0.5 * (e[0] * w[i] + c[i]);
        double k = 0.5 * QUAT_NORM_RATE * (1.0 - (e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3]));
        for (int i = 0; i < 4; i++) ed[i] += k * e[i];
    }
}

/* OVK_EULER when |sin beta| < SIN_BETA_MIN for a body (the frames in d->f give sin/cos). */
int ovk_rates(const ovk_model *M, ovk_data *d, const double *q, const double *h, double *qdot) {
    int nb = M->nb, kh = M->nh_b;
    if (M->dim == 2) {
        memcpy(qdot, h, sizeof(double) * nb * kh);
        return OVK_OK;
    }
    if (M->nq_b == 7) {
        quat_rates(M, q, h, qdot);
        return OVK_OK;
    }
    const ovk_frames *f = &d->f;
    for (int b = 0; b < nb; b++) {
        double sb = f->sb[b], cb = f->cb[b], sg = f->sg[b], cg = f->cg[b];
        if (fabs(sb) < SIN_BETA_MIN)
            return ovk_fail(d, OVK_EULER, "Euler angles singular: body %d has |sin beta| = %g < %g", b, fabs(sb),
                            SIN_BETA_MIN);
        const double *w = h + b * kh + 3;
        double H[9] = {sg / sb, cg / sb, 0.0, cg, -sg, 0.0, -cb * sg / sb, -cb * cg / sb, 1.0};
        for (int i = 0; i < 3; i++) qdot[b * 6 + i] = h[b * kh + i];
        mat3vec(H, w, qdot + b * 6 + 3);
    }
    return OVK_OK;
}
