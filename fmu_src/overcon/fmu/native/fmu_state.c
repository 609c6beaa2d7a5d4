/* FMU states, whatever the FMI version (fmi2GetFMUstate ... fmi2DeSerializeFMUstate, fmi3GetFMUState
 * ... fmi3DeserializeFMUState call these): a state holds the instance's mode,
 * parameters, time, outputs, state vector and the run's bytes (ovk_sim_get_state), so setting it
 * continues exactly where it was taken (the same bits). Serialized: "OVKFMUS1", the GUID, the
 * scalars, the arrays and the run's bytes, in native byte order (a state is restored on the
 * machine and build that saved it). A state of another FMU, or bytes that are not a state, are
 * refused with the reason. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"

#define STATE_MAGIC "OVKFMUS1"

static void free_saved(fmu_saved *s) {
    if (!s) return;
    free(s->pval), free(s->pset), free(s->outputs), free(s->y), free(s->sim), free(s->uval), free(s);
}

static fmu_saved *new_saved(const fmu_inst *c, size_t sim_size) {
    const fmu_model *fm = &c->fm;
    fmu_saved *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    s->pval = calloc((size_t)fm->nparam + 1, sizeof(double));
    s->pset = calloc((size_t)fm->nparam + 1, sizeof(int));
    s->outputs = calloc((size_t)fm->nout + 1, sizeof(double));
    s->y = calloc((size_t)fm->ny + 1, sizeof(double));
    s->sim = calloc(sim_size ? sim_size : 1, 1);
    s->sim_size = sim_size;
    s->uval = calloc(2 * (size_t)fm->M.nu + 1, sizeof(double)); /* the inputs as the host set them */
    if (!s->pval || !s->pset || !s->outputs || !s->y || !s->sim || !s->uval) {
        free_saved(s);
        return NULL;
    }
    return s;
}

/* 1 if s is a state of this instance (in its list). */
static int owned(const fmu_inst *c, const fmu_saved *s) {
    for (const fmu_saved *p = c->states; p; p = p->next)
        if (p == s) return 1;
    return 0;
}

/* The instance's fields into s (sized for it). */
static void snapshot(fmu_inst *c, fmu_saved *s) {
    const fmu_model *fm = &c->fm;
    s->mode = c->mode, s->tol_source = c->tol_source, s->have_outputs = c->have_outputs;
    s->derived_stale = c->derived_stale, s->has_y = c->has_y, s->has_failed = c->has_failed;
    s->has_sim = c->sim_valid && c->sim != NULL;
    s->start_time = c->start_time, s->t = c->t, s->stable_step = c->stable_step;
    memcpy(s->pval, c->pval, (size_t)fm->nparam * sizeof(double));
    memcpy(s->pset, c->pset, (size_t)fm->nparam * sizeof(int));
    memcpy(s->outputs, c->outputs, (size_t)fm->nout * sizeof(double));
    memcpy(s->y, c->y, (size_t)fm->ny * sizeof(double));
    if (s->has_sim) ovk_sim_get_state(c->sim, s->sim, s->sim_size);
    memcpy(s->uval, c->uval, 2 * (size_t)fm->M.nu * sizeof(double)); /* inputs */
    s->u_flags[0] = c->u_dirty, s->u_flags[1] = c->u_pending;
}

fmi2Status fmu_state_get(fmu_inst *c, const char *fn, fmi2FMUstate *state) {
    if (!state) return fmu_log(c, fmi2Error, "%s: FMUstate is NULL", fn), fmi2Error;
    size_t size = c->sim_valid && c->sim ? ovk_sim_state_size(c->sim) : 0;
    fmu_saved *s = *state && owned(c, *state) ? *state : NULL;
    if (s && s->sim_size != size) { /* overwrite an own state of another size: new arrays */
        fmu_saved *fresh = new_saved(c, size);
        if (!fresh) return fmu_log(c, fmi2Error, "%s: out of memory", fn), fmi2Error;
        free(s->sim);
        s->sim = fresh->sim, s->sim_size = size;
        fresh->sim = NULL;
        free_saved(fresh);
    } else if (!s) {
        if (!(s = new_saved(c, size))) return fmu_log(c, fmi2Error, "%s: out of memory", fn), fmi2Error;
        s->next = c->states;
        c->states = s;
    }
    snapshot(c, s);
    *state = s;
    return fmi2OK;
}

