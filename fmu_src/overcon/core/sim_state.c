/* The state of a run as plain bytes (FMI get/set/serialize FMU state): every field that changes
 * during a run, in one fixed order written by one function for measuring, saving and loading, so
 * the three can never disagree. Layout: the magic "OVKSIM", a format version and the sizes (method,
 * n, ncols, m), which a load checks against the run it restores into, then the fields as native
 * bytes (a state is restored on the machine and build that saved it, as FMI requires). A restore
 * is exact: the same bits continue the same trajectory. The wall time spent is not part of the
 * state (Simulation.get_state leaves it out too). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"

#define STATE_MAGIC "OVKSIM"
#define STATE_VERSION 6

typedef struct {
    unsigned char *w;       /* saving: the next byte to write */
    const unsigned char *r; /* loading: the next byte to read */
    size_t size, cap;       /* bytes so far; capacity of the buffer */
    int bad;
} codec;

static void io(codec *c, void *x, size_t n) {
    if (c->size + n > c->cap) c->bad = 1;
    if (!c->bad && c->w) memcpy(c->w + c->size, x, n);
    if (!c->bad && c->r) memcpy(x, c->r + c->size, n);
    c->size += n;
}

static void io_hist(codec *c, ovk_hist *h, int nc) {
    io(c, &h->count, sizeof h->count);
    io(c, h->t, sizeof h->t);
    io(c, h->q[0], (size_t)nc * sizeof(double));
    io(c, h->q[1], (size_t)nc * sizeof(double));
}

/* The integrator: its counters and scalars, then the arrays that are state for its method (the
 * stages and dense output coefficients of the last step; radau's Jacobian, LU factors with their
 * pivots, and the last step's Z), each of a size fixed by the method and n, so every state of a run
 * has one size. dense_status is no state: a restored run computes the dense output again. */
static void io_rk(codec *c, ovk_rk *rk) {
    size_t n = (size_t)rk->n * sizeof(double);
    int ints[9] = {rk->has_K, rk->dense_ready, rk->n_stiff, rk->n_nonstiff, rk->n_limited, rk->current_jac,
                   rk->has_lu, rk->has_old, rk->dense_kept};
    long long counts[6] = {rk->k, rk->nfev, rk->nsteps, rk->stiff_steps, rk->njev, rk->nlu};
    double reals[9] = {rk->t, rk->h, rk->t0, rk->t_old, rk->h_old, rk->stable_step, rk->h_abs_old,
                       rk->error_norm_old, rk->lu_h};
    io(c, ints, sizeof ints);
    io(c, counts, sizeof counts);
    io(c, reals, sizeof reals);
    if (c->r && !c->bad) {
        rk->has_K = ints[0], rk->dense_ready = ints[1], rk->n_stiff = ints[2], rk->n_nonstiff = ints[3];
        rk->n_limited = ints[4], rk->current_jac = ints[5], rk->has_lu = ints[6], rk->has_old = ints[7];
        rk->dense_kept = ints[8];
        rk->k = counts[0], rk->nfev = counts[1], rk->nsteps = counts[2], rk->stiff_steps = counts[3];
        rk->njev = counts[4], rk->nlu = counts[5];
        rk->t = reals[0], rk->h = reals[1], rk->t0 = reals[2], rk->t_old = reals[3], rk->h_old = reals[4];
        rk->stable_step = reals[5], rk->h_abs_old = reals[6], rk->error_norm_old = reals[7], rk->lu_h = reals[8];
        rk->dense_status = OVK_OK;
    }
    io(c, rk->y, n);
    io(c, rk->f, n);
    io(c, rk->y_old, n);
    io(c, rk->f_old, n);
    io(c, rk->K, (size_t)rk->nK * n);
    io(c, rk->Q, (size_t)rk->nQ * n);
    if (rk->method == OVK_METHOD_RADAU) {
        io(c, rk->J, (size_t)rk->n * n);
        io(c, rk->LU, (size_t)rk->n * n);
        io(c, rk->LUc, 2 * (size_t)rk->n * n);
        io(c, rk->piv, 2 * (size_t)rk->n * sizeof(int)); /* piv and pivc */
        io(c, rk->Zs, 3 * n);
    }
}

/* The inputs (inputs.c): values, slopes and their time, as the host last set them (only in the
 * state of a model with inputs: the others' states are as before). */
