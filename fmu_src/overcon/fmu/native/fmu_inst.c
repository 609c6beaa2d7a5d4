/* An instance of an overcon FMU without Python, whatever the FMI version: made from its resources
 * folder (the model file read, the GUID checked, the arrays allocated), freed, its logging (the
 * categories, fmu_log), its mode checks (fmu_allowed) and number formatting (fmu_repr). The FMI
 * functions of each version (fmi2_*.c, fmi3_*.c) call these. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"
static const char *category_names[N_CATEGORIES] = {"logEvents", "logStatusWarning", "logStatusError",
                                                   "logStatusFatal"};

static void default_categories(fmu_inst *c, int logging_on) {
    for (int k = 0; k < N_CATEGORIES; k++) c->enabled[k] = logging_on || k != CAT_EVENTS;
}

/* A message to the host's logger in the category of its status (errors always; warnings unless
 * switched off; the rest with debug logging on); every % doubled (the logger takes a format). */
void fmu_log(fmu_inst *c, fmi2Status status, const char *fmt, ...) {
    int cat = status == fmi2OK ? CAT_EVENTS : status <= fmi2Discard ? CAT_WARNING : status == fmi2Error ? CAT_ERROR
                                                                                                       : CAT_FATAL;
    if (!c || !(c->logger || c->log3) || (status < fmi2Error && !c->enabled[cat])) return;
    char msg[4 * FMU_MSG], esc[8 * FMU_MSG];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (c->log3) { /* FMI 3.0: the message is not a format */
        c->log3(c->env, (fmi3Status)status, category_names[cat], msg);
        return;
    }
    size_t j = 0;
    for (const char *s = msg; *s && j + 2 < sizeof esc; s++) {
        esc[j++] = *s;
        if (*s == '%') esc[j++] = '%';
    }
    esc[j] = '\0';
    c->logger(c->env, c->name, status, category_names[cat], esc);
}

/* x as Python's repr(float): the shortest digits that read back as x, fixed notation for
 * exponents -4 to 15 (with ".0" when integral), else d.ddde+XX. */
void fmu_repr(double x, char *buf, size_t size) {
    if (isnan(x)) { snprintf(buf, size, "nan"); return; }
    if (isinf(x)) { snprintf(buf, size, x > 0 ? "inf" : "-inf"); return; }
    char e[40];
    int p = 1;
    for (; p < 17; p++) {
        snprintf(e, sizeof e, "%.*e", p - 1, x);
        if (strtod(e, NULL) == x) break;
    }
    snprintf(e, sizeof e, "%.*e", p - 1, x);
    int exp10 = atoi(strchr(e, 'e') + 1);
    if (exp10 < -4 || exp10 >= 16) { snprintf(buf, size, "%s", e); return; }
    int decimals = p - 1 - exp10 > 0 ? p - 1 - exp10 : 0;
    snprintf(buf, size, "%.*f", decimals, x);
    if (!strchr(buf, '.') && strlen(buf) + 3 <= size) strcat(buf, ".0");
}

static const char *mode_name(int mode) {
    switch (mode) {
    case M_INSTANTIATED: return "instantiated";
    case M_INITIALIZATION: return "initialization mode";
    case M_STEPPING: return "slave initialized";
    case M_EVENT: return "event mode";
    case M_CONTINUOUS: return "continuous-time mode";
    case M_ERROR: return "error";
    default: return "terminated";
    }
}

/* 1 if the instance's mode is one of modes, else the refusal logged (names in sorted order). */
int fmu_allowed(fmu_inst *c, const char *fn, int modes) {
    if (c->mode & modes) return 1;
    static const int sorted[7] = {M_CONTINUOUS, M_ERROR, M_EVENT, M_INITIALIZATION, M_INSTANTIATED, M_STEPPING,
                                  M_TERMINATED};
    char list[200] = "";
    for (int k = 0; k < 7; k++)
        if (modes & sorted[k]) {
            if (list[0]) strcat(list, ", ");
            strcat(list, mode_name(sorted[k]));
        }
    fmu_log(c, fmi2Error, "%s: not allowed in state '%s' (allowed in: %s)", fn, mode_name(c->mode), list);
    return 0;
}

fmu_inst *fmu_checked(fmi2Component comp, const char *fn) {
    if (!comp) fprintf(stderr, "overcon FMU: %s called with a NULL component\n", fn);
    return (fmu_inst *)comp;
}

