/* The energy outputs of a C run, as overcon.simulate.Simulation's (energy.kinetic, potential,
 * dissipated, applied): the kinetic energy 1/2 h^T M h and the potential energy of gravity and the
 * springs at a state; the work of joint friction and of the constant forces and torques since the
 * start from the ledger of simulate._WorkLedger: Simpson's rule over each accepted step on the
 * powers at its start, middle (dense output) and end, read inside the last step by the cubic
 * Hermite interpolant of the work and the powers at the step's ends. Each power costs one
 * evaluation of Eq. 18 for the friction forces when the model has friction joints, warm-started
 * like the dense output and counted as the Python run counts it. Under redundancy "compliant" the
 * compliant joints' springs are in the potential energy and their dampers' power in the dissipated
 * work (ovk_compliant_energy). */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

/* The compliant joints' elastic energy (J) and damper power (W, >= 0) at (q, h), the frames of d
 * built there (compliance.c's force law: lam = k Phi + d Phi_h h on the scalar rows, so the
 * spring's energy is 1/2 k Phi^2 and the damper takes d (Phi_h h)^2; per-axis joints: the
 * joint-frame components of the deformation, FU Phi, and of its rate, FU Phi_h h, give
 * 1/2 sum_x k_x (FU Phi)_x^2 and sum_x d_x (FU Phi_h h)_x^2). Zero without compliant rows. */
void ovk_compliant_energy(const ovk_model *M, ovk_data *d, const double *q, const double *h, double *elastic,
                          double *damping) {
    *elastic = *damping = 0.0;
    if (M->redundancy != OVK_COMPLIANT || M->nrig == M->nR) return;
    ovk_constraint_rows(M, d, q);
    for (int p = 0; p < M->nR; p++) {
        if (M->ckind[p] != 1) continue;
        int row = M->retained[p];
        double rate = ovk_row_rate(M, d, p, h);
        *elastic += 0.5 * M->ck[row] * d->phi[row] * d->phi[row];
        *damping += M->cd[row] * rate * rate;
    }
    for (int a = 0; a < M->nax; a++)
        for (int rot = 0; rot < 2; rot++) {
            const double *kv = M->axp + OVK_NAXP * a + 9 + 6 * rot, *dv = kv + 3;
            double FU[3][3], phi[3], rate[3];
            int n = ovk_axis_group(M, d, a, rot, h, FU, phi, rate);
            for (int x = 0; x < 3 && n; x++) {
                double dx = 0.0, vx = 0.0;
                for (int e = 0; e < n; e++) {
                    dx += FU[x][e] * phi[e];
                    vx += FU[x][e] * rate[e];
                }
                *elastic += 0.5 * kv[x] * dx * dx;
                *damping += dv[x] * vx * vx;
            }
        }
}

/* [power dissipated by joint friction and the compliant joints' dampers (W, >= 0), power of the
 * constant forces and torques and of the inputs at t (W)] at (t, y) (Simulation._powers). */
