/* The C core's test driver (ci/sanitize.sh builds it with the core under AddressSanitizer and
 * UndefinedBehaviorSanitizer): reads the cases make_cases.py wrote, packs each model into an
 * ovk_model whose arrays are allocated to their exact length (so any read past them is caught),
 * and evaluates every case REPS times in each of two workspaces, interleaved, requiring the same
 * status, friction force evaluations, damped flag and, for a success, the same bits of y', lam, qf,
 * the reactions and friction outputs as the installed core gave; a failure must come with a
 * message and a success without one. Also: a model the core must refuse, an invalid guess mode,
 * a null model and a null workspace, each a status with a message.
 *
 * Usage: driver CASES [REPS]   (exit 0: all as expected; 1: a difference, printed; 2: bad input) */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"

#define NFIELDS 38 /* the arrays of ovk_model: 25, the redundancy block 10, the inputs 3 */
#define MAX_ITEMS (1 << 24)

typedef struct {
    const unsigned char *p, *end;
    int bad; /* 1 truncated or malformed, 2 out of memory */
} reader;

static void rd(reader *r, void *out, size_t n) {
    if (r->bad || (size_t)(r->end - r->p) < n) {
        if (!r->bad) r->bad = 1;
        memset(out, 0, n);
        return;
    }
    memcpy(out, r->p, n);
    r->p += n;
}
static int rd_i32(reader *r) {
    int32_t v;
    rd(r, &v, sizeof v);
    return (int)v;
}

/* An array: int32 length, then the items; allocated to exactly that length (one item if empty). */
static void *rd_array(reader *r, size_t item, int *count) {
    int n = rd_i32(r);
    *count = 0;
    if (r->bad) return NULL;
    if (n < 0 || n > MAX_ITEMS) { r->bad = 1; return NULL; }
    void *a = malloc((size_t)(n ? n : 1) * item);
    if (!a) { r->bad = 2; return NULL; }
    rd(r, a, (size_t)n * item);
    if (r->bad) { free(a); return NULL; }
    *count = n;
    return a;
}

typedef struct {
    ovk_model M;
    void *arrays[NFIELDS];
    int n_arrays;
    ovk_data *d[2];
} model_t;

static void free_model(model_t *m) {
    for (int i = 0; i < m->n_arrays; i++) free(m->arrays[i]);
    ovk_free_data(m->d[0]);
    ovk_free_data(m->d[1]);
    memset(m, 0, sizeof *m);
}

static const void *keep(model_t *m, reader *r, size_t item) {
    int n;
    void *a = rd_array(r, item, &n);
    if (a) m->arrays[m->n_arrays++] = a;
    return a;
}

