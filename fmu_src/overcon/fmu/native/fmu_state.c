/* FMU states, whatever the FMI version (fmi2GetFMUstate ... fmi2DeSerializeFMUstate, fmi3GetFMUState
 * ... fmi3DeserializeFMUState call these): a state holds the instance's mode, parameters, time,
 * outputs, state vector and the run's bytes (ovk_sim_get_state), so setting it continues exactly
 * where it was taken (the same bits).
 *
 * Serialized (native byte order: a state is restored on the machine and build that saved it):
 *   "OVKFMUS2", the GUID with its NUL,
 *   a header of 4 uint32: FMI version (2 or 3), instance kind (0 co-simulation, 1 Model Exchange),
 *     the CRC-32 of the payload, 0; then uint64 the size of the run's bytes,
 *   the payload: the fields of STATE_FIELDS below in their order, then the run's bytes.
 * Serialized bytes are untrusted input (a host may keep them on disk, send them over a network or
 * mix them up between instances): a deserialized state is checked completely before anything of it
 * is used (state_refused: GUID, version, kind, sizes, checksum, then every field by its rule, the
 * parameters by the setters' own rule, fmu_param_refuses) and the run's bytes by the core when the
 * state is set (ovk_sim_set_state: every index, count and flag); a state refused at set leaves the
 * instance with the state it had before. The checksum is CRC-32 (IEEE 802.3, bitwise): it catches
 * the accidents (a truncated, flipped or mixed-up buffer) with a clear message; it is no
 * protection against someone who writes a state on purpose (they can recompute it), which is what
 * the field checks are for. */
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"

#define STATE_MAGIC "OVKFMUS2"
#define HEADER_SIZE (4 * sizeof(uint32_t) + sizeof(uint64_t))

/* ---- The layout of a state: one line per field (adding a field: a member of fmu_saved and of
 * fmu_inst of the same name, and one line here). ---- */
enum { FT_INT, FT_DOUBLE };                               /* element type */
enum { FN_ONE, FN_PARAM, FN_OUT, FN_Y, FN_U };            /* element count: 1, nparam, nout, ny, 2 nu */
enum { CK_ANY, CK_FLAG, CK_MODE, CK_TOL_SOURCE, CK_FINITE, CK_STABLE_STEP, CK_PARAM }; /* the rule of every element */
typedef struct {
    const char *name;
    size_t saved, inst; /* offsetof in fmu_saved and fmu_inst ((size_t)-1: none) */
    int array;          /* the members are pointers to count elements */
    int type, count, check;
    int before_run;     /* restored before the run is made again (it shapes the run) */
} state_field;
#define SCALAR(f, type, check, before) {#f, offsetof(fmu_saved, f), offsetof(fmu_inst, f), 0, type, FN_ONE, check, before}
#define ARRAY(f, type, count, check, before) {#f, offsetof(fmu_saved, f), offsetof(fmu_inst, f), 1, type, count, check, before}
static const state_field STATE_FIELDS[] = {
    SCALAR(mode, FT_INT, CK_MODE, 0),
    SCALAR(tol_source, FT_INT, CK_TOL_SOURCE, 1),
    SCALAR(have_outputs, FT_INT, CK_FLAG, 0),
    SCALAR(derived_stale, FT_INT, CK_FLAG, 0),
    SCALAR(has_y, FT_INT, CK_FLAG, 0),
    {"has_sim", offsetof(fmu_saved, has_sim), (size_t)-1, 0, FT_INT, FN_ONE, CK_FLAG, 0}, /* the run's bytes follow */
    SCALAR(has_failed, FT_INT, CK_FLAG, 0),
    SCALAR(start_time, FT_DOUBLE, CK_FINITE, 1),
    SCALAR(t, FT_DOUBLE, CK_FINITE, 0),
    SCALAR(stable_step, FT_DOUBLE, CK_STABLE_STEP, 0),
    ARRAY(pval, FT_DOUBLE, FN_PARAM, CK_PARAM, 1),
    ARRAY(pset, FT_INT, FN_PARAM, CK_FLAG, 1),
    ARRAY(outputs, FT_DOUBLE, FN_OUT, CK_ANY, 0), /* finite when have_outputs (fields_refused) */
    ARRAY(y, FT_DOUBLE, FN_Y, CK_ANY, 0),         /* finite when has_y */
    ARRAY(uval, FT_DOUBLE, FN_U, CK_FINITE, 1),   /* the inputs' values, then their first derivatives */
    SCALAR(u_dirty, FT_INT, CK_FLAG, 0),          /* inputs: the run's bytes hold those it ran with */
    SCALAR(u_pending, FT_INT, CK_FLAG, 0),
};
#define NFIELDS (sizeof STATE_FIELDS / sizeof STATE_FIELDS[0])

