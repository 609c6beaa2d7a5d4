/* Stage: spatial axis joints (revolute, prismatic, cylindrical, universal, fixed; their constants
 * from overcon.joints.spatial_rows) and the spatial point-on-line joint (overcon.joints.point_on_line:
 * s_i, s_j, a_j, b1_j, b2_j at their places below, its friction a force along R_j a_j at P_i), each a
 * tuple of row primitives (POINT: P_i - P_j, 3 rows;
 * DOT: (R_i a)·(R_j b); POINTDOT: (P_i - P_j)·(R_j b)); the reaction in the joint frame and the
 * friction of the revolute (bearing and collar torque), prismatic (guide force) and cylindrical
 * (slip along (v_rel, a omega_rel)) joints. These types have no analytic friction Jacobian:
 * forward differences of the forces, step 1e-7 max(1, |lam|).
 *
 * Constants per joint (jconst, packed by overcon.kernel): s_i [0:3], s_j [3:6], a_i [6:9],
 * a_j [9:12], b1_j [12:15], b2_j [15:18], c_i [18:21], E [21:30] (row-major: columns x, y, z of the
 * joint frame in body i axes), friction sizes [30:33] (revolute: radius, length, collar_radius;
 * prismatic and cylindrical: length, radius). */
#include <math.h>
#include <string.h>

#include "core.h"
#include "small.h"

enum { V_SI = 0, V_SJ = 3, V_AI = 6, V_AJ = 9, V_B1 = 12, V_B2 = 15, V_CI = 18, V_E = 21, V_SIZE = 30 };
enum { ROW_POINT = 1, ROW_DOT = 2, ROW_POINTDOT = 3 };

typedef struct {
    int kind, a, b; /* primitive, offsets of its body i and body j vectors */
} axis_row;

typedef struct {
    int nrows;
    axis_row rows[5];
    int ncomp, comp[6]; /* reported components of [Fx, Fy, Fz, Tx, Ty, Tz] */
} axis_type;

static const axis_type REVOLUTE = {3, {{ROW_POINT, 0, 0}, {ROW_DOT, V_AI, V_B1}, {ROW_DOT, V_AI, V_B2}},
                                   5, {0, 1, 2, 3, 4}};
static const axis_type PRISMATIC = {5, {{ROW_POINTDOT, 0, V_B1}, {ROW_POINTDOT, 0, V_B2}, {ROW_DOT, V_AI, V_B1},
                                        {ROW_DOT, V_AI, V_B2}, {ROW_DOT, V_CI, V_B2}},
                                    5, {0, 1, 3, 4, 5}};
static const axis_type CYLINDRICAL = {4, {{ROW_POINTDOT, 0, V_B1}, {ROW_POINTDOT, 0, V_B2}, {ROW_DOT, V_AI, V_B1},
                                          {ROW_DOT, V_AI, V_B2}},
                                      4, {0, 1, 3, 4}};
/* the point-on-line joint (overcon.joints.point_on_line): the cylindrical joint's point rows; its
 * reaction is reported from its rows' normals (outputs.c), not from E */
static const axis_type POINT_LINE = {2, {{ROW_POINTDOT, 0, V_B1}, {ROW_POINTDOT, 0, V_B2}}, 0, {0}};
static const axis_type UNIVERSAL = {2, {{ROW_POINT, 0, 0}, {ROW_DOT, V_AI, V_AJ}}, 5, {0, 1, 2, 3, 4}};
static const axis_type FIXED = {4, {{ROW_POINT, 0, 0}, {ROW_DOT, V_AI, V_B1}, {ROW_DOT, V_AI, V_B2},
                                    {ROW_DOT, V_CI, V_B2}},
                                6, {0, 1, 2, 3, 4, 5}};