static void io_inputs(codec *c, ovk_sim *s) {
    io(c, s->d->u, (2 * (size_t)s->M->nu + 1) * sizeof(double));
    io(c, &s->t_comm, sizeof s->t_comm);
    io(c, &s->t_changed, sizeof s->t_changed);
}

/* The header and every field of the run, in order. */
static void io_sim(codec *c, ovk_sim *s) {
    char magic[8] = STATE_MAGIC;
    int head[5] = {STATE_VERSION, s->rk.method, s->ny, s->ncols, s->m}, want[5];
    memcpy(want, head, sizeof head);
    io(c, magic, sizeof magic);
    io(c, head, sizeof head);
    if (c->r && !c->bad && (memcmp(magic, STATE_MAGIC, sizeof STATE_MAGIC) || memcmp(head, want, sizeof head)))
        c->bad = 2;
    io_rk(c, &s->rk);
    io(c, &s->has_lam, sizeof s->has_lam);
    io(c, s->lam, (size_t)s->m * sizeof(double));
    io_hist(c, &s->warm, s->ncols);
    io_hist(c, &s->step_warm, s->ncols);
    io(c, &s->has_last, sizeof s->has_last);
    io(c, &s->last_t, sizeof s->last_t);
    io(c, s->last_y, (size_t)s->ny * sizeof(double));
    io(c, s->last_lam, (size_t)s->m * sizeof(double));
    io(c, &s->friction_iterations, sizeof s->friction_iterations);
    io(c, &s->evaluations, sizeof s->evaluations);
    io(c, &s->max_drift, sizeof s->max_drift);
    io(c, &s->min_ratio, sizeof s->min_ratio);
    io(c, &s->t_prev, sizeof s->t_prev);
    io(c, &s->rate, sizeof s->rate);
    io(c, &s->ratio, sizeof s->ratio);
    if (s->eig) { /* the watch's tracked vectors (watch_eig.c): the warm start of its next estimate */
        io(c, &s->watch_capped, sizeof s->watch_capped);
        io(c, &s->eig->have, sizeof s->eig->have);
        io(c, s->eig->umin, (size_t)s->eig->nR * sizeof(double));
        io(c, s->eig->umax, (size_t)s->eig->nR * sizeof(double));
    }
    io(c, s->work_t, sizeof s->work_t);
    io(c, s->work_w, sizeof s->work_w);
    io(c, s->work_p, sizeof s->work_p);
    int *kept = c->r ? s->kept + 5 * s->m + 2 * OVK_MAXEQ * s->Mrun.nfj : (int *)s->Mrun.retained; /* load: scratch */
    io(c, kept, (size_t)s->Mrun.nR * sizeof(int)); /* the kept equations (chosen again during the run) */
    io(c, &s->along_rank, sizeof s->along_rank);
    io(c, s->along_unique, (size_t)s->M->nj * sizeof(int));
    io(c, &s->along_certified, sizeof s->along_certified);
    if (s->M->nu) io_inputs(c, s);
    io(c, &s->nevents, sizeof s->nevents); /* last: a load sizes the list from it (ovk_sim_set_state) */
    for (int k = 0; k < s->nevents && !c->bad; k++) io(c, &s->events[k], sizeof s->events[k]);
}

size_t ovk_sim_state_size(const ovk_sim *s) {
    if (!s || !s->mem) return 0;
    codec c = {NULL, NULL, 0, (size_t)-1, 0};
    io_sim(&c, (ovk_sim *)s); /* measuring: nothing is read or written */
    return c.size;
}

int ovk_sim_get_state(ovk_sim *s, unsigned char *buf, size_t size) {
    if (!s) return OVK_NOMEM;
    if (!s->mem || !buf) return snprintf(s->msg, sizeof s->msg, "get state: no run or no buffer"), OVK_INVALID;
    codec c = {buf, NULL, 0, size, 0};
    io_sim(&c, s);
    if (c.bad || c.size != size)
        return snprintf(s->msg, sizeof s->msg, "get state: a buffer of %zu bytes for a state of %zu", size,
                        ovk_sim_state_size(s)), OVK_INVALID;
    return OVK_OK;
}

/* 1 if x is 0 or 1. */
static int flag(long long x) { return x == 0 || x == 1; }

/* The fields a load put into the run, checked before anything computes with them: every index
 * against its bound (radau's pivots, the kept equations, the events' kinds and texts), every
 * counter non-negative, every flag 0 or 1, the integrator's times and step finite (its step > 0)
 * and its state vector finite. kept: the loaded kept equations (nR). 0, or 1 with the reason in
 * why. The numbers that only enter arithmetic (stages, multipliers, warm starts) are not bounded:
 * a wrong one ends in a refused step, never outside an array. */
