/* Stage: distance joints (overcon.joints.distance), planar and spatial: a massless rigid link of
 * length L between the point s_i on body i and s_j on body j (either may be the base or a
 * particle), one equation
 *   Phi = |d| - L,  d = r_i + R_i s_i - r_j - R_j s_j,  u = d / |d|,
 * Phi_h = u^T [dd/dh]: planar [u, u . (Omega a_i)] and [-u, -u . (Omega a_j)] (a = R s, Omega a =
 * (-a_y, a_x)); spatial (velocities [v global, omega body axes], Eq. 7) [u^T, -u^T R_i skew(s_i)]
 * and [-u^T, u^T R_j skew(s_j)]; gamma = -(the part of d^2|d|/dt^2 without accelerations):
 *   gamma = -u . c - (|d'|^2 - (u . d')^2) / |d|,
 * c the velocity-quadratic part of d'' (planar -w_i^2 a_i + w_j^2 a_j; spatial R_i (w_i x (w_i x
 * s_i)) - R_j (w_j x (w_j x s_j))). Since u is a unit vector, the multiplier lam is the force along
 * the link: the joint pulls body i by -lam u (towards body j for lam > 0), so lam is its tension
 * (positive pulling, negative pushing), the reported component "tension" (outputs.c). At |d| = 0
 * the direction is undefined: u = 0 there, a zero row the watch reports as a singular position
 * (the scene loader refuses L <= 0, so only a motion through the coincidence reaches it). No
 * friction (a link carries no friction model). Constants c: s_i (c[0:3]), s_j (c[3:6]), L (c[6]);
 * planar uses the first two of each. */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

void ovk_distance_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                       double *gam) {
    const double *c = M->jconst + NJC * j;
    int bi = ovk_slot(M, M->jbi[j]), bj = ovk_slot(M, M->jbj[j]), dim = M->dim, kh = M->nh_b;
    double ai[3] = {0.0, 0.0, 0.0}, aj[3] = {0.0, 0.0, 0.0}, d[3] = {0.0, 0.0, 0.0}, dd[3] = {0.0, 0.0, 0.0};
    double cq[3] = {0.0, 0.0, 0.0}, u[3] = {0.0, 0.0, 0.0};
    double ti[3] = {0.0, 0.0, 0.0}, tj[3] = {0.0, 0.0, 0.0}; /* d a_i / d omega_i applied: the rows' rotation parts */
    memset(Ji, 0, (size_t)kh * sizeof(double));
    memset(Jj, 0, (size_t)kh * sizeof(double));
    if (dim == 2) {
        const double *Ri = f->R + 4 * bi, *Rj = f->R + 4 * bj;
        mat2vec(Ri, c, ai);
        mat2vec(Rj, c + 3, aj);
        double wi = f->w[bi], wj = f->w[bj];
        for (int k = 0; k < 2; k++) {
            d[k] = f->r[2 * bi + k] + ai[k] - f->r[2 * bj + k] - aj[k];
            cq[k] = -wi * wi * ai[k] + wj * wj * aj[k];
        }
        double oi[2] = {-ai[1], ai[0]}, oj[2] = {-aj[1], aj[0]};
        for (int k = 0; k < 2; k++) dd[k] = f->v[2 * bi + k] + wi * oi[k] - f->v[2 * bj + k] - wj * oj[k];
        double len = sqrt(d[0] * d[0] + d[1] * d[1]);
        if (len > 0.0) u[0] = d[0] / len, u[1] = d[1] / len;
        phi[0] = len - c[6];
        Ji[0] = u[0], Ji[1] = u[1], Ji[2] = u[0] * oi[0] + u[1] * oi[1];
        Jj[0] = -u[0], Jj[1] = -u[1], Jj[2] = -(u[0] * oj[0] + u[1] * oj[1]);
        double ud = u[0] * dd[0] + u[1] * dd[1], d2 = dd[0] * dd[0] + dd[1] * dd[1];
        gam[0] = -(u[0] * cq[0] + u[1] * cq[1]) - (len > 0.0 ? (d2 - ud * ud) / len : 0.0);
        return;
    }
    const double *Ri = f->R + 9 * bi, *Rj = f->R + 9 * bj, *si = c, *sj = c + 3;
    const double *wi = f->w + 3 * bi, *wj = f->w + 3 * bj;
    double t[3], t2[3], vi[3], vj[3], qi[3], qj[3];
    mat3vec(Ri, si, ai);
    mat3vec(Rj, sj, aj);
    cross3(wi, si, t); /* omega_i x s_i (body axes) */
    mat3vec(Ri, t, vi);
    cross3(wi, t, t2);
    mat3vec(Ri, t2, qi);
    cross3(wj, sj, t);
    mat3vec(Rj, t, vj);
    cross3(wj, t, t2);
    mat3vec(Rj, t2, qj);
    for (int k = 0; k < 3; k++) {
        d[k] = f->r[3 * bi + k] + ai[k] - f->r[3 * bj + k] - aj[k];
        dd[k] = f->v[3 * bi + k] + vi[k] - f->v[3 * bj + k] - vj[k];
        cq[k] = qi[k] - qj[k];
    }
    double len = sqrt(dot3(d, d));
    if (len > 0.0)
        for (int k = 0; k < 3; k++) u[k] = d[k] / len;
    phi[0] = len - c[6];
    double Riu[3], Rju[3];
    mat3tvec(Ri, u, Riu);
    mat3tvec(Rj, u, Rju);
    cross3(si, Riu, ti); /* u^T (-R_i skew(s_i)) x = (s_i x R_i^T u) . x; body j's: the opposite sign */
    cross3(sj, Rju, tj);
    for (int k = 0; k < 3; k++) {
        Ji[k] = u[k], Ji[3 + k] = ti[k];
        Jj[k] = -u[k], Jj[3 + k] = -tj[k];
    }
    double ud = dot3(u, dd), d2 = dot3(dd, dd);
    gam[0] = -dot3(u, cq) - (len > 0.0 ? (d2 - ud * ud) / len : 0.0);
}
