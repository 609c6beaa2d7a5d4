/* Stage: coordinate rates q' from the velocities h (overcon.evaluation.coordinate_rates): planar
 * q' = h; spatial positions' rates are the velocities and the z-x-z Euler angles' rates are
 * H(beta, gamma) w (kinematics.euler_H_rows), singular where sin beta = 0. */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

/* OVK_EULER when |sin beta| < SIN_BETA_MIN for a body (the frames in d->f give sin/cos). */
int ovk_rates(const ovk_model *M, ovk_data *d, const double *h, double *qdot) {
    int nb = M->nb, kh = M->nh_b;
    if (M->dim == 2) {
        memcpy(qdot, h, sizeof(double) * nb * kh);
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