static const axis_type *type_of(int jtype) {
    switch (jtype) {
    case J_SREVOLUTE: return &REVOLUTE;
    case J_PRISMATIC: return &PRISMATIC;
    case J_CYLINDRICAL: return &CYLINDRICAL;
    case J_UNIVERSAL: return &UNIVERSAL;
    case J_POINT_LINE: return &POINT_LINE;
    default: return &FIXED;
    }
}

/* w x (w x x) */
static void ww(const double *w, const double *x, double *out) {
    double t[3];
    cross3(w, x, t);
    cross3(w, t, out);
}

/* The geometry of one joint in one evaluation. */
typedef struct {
    const double *c, *Ri, *Rj, *ri, *rj, *vi, *vj, *wi, *wj;
} axis_geo;

static axis_geo geometry(const ovk_model *M, const ovk_frames *f, int j) {
    int bi = ovk_slot(M, M->jbi[j]), bj = ovk_slot(M, M->jbj[j]);
    axis_geo g = {M->jconst + NJC * j, f->R + 9 * bi, f->R + 9 * bj, f->r + 3 * bi, f->r + 3 * bj,
                  f->v + 3 * bi, f->v + 3 * bj, f->w + 3 * bi, f->w + 3 * bj};
    return g;
}

/* d = P_i - P_j (global) */
static void point_difference(const axis_geo *g, double *d) {
    double ai[3], aj[3];
    mat3vec(g->Ri, g->c + V_SI, ai);
    mat3vec(g->Rj, g->c + V_SJ, aj);
    for (int k = 0; k < 3; k++) d[k] = g->ri[k] + ai[k] - g->rj[k] - aj[k];
}

/* One row (R_i a)·(R_j b): value, Ji, Jj (1 x 6 each), gamma. */
static void dot_row(const axis_geo *g, const double *a, const double *b, double *phi, double *Ji, double *Jj,
                    double *gam) {
    double A[3], B[3], t[3], u[3], x[3], y[3];
    mat3vec(g->Ri, a, A);
    mat3vec(g->Rj, b, B);
    *phi = dot3(A, B);
    for (int k = 0; k < 3; k++) Ji[k] = Jj[k] = 0.0;
    mat3tvec(g->Ri, B, t);
    cross3(a, t, Ji + 3);
    mat3tvec(g->Rj, A, t);
    cross3(b, t, Jj + 3);
    ww(g->wi, a, t);
    mat3vec(g->Ri, t, u);
    double s1 = dot3(u, B);
    cross3(g->wi, a, t);
    mat3vec(g->Ri, t, x);
    cross3(g->wj, b, t);
    mat3vec(g->Rj, t, y);
    double s2 = 2.0 * dot3(x, y);
    ww(g->wj, b, t);
    mat3vec(g->Rj, t, u);
    double s3 = dot3(A, u);
    *gam = -(s1 + s2 + s3);
}

/* One row (P_i - P_j)·(R_j b): value, Ji, Jj (1 x 6 each), gamma. */
static void pointdot_row(const axis_geo *g, const double *b, double *phi, double *Ji, double *Jj, double *gam) {
    const double *si = g->c + V_SI, *sj = g->c + V_SJ;
    double d[3], B[3], t[3], u[3], x[3], dd1[3], dd2[3], p[3], q[3];
    point_difference(g, d);
    mat3vec(g->Rj, b, B);
    *phi = dot3(d, B);
    for (int k = 0; k < 3; k++) { Ji[k] = B[k]; Jj[k] = -B[k]; }
    mat3tvec(g->Ri, B, t);
    cross3(si, t, Ji + 3);
    mat3tvec(g->Rj, d, t);
    cross3(b, t, u);
    mat3tvec(g->Rj, B, t);
    cross3(sj, t, x);
    for (int k = 0; k < 3; k++) Jj[3 + k] = u[k] - x[k];
    cross3(g->wi, si, t);
    mat3vec(g->Ri, t, p);
    cross3(g->wj, sj, t);
    mat3vec(g->Rj, t, q);
    for (int k = 0; k < 3; k++) dd1[k] = g->vi[k] + p[k] - g->vj[k] - q[k];
    ww(g->wi, si, t);
    mat3vec(g->Ri, t, p);
    ww(g->wj, sj, t);
    mat3vec(g->Rj, t, q);
    for (int k = 0; k < 3; k++) dd2[k] = p[k] - q[k];
    cross3(g->wj, b, t);
    mat3vec(g->Rj, t, p);
    ww(g->wj, b, t);
    mat3vec(g->Rj, t, q);
    double second = dot3(dd2, B) + 2.0 * dot3(dd1, p) + dot3(d, q);
    *gam = -second;
}