static int read_model(reader *r, model_t *m) {
    memset(m, 0, sizeof *m);
    ovk_model *M = &m->M;
    int *counts[] = {&M->dim, &M->nb, &M->nq_b, &M->nh_b, &M->m, &M->nR, &M->nj, &M->nl,
                     &M->nx, &M->ncols, &M->nfj, &M->nfg, &M->max_iter};
    for (size_t i = 0; i < sizeof counts / sizeof counts[0]; i++) *counts[i] = rd_i32(r);
    rd(r, &M->baumgarte, sizeof M->baumgarte);
    rd(r, &M->tol, sizeof M->tol);
    size_t I = sizeof(int), D = sizeof(double);
    M->retained = keep(m, r, I);
    M->Minv = keep(m, r, D);
    M->mass = keep(m, r, D);
    M->inertia = keep(m, r, D);
    M->gravity = keep(m, r, D);
    M->jtype = keep(m, r, I);
    M->jbi = keep(m, r, I);
    M->jbj = keep(m, r, I);
    M->jneq = keep(m, r, I);
    M->jrows = keep(m, r, I);
    M->jconst = keep(m, r, D);
    M->jlaw = keep(m, r, I);
    M->jlawp = keep(m, r, D);
    M->ltype = keep(m, r, I);
    M->lbi = keep(m, r, I);
    M->lbj = keep(m, r, I);
    M->lp = keep(m, r, D);
    M->xrows = keep(m, r, I);
    M->cols = keep(m, r, I);
    M->fj = keep(m, r, I);
    M->fgroup = keep(m, r, I);
    M->fx = keep(m, r, I);
    M->fci = keep(m, r, I);
    M->fcj = keep(m, r, I);
    M->rbody = keep(m, r, I);
    int *red[] = {&M->redundancy, &M->nrig, &M->nax, &M->nwatch, &M->nfull}; /* the redundancy block */
    for (size_t i = 0; i < sizeof red / sizeof red[0]; i++) *red[i] = rd_i32(r);
    M->ckind = keep(m, r, I);
    M->ck = keep(m, r, D);
    M->cd = keep(m, r, D);
    M->rigpos = keep(m, r, I);
    M->rigrows = keep(m, r, I);
    M->rigbody = keep(m, r, I);
    M->axi = keep(m, r, I);
    M->axp = keep(m, r, D);
    M->watch = keep(m, r, I);
    M->full = keep(m, r, I);
    M->formulation = rd_i32(r);
    M->nu = rd_i32(r); /* the inputs (core/inputs.c) */
    M->ukind = keep(m, r, I);
    M->uidx = keep(m, r, I);
    M->up = keep(m, r, D);
    if (r->bad) return 0;
    for (int w = 0; w < 2; w++) {
        m->d[w] = ovk_make_data(M);
        if (!m->d[w]) { r->bad = 2; return 0; }
    }
    return 1;
}

typedef struct {
    int models, evaluations, calls, failures, statuses[8], damped;
} tally;

static void fail(tally *t, const char *what) {
    if (t->failures++ < 20) fprintf(stderr, "driver: %s\n", what);
}

static void compare(tally *t, const char *where, const char *name, const double *got, const double *want, int n) {
    for (int i = 0; i < n; i++)
        if (memcmp(got + i, want + i, sizeof(double))) {
            char msg[512];
            snprintf(msg, sizeof msg, "%s: %s[%d] = %.17g, expected %.17g", where, name, i, got[i], want[i]);
            fail(t, msg);
            return;
        }
}

