/* The singularity watch's weighting of the constraint rows (watch.c, watch_eig.c): the rows it
 * judges are equilibrated as the pre-check's decision matrix is (unique.c, analysis.equilibrate),
 * never weighted by the mass matrix, so its ratio r = sigma_min / sigma_max and its rank decisions
 * are invariant to how masses and inertias are scaled (a body of inertia 1e-12 kg m^2 on a
 * revolute joint 1 m from its centre of mass is as regular as one of 1 kg m^2) and to the units
 * of the coordinates (a column scaling). The rule, at one state:
 *   entries of a column of round-off only (max-norm <= 100 max(k, nh) eps max|W|) set to zero,
 *   rows likewise; then Ruiz sweeps (rows and columns to unit max-norm) until every max-norm is
 *   within RUIZ_TOL of 1, at most RUIZ_SWEEPS; then each row scaled to unit 2-norm (a zero row
 *   stays zero: the watch then reads r = 0 there).
 * The pre-check's constants (sweeps, tolerance). The column scaling is returned, so that the rows
 * at nearby states are weighted the same way: the forward difference of the rows in the watch's
 * dr/dt, and the golden-section search for a minimum of r inside a step, which both must see r
 * under one scaling (a scaling taken afresh could move r by up to RUIZ_TOL where the sweep count
 * changes); the watch takes it afresh once per check, at the step's end (watch.c). Rows are held
 * either densely (width = nh, body = NULL) or as watch_eig.c holds them: 2 kh values on the
 * columns of their two bodies body[2 r], body[2 r + 1] (-1: the ground, no column). */
#include <math.h>

#include "core.h"

#define RUIZ_SWEEPS 50   /* analysis._RUIZ_SWEEPS */
#define RUIZ_TOL 1e-3    /* analysis._RUIZ_TOL: max-norm deviation from 1 at which the sweeps stop */
#define NOISE 100.0      /* analysis.NOISE_FACTOR: round-off entries, relative to max |W| */
#define EPS 2.220446049250313e-16

/* Entry blocks of row r: with body, its two bodies' kh columns each (first column b kh, -1 for the
 * ground); dense, one block of the whole width. */
static int blocks(const int *body) { return body ? 2 : 1; }
static int block_first(const int *body, int kh, int r, int t) {
    if (!body) return 0;
    int b = body[2 * r + t];
    return b < 0 ? -1 : b * kh;
}

/* Rows scaled to unit 2-norm (a zero row left zero). */
static void unit_rows(double *w, int k, int width) {
    for (int r = 0; r < k; r++) {
        double *o = w + (size_t)r * width, n2 = 0.0;
        for (int i = 0; i < width; i++) n2 += o[i] * o[i];
        double n = sqrt(n2);
        for (int i = 0; n > 0.0 && i < width; i++) o[i] /= n;
    }
}

void ovk_watch_apply(double *w, int k, int width, const int *body, int kh, const double *scale) {
    int nblk = blocks(body), bw = body ? kh : width;
    for (int r = 0; r < k; r++)
        for (int t = 0; t < nblk; t++) {
            int first = block_first(body, kh, r, t);
            double *o = w + (size_t)r * width + (size_t)t * bw;
            for (int c = 0; c < bw; c++) o[c] = first < 0 ? 0.0 : o[c] * scale[first + c];
        }
    unit_rows(w, k, width);
}

void ovk_watch_scale(double *w, int k, int width, const int *body, int kh, int nh, double *scale, double *work) {
    int nblk = blocks(body), bw = body ? kh : width;
    double *cn = work, *rn = work + nh, amax = 0.0;
    for (int c = 0; c < nh; c++) scale[c] = 1.0, cn[c] = 0.0;
    for (int r = 0; r < k; r++) {
        rn[r] = 0.0;
        for (int t = 0; t < nblk; t++) {
            int first = block_first(body, kh, r, t);
            double *o = w + (size_t)r * width + (size_t)t * bw;
            for (int c = 0; c < bw; c++) {
                if (first < 0) {
                    o[c] = 0.0;
                    continue;
                }
                double a = fabs(o[c]);
                cn[first + c] = a > cn[first + c] ? a : cn[first + c];
                rn[r] = a > rn[r] ? a : rn[r];
                amax = a > amax ? a : amax;
            }
        }
    }
    if (amax > 0.0) {
        double floor = NOISE * (k > nh ? k : nh) * EPS * amax;
        for (int c = 0; c < nh; c++)
            if (cn[c] <= floor) scale[c] = 0.0; /* a column of round-off only */
        for (int r = 0; r < k; r++)
            for (int t = 0; t < nblk; t++) {
                int first = block_first(body, kh, r, t);
                double *o = w + (size_t)r * width + (size_t)t * bw;
                for (int c = 0; first >= 0 && c < bw; c++)
                    if (scale[first + c] == 0.0 || rn[r] <= floor) o[c] = 0.0;
            }
    }
    for (int sweep = 0; amax > 0.0 && sweep < RUIZ_SWEEPS; sweep++) {
        double dev = 0.0;
        for (int c = 0; c < nh; c++) cn[c] = 0.0;
        for (int r = 0; r < k; r++) {
            rn[r] = 0.0;
            for (int t = 0; t < nblk; t++) {
                int first = block_first(body, kh, r, t);
                const double *o = w + (size_t)r * width + (size_t)t * bw;
                for (int c = 0; first >= 0 && c < bw; c++) {
                    double a = fabs(o[c]);
                    cn[first + c] = a > cn[first + c] ? a : cn[first + c];
                    rn[r] = a > rn[r] ? a : rn[r];
                }
            }
            if (rn[r] > 0.0 && fabs(1.0 - rn[r]) > dev) dev = fabs(1.0 - rn[r]);
        }
        for (int c = 0; c < nh; c++)
            if (cn[c] > 0.0 && fabs(1.0 - cn[c]) > dev) dev = fabs(1.0 - cn[c]);
        if (dev <= RUIZ_TOL) break;
        for (int c = 0; c < nh; c++) {
            cn[c] = cn[c] > 0.0 ? 1.0 / sqrt(cn[c]) : 1.0;
            scale[c] *= cn[c];
        }
        for (int r = 0; r < k; r++) {
            double f = rn[r] > 0.0 ? 1.0 / sqrt(rn[r]) : 1.0;
            for (int t = 0; t < nblk; t++) {
                int first = block_first(body, kh, r, t);
                double *o = w + (size_t)r * width + (size_t)t * bw;
                for (int c = 0; first >= 0 && c < bw; c++) o[c] *= f * cn[first + c];
            }
        }
    }
    unit_rows(w, k, width);
}
