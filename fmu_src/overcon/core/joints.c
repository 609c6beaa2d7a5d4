/* Stage: the joint table. Dispatch by joint type (and dimension: the point-on-line joint) to
 * joints_planar.c, joints_spherical.c, joints_distance.c and joints_spatial.c, and the
 * assembly of every joint's rows into Phi (m), Phi_h (m x nh) and gamma (m). */
#include <string.h>

#include "core.h"

/* Phi, Jacobian blocks and gamma of joint j; Ji, Jj are (neq, nh_b) row-major. */
void ovk_joint_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                    double *gam) {
    switch (M->jtype[j]) {
    case J_REVOLUTE: ovk_revolute_rows(M, f, j, phi, Ji, Jj, gam); break;
    case J_TRANSLATIONAL: ovk_translational_rows(M, f, j, phi, Ji, Jj, gam); break;
    case J_SPHERICAL: ovk_spherical_rows(M, f, j, phi, Ji, Jj, gam); break;
    case J_DRIVER: ovk_driver_rows(M, f, j, phi, Ji, Jj, gam); break;
    case J_DISTANCE: ovk_distance_rows(M, f, j, phi, Ji, Jj, gam); break;
    case J_POINT_LINE:
        if (M->dim == 2) ovk_line_rows(M, f, j, phi, Ji, Jj, gam);
        else ovk_axis_rows(M, f, j, phi, Ji, Jj, gam);
        break;
    default: ovk_axis_rows(M, f, j, phi, Ji, Jj, gam); break;
    }
}

/* Zeros in joint j's rows of Phi_h (both slots of each, OVK_JROW). */
static void clear_blocks(const ovk_model *M, double *J, int j) {
    for (int e = 0; e < M->jneq[j]; e++)
        memset(OVK_JROW(M, J, M->jrows[OVK_MAXEQ * j + e]), 0, sizeof(double) * 2 * (size_t)M->nh_b);
}

void ovk_row_dense(const ovk_model *M, const double *Jb, int row, int bi, int bj, double *out) {
    int kh = M->nh_b, nh = M->nb * kh;
    const double *r = OVK_JROW(M, Jb, row);
    memset(out, 0, sizeof(double) * (size_t)nh);
    if (bi >= 0)
        for (int k = 0; k < kh; k++) out[bi * kh + k] = r[k];
    if (bj >= 0 && bj != bi)
        for (int k = 0; k < kh; k++) out[bj * kh + k] = r[kh + k];
}

/* d->phi, d->J (Phi_h), d->gam from the frames in d->f, and every joint's (J_X)_i block in
 * d->Jblk (the friction setup needs it). Each row of Phi_h is nonzero on its joint's two bodies'
 * columns only, and only these are stored (d->J, OVK_JROW: slot 0 body i's, slot 1 body j's; a
 * joint of a body with itself adds both into slot 0): cleared, all of them before any is filled,
 * so the cost and the memory are the nonzeros', not m x nh. */
void ovk_constraint_rows(const ovk_model *M, ovk_data *d, const double *q) {
    int kh = M->nh_b;
    double *J = d->J;
    for (int j = 0; j < M->nj; j++) clear_blocks(M, J, j);
    double blkJ[6 * OVK_MAXEQ], ph[OVK_MAXEQ], gm[OVK_MAXEQ];
    for (int j = 0; j < M->nj; j++) {
        int ne = M->jneq[j];
        double *blkI = d->Jblk + 6 * OVK_MAXEQ * j;
        ovk_joint_rows(M, &d->f, j, ph, blkI, blkJ, gm);
        if (M->jtype[j] == J_TRANSLATIONAL) {
            double pi = M->jbi[j] >= 0 ? q[M->jbi[j] * M->nq_b + 2] : 0.0;
            double pj = M->jbj[j] >= 0 ? q[M->jbj[j] * M->nq_b + 2] : 0.0;
            ph[1] = pi - pj - M->jconst[NJC * j + 6];
        }
        if (M->jtype[j] == J_DRIVER) d->phit[M->jrows[OVK_MAXEQ * j]] = ovk_driver_phit(M, j, d->f.t);
        int same = M->jbj[j] == M->jbi[j];
        for (int e = 0; e < ne; e++) {
            int row = M->jrows[OVK_MAXEQ * j + e];
            double *Jr = OVK_JROW(M, J, row);
            d->phi[row] = ph[e];
            d->gam[row] = gm[e];
            if (M->jbi[j] >= 0)
                for (int k = 0; k < kh; k++) Jr[k] += blkI[e * kh + k];
            if (M->jbj[j] >= 0)
                for (int k = 0; k < kh; k++) Jr[(same ? 0 : kh) + k] += blkJ[e * kh + k];
        }
    }
}

/* The friction of joint j (a distance joint has none: check_model in api.c refuses a law on one,
 * so these are never called for it). The planar point-on-line joint's is joints_planar.c's
 * ovk_line_*, the spatial one's the axis joints'. */
static int planar_line(const ovk_model *M, int j) { return M->jtype[j] == J_POINT_LINE && M->dim == 2; }

void ovk_joint_friction_setup(const ovk_model *M, const ovk_frames *f, int j, const double *Ji, ovk_fctx *cx) {
    if (planar_line(M, j)) ovk_line_friction_setup(M, f, j, cx);
    else if (M->jtype[j] == J_SPHERICAL) ovk_spherical_friction_setup(M, f, j, cx);
    else if (M->jtype[j] >= J_SREVOLUTE) ovk_axis_friction_setup(M, f, j, Ji, cx);
    else ovk_planar_friction_setup(M, f, j, Ji, cx);
}

void ovk_joint_friction_forces(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *Qi,
                               double *Qj) {
    if (planar_line(M, j)) ovk_line_friction_forces(M, j, cx, lam, Qi, Qj);
    else if (M->jtype[j] == J_SPHERICAL) ovk_spherical_friction_forces(M, j, cx, lam, Qi, Qj);
    else if (M->jtype[j] >= J_SREVOLUTE) ovk_axis_friction_forces(M, j, cx, lam, Qi, Qj);
    else ovk_planar_friction_forces(M, j, cx, lam, Qi, Qj);
}

void ovk_joint_friction_jac(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *dQi,
                            double *dQj) {
    if (planar_line(M, j)) ovk_line_friction_jac(M, j, cx, lam, dQi, dQj);
    else if (M->jtype[j] == J_SPHERICAL) ovk_spherical_friction_jac(M, j, cx, lam, dQi, dQj);
    else if (M->jtype[j] >= J_SREVOLUTE) ovk_axis_friction_jac(M, j, cx, lam, dQi, dQj);
    else ovk_planar_friction_jac(M, j, cx, lam, dQi, dQj);
}

double ovk_joint_friction_output(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam) {
    if (planar_line(M, j)) return ovk_line_friction_output(M, j, cx, lam);
    if (M->jtype[j] == J_SPHERICAL) return ovk_spherical_friction_output(M, j, cx, lam);
    if (M->jtype[j] >= J_SREVOLUTE) return ovk_axis_friction_output(M, j, cx, lam);
    return ovk_planar_friction_output(M, j, cx, lam);
}