/* One 'E' record: evaluated reps times in each workspace, interleaved. Returns 0 on bad input. */
static int run_evaluation(reader *r, model_t *m, int reps, tally *t) {
    const ovk_model *M = &m->M;
    int ok = 0, ny = 0, ng = 0, n_exp[5] = {0};
    double *y = NULL, *guess = NULL, *exp[5] = {NULL}, *out[5] = {NULL};
    int mode = rd_i32(r);
    y = rd_array(r, sizeof(double), &ny);
    guess = rd_array(r, sizeof(double), &ng);
    int status = rd_i32(r), its = rd_i32(r), damped = rd_i32(r), rstatus = -1, n_r0 = 0, n_r1 = 0;
    double *robust[2] = {NULL, NULL};
    if (status == OVK_FRICTION) { /* the robust path's outcome */
        rstatus = rd_i32(r);
        if (rstatus == 0) robust[0] = rd_array(r, sizeof(double), &n_r0), robust[1] = rd_array(r, sizeof(double), &n_r1);
    }
    int n = M->nb * M->nq_b, nh = M->nb * M->nh_b;
    int sizes[5] = {n + nh, M->m, M->ncols, OVK_NREAC * M->nj, M->nj};
    const char *names[5] = {"ydot", "lam", "qf", "reactions", "friction"};
    if (status == 0)
        for (int k = 0; k < 5; k++) exp[k] = rd_array(r, sizeof(double), &n_exp[k]);
    if (r->bad) goto done;
    if (ny != n + nh || status < 0 || status > 7 || (status == 0 && (n_exp[0] != sizes[0] || n_exp[1] != sizes[1] ||
        n_exp[2] != sizes[2] || n_exp[3] != sizes[3] || n_exp[4] != sizes[4]))) {
        r->bad = 1;
        goto done;
    }
    for (int k = 0; k < 5; k++) {
        out[k] = malloc((size_t)(sizes[k] ? sizes[k] : 1) * sizeof(double));
        if (!out[k]) { r->bad = 2; goto done; }
    }
    t->evaluations++;
    t->statuses[status]++;
    t->damped += status == 0 && damped;
    for (int rep = 0; rep < reps; rep++)
        for (int w = 0; w < 2; w++) {
            char where[160];
            snprintf(where, sizeof where, "model %d, evaluation %d, workspace %d, repetition %d", t->models,
                     t->evaluations, w, rep);
            for (int k = 0; k < 5; k++)
                for (int i = 0; i < (sizes[k] ? sizes[k] : 1); i++) out[k][i] = -1.0e300; /* stale values show */
            int got_its = -1, got_damped = -1;
            int got = ovk_evaluate(M, m->d[w], 0.0, y, mode, ng ? guess : NULL, out[0], out[1], out[2], &got_its,
                                   &got_damped);
            t->calls++;
            const char *msg = ovk_message(m->d[w]);
            char line[640];
            if (got != status || got_its != its || got_damped != damped) {
                snprintf(line, sizeof line, "%s: status %d, %d force evaluations, damped %d; expected %d, %d, %d (%s)",
                         where, got, got_its, got_damped, status, its, damped, msg);
                fail(t, line);
                continue;
            }
            if ((status != 0) != (msg[0] != '\0')) {
                snprintf(line, sizeof line, "%s: status %d with message \"%s\"", where, status, msg);
                fail(t, line);
            }
            if (status == OVK_FRICTION) { /* finished by the robust path, or given up, as the installed core */
                int more = 0, got_r = ovk_evaluate_robust(M, m->d[w], y, mode == 2 ? guess : NULL, out[0], out[1],
                                                          out[2], &more);
                t->calls++;
                if (got_r != rstatus) {
                    snprintf(line, sizeof line, "%s: robust path status %d, expected %d (%s)", where, got_r, rstatus,
                             ovk_message(m->d[w]));
                    fail(t, line);
                } else if (got_r == 0 && n_r0 == sizes[0] && n_r1 == sizes[1]) {
                    compare(t, where, "robust ydot", out[0], robust[0], sizes[0]);
                    compare(t, where, "robust lam", out[1], robust[1], sizes[1]);
                }
            }
            if (status) continue;
            compare(t, where, names[0], out[0], exp[0], sizes[0]);
            compare(t, where, names[1], out[1], exp[1], sizes[1]);
            compare(t, where, names[2], out[2], exp[2], sizes[2]);
            if (ovk_outputs(M, m->d[w], y, out[1], out[3], out[4]) != OVK_OK) {
                snprintf(line, sizeof line, "%s: ovk_outputs failed (%s)", where, ovk_message(m->d[w]));
                fail(t, line);
                continue;
            }
            t->calls++;
            compare(t, where, names[3], out[3], exp[3], sizes[3]);
            compare(t, where, names[4], out[4], exp[4], sizes[4]);
            /* uniqueness along the motion (unique.c): twice, the same rank and verdicts */
            int rank[2] = {-1, -2}, *uq = calloc(2 * (size_t)M->nj + 2, sizeof(int));
            if (!uq || ovk_unique(M, m->d[w], y, &rank[0], uq) || ovk_unique(M, m->d[w], y, &rank[1], uq + M->nj + 1) ||
                rank[0] != rank[1] || rank[0] < 0 || rank[0] > M->m ||
                memcmp(uq, uq + M->nj + 1, (size_t)M->nj * sizeof(int))) {
                snprintf(line, sizeof line, "%s: ovk_unique failed or differs between calls (%s)", where,
                         ovk_message(m->d[w]));
                fail(t, line);
            }
            free(uq);
        }
    ok = 1;
done:
    free(robust[0]);
    free(robust[1]);
    free(y);
    free(guess);
    for (int k = 0; k < 5; k++) { free(exp[k]); free(out[k]); }
    return ok;
}