static int hexval(char ch) {
    return ch >= '0' && ch <= '9' ? ch - '0' : ch >= 'a' && ch <= 'f' ? ch - 'a' + 10
                                             : ch >= 'A' && ch <= 'F' ? ch - 'A' + 10 : -1;
}

#if defined(_WIN32)
static int drive_letter(const char *p) { /* "C:/" or "C:\\": a Windows path's drive */
    return ((p[0] >= 'A' && p[0] <= 'Z') || (p[0] >= 'a' && p[0] <= 'z')) && p[1] == ':' &&
           (p[2] == '/' || p[2] == '\\');
}
#else
#define drive_letter(p) 0 /* elsewhere /C:/dir is a path like any other */
#endif

/* The resources folder of a file: URI (or a plain absolute path), percent escapes decoded; 0 for
 * one that is not, or whose escapes hold %00 (a NUL would silently cut the path there). On
 * Windows, the URI file:///C:/dir names the path C:/dir (not /C:/dir) and a plain path with a drive
 * (FMI 3.0's resourcePath, C:\dir\ or C:/dir/) is taken as it is. */
int fmu_resource_dir(const char *uri, char *out, size_t size) {
    const char *p = uri;
    if (!strncmp(p, "file://localhost/", 17)) p += 16;
    else if (!strncmp(p, "file:///", 8)) p += 7;
    else if (!strncmp(p, "file:/", 6)) p += 5;
    else if (p[0] != '/' && !drive_letter(p)) return 0;
    while (p[0] == '/' && p[1] == '/') p++;
    if (p[0] == '/' && drive_letter(p + 1)) p++;
    size_t j = 0;
    for (; *p && j + 1 < size; p++) {
        if (*p == '%' && hexval(p[1]) >= 0 && hexval(p[2]) >= 0) {
            if (hexval(p[1]) == 0 && hexval(p[2]) == 0) return 0; /* %00 would cut the path short */
            out[j++] = (char)(hexval(p[1]) * 16 + hexval(p[2]));
            p += 2;
        } else {
            out[j++] = *p;
        }
    }
    while (j > 1 && (out[j - 1] == '/' || (out[j - 1] == '\\' && drive_letter(out)))) j--;
    out[j] = '\0';
    return 1;
}

/* The state after fmi2Instantiate and fmi2Reset: defaults, no run. */
void fmu_init_fields(fmu_inst *c) {
    const fmu_model *fm = &c->fm;
    for (int k = 0; k < fm->nparam; k++) {
        const fmu_param *p = &fm->par[k];
        c->pval[k] = p->ddefault;
        for (int i = 0; p->rule == RULE_CHOICE && i < p->nchoices; i++)
            if (!strcmp(p->choices[i], p->sdefault)) c->pval[k] = i;
        c->pset[k] = 0;
    }
    c->tol_source = 0;
    c->start_time = c->t = fm->start_time;
    c->mode = M_INSTANTIATED;
    ovk_sim_free(c->sim);
    c->sim = NULL;
    c->sim_valid = c->have_outputs = c->derived_stale = c->derived_read = c->has_y = c->has_failed = 0;
    c->stable_step = 0.0;
    c->dx_valid = 0;
    memset(c->outputs, 0, (size_t)(fm->nout ? fm->nout : 1) * sizeof(double));
    for (int k = 0; k < fm->M.nu; k++) { /* the inputs' start values, no derivatives */
        c->uval[k] = fm->M.up[OVK_NUP * k + 7];
        c->uval[fm->M.nu + k] = 0.0;
    }
    c->u_dirty = 1;
    c->u_pending = 0;
}

void fmu_free_inst(fmu_inst *c) {
    while (c->states) {
        fmu_saved *s = c->states;
        c->states = s->next;
        fmu_saved_free(s);
    }
    ovk_sim_free(c->sim);
    free(c->jlawp), free(c->pval), free(c->pset), free(c->outputs), free(c->y), free(c->reac), free(c->fric), free(c->dx);
    free(c->strings), free(c->along), free(c->uval);
    fmu_model_free(&c->fm);
    free(c->name);
    free(c);
}