static int loaded_bad(const ovk_sim *s, const int *kept, char *why, size_t size) {
    const ovk_rk *rk = &s->rk;
    const int *flags[] = {&rk->has_K, &rk->dense_ready, &rk->current_jac, &rk->has_lu, &rk->has_old, &s->has_lam,
                          &s->has_last, &rk->dense_kept};
    static const char *flag_names[] = {"has_K", "dense_ready", "current_jac", "has_lu", "has_old", "has_lam",
                                       "has_last", "dense_kept"};
    for (size_t k = 0; k < sizeof flags / sizeof flags[0]; k++)
        if (!flag(*flags[k])) return snprintf(why, size, "flag %s = %d (0 or 1)", flag_names[k], *flags[k]), 1;
    const long long counts[] = {rk->n_stiff, rk->n_nonstiff, rk->n_limited, rk->k, rk->nfev, rk->nsteps,
                                rk->stiff_steps, rk->njev, rk->nlu, s->friction_iterations, s->evaluations,
                                s->along_certified};
    for (size_t k = 0; k < sizeof counts / sizeof counts[0]; k++)
        if (counts[k] < 0) return snprintf(why, size, "counter %zu = %lld (>= 0)", k, counts[k]), 1;
    const double times[] = {rk->t, rk->t0, rk->t_old, rk->h_old, rk->h_abs_old, rk->error_norm_old, rk->lu_h,
                            s->last_t, s->t_prev};
    for (size_t k = 0; k < sizeof times / sizeof times[0]; k++)
        if (!isfinite(times[k])) return snprintf(why, size, "integrator number %zu = %g (finite)", k, times[k]), 1;
    if (!(isfinite(rk->h) && rk->h > 0.0)) return snprintf(why, size, "step h = %g (finite, > 0)", rk->h), 1;
    if (isnan(rk->stable_step) || rk->stable_step < 0.0)
        return snprintf(why, size, "stable step = %g (>= 0)", rk->stable_step), 1;
    for (int i = 0; i < rk->n; i++)
        if (!isfinite(rk->y[i])) return snprintf(why, size, "y[%d] = %g (finite)", i, rk->y[i]), 1;
    if (rk->method == OVK_METHOD_RADAU)
        for (int i = 0; i < 2 * rk->n; i++) /* piv then pivc, n each (one block) */
            if (rk->piv[i] < 0 || rk->piv[i] >= rk->n)
                return snprintf(why, size, "radau pivot %s[%d] = %d (0 to %d)", i < rk->n ? "piv" : "pivc",
                                i % rk->n, rk->piv[i], rk->n - 1), 1;
    const ovk_hist *hist[2] = {&s->warm, &s->step_warm};
    for (int k = 0; k < 2; k++) {
        if (hist[k]->count < 0 || hist[k]->count > 2)
            return snprintf(why, size, "warm start count = %d (0 to 2)", hist[k]->count), 1;
        for (int i = 0; i < hist[k]->count; i++)
            if (!isfinite(hist[k]->t[i])) return snprintf(why, size, "warm start time = %g (finite)", hist[k]->t[i]), 1;
    }
    for (int p = 0; p < s->Mrun.nR; p++)
        if (kept[p] < 0 || kept[p] >= s->m || (p && kept[p] <= kept[p - 1]))
            return snprintf(why, size, "kept equation %d = %d (ascending, 0 to %d)", p, kept[p], s->m - 1), 1;
    if (s->along_rank < 0 || s->along_rank > s->m)
        return snprintf(why, size, "rank along the motion = %d (0 to %d)", s->along_rank, s->m), 1;
    for (int k = 0; k < 2 * s->M->nu + 1; k++) /* the inputs: finite, as ovk_set_inputs takes them */
        if (!isfinite(s->d->u[k])) return snprintf(why, size, "input entry %d = %g (finite)", k, s->d->u[k]), 1;
    for (int j = 0; j < s->M->nj; j++)
        if (!flag(s->along_unique[j])) return snprintf(why, size, "reaction_unique[%d] = %d (0 or 1)", j, s->along_unique[j]), 1;
    if (s->eig && (!flag(s->eig->have) || s->watch_capped < 0))
        return snprintf(why, size, "watch: have = %d, capped = %lld", s->eig->have, s->watch_capped), 1;
    for (int k = 0; k < s->nevents; k++) {
        const ovk_event *e = &s->events[k];
        if (!isfinite(e->t) || e->kind < OVK_EV_SINGULAR || e->kind > OVK_EV_STOPPED ||
            !memchr(e->detail, '\0', sizeof e->detail))
            return snprintf(why, size, "event %d: time %g, kind %d (0 to 4), text %s", k, e->t, e->kind,
                            memchr(e->detail, '\0', sizeof e->detail) ? "ended" : "not ended"), 1;
    }
    return 0;
}