/* The instance set to s (overcon.fmu.slave._restore): the run remade with the state's
 * parameters and given the state's bytes. */
static fmi2Status restore(fmu_inst *c, const char *fn, const fmu_saved *s) {
    const fmu_model *fm = &c->fm;
    for (int k = 0; k < 2 * fm->M.nu; k++) /* inputs: finite, as fmu_set_input takes them */
        if (!isfinite(s->uval[k])) return fmu_log(c, fmi2Error, "%s: input entry %d of the state is not finite", fn, k),
                                          fmi2Error;
    memcpy(c->uval, s->uval, 2 * (size_t)fm->M.nu * sizeof(double));
    memcpy(c->pval, s->pval, (size_t)fm->nparam * sizeof(double));
    memcpy(c->pset, s->pset, (size_t)fm->nparam * sizeof(int));
    c->start_time = s->start_time, c->tol_source = s->tol_source;
    c->sim_valid = 0;
    if (s->has_sim) {
        if (!fmu_ensure_sim(c, 0)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), fmi2Error;
        if (ovk_sim_set_state(c->sim, s->sim, s->sim_size)) {
            fmu_log(c, fmi2Error, "%s: %s", fn, ovk_sim_message(c->sim));
            c->sim_valid = 0;
            return fmi2Error;
        }
    } else {
        ovk_sim_free(c->sim);
        c->sim = NULL;
    }
    c->u_dirty = s->u_flags[0], c->u_pending = s->u_flags[1]; /* inputs: the run's bytes hold those it ran with */
    c->mode = s->mode, c->t = s->t;
    memcpy(c->outputs, s->outputs, (size_t)fm->nout * sizeof(double));
    memcpy(c->y, s->y, (size_t)fm->ny * sizeof(double));
    c->have_outputs = s->have_outputs, c->has_failed = s->has_failed, c->stable_step = s->stable_step;
    c->has_y = s->has_y;
    c->dx_valid = 0;
    c->derived_stale = s->derived_stale && s->has_y;
    return fmi2OK;
}

fmi2Status fmu_state_set(fmu_inst *c, const char *fn, fmi2FMUstate state) {
    if (!state || !owned(c, state))
        return fmu_log(c, fmi2Error, "%s: FMUstate %p is not a state of this instance (freed or never got)",
                       fn, state), fmi2Error;
    return restore(c, fn, state);
}

fmi2Status fmu_state_free(fmu_inst *c, const char *fn, fmi2FMUstate *state) {
    if (!state) return fmu_log(c, fmi2Error, "%s: FMUstate is NULL", fn), fmi2Error;
    if (!*state) return fmi2OK;
    fmu_saved **p = &c->states;
    while (*p && *p != *state) p = &(*p)->next;
    if (!*p)
        return fmu_log(c, fmi2Error, "%s: FMUstate %p is not a state of this instance (freed or never "
                       "got)", fn, *state), fmi2Error;
    fmu_saved *s = *p;
    *p = s->next;
    free_saved(s);
    *state = NULL;
    return fmi2OK;
}

typedef struct {
    unsigned char *w;
    const unsigned char *r;
    size_t size, cap;
    int bad;
} codec;

static void io(codec *k, void *x, size_t n) {
    if (k->size + n > k->cap) k->bad = 1;
    if (!k->bad && k->w) memcpy(k->w + k->size, x, n);
    if (!k->bad && k->r) memcpy(x, k->r + k->size, n);
    k->size += n;
}

/* Every field of a state in one order, for measuring, writing and reading. */
static void io_saved(codec *k, const fmu_inst *c, fmu_saved *s) {
    const fmu_model *fm = &c->fm;
    int ints[7] = {s->mode, s->tol_source, s->have_outputs, s->derived_stale, s->has_y, s->has_sim, s->has_failed};
    double reals[3] = {s->start_time, s->t, s->stable_step};
    uint64_t sim_size = s->sim_size;
    io(k, ints, sizeof ints);
    io(k, reals, sizeof reals);
    io(k, s->pval, (size_t)fm->nparam * sizeof(double));
    io(k, s->pset, (size_t)fm->nparam * sizeof(int));
    io(k, s->outputs, (size_t)fm->nout * sizeof(double));
    io(k, s->y, (size_t)fm->ny * sizeof(double));
    if (fm->M.nu) { /* inputs */
        io(k, s->uval, 2 * (size_t)fm->M.nu * sizeof(double));
        io(k, s->u_flags, sizeof s->u_flags);
    }
    io(k, &sim_size, sizeof sim_size);
    if (k->r && !k->bad) {
        s->mode = ints[0], s->tol_source = ints[1], s->have_outputs = ints[2], s->derived_stale = ints[3];
        s->has_y = ints[4], s->has_sim = ints[5], s->has_failed = ints[6];
        s->start_time = reals[0], s->t = reals[1], s->stable_step = reals[2];
    }
}