/* What the core must refuse, each with a status and a message. */
static void refusals(model_t *m, tally *t) {
    ovk_model bad = m->M;
    bad.nx = OVK_MAXEQ * bad.nfj + 1; /* more friction multipliers than the friction joints have equations */
    ovk_data *d = ovk_make_data(&bad);
    if (!d) { fail(t, "refusals: out of memory"); return; }
    if (ovk_data_status(d) != OVK_INVALID || !ovk_message(d)[0]) fail(t, "refusals: more friction multipliers than equations accepted");
    ovk_free_data(d);
    bad = m->M;
    bad.dim = 4;
    d = ovk_make_data(&bad);
    if (!d) { fail(t, "refusals: out of memory"); return; }
    if (ovk_data_status(d) != OVK_INVALID || !ovk_message(d)[0]) fail(t, "refusals: dimension 4 accepted");
    double ydot_dummy = 0.0;
    int its, damped;
    if (ovk_evaluate(&bad, d, 0.0, &ydot_dummy, 0, NULL, &ydot_dummy, &ydot_dummy, &ydot_dummy, &its, &damped) !=
        OVK_INVALID)
        fail(t, "refusals: a refused workspace evaluated");
    ovk_free_data(d);
    bad = m->M;
    bad.formulation = 2;
    d = ovk_make_data(&bad);
    if (!d) { fail(t, "refusals: out of memory"); return; }
    if (ovk_data_status(d) != OVK_INVALID || !ovk_message(d)[0]) fail(t, "refusals: formulation 2 accepted");
    double drift = 0.0;
    if (ovk_project(&bad, d, 0.0, &ydot_dummy, 1e-11, 20, &drift) != OVK_INVALID)
        fail(t, "refusals: a refused workspace projected");
    ovk_free_data(d);
    d = ovk_make_data(NULL);
    if (!d) { fail(t, "refusals: out of memory"); return; }
    if (ovk_data_status(d) != OVK_INVALID || !ovk_message(d)[0]) fail(t, "refusals: a null model accepted");
    ovk_free_data(d);
    if (ovk_evaluate(&m->M, NULL, 0.0, NULL, 0, NULL, NULL, NULL, NULL, &its, &damped) != OVK_NOMEM)
        fail(t, "refusals: a null workspace evaluated");
    int n = m->M.nb * (m->M.nq_b + m->M.nh_b);
    double *y = calloc((size_t)n, sizeof(double)), *yd = calloc((size_t)n, sizeof(double));
    double *lam = calloc((size_t)m->M.m, sizeof(double)), *qf = calloc((size_t)(m->M.ncols + 1), sizeof(double));
    if (y && yd && lam && qf) {
        if (ovk_evaluate(&m->M, m->d[0], 0.0, y, 3, qf, yd, lam, qf, &its, &damped) != OVK_INVALID ||
            !ovk_message(m->d[0])[0])
            fail(t, "refusals: guess mode 3 accepted");
        if (ovk_evaluate(&m->M, m->d[0], 0.0, y, 1, NULL, yd, lam, qf, &its, &damped) != OVK_INVALID)
            fail(t, "refusals: guess mode 1 without a guess accepted");
        double drift = 0.0;
        if (ovk_project(&m->M, m->d[0], 0.0, y, 0.0, 20, &drift) != OVK_INVALID || !ovk_message(m->d[0])[0])
            fail(t, "refusals: a projection with tolerance 0 accepted");
    } else {
        fail(t, "refusals: out of memory");
    }
    free(y);
    free(yd);
    free(lam);
    free(qf);
}

/* ovk_sim_watch_extremes at the run's state y, warm and cold: 0 <= sigma_min <= sigma_max, and the
 * run left as it was (its state's bytes before and after). */
static void watch_extremes(ovk_sim *s, const double *y, tally *t) {
    size_t size = ovk_sim_state_size(s);
    unsigned char *before = malloc(size ? size : 1), *after = malloc(size ? size : 1);
    double ex[2] = {0.0, 0.0};
    if (!before || !after || ovk_sim_get_state(s, before, size)) fail(t, "watch extremes: no state");
    for (int cold = 0; cold < 2 && before && after; cold++) {
        if (ovk_sim_watch_extremes(s, y, cold, ex)) fail(t, ovk_sim_message(s));
        else if (!(ex[0] >= 0.0 && ex[0] <= ex[1] * (1.0 + 1e-12))) fail(t, "watch extremes: sigma_min > sigma_max");
    }
    if (before && after && (ovk_sim_get_state(s, after, size) || memcmp(before, after, size)))
        fail(t, "watch extremes: the run's state changed");
    free(before);
    free(after);
}