/* The instance's arrays, sized from its model; 0 when out of memory. */
static int alloc_arrays(fmu_inst *c) {
    const fmu_model *fm = &c->fm;
    size_t nj = (size_t)(fm->M.nj ? fm->M.nj : 1), np = (size_t)fm->nparam + 1;
    c->jlawp = calloc(nj * NLP, sizeof(double));
    c->pval = calloc(np, sizeof(double));
    c->pset = calloc(np, sizeof(int));
    c->outputs = calloc((size_t)fm->nout + 1, sizeof(double));
    c->y = calloc((size_t)fm->ny + 1, sizeof(double));
    c->reac = calloc(nj * OVK_NREAC, sizeof(double));
    c->fric = calloc(nj, sizeof(double));
    c->dx = calloc((size_t)fm->ny + 1, sizeof(double));
    c->strings = calloc((size_t)fm->nvar + 1, sizeof(char *));
    c->along = calloc(nj, sizeof(int));
    c->uval = calloc(2 * (size_t)fm->M.nu + 1, sizeof(double));
    return c->jlawp && c->pval && c->pset && c->outputs && c->y && c->reac && c->fric && c->dx && c->strings &&
           c->along && c->uval;
}

/* The instance named tmp->name with tmp's logger, its model read from the resources folder
 * `resources`; NULL with the reason logged (fn: the FMI call) when the model file cannot be read,
 * the GUID differs or memory runs out. */
fmu_inst *fmu_instantiate(const fmu_inst *tmp, const char *fn, const char *resources, const char *guid,
                          int logging_on) {
    char path[4200], err[600];
    fmu_inst *c = NULL;
    snprintf(path, sizeof path, "%s/overcon_model.bin", resources);
    if (!(c = calloc(1, sizeof *c)) || !(c->name = malloc(strlen(tmp->name) + 1))) {
        free(c);
        fmu_log((fmu_inst *)tmp, fmi2Error, "%s: out of memory", fn);
        return NULL;
    }
    strcpy(c->name, tmp->name);
    c->logger = tmp->logger, c->log3 = tmp->log3, c->env = tmp->env;
    c->fmi3 = tmp->fmi3, c->me = tmp->me;
    default_categories(c, logging_on);
    if (!fmu_model_read(path, &c->fm, err, sizeof err)) {
        fmu_log(c, fmi2Error, "%s: %s", fn, err);
        fmu_free_inst(c);
        return NULL;
    }
    if (!guid) {
        fmu_log(c, fmi2Error, "%s: the GUID (instantiationToken) is NULL; this FMU's is %s", fn, c->fm.guid);
        fmu_free_inst(c);
        return NULL;
    }
    if (strcmp(guid, c->fm.guid)) {
        fmu_log(c, fmi2Error, "%s: GUID %s does not match this FMU's %s (modelDescription.xml of another "
                "build?)", fn, guid, c->fm.guid);
        fmu_free_inst(c);
        return NULL;
    }
    if (!alloc_arrays(c)) {
        fmu_log(c, fmi2Error, "%s: out of memory", fn);
        fmu_free_inst(c);
        return NULL;
    }
    fmu_init_fields(c);
    for (int k = 0; k < c->fm.nmsg; k++) fmu_log(c, (fmi2Status)c->fm.msg_status[k], "%s", c->fm.msg[k]);
    return c;
}

void fmu_default_categories(fmu_inst *c, int logging_on) { default_categories(c, logging_on); }

/* fn (fmi2SetDebugLogging, fmi3SetDebugLogging): the categories switched on or off. */
int fmu_set_debug_logging(fmu_inst *c, const char *fn, int logging_on, size_t n, const char *const categories[]) {
    if (n == 0) {
        default_categories(c, logging_on);
        return 1;
    }
    if (!categories) {
        fmu_log(c, fmi2Error, "%s: categories is NULL but nCategories = %zu", fn, n);
        return 0;
    }
    for (size_t i = 0; i < n; i++) {
        const char *name = categories[i] ? categories[i] : "(NULL)";
        int found = 0;
        for (int k = 0; k < N_CATEGORIES; k++)
            if (!strcmp(name, category_names[k]) || !strcmp(name, "logAll")) c->enabled[k] = logging_on ? 1 : 0, found = 1;
        if (!found) {
            fmu_log(c, fmi2Error, "%s: unknown log category \"%s\" (categories: logEvents, "
                    "logStatusWarning, logStatusError, logStatusFatal, logAll)", fn, name);
            return 0;
        }
    }
    return 1;
}
