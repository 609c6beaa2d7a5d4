/* Stage: spatial spherical joints (overcon.joints.spherical, z-x-z Euler angles): the rows Phi,
 * Phi_h and gamma, the friction setup (the relative angular velocity in body i's axes), the
 * friction forces at the contact point s_C = -size F'/|F'| and their Jacobian in the multipliers. */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

/* s_i (c[0:3]) on body i meets s_j (c[3:6]) on body j. Ji, Jj are (3, 6) row-major. */
void ovk_spherical_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                        double *gam) {
    const double *c = M->jconst + NJC * j;
    int bi = ovk_slot(M, M->jbi[j]), bj = ovk_slot(M, M->jbj[j]);
    const double *si = c, *sj = c + 3;
    const double *Ri = f->R + 9 * bi, *Rj = f->R + 9 * bj;
    const double *ri = f->r + 3 * bi, *rj = f->r + 3 * bj;
    double ai[3], aj[3];
    mat3vec(Ri, si, ai);
    mat3vec(Rj, sj, aj);
    for (int k = 0; k < 3; k++) phi[k] = ri[k] + ai[k] - rj[k] - aj[k];
    double Si[9], Sj[9], nRi[9], Ai[9], Aj[9];
    skew3(si, Si);
    skew3(sj, Sj);
    for (int k = 0; k < 9; k++) nRi[k] = -Ri[k];
    mat3mul(nRi, Si, Ai);
    mat3mul(Rj, Sj, Aj);
    for (int r = 0; r < 3; r++) {
        for (int k = 0; k < 3; k++) {
            Ji[6 * r + k] = r == k ? 1.0 : 0.0;
            Jj[6 * r + k] = r == k ? -1.0 : 0.0;
            Ji[6 * r + 3 + k] = Ai[3 * r + k];
            Jj[6 * r + 3 + k] = Aj[3 * r + k];
        }
    }
    const double *wi = f->w + 3 * bi, *wj = f->w + 3 * bj;
    double t[3], ti[3], tj[3], gi[3], gj[3];
    cross3(wi, si, t);
    cross3(wi, t, ti);
    cross3(wj, sj, t);
    cross3(wj, t, tj);
    mat3vec(nRi, ti, gi);
    mat3vec(Rj, tj, gj);
    for (int k = 0; k < 3; k++) gam[k] = gi[k] + gj[k];
}

/* R_i, R_i^T, R_j^T R_i and omega = R_i^T R_j w_j - w_i (the relative angular velocity in body i's axes). */
void ovk_spherical_friction_setup(const ovk_model *M, const ovk_frames *f, int j, ovk_fctx *cx) {
    int bi = ovk_slot(M, M->jbi[j]), bj = ovk_slot(M, M->jbj[j]);
    const double *Ri = f->R + 9 * bi, *Rj = f->R + 9 * bj;
    double t[3], u[3], RjT[9];
    memcpy(cx->Ri, Ri, sizeof cx->Ri);
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) { cx->RiT[3 * a + b] = Ri[3 * b + a]; RjT[3 * a + b] = Rj[3 * b + a]; }
    mat3vec(Rj, f->w + 3 * bj, t);
    mat3vec(cx->RiT, t, u);
    for (int k = 0; k < 3; k++) cx->omega[k] = u[k] - f->w[3 * bi + k];
    mat3mul(RjT, Ri, cx->Rji);
}

/* Friction forces of spherical joint j: Qi, Qj (6 each) at its multipliers lam (3). No contact
 * point (F' = 0): no friction. */
void ovk_spherical_friction_forces(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *Qi,
                                   double *Qj) {
    const double *c = M->jconst + NJC * j, *lp = M->jlawp + NLP * j;
    int law = M->jlaw[j];
    const double *si = c, *sj = c + 3;
    double F[3];
    mat3vec(cx->RiT, lam, F);
    double norm = sqrt(dot3(F, F));
    if (norm == 0.0) {
        for (int k = 0; k < 6; k++) Qi[k] = Qj[k] = 0.0;
        return;
    }
    double sC[3], v[3], Ffr[3], RiF[3], t[3], u[3], a1[3], a2[3];
    double nr = -lp[2];
    for (int k = 0; k < 3; k++) sC[k] = nr * F[k] / norm;
    cross3(cx->omega, sC, v);
    double speed = sqrt(dot3(v, v));
    double mn = ovk_law_mu_over_speed(lp, law, speed) * norm;
    for (int k = 0; k < 3; k++) Ffr[k] = mn * v[k];
    mat3vec(cx->Ri, Ffr, RiF);
    double arm[3] = {si[0] + sC[0], si[1] + sC[1], si[2] + sC[2]};
    cross3(arm, Ffr, t);
    for (int k = 0; k < 3; k++) { Qi[k] = RiF[k]; Qi[3 + k] = t[k]; }
    mat3vec(cx->Rji, Ffr, u);
    cross3(sj, u, a1);
    cross3(sC, Ffr, t);
    mat3vec(cx->Rji, t, a2);
    for (int k = 0; k < 3; k++) { Qj[k] = -RiF[k]; Qj[3 + k] = -(a1[k] + a2[k]); }
}