static int powers(ovk_sim *s, double t, const double *y, double *p) {
    const ovk_model *M = s->M;
    int kh = M->nh_b, dim = M->dim, n = s->n;
    const double *h = y + n;
    ovk_frames_build(M, y, h, &s->d->f);
    memset(s->qload, 0, (size_t)s->nh * sizeof(double));
    for (int l = 0; l < M->nl; l++) {
        const double *lp = M->lp + NLD * l;
        int bi = M->lbi[l];
        if (M->ltype[l] == LD_FORCE) {
            for (int i = 0; i < dim; i++) s->qload[bi * kh + i] += lp[i];
        } else if (M->ltype[l] == LD_TORQUE && dim == 2) {
            s->qload[bi * kh + 2] += lp[0];
        } else if (M->ltype[l] == LD_TORQUE) {
            double tb[3];
            mat3tvec(s->d->f.R + 9 * bi, lp, tb);
            for (int i = 0; i < 3; i++) s->qload[bi * kh + 3 + i] += tb[i];
        }
    }
    if (M->nu) ovk_input_forces(M, s->d, t, s->qload);
    double applied = 0.0, elastic, damper;
    for (int k = 0; k < s->nh; k++) applied += h[k] * s->qload[k];
    ovk_compliant_energy(M, s->d, y, h, &elastic, &damper);
    p[0] = damper;
    p[1] = applied;
    int drivers = 0;
    for (int j = 0; j < M->nj; j++) drivers += M->jtype[j] == J_DRIVER;
    if (!M->nfj && !drivers) return OVK_OK;
    int its = 0, status = ovk_sim_solve(s, t, y, &s->warm, s->has_lam ? s->lam : NULL, s->yout, &its);
    if (status) return status;
    s->evaluations++;
    for (int j = 0; drivers && j < M->nj; j++) { /* a driver's power: its effort -lam times the rate Phi_h h */
        if (M->jtype[j] != J_DRIVER) continue;
        int row = M->jrows[OVK_MAXEQ * j], kh = M->nh_b, bi = M->jbi[j], bj = M->jbj[j];
        const double *Jr = OVK_JROW(M, s->d->J, row); /* body i's slot, then body j's (joints.c) */
        double rate = 0.0;
        if (bi >= 0)
            for (int k = 0; k < kh; k++) rate += Jr[k] * h[bi * kh + k];
        if (bj >= 0 && bj != bi)
            for (int k = 0; k < kh; k++) rate += Jr[kh + k] * h[bj * kh + k];
        p[1] += -s->ev_lam[row] * rate;
    }
    if (!M->nfj) return OVK_OK;
    double fp = 0.0;
    for (int k = 0; k < s->ncols; k++) fp += h[M->cols[k]] * s->ev_qf[k];
    p[0] = damper - fp;
    return OVK_OK;
}

/* The ledger at the start t0 (y0): no work yet, the powers there. */
int ovk_sim_energy_start(ovk_sim *s, double t0, const double *y0) {
    const double none[2] = {0.0, 0.0};
    return ovk_sim_energy_rewind(s, t0, y0, none); /* the ledger started anew at (t0, y0) */
}

/* The ledger after the accepted step (t_old, t] (_WorkLedger.step): Simpson on its powers. */
int ovk_sim_energy_step(ovk_sim *s) {
    if (!s->o.energy) return OVK_OK;
    ovk_rk *rk = &s->rk;
    double mid = 0.5 * (rk->t_old + rk->t), pm[2], pe[2];
    ovk_rk_dense(rk, mid, s->ystar);
    int status = powers(s, mid, s->ystar, pm);
    if (!status) status = powers(s, rk->t, rk->y, pe);
    if (status) return status;
    double t0 = s->work_t[1], w[2];
    for (int k = 0; k < 2; k++)
        w[k] = s->work_w[1][k] + (rk->t - t0) / 6.0 * (s->work_p[1][k] + 4.0 * pm[k] + pe[k]);
    s->work_t[0] = s->work_t[1];
    memcpy(s->work_w[0], s->work_w[1], sizeof w);
    memcpy(s->work_p[0], s->work_p[1], sizeof w);
    s->work_t[1] = rk->t;
    memcpy(s->work_w[1], w, sizeof w);
    memcpy(s->work_p[1], pe, sizeof pe);
    return OVK_OK;
}

/* After the inputs changed at the last step's end: the powers there with their new values, the
 * start of the next step's Simpson rule (the work so far stays). */
int ovk_sim_energy_inputs(ovk_sim *s) {
    if (!s->o.energy) return OVK_OK;
    return powers(s, s->work_t[1], s->rk.y, s->work_p[1]);
}

/* The ledger taken back to (t, y) inside the last step, its work there w (ovk_sim_work_at before
 * the integrator was taken back): the inputs changed at t (sim.c ovk_sim_set_inputs). */