/* Phi, Jacobian blocks (neq x 6, row-major) and gamma of axis joint j, its rows in order. */
void ovk_axis_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                   double *gam) {
    const axis_type *t = type_of(M->jtype[j]);
    axis_geo g = geometry(M, f, j);
    int e = 0;
    for (int r = 0; r < t->nrows; r++) {
        const axis_row *w = t->rows + r;
        if (w->kind == ROW_POINT) {
            ovk_spherical_rows(M, f, j, phi + e, Ji + 6 * e, Jj + 6 * e, gam + e);
            e += 3;
        } else if (w->kind == ROW_DOT) {
            dot_row(&g, g.c + w->a, g.c + w->b, phi + e, Ji + 6 * e, Jj + 6 * e, gam + e);
            e += 1;
        } else {
            pointdot_row(&g, g.c + w->b, phi + e, Ji + 6 * e, Jj + 6 * e, gam + e);
            e += 1;
        }
    }
}

/* [Fx, Fy, Fz, Tx, Ty, Tz] in the joint frame of fi = (J_X)_i^T lam (spatial_rows.frame_reaction). */
static void frame_reaction(const double *c, const double *RiT, const double *fi, double *p) {
    double F[3], t[3], T[3];
    mat3vec(RiT, fi, t);
    for (int k = 0; k < 3; k++) F[k] = -t[k];
    cross3(c + V_SI, F, t);
    for (int k = 0; k < 3; k++) T[k] = -fi[3 + k] - t[k];
    mat3tvec(c + V_E, F, p);
    mat3tvec(c + V_E, T, p + 3);
}

/* The reported components of axis joint j (their count) in out, from fi (6). */
int ovk_axis_reaction(const ovk_model *M, const ovk_frames *f, int j, const double *fi, double *out) {
    const axis_type *t = type_of(M->jtype[j]);
    const double *Ri = f->R + 9 * ovk_slot(M, M->jbi[j]);
    double RiT[9], p[6];
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) RiT[3 * a + b] = Ri[3 * b + a];
    frame_reaction(M->jconst + NJC * j, RiT, fi, p);
    for (int k = 0; k < t->ncomp; k++) out[k] = p[t->comp[k]];
    return t->ncomp;
}

/* The frames-only part of the friction (spatial_rows.friction_context and the types'
 * friction_setup): (J_X)_i^T, u = R_i a_i, omega_rel, v_rel, R_i^T, R_j^T, the arm of P_i on body j,
 * and the coefficient(s) of the joint's law. */
