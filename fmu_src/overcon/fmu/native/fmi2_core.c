/* The FMI 2.0 co-simulation functions of an overcon FMU without Python (see fmi2_core.h): an
 * instance owns its model file, parameters, the core's run (ovk_sim) and outputs. The behaviour
 * and the messages are those of the Python slave (overcon.fmu.slave; its module docstring is the
 * specification): the state machine, variable access, parameters refused with the rule's reason,
 * the tolerance rule, the doStep work budget, reactions computed once the host reads one. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2_core.h"

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
    if (!c || !c->logger || (status < fmi2Error && !c->enabled[cat])) return;
    char msg[4 * FMU_MSG], esc[8 * FMU_MSG];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
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
    case M_ERROR: return "error";
    default: return "terminated";
    }
}

/* 1 if the instance's mode is one of modes, else the refusal logged (names in sorted order). */
int fmu_allowed(fmu_inst *c, const char *fn, int modes) {
    if (c->mode & modes) return 1;
    static const int sorted[5] = {M_ERROR, M_INITIALIZATION, M_INSTANTIATED, M_STEPPING, M_TERMINATED};
    char list[160] = "";
    for (int k = 0; k < 5; k++)
        if (modes & sorted[k]) {
            if (list[0]) strcat(list, ", ");
            strcat(list, mode_name(sorted[k]));
        }
    fmu_log(c, fmi2Error, "%s: not allowed in state '%s' (allowed in: %s)", fn, mode_name(c->mode), list);
    return 0;
}

static fmu_inst *checked(fmi2Component comp, const char *fn) {
    if (!comp) fprintf(stderr, "overcon FMU: %s called with a NULL component\n", fn);
    return (fmu_inst *)comp;
}

static int hexval(char ch) {
    return ch >= '0' && ch <= '9' ? ch - '0' : ch >= 'a' && ch <= 'f' ? ch - 'a' + 10
                                             : ch >= 'A' && ch <= 'F' ? ch - 'A' + 10 : -1;
}

/* The resources folder of a file: URI (or a plain absolute path), percent escapes decoded. */
static int resource_dir(const char *uri, char *out, size_t size) {
    const char *p = uri;
    if (!strncmp(p, "file://localhost/", 17)) p += 16;
    else if (!strncmp(p, "file:///", 8)) p += 7;
    else if (!strncmp(p, "file:/", 6)) p += 5;
    else if (p[0] != '/') return 0;
    while (p[0] == '/' && p[1] == '/') p++;
    size_t j = 0;
    for (; *p && j + 1 < size; p++) {
        if (*p == '%' && hexval(p[1]) >= 0 && hexval(p[2]) >= 0) {
            out[j++] = (char)(hexval(p[1]) * 16 + hexval(p[2]));
            p += 2;
        } else {
            out[j++] = *p;
        }
    }
    while (j > 1 && out[j - 1] == '/') j--;
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
    memset(c->outputs, 0, (size_t)(fm->nout ? fm->nout : 1) * sizeof(double));
}

static void free_inst(fmu_inst *c) {
    while (c->states) {
        fmu_saved *s = c->states;
        c->states = s->next;
        free(s->pval), free(s->pset), free(s->outputs), free(s->y), free(s->sim), free(s);
    }
    ovk_sim_free(c->sim);
    free(c->jlawp), free(c->pval), free(c->pset), free(c->outputs), free(c->y), free(c->reac), free(c->fric);
    free(c->strings);
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
    c->strings = calloc((size_t)fm->nvar + 1, sizeof(char *));
    return c->jlawp && c->pval && c->pset && c->outputs && c->y && c->reac && c->fric && c->strings;
}

FMU_EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
FMU_EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

FMU_EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String guid,
                                         fmi2String resourceLocation, const fmi2CallbackFunctions *functions,
                                         fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)visible;
    fmu_inst tmp = {0}, *c = NULL;
    tmp.name = (char *)(instanceName ? instanceName : "");
    if (functions) tmp.logger = functions->logger, tmp.env = functions->componentEnvironment;
    default_categories(&tmp, loggingOn);
    char resources[4096], path[4200], err[600];
    if (!instanceName || !instanceName[0]) {
        fmu_log(&tmp, fmi2Error, "fmi2Instantiate: instanceName is empty");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        fmu_log(&tmp, fmi2Error, "fmi2Instantiate: this FMU supports co-simulation only (fmuType %d given)", fmuType);
        return NULL;
    }
    if (!resourceLocation || !resource_dir(resourceLocation, resources, sizeof resources)) {
        fmu_log(&tmp, fmi2Error, "fmi2Instantiate: fmuResourceLocation %s is not a file: URI of the FMU's resources "
                "folder", resourceLocation ? resourceLocation : "(NULL)");
        return NULL;
    }
    snprintf(path, sizeof path, "%s/overcon_model.bin", resources);
    if (!(c = calloc(1, sizeof *c)) || !(c->name = malloc(strlen(tmp.name) + 1))) {
        free(c);
        fmu_log(&tmp, fmi2Error, "fmi2Instantiate: out of memory");
        return NULL;
    }
    strcpy(c->name, tmp.name);
    c->logger = tmp.logger, c->env = tmp.env;
    default_categories(c, loggingOn);
    if (!fmu_model_read(path, &c->fm, err, sizeof err)) {
        fmu_log(c, fmi2Error, "fmi2Instantiate: %s", err);
        free_inst(c);
        return NULL;
    }
    if (guid && strcmp(guid, c->fm.guid)) {
        fmu_log(c, fmi2Error, "fmi2Instantiate: GUID %s does not match this FMU's %s (modelDescription.xml of another "
                "build?)", guid, c->fm.guid);
        free_inst(c);
        return NULL;
    }
    if (!alloc_arrays(c)) {
        fmu_log(c, fmi2Error, "fmi2Instantiate: out of memory");
        free_inst(c);
        return NULL;
    }
    fmu_init_fields(c);
    for (int k = 0; k < c->fm.nmsg; k++) fmu_log(c, (fmi2Status)c->fm.msg_status[k], "%s", c->fm.msg[k]);
    return c;
}

FMU_EXPORT void fmi2FreeInstance(fmi2Component comp) {
    fmu_inst *c = checked(comp, "fmi2FreeInstance");
    if (c) free_inst(c);
}

FMU_EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories,
                                          const fmi2String categories[]) {
    fmu_inst *c = checked(comp, "fmi2SetDebugLogging");
    if (!c) return fmi2Error;
    if (nCategories == 0) {
        default_categories(c, loggingOn);
        return fmi2OK;
    }
    if (!categories) {
        fmu_log(c, fmi2Error, "fmi2SetDebugLogging: categories is NULL but nCategories = %zu", nCategories);
        return fmi2Error;
    }
    for (size_t i = 0; i < nCategories; i++) {
        const char *name = categories[i] ? categories[i] : "(NULL)";
        int found = 0;
        for (int k = 0; k < N_CATEGORIES; k++)
            if (!strcmp(name, category_names[k]) || !strcmp(name, "logAll")) c->enabled[k] = loggingOn ? 1 : 0, found = 1;
        if (!found) {
            fmu_log(c, fmi2Error, "fmi2SetDebugLogging: unknown log category \"%s\" (categories: logEvents, "
                    "logStatusWarning, logStatusError, logStatusFatal, logAll)", name);
            return fmi2Error;
        }
    }
    return fmi2OK;
}