static size_t field_count(const fmu_model *fm, const state_field *f) {
    return f->count == FN_PARAM ? (size_t)fm->nparam : f->count == FN_OUT ? (size_t)fm->nout
           : f->count == FN_Y   ? (size_t)fm->ny : f->count == FN_U ? 2 * (size_t)fm->M.nu : 1;
}
static size_t field_item(const state_field *f) { return f->type == FT_INT ? sizeof(int) : sizeof(double); }
/* The elements of field f of an fmu_saved or fmu_inst (base) and of its offset. */
static void *field_data(void *base, size_t offset, const state_field *f) {
    char *member = (char *)base + offset;
    return f->array ? *(void **)member : (void *)member;
}
/* The value of element i of a field as a number (for the checks and their messages). */
static double field_value(const void *data, const state_field *f, size_t i) {
    return f->type == FT_INT ? (double)((const int *)data)[i] : ((const double *)data)[i];
}

/* CRC-32 (IEEE 802.3: polynomial 0xEDB88320 reflected, initial and final xor 0xFFFFFFFF) of n bytes,
 * bit by bit (no table: no global state; a state of 100 kB takes well under a millisecond). */
static uint32_t crc32_of(const unsigned char *p, size_t n) {
    uint32_t crc = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) {
        crc ^= p[i];
        for (int b = 0; b < 8; b++) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
    return crc ^ 0xFFFFFFFFu;
}

static void free_saved(fmu_saved *s) {
    if (!s) return;
    for (size_t k = 0; k < NFIELDS; k++)
        if (STATE_FIELDS[k].array) free(*(void **)((char *)s + STATE_FIELDS[k].saved));
    free(s->sim), free(s);
}

static fmu_saved *new_saved(const fmu_inst *c, size_t sim_size) {
    fmu_saved *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    int ok = 1;
    for (size_t k = 0; k < NFIELDS; k++) {
        const state_field *f = &STATE_FIELDS[k];
        if (!f->array) continue;
        void *a = calloc(field_count(&c->fm, f) + 1, field_item(f));
        *(void **)((char *)s + f->saved) = a;
        ok = ok && a;
    }
    s->sim = calloc(sim_size ? sim_size : 1, 1);
    s->sim_size = sim_size;
    if (!ok || !s->sim) {
        free_saved(s);
        return NULL;
    }
    return s;
}

void fmu_saved_free(fmu_saved *s) { free_saved(s); }

/* 1 if s is a state of this instance (in its list). */
static int owned(const fmu_inst *c, const fmu_saved *s) {
    for (const fmu_saved *p = c->states; p; p = p->next)
        if (p == s) return 1;
    return 0;
}

/* Copies the fields between an instance and a state (to_state: into s), those restored before the
 * run or after it (before: 1, 0; -1 every field). */
static void copy_fields(fmu_inst *c, fmu_saved *s, int to_state, int before) {
    for (size_t k = 0; k < NFIELDS; k++) {
        const state_field *f = &STATE_FIELDS[k];
        if (f->inst == (size_t)-1 || (before >= 0 && f->before_run != before)) continue;
        void *a = field_data(c, f->inst, f), *b = field_data(s, f->saved, f);
        size_t n = field_count(&c->fm, f) * field_item(f);
        if (to_state) memcpy(b, a, n);
        else memcpy(a, b, n);
    }
}

/* The instance's fields into s (sized for it). */
static void snapshot(fmu_inst *c, fmu_saved *s) {
    copy_fields(c, s, 1, -1);
    s->has_sim = c->sim_valid && c->sim != NULL;
    if (s->has_sim) ovk_sim_get_state(c->sim, s->sim, s->sim_size);
}