#define OVK_MAX_JOINTS_CHECKED 64 /* the grid's check reads the first reaction entry of at most these joints */

/* The same run through ovk_sim_grid (core/sim_out.c) over 4 points to the end, with a plan of every
 * entry of y, the energies (with the ledger), every joint's first reaction entry and friction
 * output: the last row must give the installed core's y, reactions, friction outputs and energies
 * bits; then the refusals of a plan out of range, times not ascending, and an empty grid. */
static void run_grid(const model_t *m, const ovk_sim_opts *o, const double *y0, int n_y, double t_end, int want_status,
                     const double *want_y, const double *want_reac, int n_r, const double *want_fric, int n_f,
                     const double *want_en, int n_en, tally *t) {
    int nj = m->M.nj, nout = n_y + (o->energy ? 4 : 0) + 2 * nj, k = 0;
    ovk_out *plan = calloc((size_t)nout + 1, sizeof *plan);
    double times[4] = {0.25 * t_end, 0.5 * t_end, 0.75 * t_end, t_end}, *values = calloc(4 * (size_t)nout + 1, sizeof(double));
    ovk_sim *s = ovk_sim_new(&m->M, o, 0.0, y0);
    if (!plan || !values || !s) {
        fail(t, "grid: out of memory");
        free(plan), free(values), ovk_sim_free(s);
        return;
    }
    for (int i = 0; i < n_y; i++) plan[k++] = (ovk_out){OVK_OUT_STATE, i, 0};
    for (int i = 0; o->energy && i < 4; i++) plan[k++] = (ovk_out){OVK_OUT_ENERGY, i, 0};
    for (int j = 0; j < nj; j++) plan[k++] = (ovk_out){OVK_OUT_REACTION, j, 0};
    for (int j = 0; j < nj; j++) plan[k++] = (ovk_out){OVK_OUT_FRICTION, j, 0};
    long long rows = -1;
    int status = ovk_sim_status(s);
    if (!status) status = ovk_sim_grid(s, plan, nout, times, 4, values, &rows);
    if (status != want_status) fail(t, ovk_sim_message(s));
    if (!status) {
        const double *last = values + 3 * (size_t)nout;
        double reac0[OVK_MAX_JOINTS_CHECKED], en[4];
        int nr = nj < OVK_MAX_JOINTS_CHECKED ? nj : OVK_MAX_JOINTS_CHECKED;
        if (rows != 4) fail(t, "grid: not every row written");
        compare(t, "grid", "y", last, want_y, n_y);
        for (int j = 0; j < nr && j * OVK_NREAC < n_r; j++) reac0[j] = want_reac[j * OVK_NREAC];
        compare(t, "grid", "reactions", last + n_y + (o->energy ? 4 : 0), reac0, n_r ? nr : 0);
        compare(t, "grid", "friction", last + n_y + (o->energy ? 4 : 0) + nj, want_fric, n_f < nj ? n_f : nj);
        for (int i = 0; i < 4 && o->energy; i++) en[i] = last[n_y + i];
        if (o->energy) compare(t, "grid", "energies", en, want_en, n_en < 4 ? n_en : 4);
        ovk_out bad = {4, 0, 0};
        double back[2] = {t_end, 0.5 * t_end};
        if (ovk_sim_grid(s, &bad, 1, times, 1, values, &rows) != OVK_INVALID || rows != 0)
            fail(t, "grid: a plan of kind 4 was not refused");
        if (ovk_sim_grid(s, plan, nout, back, 2, values, &rows) != OVK_INVALID) fail(t, "grid: times going back");
        if (ovk_sim_grid(s, plan, nout, times, 0, NULL, &rows) || rows != 0) fail(t, "grid: an empty grid");
    } else if (rows < 0 || rows > 3) {
        fail(t, "grid: a stopped run's rows");
    }
    t->calls++;
    free(plan);
    free(values);
    ovk_sim_free(s);
}

