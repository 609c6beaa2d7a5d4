/* Stage: the reported reactions and friction forces at y and the multipliers lam (m)
 * (the outputs' reactions and friction forces): per joint j, reac[OVK_NREAC j ...] =
 * -A_i fi in its auxiliary frame (planar Fx, Fy, T; spherical Fx, Fy, Fz; distance its tension; point on line its normal force
 * along each of its rows' normals; the axis joints their
 * type's components of [Fx, Fy, Fz, Tx, Ty, Tz] in the joint frame), then -fi[:dim] in the global
 * frame, fi = (J_X)_i^T lam_X, zeros after; fric[j] = the friction output of a joint with friction
 * (else 0). */
#include "core.h"
#include "small.h"

/* The components in the auxiliary frame of joint j (their count) from fi; blkI its (J_X)_i. */
static int auxiliary(const ovk_model *M, const ovk_frames *f, int j, const double *blkI, const double *fi,
                     double *out) {
    int bi = ovk_slot(M, M->jbi[j]);
    if (M->jtype[j] == J_DISTANCE) { /* the tension: fi's force part is lam u, blkI's first dim entries u */
        double t = 0.0;
        for (int k = 0; k < M->dim; k++) t += fi[k] * blkI[k];
        out[0] = t;
        return 1;
    }
    if (M->jtype[j] == J_POINT_LINE) { /* the force on body i, -fi, along each row's unit normal (its force part) */
        int ne = M->jneq[j], kh = M->nh_b;
        for (int e = 0; e < ne; e++) {
            double t = 0.0;
            for (int k = 0; k < M->dim; k++) t += fi[k] * blkI[e * kh + k];
            out[e] = -t;
        }
        return ne;
    }
    if (M->jtype[j] == J_SPHERICAL) {
        double t[3];
        mat3tvec(f->R + 9 * bi, fi, t);
        for (int k = 0; k < 3; k++) out[k] = -t[k];
        return 3;
    }
    if (M->jtype[j] >= J_SREVOLUTE) return ovk_axis_reaction(M, f, j, fi, out);
    ovk_fctx cx;
    ovk_planar_friction_setup(M, f, j, blkI, &cx); /* A_i (the friction constants unused without a law) */
    for (int a = 0; a < 3; a++) out[a] = -(cx.A[3 * a] * fi[0] + cx.A[3 * a + 1] * fi[1] + cx.A[3 * a + 2] * fi[2]);
    return 3;
}

void ovk_reported(const ovk_model *M, ovk_data *d, const double *y, const double *lam, double *reac, double *fric) {
    int kh = M->nh_b, n = M->nb * M->nq_b;
    const ovk_frames *f = &d->f;
    ovk_frames_build(M, y, y + n, &d->f);
    double blkI[6 * OVK_MAXEQ], blkJ[6 * OVK_MAXEQ], ph[OVK_MAXEQ], gm[OVK_MAXEQ], lj[OVK_MAXEQ], fi[6];
    for (int j = 0; j < M->nj; j++) {
        int ne = M->jneq[j];
        double *out = reac + OVK_NREAC * j;
        if (M->jtype[j] == J_DRIVER) { /* the effort: the motor's torque or force on body i, -lam (drivers.c) */
            for (int k = 0; k < OVK_NREAC; k++) out[k] = 0.0;
            out[0] = -lam[M->jrows[OVK_MAXEQ * j]];
            fric[j] = 0.0;
            continue;
        }
        ovk_joint_rows(M, f, j, ph, blkI, blkJ, gm);
        for (int e = 0; e < ne; e++) lj[e] = lam[M->jrows[OVK_MAXEQ * j + e]];
        for (int k = 0; k < kh; k++) {
            double s = 0.0;
            for (int e = 0; e < ne; e++) s += blkI[e * kh + k] * lj[e];
            fi[k] = s;
        }
        for (int k = 0; k < OVK_NREAC; k++) out[k] = 0.0;
        int nc = auxiliary(M, f, j, blkI, fi, out);
        for (int k = 0; k < M->dim; k++) out[nc + k] = -fi[k];
        fric[j] = 0.0;
        if (M->jlaw[j] == LAW_NONE) continue;
        ovk_fctx cx;
        ovk_joint_friction_setup(M, f, j, blkI, &cx);
        fric[j] = ovk_joint_friction_output(M, j, &cx, lj);
    }
}