/* Restores a state saved by ovk_sim_get_state of a run of the same model and method; the run's
 * status is cleared (a stopped run continues from the restored state). A state of another
 * size, format or run is refused and the run is left as it was. The bytes are read into the run's
 * fields and every field is checked (loaded_bad) before anything computes with them; a state that
 * fails is refused with the reason, and the run's own state, kept aside before the load, is put
 * back (the run continues as if the call had not happened). */
static int load(ovk_sim *s, const unsigned char *buf, size_t size, char *why, size_t whysize) {
    codec c = {NULL, buf, 0, size, 0};
    io_sim(&c, s); /* nevents is read before the events: the loop reads the saved ones */
    const int *kept = s->kept + 5 * s->m + 2 * OVK_MAXEQ * s->Mrun.nfj;
    if (loaded_bad(s, kept, why, whysize)) return OVK_INVALID;
    if (memcmp(kept, s->Mrun.retained, (size_t)s->Mrun.nR * sizeof(int))) { /* another kept set: its arrays */
        int status = ovk_sim_use_kept(s, kept);
        if (status) return snprintf(why, whysize, "%s", s->msg), status;
    }
    return OVK_OK;
}

int ovk_sim_set_state(ovk_sim *s, const unsigned char *buf, size_t size) {
    if (!s) return OVK_NOMEM;
    /* the size of a state of this run with the saved number of events (the last int before them) */
    size_t fixed = ovk_sim_state_size(s) - (size_t)s->nevents * sizeof(ovk_event), need = fixed;
    int saved = -1;
    if (buf && size >= fixed) {
        memcpy(&saved, buf + fixed - sizeof saved, sizeof saved);
        need = saved >= 0 && (size_t)saved <= (size - fixed) / sizeof(ovk_event)
                   ? fixed + (size_t)saved * sizeof(ovk_event) : 0;
    }
    if (!s->mem || !s->eig || !buf || size != need)
        return snprintf(s->msg, sizeof s->msg, "set state: %zu bytes, a state of this run has %zu", size, need),
               OVK_INVALID;
    if (saved > s->cap_events) { /* room for the saved events before anything is overwritten */
        ovk_event *grown = realloc(s->events, (size_t)saved * sizeof *grown);
        if (!grown) return snprintf(s->msg, sizeof s->msg, "set state: out of memory for %d events", saved), OVK_NOMEM;
        s->events = grown;
        s->cap_events = saved;
    }
    codec probe = {NULL, buf, 0, size, 0};
    char magic[8];
    int head[5], want[5] = {STATE_VERSION, s->rk.method, s->ny, s->ncols, s->m};
    io(&probe, magic, sizeof magic);
    io(&probe, head, sizeof head);
    if (memcmp(magic, STATE_MAGIC, sizeof STATE_MAGIC) || memcmp(head, want, sizeof want))
        return snprintf(s->msg, sizeof s->msg, "set state: not a state of this run (format %d, method %d, %d "
                        "states, %d friction columns, %d rows)", head[0], head[1], head[2], head[3], head[4]),
               OVK_INVALID;
    size_t own_size = ovk_sim_state_size(s);
    unsigned char *own = malloc(own_size ? own_size : 1);
    if (!own) return snprintf(s->msg, sizeof s->msg, "set state: out of memory (%zu bytes)", own_size), OVK_NOMEM;
    int status = ovk_sim_get_state(s, own, own_size);
    char why[OVK_MSG] = "";
    if (!status && (status = load(s, buf, size, why, sizeof why))) {
        char ignored[OVK_MSG];
        int back = load(s, own, own_size, ignored, sizeof ignored); /* the run's own state: checked before */
        snprintf(s->msg, sizeof s->msg, "set state: refused: %.900s%s", why,
                 back ? " (and the previous state could not be put back)" : "");
        if (back) s->status = back;
    }
    free(own);
    if (status) return status;
    ovk_sim_watch_adopt(s);
    s->status = OVK_OK;
    s->msg[0] = '\0';
    return OVK_OK;
}
