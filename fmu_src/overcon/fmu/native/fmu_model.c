/* Reads the model file resources/overcon_model.bin (layout: overcon.fmu.cmodel) into an
 * fmu_model: arrays copied to their own (aligned) memory, strings left in the file's bytes.
 * Every count is checked before it sizes anything, and the packed model goes through the core's
 * own check (ovk_make_data) when the run is made; a file that is short, of another format or of
 * another core ABI is refused with the reason. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"

#define MAX_ITEMS (1 << 24)
#define FMU_FORMAT 5 /* overcon.fmu.cmodel.FORMAT */

typedef struct {
    const unsigned char *p, *end;
    int bad; /* 1 short or malformed, 2 out of memory */
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
static int rd_int(reader *r) {
    int32_t v;
    rd(r, &v, sizeof v);
    return (int)v;
}
static double rd_double(reader *r) {
    double v;
    rd(r, &v, sizeof v);
    return v;
}
/* A string: int32 length (with the zero), the bytes, the zero; a pointer into the file. */
static const char *rd_string(reader *r) {
    int n = rd_int(r);
    if (r->bad || n < 1 || (size_t)(r->end - r->p) < (size_t)n || r->p[n - 1] != '\0') {
        r->bad = 1;
        return "";
    }
    const char *s = (const char *)r->p;
    r->p += n;
    return s;
}
/* An array of int32 count then items, copied into memory of its own (one item if empty). */
static void *rd_array(reader *r, size_t item, int *count) {
    int n = rd_int(r);
    if (count) *count = 0;
    if (r->bad || n < 0 || n > MAX_ITEMS || (size_t)(r->end - r->p) < (size_t)n * item) { /* before it allocates */
        r->bad = 1;
        return NULL;
    }
    void *a = calloc((size_t)(n ? n : 1), item);
    if (!a) { r->bad = 2; return NULL; }
    rd(r, a, (size_t)n * item);
    if (count) *count = n;
    return a;
}

/* The redundancy block of ovk_model (overcon.kernel.REDUNDANCY_COUNTS, REDUNDANCY_ARRAYS): its
 * sizes checked here, its indices by the core (ovk_make_data). */
static void read_redundancy(reader *r, ovk_model *M, void **arrays) {
    int *counts[] = {&M->redundancy, &M->nrig, &M->nax, &M->nwatch, &M->nfull};
    for (size_t i = 0; i < sizeof counts / sizeof counts[0]; i++) *counts[i] = rd_int(r);
    const void **fields[10] = {(const void **)&M->ckind, (const void **)&M->ck, (const void **)&M->cd,
                               (const void **)&M->rigpos, (const void **)&M->rigrows, (const void **)&M->rigbody,
                               (const void **)&M->axi, (const void **)&M->axp, (const void **)&M->watch,
                               (const void **)&M->full};
    static const int is_double[10] = {0, 1, 1, 0, 0, 0, 0, 1, 0, 0};
    int comp = M->redundancy == OVK_COMPLIANT, any = M->redundancy != OVK_ELIMINATE;
    const long long want[10] = {comp ? M->nR : 0, comp ? M->m : 0, comp ? M->m : 0, M->nrig, M->nrig,
                                2LL * M->nrig, (long long)OVK_NAXI * M->nax, (long long)OVK_NAXP * M->nax,
                                any && M->nwatch > 0 ? M->nwatch : 0, any && M->nfull > 0 ? M->nfull : 0};
    for (int k = 0; k < 10; k++) {
        int count = 0;
        arrays[25 + k] = rd_array(r, is_double[k] ? sizeof(double) : sizeof(int), &count);
        *fields[k] = arrays[25 + k];
        if (!r->bad && !(count == want[k] || (want[k] == 0 && count == 1))) r->bad = 1; /* empty: one zero */
    }
}

static void read_packed(reader *r, ovk_model *M, void **arrays) {
    int *counts[] = {&M->dim, &M->nb, &M->nq_b, &M->nh_b, &M->m, &M->nR, &M->nj, &M->nl,
                     &M->nx, &M->ncols, &M->nfj, &M->nfg, &M->max_iter};
    for (size_t i = 0; i < sizeof counts / sizeof counts[0]; i++) *counts[i] = rd_int(r);
    M->baumgarte = rd_double(r);
    M->tol = rd_double(r);
    const void **fields[25] = {
        (const void **)&M->retained, (const void **)&M->Minv, (const void **)&M->mass, (const void **)&M->inertia,
        (const void **)&M->gravity, (const void **)&M->jtype, (const void **)&M->jbi, (const void **)&M->jbj,
        (const void **)&M->jneq, (const void **)&M->jrows, (const void **)&M->jconst, (const void **)&M->jlaw,
        (const void **)&M->jlawp, (const void **)&M->ltype, (const void **)&M->lbi, (const void **)&M->lbj,
        (const void **)&M->lp, (const void **)&M->xrows, (const void **)&M->cols, (const void **)&M->fj,
        (const void **)&M->fgroup, (const void **)&M->fx, (const void **)&M->fci, (const void **)&M->fcj,
        (const void **)&M->rbody};
    static const int is_double[25] = {0, 1, 1, 1, 1, 0, 0, 0, 0, 0, 1, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0};
    long long nj = M->nj, nl = M->nl, nfj = M->nfj;
    const long long want[25] = {M->nR, (long long)M->nb * M->nh_b, M->nb, 3LL * M->nb, M->dim, nj, nj, nj, nj,
                                nj * OVK_MAXEQ, nj * NJC, nj, nj * NLP, nl, nl, nl, nl * NLD, M->nx, M->ncols, nfj,
                                M->nfg + 1LL, nfj * OVK_MAXEQ, nfj * 6, nfj * 6, 2LL * M->nR};
    for (int k = 0; k < 25; k++) {
        int count = 0;
        arrays[k] = rd_array(r, is_double[k] ? sizeof(double) : sizeof(int), &count);
        *fields[k] = arrays[k];
        if (!r->bad && !(count == want[k] || (want[k] == 0 && count == 1))) r->bad = 1; /* empty: one zero */
    }
    read_redundancy(r, M, arrays);
    M->formulation = rd_int(r); /* OVK_FORM_*: checked by the core (ovk_make_data) */
    M->nu = rd_int(r); /* the inputs: their sizes here, their contents by the core (ovk_make_data) */
    if (M->nu < 0 || M->nu > MAX_ITEMS) r->bad = 1;
    const void **ufields[3] = {(const void **)&M->ukind, (const void **)&M->uidx, (const void **)&M->up};
    const long long want_u[3] = {M->nu, 3LL * M->nu, (long long)OVK_NUP * M->nu};
    for (int k = 0; k < 3 && !r->bad; k++) {
        int count = 0;
        arrays[35 + k] = rd_array(r, k == 2 ? sizeof(double) : sizeof(int), &count);
        *ufields[k] = arrays[35 + k];
        if (!r->bad && !(count == want_u[k] || (want_u[k] == 0 && count == 1))) r->bad = 1;
    }
}

/* The packed models of the redundancy parameter's other methods (at most two). */
static void read_alternatives(reader *r, fmu_model *fm) {
    fm->nalt = rd_int(r);
    if (fm->nalt < 0 || fm->nalt > 2) { r->bad = 1; fm->nalt = 0; }
    for (int a = 0; a < fm->nalt && !r->bad; a++) {
        fm->alt_code[a] = rd_int(r);
        read_packed(r, &fm->alt[a], fm->alt_arrays[a]);
        const ovk_model *A = &fm->alt[a], *M = &fm->M;
        if (fm->alt_code[a] < OVK_ELIMINATE || fm->alt_code[a] > OVK_COMPLIANT || A->dim != M->dim || A->nb != M->nb ||
            A->nq_b != M->nq_b || A->nh_b != M->nh_b || A->m != M->m || A->nj != M->nj || A->nl != M->nl ||
            A->nu != M->nu)
            r->bad = 1; /* another mechanism than the scene's */
    }
}

/* The packed model of redundancy method `code` (the parameter's value - 1; -1: the scene's own). */
const ovk_model *fmu_model_for(const fmu_model *fm, int code) {
    for (int a = 0; a < fm->nalt; a++)
        if (fm->alt_code[a] == code) return &fm->alt[a];
    return &fm->M;
}

static void read_param(reader *r, fmu_param *p) {
    p->name = rd_string(r);
    p->type = rd_int(r);
    p->target = rd_int(r);
    p->joint = rd_int(r);
    p->rule = rd_int(r);
    p->lo = rd_double(r);
    p->hi = rd_double(r);
    p->has_lo = rd_int(r);
    p->has_hi = rd_int(r);
    p->low_open = rd_int(r);
    p->range_text = rd_string(r);
    p->why = rd_string(r);
    p->nchoices = rd_int(r);
    if (p->nchoices < 0 || p->nchoices > FMU_MAX_CHOICES) { r->bad = 1; p->nchoices = 0; }
    for (int k = 0; k < p->nchoices; k++) p->choices[k] = rd_string(r);
    p->ddefault = rd_double(r);
    p->sdefault = rd_string(r);
    p->tunable = rd_int(r);
}

static int counted(reader *r, int *n) {
    *n = rd_int(r);
    if (*n < 0 || *n > MAX_ITEMS) r->bad = 1;
    return !r->bad;
}

/* The parts after the packed model: the run, outputs, variables, parameters and messages. */
static void read_rest(reader *r, fmu_model *fm) {
    fm->n = rd_int(r);
    fm->nh = rd_int(r);
    fm->quaternion = rd_int(r);
    fm->start_time = rd_double(r);
    fm->stop_time = rd_double(r);
    int ny = 0;
    fm->y0 = rd_array(r, sizeof(double), &ny);
    /* the sizes checked before they are added (and against the packed model: n + nh states) */
    long long nq = (long long)fm->M.nb * fm->M.nq_b, nv = (long long)fm->M.nb * fm->M.nh_b;
    if (fm->n < 0 || fm->nh < 0 || fm->n > MAX_ITEMS || fm->nh > MAX_ITEMS || fm->n != nq || fm->nh != nv ||
        (fm->quaternion != 0 && (fm->quaternion != 1 || fm->M.nq_b != 7))) {
        r->bad = 1;
        fm->n = fm->nh = 0;
    }
    fm->ny = fm->n + fm->nh;
    if (ny != fm->ny) r->bad = 1;
    if (counted(r, &fm->nout) && (fm->out = calloc((size_t)fm->nout + 1, sizeof *fm->out)) == NULL) r->bad = 2;
    for (int k = 0; k < fm->nout && !r->bad; k++) {
        fm->out[k].kind = rd_int(r), fm->out[k].a = rd_int(r), fm->out[k].b = rd_int(r);
        if (fm->out[k].kind == O_POSITION || fm->out[k].kind == O_VELOCITY) fm->nstate_out = k + 1;
        if (fm->out[k].kind == O_ENERGY) fm->energy = 1;
    }
    if (counted(r, &fm->nvar) && (fm->var = calloc((size_t)fm->nvar + 1, sizeof *fm->var)) == NULL) r->bad = 2;
    for (int k = 0; k < fm->nvar && !r->bad; k++) {
        fmu_var *v = &fm->var[k];
        v->name = rd_string(r);
        v->type = rd_int(r), v->causality = rd_int(r), v->variability = rd_int(r);
        v->key = rd_int(r), v->arg = rd_int(r);
        if (v->key == K_STATE) fm->me = 1;
    }
    if (counted(r, &fm->nparam) && (fm->par = calloc((size_t)fm->nparam + 1, sizeof *fm->par)) == NULL) r->bad = 2;
    for (int k = 0; k < fm->nparam && !r->bad; k++) read_param(r, &fm->par[k]);
    if (counted(r, &fm->nmsg)) {
        fm->msg_status = calloc((size_t)fm->nmsg + 1, sizeof *fm->msg_status);
        fm->msg = calloc((size_t)fm->nmsg + 1, sizeof *fm->msg);
        if (!fm->msg_status || !fm->msg) r->bad = 2;
    }
    for (int k = 0; k < fm->nmsg && !r->bad; k++) fm->msg_status[k] = rd_int(r), fm->msg[k] = rd_string(r);
}

/* Indices of the tables checked against their sizes (outputs, keys, joints). */
static int check_tables(const fmu_model *fm, char *err, size_t errsize) {
    char why[OVK_MSG];
    if (fm->n != fm->M.nb * fm->M.nq_b || fm->nh != fm->M.nb * fm->M.nh_b)
        return snprintf(err, errsize, "%d coordinates and %d velocities for the model's %d and %d", fm->n, fm->nh,
                        fm->M.nb * fm->M.nq_b, fm->M.nb * fm->M.nh_b), 0;
    if (ovk_plan_check(&fm->M, fm->out, fm->nout, why)) return snprintf(err, errsize, "%s", why), 0;
    for (int k = 0; k < fm->nvar; k++) {
        const fmu_var *v = &fm->var[k];
        int lim = v->key == K_OUTPUT || v->key == K_ARRAY ? fm->nout : v->key == K_PARAM ? fm->nparam
                  : v->key == K_STATE || v->key == K_DERIVATIVE ? fm->ny : v->key == K_ALONG ? 3 + fm->M.nj
                  : v->key == K_INPUT ? fm->M.nu : 2;
        if (v->type < T_REAL || v->type > T_STRING || v->causality < 0 || v->causality > 4 || v->variability < 0 ||
            v->variability > 4 || v->key < K_OUTPUT || v->key > K_INPUT || v->arg < 0 ||
            (v->key == K_INPUT && v->type != T_REAL) ||
            (v->key != K_STABLE_STEP && v->key != K_TIME && v->arg >= lim))
            return snprintf(err, errsize, "variable %d (%s): type %d, key %d, %d out of range", k, v->name, v->type,
                            v->key, v->arg), 0;
    }
    for (int k = 0; k < fm->nparam; k++) {
        const fmu_param *p = &fm->par[k];
        if (p->target < P_MU || (p->target <= P_VSTRIBECK && (p->joint < 0 || p->joint >= fm->M.nj)) ||
            p->target > P_REDUNDANCY || (p->target > P_VSTRIBECK && p->target < P_METHOD) ||
            (p->rule == RULE_CHOICE && p->nchoices < 1))
            return snprintf(err, errsize, "parameter %s: target %d, joint %d out of range", p->name, p->target,
                            p->joint), 0;
    }
    return 1;
}

/* Reads path into fm: 1, or 0 with the reason in err (fm is then freed). */
int fmu_model_read(const char *path, fmu_model *fm, char *err, size_t errsize) {
    memset(fm, 0, sizeof *fm);
    FILE *f = fopen(path, "rb");
    if (!f) return snprintf(err, errsize, "cannot open %s", path), 0;
    long size = fseek(f, 0, SEEK_END) == 0 ? ftell(f) : -1;
    if (size < 16 || fseek(f, 0, SEEK_SET) != 0 || !(fm->bytes = malloc((size_t)size))) {
        fclose(f);
        return snprintf(err, errsize, "%s: %s", path, size < 16 ? "not a model file" : "out of memory"), 0;
    }
    fm->size = fread(fm->bytes, 1, (size_t)size, f);
    fclose(f);
    reader r = {fm->bytes, fm->bytes + fm->size, fm->size != (size_t)size};
    char magic[8];
    rd(&r, magic, sizeof magic);
    int format = rd_int(&r), abi = rd_int(&r);
    if (r.bad || memcmp(magic, "OVKFMU01", 8) || format != FMU_FORMAT || abi != OVK_ABI) {
        snprintf(err, errsize, "%s: not a model file of this FMU's core (format %d, ABI %d; expected %d, %d)", path,
                 format, abi, FMU_FORMAT, OVK_ABI);
        fmu_model_free(fm);
        return 0;
    }
    fm->guid = rd_string(&r);
    read_packed(&r, &fm->M, fm->arrays);
    read_alternatives(&r, fm);
    read_rest(&r, fm);
    if (r.bad || r.p != r.end || !check_tables(fm, err, errsize)) {
        if (r.bad || r.p != r.end)
            snprintf(err, errsize, "%s: %s", path, r.bad == 2 ? "out of memory" : "truncated or malformed");
        fmu_model_free(fm);
        return 0;
    }
    return 1;
}

void fmu_model_free(fmu_model *fm) {
    for (int k = 0; k < 38; k++) {
        free(fm->arrays[k]);
        for (int a = 0; a < 2; a++) free(fm->alt_arrays[a][k]);
    }
    free(fm->y0);
    free(fm->out);
    free(fm->var);
    free(fm->par);
    free(fm->msg_status);
    free(fm->msg);
    free(fm->bytes);
    memset(fm, 0, sizeof *fm);
}
