/* Stage: applied forces Q (nh) at the frames in d->f: gravity,
 * the gyroscopic term -w x (J w) of spatial bodies, forces and torques on one body, springs
 * between two bodies (or a body and the base). */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

/* The two attachment points of spring lp (dim entries each, global frame) at the frames f. */
void ovk_spring_points(const ovk_model *M, const ovk_frames *f, const double *lp, int bi, int bj, double *pi,
                       double *pj) {
    int si = ovk_slot(M, bi), sj = ovk_slot(M, bj);
    double t[3];
    if (M->dim == 2) {
        mat2vec(f->R + 4 * si, lp + 3, t);
        for (int i = 0; i < 2; i++) pi[i] = f->r[2 * si + i] + t[i];
        mat2vec(f->R + 4 * sj, lp + 6, t);
        for (int i = 0; i < 2; i++) pj[i] = f->r[2 * sj + i] + t[i];
    } else {
        mat3vec(f->R + 9 * si, lp + 3, t);
        for (int i = 0; i < 3; i++) pi[i] = f->r[3 * si + i] + t[i];
        mat3vec(f->R + 9 * sj, lp + 6, t);
        for (int i = 0; i < 3; i++) pj[i] = f->r[3 * sj + i] + t[i];
    }
}

/* The applied forces at time t (the inputs' values depend on it: inputs.c). OVK_SPRING when a spring of positive free length has coinciding points (its direction is
 * undefined); a spring of free length 0 pulls with -k d, defined there too. */
int ovk_loads(const ovk_model *M, ovk_data *d, double t) {
    int nb = M->nb, dim = M->dim, kh = M->nh_b;
    const ovk_frames *f = &d->f;
    double *Q = d->Q;
    memset(Q, 0, sizeof(double) * nb * kh);
    for (int b = 0; b < nb; b++) {
        for (int i = 0; i < dim; i++) Q[b * kh + i] = M->mass[b] * M->gravity[i];
        if (dim == 3) {
            const double *w = f->w + 3 * b;
            double Jw[3] = {M->inertia[3 * b] * w[0], M->inertia[3 * b + 1] * w[1], M->inertia[3 * b + 2] * w[2]}, c[3];
            cross3(w, Jw, c);
            for (int i = 0; i < 3; i++) Q[b * kh + 3 + i] -= c[i];
        }
    }
    for (int l = 0; l < M->nl; l++) {
        const double *lp = M->lp + NLD * l;
        int bi = M->lbi[l], bj = M->lbj[l];
        if (M->ltype[l] == LD_FORCE) {
            for (int i = 0; i < dim; i++) Q[bi * kh + i] += lp[i];
        } else if (M->ltype[l] == LD_TORQUE) {
            if (dim == 2) Q[bi * kh + 2] += lp[0];
            else {
                double tb[3];
                mat3tvec(f->R + 9 * bi, lp, tb);
                for (int i = 0; i < 3; i++) Q[bi * kh + 3 + i] += tb[i];
            }
        } else { /* spring */
            int si = ovk_slot(M, bi), sj = ovk_slot(M, bj);
            double pi[3] = {0}, pj[3] = {0}, dv[3] = {0};
            ovk_spring_points(M, f, lp, bi, bj, pi, pj);
            double len2 = 0.0;
            for (int i = 0; i < dim; i++) { dv[i] = pi[i] - pj[i]; len2 += dv[i] * dv[i]; }
            double len = sqrt(len2), L0 = lp[10];
            double F[3] = {0};
            if (L0 == 0.0) {
                for (int i = 0; i < dim; i++) F[i] = -lp[9] * dv[i];
            } else {
                if (len < 1e-12 * L0)
                    return ovk_fail(d, OVK_SPRING, "spring loads[%d]: attachment points coincide (distance %g m) "
                                    "while its free length is %g m", l, len, L0);
                for (int i = 0; i < dim; i++) F[i] = -lp[9] * (len - L0) * dv[i] / len;
            }
            for (int side = 0; side < 2; side++) {
                int b = side ? bj : bi, sl = side ? sj : si;
                double sign = side ? -1.0 : 1.0, *pt = side ? pj : pi;
                if (b < 0) continue;
                double Fs[3] = {sign * F[0], sign * F[1], sign * F[2]};
                if (dim == 2) {
                    double arm[2] = {pt[0] - f->r[2 * sl], pt[1] - f->r[2 * sl + 1]};
                    Q[b * kh] += Fs[0];
                    Q[b * kh + 1] += Fs[1];
                    Q[b * kh + 2] += arm[0] * Fs[1] - arm[1] * Fs[0];
                } else {
                    double arm[3], ab[3], fb[3], c[3];
                    for (int i = 0; i < 3; i++) arm[i] = pt[i] - f->r[3 * sl + i];
                    mat3tvec(f->R + 9 * sl, arm, ab);
                    mat3tvec(f->R + 9 * sl, Fs, fb);
                    cross3(ab, fb, c);
                    for (int i = 0; i < 3; i++) { Q[b * kh + i] += Fs[i]; Q[b * kh + 3 + i] += c[i]; }
                }
            }
        }
    }
    if (M->nu) ovk_input_forces(M, d, t, Q);
    return OVK_OK;
}
