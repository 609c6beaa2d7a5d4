/* Stage: planar joints (overcon.joints.revolute, .translational, .point_on_line): the rows Phi,
 * Phi_h (the blocks of body i and body j) and gamma, the paper's reaction/friction transformation (A_i, the
 * auxiliary frame) and the friction forces with their Jacobian in the multipliers. */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

/* Revolute: s_i (c[0:2]) on body i meets s_j (c[2:4]) on body j. Ji, Jj are (2, 3) row-major. */
void ovk_revolute_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                       double *gam) {
    const double *c = M->jconst + NJC * j;
    int bi = ovk_slot(M, M->jbi[j]), bj = ovk_slot(M, M->jbj[j]);
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
}

/* One row (P_A - P_B)·(R_j v), P_A = r_i + R_i s_A on body i, P_B = r_j + R_j s_B on body j, v fixed
 * in body j: value, the blocks Ji, Jj (3 entries each: x, y, phi) and gamma. The translational
 * joint's first row and the point-on-line joint's row (s_A = s_i, s_B = s_j, v = n_j). */
static void pointdot_row(const ovk_frames *f, int bi, int bj, const double *sA, const double *sB, const double *v,
                         double *phi, double *Ji, double *Jj, double *gam) {
    const double *Ri = f->R + 4 * bi, *Rj = f->R + 4 * bj;
    const double *ri = f->r + 2 * bi, *rj = f->r + 2 * bj;
    double ai[2], bjv[2], dd[2], u[2];
    mat2vec(Ri, sA, ai);
    mat2vec(Rj, sB, bjv);
    for (int k = 0; k < 2; k++) dd[k] = ri[k] + ai[k] - rj[k] - bjv[k];
    mat2vec(Rj, v, u);
    phi[0] = dd[0] * u[0] + dd[1] * u[1];
    double oai[2] = {-ai[1], ai[0]}, obj[2] = {-bjv[1], bjv[0]}, ou[2] = {-u[1], u[0]};
    Ji[0] = u[0]; Ji[1] = u[1];
    Ji[2] = oai[0] * u[0] + oai[1] * u[1];
    Jj[0] = -u[0]; Jj[1] = -u[1];
    Jj[2] = (-obj[0] * u[0] + -obj[1] * u[1]) + (dd[0] * ou[0] + dd[1] * ou[1]);
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
    *gam = -quad;
}

/* Translational: s_A (c[0:2]) on body i, s_B (c[2:4]) and the guide v (c[4:6]) on body j, psi
 * (c[6]). phi[1] (phi_i - phi_j - psi) is filled by the assembly (joints.c) from q. */
void ovk_translational_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                            double *gam) {
    const double *c = M->jconst + NJC * j;
    int bi = ovk_slot(M, M->jbi[j]), bj = ovk_slot(M, M->jbj[j]);
    memset(Ji, 0, 6 * sizeof(double));
    memset(Jj, 0, 6 * sizeof(double));
    pointdot_row(f, bi, bj, c, c + 2, c + 4, phi, Ji, Jj, gam);
    phi[1] = 0.0;
    Ji[5] = 1.0;
    Jj[5] = -1.0;
    gam[1] = 0.0;
}

/* Point on line (overcon.joints.point_on_line): s_i (c[0:2]) on body i stays on the line of body j
 * through s_j (c[2:4]) along the unit a_j (c[6:8]): one row d·(R_j n_j), n_j (c[4:6]) = OMEGA a_j. */
void ovk_line_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                   double *gam) {
    const double *c = M->jconst + NJC * j;
    pointdot_row(f, ovk_slot(M, M->jbi[j]), ovk_slot(M, M->jbj[j]), c, c + 2, c + 4, phi, Ji, Jj, gam);
}

/* The slide of a planar contact at the point P = r_i + a_i (a_i = R_i s, global) along cx->e:
 * the arms P - r_i, P - r_j into cx, and the velocity along e of body j's material point at P
 * relative to body i's (m/s). */