void ovk_axis_friction_setup(const ovk_model *M, const ovk_frames *f, int j, const double *Ji, ovk_fctx *cx) {
    axis_geo g = geometry(M, f, j);
    const double *c = g.c, *lp = M->jlawp + NLP * j;
    int ne = M->jneq[j], law = M->jlaw[j];
    for (int a = 0; a < 6; a++)
        for (int e = 0; e < ne; e++) cx->JT[ne * a + e] = Ji[6 * e + a];
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) { cx->RiT[3 * a + b] = g.Ri[3 * b + a]; cx->RjT[3 * a + b] = g.Rj[3 * b + a]; }
    double t[3], x[3], y[3], P[3], vi[3], vj[3], dv[3];
    if (M->jtype[j] == J_POINT_LINE) mat3vec(g.Rj, c + V_AJ, cx->u); /* the line, fixed in body j */
    else mat3vec(g.Ri, c + V_AI, cx->u);
    mat3vec(g.Rj, g.wj, x);
    mat3vec(g.Ri, g.wi, y);
    for (int k = 0; k < 3; k++) dv[k] = x[k] - y[k];
    cx->spin = dot3(dv, cx->u);
    mat3vec(g.Ri, c + V_SI, t);
    for (int k = 0; k < 3; k++) P[k] = g.ri[k] + t[k];
    cross3(g.wi, c + V_SI, t);
    mat3vec(g.Ri, t, x);
    for (int k = 0; k < 3; k++) { vi[k] = g.vi[k] + x[k]; t[k] = P[k] - g.rj[k]; }
    mat3vec(cx->RjT, t, cx->armj);
    cross3(g.wj, cx->armj, t);
    mat3vec(g.Rj, t, x);
    for (int k = 0; k < 3; k++) { vj[k] = g.vj[k] + x[k]; dv[k] = vj[k] - vi[k]; }
    cx->slide = dot3(dv, cx->u);
    cx->mu = cx->mos = 0.0;
    if (law == LAW_NONE) return;
    if (M->jtype[j] == J_SREVOLUTE) cx->mu = ovk_law_coefficient(lp, law, cx->spin);
    else if (M->jtype[j] == J_PRISMATIC || M->jtype[j] == J_POINT_LINE) cx->mu = ovk_law_coefficient(lp, law, cx->slide);
    else if (M->jtype[j] == J_CYLINDRICAL) {
        double s = hypot(cx->slide, c[V_SIZE + 1] * cx->spin);
        cx->mu = ovk_law_coefficient(lp, law, s);
        cx->mos = s > 0.0 ? ovk_law_mu_over_speed(lp, law, s) : 0.0;
    }
}

/* |f_A| + |f_B| of a guide of length l (spatial_rows.guide_normal_load). */
static double guide_normal_load(const double *p, double l) {
    double fB[2] = {p[4] / l, -p[3] / l};
    double fA[2] = {p[0] - fB[0], p[1] - fB[1]};
    return hypot(fA[0], fA[1]) + hypot(fB[0], fB[1]);
}

/* |f+| + |f-| of a bearing of length L (spatial_rows.bearing_radial_load). */
static double bearing_radial_load(const double *p, double L) {
    double m[2] = {p[4] / L, -p[3] / L}, half[2] = {0.5 * p[0], 0.5 * p[1]};
    double fp[2] = {half[0] + m[0], half[1] + m[1]}, fm[2] = {half[0] - m[0], half[1] - m[1]};
    return hypot(fp[0], fp[1]) + hypot(fm[0], fm[1]);
}

/* The reaction in the joint frame at the joint's multipliers lam (spatial_rows.reaction_of). */
static void reaction_at(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *p) {
    int ne = M->jneq[j];
    double fi[6];
    for (int a = 0; a < 6; a++) {
        double s = 0.0;
        for (int e = 0; e < ne; e++) s += cx->JT[ne * a + e] * lam[e];
        fi[a] = s;
    }
    frame_reaction(M->jconst + NJC * j, cx->RiT, fi, p);
}

/* The friction output of axis joint j at its multipliers lam: the revolute's torque, the
 * prismatic's force (signed), the cylindrical's force magnitude; 0 for the other types. */
double ovk_axis_friction_output(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam) {
    const double *sz = M->jconst + NJC * j + V_SIZE;
    double p[6];
    /* point on line: mu(v) N along u, N = |(lam_1, lam_2)| the normal force (unit normals b1, b2) */
    if (M->jtype[j] == J_POINT_LINE) return cx->mu * hypot(lam[0], lam[1]);
    reaction_at(M, j, cx, lam, p);
    switch (M->jtype[j]) {
    case J_SREVOLUTE: return cx->mu * (sz[0] * bearing_radial_load(p, sz[1]) + sz[2] * fabs(p[2]));
    case J_PRISMATIC: return cx->mu * (guide_normal_load(p, sz[0]) + fabs(p[5]) / sz[1]);
    case J_CYLINDRICAL: return cx->mu * guide_normal_load(p, sz[0]);
    default: return 0.0;
    }
}