/* A new state of the instance as it is now (not in its list); NULL when out of memory. */
static fmu_saved *take(fmu_inst *c) {
    fmu_saved *s = new_saved(c, c->sim_valid && c->sim ? ovk_sim_state_size(c->sim) : 0);
    if (s) snapshot(c, s);
    return s;
}

fmi2Status fmu_state_get(fmu_inst *c, const char *fn, fmi2FMUstate *state) {
    if (!state) return fmu_log(c, fmi2Error, "%s: FMUstate is NULL", fn), fmi2Error;
    size_t size = c->sim_valid && c->sim ? ovk_sim_state_size(c->sim) : 0;
    fmu_saved *s = *state && owned(c, *state) ? *state : NULL;
    if (s && s->sim_size != size) { /* overwrite an own state of another size: new arrays */
        unsigned char *sim = calloc(size ? size : 1, 1);
        if (!sim) return fmu_log(c, fmi2Error, "%s: out of memory", fn), fmi2Error;
        free(s->sim);
        s->sim = sim, s->sim_size = size;
    } else if (!s) {
        if (!(s = new_saved(c, size))) return fmu_log(c, fmi2Error, "%s: out of memory", fn), fmi2Error;
        s->next = c->states;
        c->states = s;
    }
    snapshot(c, s);
    *state = s;
    return fmi2OK;
}

/* The instance set to s (overcon.fmu.slave._restore): the run remade with the state's parameters
 * and given the state's bytes; 0 with the reason in c->msg. */
static int restore(fmu_inst *c, const fmu_saved *s) {
    copy_fields(c, (fmu_saved *)s, 0, 1);
    c->sim_valid = 0;
    if (s->has_sim) {
        if (!fmu_ensure_sim(c, 0)) return 0;
        if (ovk_sim_set_state(c->sim, s->sim, s->sim_size)) {
            snprintf(c->msg, sizeof c->msg, "%s", ovk_sim_message(c->sim));
            c->sim_valid = 0;
            return 0;
        }
    } else {
        ovk_sim_free(c->sim);
        c->sim = NULL;
    }
    copy_fields(c, (fmu_saved *)s, 0, 0);
    c->dx_valid = 0;
    c->derived_stale = s->derived_stale && s->has_y;
    return 1;
}