/* An 'R' record: the run in C twice, each saving its state half-way, finishing, restoring the
 * state and finishing again; every finish must give the installed core's bits. */
static int run_sim(reader *r, model_t *m, tally *t) {
    int method = rd_i32(r), energy = rd_i32(r), n_y = 0, n_e = 0, n_i = 0, n_r = 0, n_f = 0;
    double v[4];
    rd(r, v, sizeof v);
    double *y0 = rd_array(r, sizeof(double), &n_y);
    int want_status = rd_i32(r);
    double *want_y = rd_array(r, sizeof(double), &n_e), *want_info = rd_array(r, sizeof(double), &n_i);
    double *want_reac = rd_array(r, sizeof(double), &n_r), *want_fric = rd_array(r, sizeof(double), &n_f);
    int n_en = 0;
    double *want_en = rd_array(r, sizeof(double), &n_en), en[4] = {0.0, 0.0, 0.0, 0.0};
    double *y = calloc((size_t)(n_y ? n_y : 1), sizeof(double)), info[OVK_SIM_NINFO];
    double *reac = calloc((size_t)(n_r ? n_r : 1), sizeof(double)), *fric = calloc((size_t)(n_f ? n_f : 1), sizeof(double));
    ovk_sim_opts o = {{method, 1, v[0], v[1], 0.0, v[2]}, 0, 0.0, 1e-6, v[3], energy};
    for (int rep = 0; rep < 2 && !r->bad && y && reac && fric; rep++) {
        ovk_sim *s = ovk_sim_new(&m->M, &o, 0.0, y0);
        if (!s) { r->bad = 2; break; }
        int status = ovk_sim_status(s);
        size_t size = ovk_sim_state_size(s);
        unsigned char *saved = size ? malloc(size) : NULL;
        if (!status) status = ovk_sim_advance(s, v[3] / 2, -1, 0.0, y);
        if (!status && saved) status = ovk_sim_get_state(s, saved, size);
        for (int again = 0; again < 2 && !status; again++) {
            if (again) status = ovk_sim_set_state(s, saved, size);
            if (!status) status = ovk_sim_advance(s, v[3], -1, 0.0, y);
            if (!status) status = ovk_sim_outputs(s, v[3], y, reac, fric);
            if (!status) status = ovk_sim_energy(s, v[3], y, en);
            ovk_sim_info(s, info);
            if (status != want_status) fail(t, ovk_sim_message(s));
            if (!status) {
                compare(t, "run", "y", y, want_y, n_e);
                compare(t, "run", "info", info, want_info, n_i < OVK_SIM_NINFO ? n_i : OVK_SIM_NINFO);
                compare(t, "run", "reactions", reac, want_reac, n_r);
                compare(t, "run", "friction", fric, want_fric, n_f);
                compare(t, "run", "energies", en, want_en, n_en < 4 ? n_en : 4);
            }
            if (!status && again) watch_extremes(s, y, t);
        }
        if (!saved) fail(t, "run: no state to save");
        free(saved);
        ovk_sim_free(s);
        t->calls++;
    }
    if (!r->bad) run_grid(m, &o, y0, n_y, v[3], want_status, want_y, want_reac, n_r, want_fric, n_f, want_en, n_en, t);
    free(y0); free(want_y); free(want_info); free(want_reac); free(want_fric); free(want_en);
    free(y); free(reac); free(fric);
    return !r->bad;
}

/* A 'P' record: ovk_project in both workspaces, reps times; every call must give the installed
 * core's status, state and drift bits. */
