/* Stage: the reported reactions and friction forces at y and the multipliers lam (m)
 * (overcon.evaluation.physical_reactions and friction_output): per joint j, reac[6 j ...] = -A_i fi
 * in its auxiliary frame (3 components: planar Fx, Fy, T; spherical Fx, Fy, Fz), then -fi[:dim] in
 * the global frame, fi = (J_X)_i^T lam_X; fric[j] = the friction output of a joint with friction
 * (else 0). */
#include "core.h"
#include "small.h"

void ovk_reported(const ovk_model *M, ovk_data *d, const double *y, const double *lam, double *reac, double *fric) {
    int kh = M->nh_b, n = M->nb * M->nq_b;
    const ovk_frames *f = &d->f;
    ovk_frames_build(M, y, y + n, &d->f);
    double blkI[18], blkJ[18], ph[3], gm[3], lj[3], fi[6];
    for (int j = 0; j < M->nj; j++) {
        int ne = M->jneq[j], bi = ovk_slot(M, M->jbi[j]);
        double *out = reac + 6 * j;
        ovk_joint_rows(M, f, j, ph, blkI, blkJ, gm);
        for (int e = 0; e < ne; e++) lj[e] = lam[M->jrows[3 * j + e]];
        for (int k = 0; k < kh; k++) {
            double s = 0.0;
            for (int e = 0; e < ne; e++) s += blkI[e * kh + k] * lj[e];
            fi[k] = s;
        }
        for (int k = 0; k < 6; k++) out[k] = 0.0;
        ovk_fctx cx;
        if (M->jtype[j] == J_SPHERICAL) {
            double t[3];
            mat3tvec(f->R + 9 * bi, fi, t);
            for (int k = 0; k < 3; k++) { out[k] = -t[k]; out[3 + k] = -fi[k]; }
        } else {
            ovk_planar_friction_setup(M, f, j, blkI, &cx); /* A_i (the friction constants unused without a law) */
            for (int a = 0; a < 3; a++) out[a] = -(cx.A[3 * a] * fi[0] + cx.A[3 * a + 1] * fi[1] + cx.A[3 * a + 2] * fi[2]);
            out[3] = -fi[0];
            out[4] = -fi[1];
        }
        fric[j] = 0.0;
        if (M->jlaw[j] == LAW_NONE) continue;
        if (M->jtype[j] == J_SPHERICAL) ovk_spherical_friction_setup(M, f, j, &cx);
        fric[j] = ovk_joint_friction_output(M, j, &cx, lj);
    }
}