fmi2Status fmu_state_set(fmu_inst *c, const char *fn, fmi2FMUstate state) {
    if (!state || !owned(c, state))
        return fmu_log(c, fmi2Error, "%s: FMUstate %p is not a state of this instance (freed or never got)",
                       fn, state), fmi2Error;
    fmu_saved *before = take(c); /* the instance as it was, put back if the state is refused */
    if (!before) return fmu_log(c, fmi2Error, "%s: out of memory", fn), fmi2Error;
    fmi2Status status = fmi2OK;
    if (!restore(c, state)) {
        char why[FMU_MSG];
        snprintf(why, sizeof why, "%s", c->msg);
        int back = restore(c, before);
        fmu_log(c, fmi2Error, "%s: the state is refused: %s; %s", fn, why,
                back ? "the instance keeps the state it had before" : "the state it had before could not be put back");
        status = fmi2Error;
    }
    free_saved(before);
    return status;
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

/* ---- Serialized states ---- */

/* The bytes of the fields (the payload before the run's bytes). */
static size_t fields_size(const fmu_model *fm) {
    size_t n = 0;
    for (size_t k = 0; k < NFIELDS; k++) n += field_count(fm, &STATE_FIELDS[k]) * field_item(&STATE_FIELDS[k]);
    return n;
}

static size_t header_size(const fmu_inst *c) { return 8 + strlen(c->fm.guid) + 1 + HEADER_SIZE; }

fmi2Status fmu_state_size(fmu_inst *c, const char *fn, fmi2FMUstate state, size_t *size) {
    if (!size) return fmu_log(c, fmi2Error, "%s: size is NULL", fn), fmi2Error;
    if (!state || !owned(c, state))
        return fmu_log(c, fmi2Error, "%s: FMUstate %p is not a state of this instance", fn, state),
               fmi2Error;
    *size = header_size(c) + fields_size(&c->fm) + ((fmu_saved *)state)->sim_size;
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
    unsigned char *out = (unsigned char *)bytes, *payload = out + header_size(c), *w = payload;
    for (size_t k = 0; k < NFIELDS; k++) {
        const state_field *f = &STATE_FIELDS[k];
        size_t n = field_count(&c->fm, f) * field_item(f);
        memcpy(w, field_data(s, f->saved, f), n);
        w += n;
    }
    memcpy(w, s->sim, s->sim_size);
    w += s->sim_size;
    uint32_t head[4] = {c->fmi3 ? 3u : 2u, c->me ? 1u : 0u, crc32_of(payload, (size_t)(w - payload)), 0u};
    uint64_t sim_size = s->sim_size;
    size_t g = strlen(c->fm.guid) + 1;
    memcpy(out, STATE_MAGIC, 8);
    memcpy(out + 8, c->fm.guid, g);
    memcpy(out + 8 + g, head, sizeof head);
    memcpy(out + 8 + g + sizeof head, &sim_size, sizeof sim_size);
    return fmi2OK;
}

/* The modes an instance of this kind can be in (one of them, exactly). */
static int mode_ok(const fmu_inst *c, int mode) {
    int modes = FMU_ANY_MODE(c);
    return mode > 0 && (mode & (mode - 1)) == 0 && (mode & modes);
}

/* Why the fields of s (just read) are refused, into why; 0 if every field passes its rule. */
static int fields_refused(const fmu_inst *c, const fmu_saved *s, char *why, size_t size) {
    const fmu_model *fm = &c->fm;
    for (size_t k = 0; k < NFIELDS; k++) {
        const state_field *f = &STATE_FIELDS[k];
        const void *data = field_data((void *)s, f->saved, f);
        for (size_t i = 0; i < field_count(fm, f); i++) {
            double x = field_value(data, f, i);
            char shown[40], rule[900] = "";
            if (f->type == FT_INT) snprintf(shown, sizeof shown, "%d", ((const int *)data)[i]);
            else fmu_repr(x, shown, sizeof shown);
            if (f->check == CK_PARAM) {
                if (fmu_param_refuses(&fm->par[i], x, shown, rule, sizeof rule))
                    return snprintf(why, size, "parameter %s = %s: %s", fm->par[i].name, shown, rule), 1;
                continue;
            }
            const char *need = f->check == CK_FLAG && x != 0 && x != 1 ? "0 or 1"
                               : f->check == CK_MODE && !mode_ok(c, (int)x) ? (c->me ? "a Model Exchange mode" : "a co-simulation mode")
                               : f->check == CK_TOL_SOURCE && !(x == 0 || x == 1 || x == 2) ? "0, 1 or 2"
                               : f->check == CK_FINITE && !isfinite(x) ? "finite"
                               : f->check == CK_STABLE_STEP && !(x >= 0) ? ">= 0" : NULL;
            if (need) {
                if (f->array) return snprintf(why, size, "field %s[%zu] = %s (must be %s)", f->name, i, shown, need), 1;
                return snprintf(why, size, "field %s = %s (must be %s)", f->name, shown, need), 1;
            }
        }
    }
    /* the fields that need a run: a running instance has one, and so do outputs of the run */
    if ((s->mode & (M_STEPPING | M_EVENT | M_CONTINUOUS)) && !s->has_sim)
        return snprintf(why, size, "a running instance (mode %d) without the run's bytes", s->mode), 1;
    if ((s->have_outputs || s->derived_stale) && !s->has_sim)
        return snprintf(why, size, "outputs of a run (have_outputs %d, derived_stale %d) without the run's bytes",
                        s->have_outputs, s->derived_stale), 1;
    if (s->have_outputs && !fmu_all_finite(s->outputs, fm->nout))
        return snprintf(why, size, "have_outputs = 1 with a non-finite output"), 1;
    if (s->has_y && !fmu_all_finite(s->y, fm->ny)) return snprintf(why, size, "has_y = 1 with a non-finite state"), 1;
    if (!s->has_sim && s->sim_size)
        return snprintf(why, size, "%zu bytes of a run but has_sim = 0", s->sim_size), 1;
    return 0;
}

/* Why the bytes are refused (into why), or 0 with the state read into s (its run's bytes allocated). */
static int state_refused(const fmu_inst *c, const unsigned char *bytes, size_t size, fmu_saved *s, char *why,
                         size_t whysize) {
    size_t g = strlen(c->fm.guid) + 1, h = header_size(c), fsize = fields_size(&c->fm);
    if (size < 8 || memcmp(bytes, STATE_MAGIC, 8))
        return snprintf(why, whysize, "not an FMU state of this FMU's format (%.8s)", STATE_MAGIC), 1;
    if (size < 8 + g || memcmp(bytes + 8, c->fm.guid, g))
        return snprintf(why, whysize, "a state of another FMU (its GUID differs from %s)", c->fm.guid), 1;
    if (size < h) return snprintf(why, whysize, "truncated: %zu bytes, the header alone has %zu", size, h), 1;
    uint32_t head[4];
    uint64_t sim_size;
    memcpy(head, bytes + 8 + g, sizeof head);
    memcpy(&sim_size, bytes + 8 + g + sizeof head, sizeof sim_size);
    if (head[0] != (c->fmi3 ? 3u : 2u))
        return snprintf(why, whysize, "a state of FMI version %u, this instance is FMI %d", head[0], c->fmi3 ? 3 : 2), 1;
    if (head[1] != (c->me ? 1u : 0u))
        return snprintf(why, whysize, "a state of a %s instance, this one is %s",
                        head[1] == 1u ? "Model Exchange" : head[1] == 0u ? "co-simulation" : "unknown kind of",
                        c->me ? "Model Exchange" : "co-simulation"), 1;
    if (sim_size != (uint64_t)(size - h) - fsize || size - h < fsize)
        return snprintf(why, whysize, "%zu bytes, a state of this FMU with %llu bytes of the run has %zu (truncated or "
                        "malformed)", size, (unsigned long long)sim_size,
                        sim_size <= (uint64_t)SIZE_MAX - h - fsize ? h + fsize + (size_t)sim_size : 0), 1;
    uint32_t crc = crc32_of(bytes + h, size - h);
    if (crc != head[2] || head[3] != 0u)
        return snprintf(why, whysize, "checksum mismatch (CRC-32 %08x of the payload, the header says %08x): "
                        "corrupted or altered", (unsigned)crc, (unsigned)head[2]), 1;
    const unsigned char *r = bytes + h;
    for (size_t k = 0; k < NFIELDS; k++) {
        const state_field *f = &STATE_FIELDS[k];
        size_t n = field_count(&c->fm, f) * field_item(f);
        memcpy(field_data(s, f->saved, f), r, n);
        r += n;
    }
    s->sim_size = (size_t)sim_size;
    if (fields_refused(c, s, why, whysize)) return 1;
    free(s->sim);
    if (!(s->sim = malloc(sim_size ? (size_t)sim_size : 1))) return snprintf(why, whysize, "out of memory"), 1;
    memcpy(s->sim, r, (size_t)sim_size);
    return 0;
}

fmi2Status fmu_state_deserialize(fmu_inst *c, const char *fn, const fmi2Byte bytes[], size_t size,
                                              fmi2FMUstate *state) {
    if (!state) return fmu_log(c, fmi2Error, "%s: FMUstate is NULL", fn), fmi2Error;
    if (size && !bytes) return fmu_log(c, fmi2Error, "%s: serializedState is NULL but size = %zu", fn, size), fmi2Error;
    fmu_saved *s = new_saved(c, 0);
    if (!s) return fmu_log(c, fmi2Error, "%s: out of memory", fn), fmi2Error;
    char why[FMU_MSG];
    if (state_refused(c, (const unsigned char *)bytes, size, s, why, sizeof why)) {
        free_saved(s);
        return fmu_log(c, fmi2Error, "%s: the bytes are refused as an FMU state of this instance: %s", fn, why),
               fmi2Error;
    }
    s->next = c->states;
    c->states = s;
    *state = s;
    return fmi2OK;
}