/* d(Qi, Qj)/d lam of spherical joint j: dQi, dQj (6 x 3, row-major). */
void ovk_spherical_friction_jac(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *dQi,
                                double *dQj) {
    const double *c = M->jconst + NJC * j, *lp = M->jlawp + NLP * j;
    int law = M->jlaw[j];
    const double *si = c, *sj = c + 3;
    double F[3];
    mat3vec(cx->RiT, lam, F);
    double norm = sqrt(dot3(F, F));
    if (norm == 0.0) {
        memset(dQi, 0, 18 * sizeof(double));
        memset(dQj, 0, 18 * sizeof(double));
        return;
    }
    double u[3], sC[3], proj[9], dsC[9], W[9], v[3], dv[9];
    double nr = -lp[2];
    for (int k = 0; k < 3; k++) { u[k] = F[k] / norm; sC[k] = nr * u[k]; }
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) {
            proj[3 * a + b] = ((a == b ? 1.0 : 0.0) - u[a] * u[b]) / norm;
            dsC[3 * a + b] = nr * proj[3 * a + b];
        }
    skew3(cx->omega, W);
    cross3(cx->omega, sC, v);
    mat3mul(W, dsC, dv);
    double speed = sqrt(dot3(v, v));
    double mm = ovk_law_mu_over_speed(lp, law, speed);
    double slope = speed > 0.0 ? ovk_law_mu_over_speed_slope(lp, law, speed) : 0.0;
    double vs = speed > 0.0 ? speed : 1.0, dspeed[3];
    for (int b = 0; b < 3; b++) dspeed[b] = (v[0] / vs) * dv[b] + (v[1] / vs) * dv[3 + b] + (v[2] / vs) * dv[6 + b];
    double Ffr[3], dFfr[9], mn = mm * norm, sn = slope * norm;
    for (int k = 0; k < 3; k++) Ffr[k] = mn * v[k];
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++)
            dFfr[3 * a + b] = sn * v[a] * dspeed[b] + mm * v[a] * u[b] + mn * dv[3 * a + b];
    double SF[9], darm[9], top[9], Sa[9], arm[3], bot_i[9], t1[9], t2[9], SC[9], Sj[9], t3[9], t4[9];
    skew3(Ffr, SF);
    mat3mul(SF, dsC, darm);
    for (int k = 0; k < 9; k++) darm[k] = -darm[k];
    mat3mul(cx->Ri, dFfr, top);
    for (int k = 0; k < 3; k++) arm[k] = si[k] + sC[k];
    skew3(arm, Sa);
    mat3mul(Sa, dFfr, t1);
    for (int k = 0; k < 9; k++) bot_i[k] = darm[k] + t1[k];
    /* dQj = -[top; skew(s_j) Rji dFfr + Rji (darm + skew(s_C) dFfr)] */
    skew3(sj, Sj);
    mat3mul(cx->Rji, dFfr, t1);
    mat3mul(Sj, t1, t2);
    skew3(sC, SC);
    mat3mul(SC, dFfr, t3);
    for (int k = 0; k < 9; k++) t3[k] = darm[k] + t3[k];
    mat3mul(cx->Rji, t3, t4);
    double Gi[18], Gj[18];
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) {
            Gi[3 * a + b] = top[3 * a + b];
            Gi[9 + 3 * a + b] = bot_i[3 * a + b];
            Gj[3 * a + b] = -top[3 * a + b];
            Gj[9 + 3 * a + b] = -(t2[3 * a + b] + t4[3 * a + b]);
        }
    /* times d F'/d lam = R_i^T */
    for (int a = 0; a < 6; a++)
        for (int b = 0; b < 3; b++) {
            dQi[3 * a + b] = Gi[3 * a] * cx->RiT[b] + Gi[3 * a + 1] * cx->RiT[3 + b] + Gi[3 * a + 2] * cx->RiT[6 + b];
            dQj[3 * a + b] = Gj[3 * a] * cx->RiT[b] + Gj[3 * a + 1] * cx->RiT[3 + b] + Gj[3 * a + 2] * cx->RiT[6 + b];
        }
}

/* The reported friction output of spherical joint j at its multipliers lam (3): |F_fr| at the
 * contact point (0 without a contact point). */
double ovk_spherical_friction_output(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam) {
    const double *lp = M->jlawp + NLP * j;
    double F[3];
    mat3vec(cx->RiT, lam, F);
    if (sqrt(dot3(F, F)) == 0.0) return 0.0;
    double norm = sqrt(dot3(F, F)), sC[3], v[3], Ffr[3];
    for (int k = 0; k < 3; k++) sC[k] = -lp[2] * F[k] / norm;
    cross3(cx->omega, sC, v);
    double mn = ovk_law_mu_over_speed(lp, M->jlaw[j], sqrt(dot3(v, v))) * norm;
    for (int k = 0; k < 3; k++) Ffr[k] = mn * v[k];
    return sqrt(dot3(Ffr, Ffr));
}