static double slide_at(const ovk_frames *f, int bi, int bj, const double *ai, ovk_fctx *cx) {
    const double *ri = f->r + 2 * bi, *rj = f->r + 2 * bj;
    double point[2] = {ri[0] + ai[0], ri[1] + ai[1]};
    double pj[2] = {point[0] - rj[0], point[1] - rj[1]}, pi[2] = {point[0] - ri[0], point[1] - ri[1]};
    double wj = f->w[bj], wi = f->w[bi];
    double velj[2] = {f->v[2 * bj] + -pj[1] * wj, f->v[2 * bj + 1] + pj[0] * wj};
    double veli[2] = {f->v[2 * bi] + -pi[1] * wi, f->v[2 * bi + 1] + pi[0] * wi};
    double speed = (velj[0] - veli[0]) * cx->e[0] + (velj[1] - veli[1]) * cx->e[1];
    cx->arm_i[0] = pi[0]; cx->arm_i[1] = pi[1];
    cx->arm_j[0] = pj[0]; cx->arm_j[1] = pj[1];
    return speed;
}

/* A force F e at the contact point on body i (cx's arm_i) and -F e on body j (arm_j): Qi, Qj (3
 * each: the force and its moment about the body's origin). */
static void contact_loads(const ovk_fctx *cx, double F, double *Qi, double *Qj) {
    double Fx = F * cx->e[0], Fy = F * cx->e[1];
    Qi[0] = Fx; Qi[1] = Fy; Qi[2] = cx->arm_i[0] * Fy - cx->arm_i[1] * Fx;
    Qj[0] = -Fx; Qj[1] = -Fy; Qj[2] = -(cx->arm_j[0] * Fy - cx->arm_j[1] * Fx);
}

/* The per-evaluation constants of a planar joint: JiT = (J_X)_i^T (3 x 2), A_i (3 x 3: the
 * reaction in the auxiliary frame), and for a joint with friction its law's coefficient at the
 * joint's relative speed (revolute: size * mu(omega); translational: mu(v), the guide e, the arms). */
void ovk_planar_friction_setup(const ovk_model *M, const ovk_frames *f, int j, const double *Ji, ovk_fctx *cx) {
    const double *c = M->jconst + NJC * j, *lp = M->jlawp + NLP * j;
    int law = M->jlaw[j], bi = ovk_slot(M, M->jbi[j]), bj = ovk_slot(M, M->jbj[j]);
    const double *Ri = f->R + 4 * bi;
    for (int a = 0; a < 3; a++)
        for (int e = 0; e < 2; e++) cx->JiT[2 * a + e] = Ji[3 * e + a];
    double ai[2];
    memset(cx->A, 0, sizeof cx->A);
    if (M->jtype[j] == J_REVOLUTE) {
        mat2vec(Ri, c, ai);
        cx->A[0] = Ri[0]; cx->A[1] = Ri[2]; cx->A[3] = Ri[1]; cx->A[4] = Ri[3];
        cx->coef = law == LAW_NONE ? 0.0 : lp[2] * ovk_law_coefficient(lp, law, f->w[bj] - f->w[bi]);
    } else {
        const double *B = c + 7; /* 2 x 2 row-major, column 0 = guide in body i axes */
        mat2vec(Ri, c, ai);
        /* A[:2,:2] = B^T R_i^T */
        for (int a = 0; a < 2; a++)
            for (int b = 0; b < 2; b++) cx->A[3 * a + b] = B[a] * Ri[2 * b] + B[2 + a] * Ri[2 * b + 1];
        double bcol[2] = {B[0], B[2]};
        mat2vec(Ri, bcol, cx->e);
        double speed = slide_at(f, bi, bj, ai, cx);
        cx->coef = law == LAW_NONE ? 0.0 : ovk_law_coefficient(lp, law, speed);
    }
    cx->A[6] = ai[1]; cx->A[7] = -ai[0]; cx->A[8] = 1.0; /* -OMEGA a_i */
}