static size_t header_size(const fmu_inst *c) { return 8 + strlen(c->fm.guid) + 1; }

fmi2Status fmu_state_size(fmu_inst *c, const char *fn, fmi2FMUstate state, size_t *size) {
    if (!size) return fmu_log(c, fmi2Error, "%s: size is NULL", fn), fmi2Error;
    if (!state || !owned(c, state))
        return fmu_log(c, fmi2Error, "%s: FMUstate %p is not a state of this instance", fn, state),
               fmi2Error;
    codec k = {NULL, NULL, 0, (size_t)-1, 0};
    io_saved(&k, c, state);
    *size = header_size(c) + k.size + ((fmu_saved *)state)->sim_size;
    return fmi2OK;
}

fmi2Status fmu_state_serialize(fmu_inst *c, const char *fn, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    size_t need = 0;
    if (fmu_state_size(c, fn, state, &need) != fmi2OK) return fmi2Error;
    if (!bytes || size < need)
        return fmu_log(c, fmi2Error, "%s: the buffer holds %zu bytes, the state needs %zu "
                       "(%s)", fn, size, need,
                       c->fmi3 ? "fmi3SerializedFMUStateSize" : "fmi2SerializedFMUstateSize"), fmi2Error;
    fmu_saved *s = state;
    size_t h = header_size(c);
    memcpy(bytes, STATE_MAGIC, 8);
    memcpy(bytes + 8, c->fm.guid, h - 8);
    codec k = {(unsigned char *)bytes + h, NULL, 0, size - h, 0};
    io_saved(&k, c, s);
    memcpy(bytes + h + k.size, s->sim, s->sim_size);
    return fmi2OK;
}

fmi2Status fmu_state_deserialize(fmu_inst *c, const char *fn, const fmi2Byte bytes[], size_t size,
                                              fmi2FMUstate *state) {
    if (!state) return fmu_log(c, fmi2Error, "%s: FMUstate is NULL", fn), fmi2Error;
    if (size && !bytes) return fmu_log(c, fmi2Error, "%s: serializedState is NULL but size = %zu", fn, size), fmi2Error;
    size_t h = header_size(c);
    if (size < h || memcmp(bytes, STATE_MAGIC, 8) || memcmp(bytes + 8, c->fm.guid, h - 8))
        return fmu_log(c, fmi2Error, "%s: the bytes are not an FMU state of this FMU (format or GUID differs)", fn),
               fmi2Error;
    fmu_saved *s = new_saved(c, 0);
    if (!s) return fmu_log(c, fmi2Error, "%s: out of memory", fn), fmi2Error;
    codec k = {NULL, (const unsigned char *)bytes + h, 0, size - h, 0};
    uint64_t sim_size = 0;
    io_saved(&k, c, s);
    if (!k.bad) memcpy(&sim_size, bytes + h + k.size - sizeof sim_size, sizeof sim_size);
    if (k.bad || sim_size != size - h - k.size) {
        free_saved(s);
        return fmu_log(c, fmi2Error, "%s: the bytes are not an FMU state of this FMU (%zu bytes, truncated or "
                       "malformed)", fn, size), fmi2Error;
    }
    free(s->sim);
    s->sim = malloc(sim_size ? (size_t)sim_size : 1);
    if (!s->sim) {
        free_saved(s);
        return fmu_log(c, fmi2Error, "%s: out of memory", fn), fmi2Error;
    }
    memcpy(s->sim, bytes + h + k.size, (size_t)sim_size);
    s->sim_size = (size_t)sim_size;
    s->next = c->states;
    c->states = s;
    *state = s;
    return fmi2OK;
}