/* A force `force` u at P_i and a torque `torque` u on body i, the opposites on body j
 * (spatial_rows.axial_loads). */
static void axial_loads(const double *c, const ovk_fctx *cx, double force, double torque, double *Qi, double *Qj) {
    double F[3], tau[3], t[3], x[3], y[3];
    for (int k = 0; k < 3; k++) { F[k] = force * cx->u[k]; tau[k] = torque * cx->u[k]; }
    mat3vec(cx->RiT, F, t);
    cross3(c + V_SI, t, x);
    mat3vec(cx->RiT, tau, y);
    for (int k = 0; k < 3; k++) { Qi[k] = F[k]; Qi[3 + k] = x[k] + y[k]; }
    mat3vec(cx->RjT, F, t);
    cross3(cx->armj, t, x);
    mat3vec(cx->RjT, tau, y);
    for (int k = 0; k < 3; k++) { Qj[k] = -F[k]; Qj[3 + k] = -x[k] - y[k]; }
}

/* Friction forces Qi, Qj (6 each) of axis joint j at its multipliers lam. */
void ovk_axis_friction_forces(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *Qi,
                              double *Qj) {
    const double *c = M->jconst + NJC * j, *sz = c + V_SIZE;
    if (M->jtype[j] == J_CYLINDRICAL) {
        double p[6];
        reaction_at(M, j, cx, lam, p);
        double scale = cx->mos * guide_normal_load(p, sz[0]);
        axial_loads(c, cx, scale * cx->slide, scale * (sz[1] * sz[1]) * cx->spin, Qi, Qj);
        return;
    }
    double out = ovk_axis_friction_output(M, j, cx, lam);
    if (M->jtype[j] == J_SREVOLUTE) axial_loads(c, cx, 0.0, out, Qi, Qj);
    else axial_loads(c, cx, out, 0.0, Qi, Qj); /* prismatic, point on line (u = R_j a_j): a force at P_i */
}

/* d(Qi, Qj)/d lam (6 x neq each, row-major) by forward differences,
 * step 1e-7 max(1, |lam_e|); the point-on-line joint's
 * analytically: its forces are |lam| times the loads of the force mu(v) u (v does not depend on
 * lam), so d/d lam_e is those loads times lam_e / |lam| (0 at lam = 0). */
void ovk_axis_friction_jac(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *dQi,
                           double *dQj) {
    int ne = M->jneq[j];
    double Qi[6], Qj[6], Pi[6], Pj[6], lp[OVK_MAXEQ];
    if (M->jtype[j] == J_POINT_LINE) {
        double N = hypot(lam[0], lam[1]);
        axial_loads(M->jconst + NJC * j, cx, cx->mu, 0.0, Qi, Qj);
        for (int k = 0; k < 6; k++)
            for (int e = 0; e < 2; e++) {
                dQi[2 * k + e] = N > 0.0 ? Qi[k] * (lam[e] / N) : 0.0;
                dQj[2 * k + e] = N > 0.0 ? Qj[k] * (lam[e] / N) : 0.0;
            }
        return;
    }
    ovk_axis_friction_forces(M, j, cx, lam, Qi, Qj);
    for (int e = 0; e < ne; e++) {
        double step = 1e-7 * fmax(1.0, fabs(lam[e]));
        memcpy(lp, lam, sizeof(double) * ne);
        lp[e] += step;
        ovk_axis_friction_forces(M, j, cx, lp, Pi, Pj);
        for (int k = 0; k < 6; k++) {
            dQi[k * ne + e] = (Pi[k] - Qi[k]) / step;
            dQj[k * ne + e] = (Pj[k] - Qj[k]) / step;
        }
    }
}