/* p' = A_i (J_X)_i^T lam: the reaction in the auxiliary frame */
void ovk_planar_paux(const ovk_fctx *cx, const double *lam, double *p) {
    double fi[3];
    for (int a = 0; a < 3; a++) fi[a] = cx->JiT[2 * a] * lam[0] + cx->JiT[2 * a + 1] * lam[1];
    for (int a = 0; a < 3; a++) p[a] = cx->A[3 * a] * fi[0] + cx->A[3 * a + 1] * fi[1] + cx->A[3 * a + 2] * fi[2];
}

/* Friction forces of planar joint j: Qi, Qj (3 each) at its multipliers lam (2). */
void ovk_planar_friction_forces(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *Qi,
                                double *Qj) {
    const double *lp = M->jlawp + NLP * j;
    double p[3];
    ovk_planar_paux(cx, lam, p);
    if (M->jtype[j] == J_REVOLUTE) {
        double torque = cx->coef * hypot(p[0], p[1]);
        Qi[0] = Qi[1] = Qj[0] = Qj[1] = 0.0;
        Qi[2] = torque;
        Qj[2] = -torque;
    } else {
        double l = lp[2], N = p[1], T = p[2];
        contact_loads(cx, cx->coef * (fabs(N - T / l) + fabs(T / l)), Qi, Qj);
    }
}

/* d(Qi, Qj)/d lam of planar joint j: dQi, dQj (3 x 2, row-major). */
void ovk_planar_friction_jac(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *dQi,
                             double *dQj) {
    const double *lp = M->jlawp + NLP * j;
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
}

/* The reported friction output of planar joint j at its multipliers lam (2): the friction torque
 * (revolute) or force (translational) magnitude (the point-on-line joint's: ovk_line_friction_output). */
double ovk_planar_friction_output(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam) {
    const double *lp = M->jlawp + NLP * j;
    double pa[3];
    ovk_planar_paux(cx, lam, pa);
    if (M->jtype[j] == J_REVOLUTE) return cx->coef * hypot(pa[0], pa[1]);
    double l = lp[2];
    return cx->coef * (fabs(pa[1] - pa[2] / l) + fabs(pa[2] / l));
}

/* Point-on-line friction (overcon.joints.point_on_line): the contact at P_i, the line's direction
 * e = R_j a_j, the law's coefficient mu(v) at the slide v of body j's point at P_i relative to P_i
 * along e. */
void ovk_line_friction_setup(const ovk_model *M, const ovk_frames *f, int j, ovk_fctx *cx) {
    const double *c = M->jconst + NJC * j, *lp = M->jlawp + NLP * j;
    int bi = ovk_slot(M, M->jbi[j]), bj = ovk_slot(M, M->jbj[j]);
    double ai[2];
    mat2vec(f->R + 4 * bi, c, ai);
    mat2vec(f->R + 4 * bj, c + 6, cx->e);
    double speed = slide_at(f, bi, bj, ai, cx);
    cx->coef = M->jlaw[j] == LAW_NONE ? 0.0 : ovk_law_coefficient(lp, M->jlaw[j], speed);
}

/* The friction force mu(v) |lam| e at P_i on body i (|lam| the normal force: the row's normal is a
 * unit vector), the opposite on body j: Qi, Qj (3 each). */
void ovk_line_friction_forces(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *Qi,
                              double *Qj) {
    (void)M, (void)j;
    contact_loads(cx, cx->coef * fabs(lam[0]), Qi, Qj);
}

/* d(Qi, Qj)/d lam (3 x 1 each): the forces are mu(v) |lam| times fixed loads (v does not depend on
 * lam), so the derivative is the loads of the force mu(v) sgn(lam) (0 at lam = 0). */
void ovk_line_friction_jac(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *dQi,
                           double *dQj) {
    (void)M, (void)j;
    contact_loads(cx, cx->coef * sgn(lam[0]), dQi, dQj);
}

/* The friction output: the force on body i along +e (N, signed). */
double ovk_line_friction_output(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam) {
    (void)M, (void)j;
    return cx->coef * fabs(lam[0]);
}