static int run_projection(reader *r, model_t *m, int reps, tally *t) {
    double tol;
    rd(r, &tol, sizeof tol);
    int max_iter = rd_i32(r), n_y = 0, n_o = 0, n_d = 0;
    double *y0 = rd_array(r, sizeof(double), &n_y);
    int want_status = rd_i32(r);
    double *want_y = rd_array(r, sizeof(double), &n_o), *want_d = rd_array(r, sizeof(double), &n_d);
    double *y = calloc((size_t)(n_y ? n_y : 1), sizeof(double));
    for (int rep = 0; rep < reps && !r->bad && y; rep++)
        for (int w = 0; w < 2; w++) {
            memcpy(y, y0, sizeof(double) * (size_t)n_y);
            double drift = -1.0;
            int status = ovk_project(&m->M, m->d[w], 0.0, y, tol, max_iter, &drift);
            if (status != want_status) fail(t, ovk_message(m->d[w]));
            if (!status) {
                compare(t, "project", "y", y, want_y, n_o < n_y ? n_o : n_y);
                compare(t, "project", "drift", &drift, want_d, n_d < 1 ? n_d : 1);
            }
            t->calls++;
        }
    if (!y) r->bad = 2;
    free(y0); free(want_y); free(want_d); free(y);
    return !r->bad;
}

int main(int argc, char **argv) {
    if (argc < 2 || argc > 3) {
        fprintf(stderr, "usage: %s CASES [REPS]\n", argv[0]);
        return 2;
    }
    int reps = argc == 3 ? atoi(argv[2]) : 5;
    if (reps < 1) reps = 1;
    FILE *fp = fopen(argv[1], "rb");
    if (!fp) { perror(argv[1]); return 2; }
    if (fseek(fp, 0, SEEK_END) || ftell(fp) < 8 || fseek(fp, 0, SEEK_SET)) {
        fprintf(stderr, "driver: %s: not a cases file\n", argv[1]);
        fclose(fp);
        return 2;
    }
    fseek(fp, 0, SEEK_END);
    size_t size = (size_t)ftell(fp);
    rewind(fp);
    unsigned char *buf = malloc(size);
    if (!buf) { fprintf(stderr, "driver: out of memory (%zu bytes)\n", size); fclose(fp); return 2; }
    size_t got = fread(buf, 1, size, fp);
    fclose(fp);
    if (got != size || memcmp(buf, "OVKCASE1", 8)) {
        fprintf(stderr, "driver: %s: not a cases file (OVKCASE1)\n", argv[1]);
        free(buf);
        return 2;
    }
    reader r = {buf + 8, buf + size, 0};
    tally t = {0};
    model_t m = {0};
    int have_model = 0;
    while (!r.bad && r.p < r.end) {
        unsigned char tag = *r.p++;
        if (tag == 'M') {
            if (have_model) free_model(&m);
            have_model = read_model(&r, &m);
            if (have_model) {
                if (ovk_data_status(m.d[0]) || ovk_data_status(m.d[1])) {
                    fprintf(stderr, "driver: model %d refused: %s\n", t.models + 1, ovk_message(m.d[0]));
                    r.bad = 1;
                    break;
                }
                t.models++;
                if (t.models == 1) refusals(&m, &t);
            }
        } else if (tag == 'E' && have_model) {
            run_evaluation(&r, &m, reps, &t);
        } else if (tag == 'R' && have_model) {
            run_sim(&r, &m, &t);
        } else if (tag == 'P' && have_model) {
            run_projection(&r, &m, reps, &t);
        } else {
            r.bad = 1;
        }
    }
    if (have_model) free_model(&m);
    free(buf);
    if (r.bad) {
        fprintf(stderr, "driver: %s: %s after model %d, evaluation %d\n", argv[1],
                r.bad == 2 ? "out of memory" : "truncated or malformed", t.models, t.evaluations);
        return 2;
    }
    printf("driver: %d models, %d evaluations x %d repetitions x 2 workspaces: %d core calls; statuses", t.models,
           t.evaluations, reps, t.calls);
    for (int s = 0; s < 8; s++)
        if (t.statuses[s]) printf(" %d: %d", s, t.statuses[s]);
    printf("; damped Newton finished %d times; %s\n", t.damped,
           t.failures ? "DIFFERENCES (above)" : "all as the installed core");
    return t.failures ? 1 : 0;
}
