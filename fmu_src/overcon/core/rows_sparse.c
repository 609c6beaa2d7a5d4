/* Phi and Phi_h at y by their nonzero pattern: every equation is nonzero on its joint's two
 * bodies' velocity columns only, so the pre-check reads Phi_h as m x 2 kh entries (kh velocities
 * per body) instead of the dense m x nh matrix of ovk_rows (api.c). The values are ovk_rows'. */
#include "core.h"

/* phi (m), and per equation r its entries cols[r * 2 kh + k] (column of Phi_h; -1 for an unused
 * slot: a body that is the base) and vals[r * 2 kh + k]: body i's kh columns, then body j's
 * (body j's slots unused when it is body i). */
int ovk_rows_sparse(const ovk_model *M, ovk_data *d, const double *y, double *phi, int *cols, double *vals) {
    int status = ovk_rows_in(M, d, y), kh = M->nh_b, w = 2 * M->nh_b;
    if (status) return status;
    for (int r = 0; r < M->m * w; r++) {
        cols[r] = -1;
        vals[r] = 0.0;
    }
    for (int r = 0; r < M->m; r++) phi[r] = d->phi[r];
    for (int j = 0; j < M->nj; j++) {
        int body[2] = {M->jbi[j], M->jbj[j] == M->jbi[j] ? -1 : M->jbj[j]};
        for (int e = 0; e < M->jneq[j]; e++) {
            int row = M->jrows[OVK_MAXEQ * j + e];
            for (int s = 0; s < 2; s++) {
                if (body[s] < 0) continue;
                for (int k = 0; k < kh; k++) {
                    int c = body[s] * kh + k;
                    cols[(size_t)row * w + s * kh + k] = c;
                    vals[(size_t)row * w + s * kh + k] = OVK_JROW(M, d->J, row)[s * kh + k];
                }
            }
        }
    }
    return OVK_OK;
}