int ovk_sim_energy_rewind(ovk_sim *s, double t, const double *y, const double *w) {
    if (!s->o.energy) return OVK_OK;
    double p[2];
    int status = powers(s, t, y, p);
    if (status) return status;
    for (int k = 0; k < 2; k++) {
        s->work_t[k] = t;
        s->work_w[k][0] = w[0], s->work_w[k][1] = w[1];
        s->work_p[k][0] = p[0], s->work_p[k][1] = p[1];
    }
    return OVK_OK;
}

/* The work [dissipated, applied] at t inside the last step (_WorkLedger.at). */
void ovk_sim_work_at(const ovk_sim *s, double t, double *out) {
    double t0 = s->work_t[0], t1 = s->work_t[1];
    if (t1 <= t0 || t >= t1) {
        out[0] = s->work_w[1][0], out[1] = s->work_w[1][1];
        return;
    }
    double h = t1 - t0, x = (t - t0) / (t1 - t0), x2 = pow(x, 2.0), x3 = pow(x, 3.0);
    for (int k = 0; k < 2; k++)
        out[k] = (2 * x3 - 3 * x2 + 1) * s->work_w[0][k] + (x3 - 2 * x2 + x) * h * s->work_p[0][k] +
                 (-2 * x3 + 3 * x2) * s->work_w[1][k] + (x3 - x2) * h * s->work_p[1][k];
}

/* [kinetic, potential (gravity, springs, compliant joints), dissipated, applied] (J) at (t, y) of
 * the last step (Simulation.state_outputs);
 * the run's state is left as it was. */
int ovk_sim_energy(ovk_sim *s, double t, const double *y, double *out) {
    if (!s) return OVK_NOMEM;
    if (s->status) return s->status;
    const ovk_model *M = s->M;
    int nb = M->nb, kh = M->nh_b, dim = M->dim, n = s->n;
    const double *h = y + n;
    double kin = 0.0;
    for (int b = 0; b < nb; b++)
        for (int i = 0; i < kh; i++) {
            double mass = i < dim ? M->mass[b] : dim == 3 ? M->inertia[3 * b + i - 3] : 1.0 / M->Minv[b * kh + i];
            kin += mass * h[b * kh + i] * h[b * kh + i];
        }
    memcpy(s->ystar, y, (size_t)s->ny * sizeof(double));
    for (int b = 0; M->nq_b == 7 && b < nb; b++) { /* quaternions as e / |e| (normalized_coordinates) */
        double *e = s->ystar + 7 * b + 3, norm = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3]);
        for (int i = 0; i < 4; i++) e[i] /= norm;
    }
    ovk_frames_build(M, s->ystar, s->ystar + n, &s->d->f);
    const ovk_frames *f = &s->d->f;
    double grav = 0.0;
    for (int b = 0; b < nb; b++) {
        double rg = 0.0;
        for (int i = 0; i < dim; i++) rg += f->r[dim * b + i] * M->gravity[i];
        grav += M->mass[b] * rg;
    }
    double pot = -grav;
    for (int l = 0; l < M->nl; l++) {
        if (M->ltype[l] != LD_SPRING) continue;
        const double *lp = M->lp + NLD * l;
        double pi[3] = {0}, pj[3] = {0}, len2 = 0.0;
        ovk_spring_points(M, f, lp, M->lbi[l], M->lbj[l], pi, pj);
        for (int i = 0; i < dim; i++) len2 += (pi[i] - pj[i]) * (pi[i] - pj[i]);
        double stretch = sqrt(len2) - lp[10];
        pot += 0.5 * lp[9] * stretch * stretch;
    }
    double elastic, damper;
    ovk_compliant_energy(M, s->d, s->ystar, s->ystar + n, &elastic, &damper);
    pot += elastic;
    out[0] = 0.5 * kin;
    out[1] = pot;
    if (s->o.energy) ovk_sim_work_at(s, t, out + 2);
    else out[2] = out[3] = 0.0;
    return OVK_OK;
}
