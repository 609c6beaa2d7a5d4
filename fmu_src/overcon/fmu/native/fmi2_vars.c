/* Variable access (fmi2Get*, fmi2Set*) with the checks of overcon.fmu.slave (_refs, _get, _set,
 * _set_param): an unknown reference or one of another type, a write to an output or constant, or
 * a parameter value outside its rule is fmi2Error with the reason, and nothing is set; and the
 * remaining calls: fmi2Reset, the status queries, the functions this FMU does not have. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2_core.h"

#define READABLE (M_INITIALIZATION | M_STEPPING | M_ERROR | M_TERMINATED)
#define WRITABLE (M_INSTANTIATED | M_INITIALIZATION | M_STEPPING)
#define ANY_MODE (M_INSTANTIATED | M_INITIALIZATION | M_STEPPING | M_ERROR | M_TERMINATED)

static const char *type_names[4] = {"Real", "Integer", "Boolean", "String"};
static const char *causality_names[3] = {"output", "parameter", "local"};
static const char *variability_names[5] = {"continuous", "constant", "fixed", "tunable", "discrete"};

/* The references checked: each exists and has type `type`; 0 with the refusal logged. */
static int check_refs(fmu_inst *c, const char *fn, const fmi2ValueReference vr[], size_t nvr, const void *values,
                      int type) {
    if (nvr && !vr) return fmu_log(c, fmi2Error, "%s: vr is NULL but nvr = %zu", fn, nvr), 0;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= (fmi2ValueReference)c->fm.nvar)
            return fmu_log(c, fmi2Error, "%s: value reference %u does not exist (this FMU has 0 to %d)", fn, vr[i],
                           c->fm.nvar - 1), 0;
        const fmu_var *v = &c->fm.var[vr[i]];
        if (v->type != type)
            return fmu_log(c, fmi2Error, "%s: value reference %u (%s) is a %s variable, not %s", fn, vr[i], v->name,
                           type_names[v->type], type_names[type]), 0;
    }
    if (nvr && !values) return fmu_log(c, fmi2Error, "%s: value is NULL but nvr = %zu", fn, nvr), 0;
    return 1;
}

/* The value of variable v as a number (strings: the index of the choice); 0 with the reason
 * logged when an output cannot be computed. */
static int value_of(fmu_inst *c, const char *fn, const fmu_var *v, double *out) {
    if (v->key == K_OUTPUT) {
        if (!c->have_outputs && !fmu_ensure_sim(c, 1)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), 0;
        if (v->arg >= c->fm.nstate_out && !fmu_read_derived(c)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), 0;
        *out = c->outputs[v->arg];
    } else if (v->key == K_CONSTANT) {
        *out = v->arg;
    } else if (v->key == K_STABLE_STEP) {
        *out = c->stable_step;
    } else if (v->key == K_ALONG) {
        if (!fmu_along_value(c, v->arg, out)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), 0;
    } else {
        *out = c->pval[v->arg];
    }
    return 1;
}

static fmi2Status get_values(fmi2Component comp, const char *fn, const fmi2ValueReference vr[], size_t nvr,
                             void *values, int type) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, fn, READABLE) || !check_refs(c, fn, vr, nvr, values, type)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const fmu_var *v = &c->fm.var[vr[i]];
        double x;
        if (!value_of(c, fn, v, &x)) return fmi2Error;
        if (type == T_REAL) ((fmi2Real *)values)[i] = x;
        else if (type == T_INTEGER) ((fmi2Integer *)values)[i] = (fmi2Integer)x;
        else if (type == T_BOOLEAN) ((fmi2Boolean *)values)[i] = x != 0.0;
        else {
            const fmu_param *p = v->key == K_PARAM ? &c->fm.par[v->arg] : NULL;
            int k = (int)x;
            ((fmi2String *)values)[i] = p && k >= 0 && k < p->nchoices ? p->choices[k] : "";
        }
    }
    return fmi2OK;
}

FMU_EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    return get_values(c, "fmi2GetReal", vr, nvr, value, T_REAL);
}
FMU_EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    return get_values(c, "fmi2GetInteger", vr, nvr, value, T_INTEGER);
}
FMU_EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    return get_values(c, "fmi2GetBoolean", vr, nvr, value, T_BOOLEAN);
}
FMU_EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    return get_values(c, "fmi2GetString", vr, nvr, (void *)value, T_STRING);
}

/* The reason a number is refused by the rule of p (overcon.params.Rule.check), or 0. */
static int rule_refuses(const fmu_param *p, double x, const char *shown, char *why, size_t size) {
    if (!isfinite(x)) return snprintf(why, size, "must be finite, got %s", shown), 1;
    int low = p->has_lo && (p->low_open ? x <= p->lo : x < p->lo), high = p->has_hi && x > p->hi;
    if (!low && !high) return 0;
    snprintf(why, size, "must be %s, got %s%s%s%s", p->range_text, shown, p->why[0] ? " (" : "", p->why,
             p->why[0] ? ")" : "");
    return 1;
}

/* One parameter set to x (strings: the text s) as overcon.fmu.slave._set_param; 0 with the
 * refusal logged. */
static int set_param(fmu_inst *c, const char *fn, int k, double x, const char *s) {
    const fmu_param *p = &c->fm.par[k];
    char shown[600], why[900] = "";
    if (p->rule == RULE_CHOICE) snprintf(shown, sizeof shown, "'%s'", s ? s : "None");
    else if (p->type == T_INTEGER) snprintf(shown, sizeof shown, "%d", (int)x);
    else fmu_repr(x, shown, sizeof shown);
    if (c->mode == M_STEPPING && !p->tunable)
        snprintf(why, sizeof why, "variability fixed: it cannot change after initialization (fmi2Reset first)");
    else if (p->rule == RULE_CHOICE && !s)
        snprintf(why, sizeof why, "a value is required");
    else if (p->rule == RULE_CHOICE) {
        int found = -1;
        for (int i = 0; i < p->nchoices; i++)
            if (!strcmp(s, p->choices[i])) found = i;
        if (found < 0) {
            size_t len = (size_t)snprintf(why, sizeof why, "must be one of ");
            for (int i = 0; i < p->nchoices && len < sizeof why; i++)
                len += (size_t)snprintf(why + len, sizeof why - len, "%s%s", i ? ", " : "", p->choices[i]);
            if (len < sizeof why) snprintf(why + len, sizeof why - len, ", got %s", shown);
        }
        x = found;
    } else if (!rule_refuses(p, x, shown, why, sizeof why) && p->target == P_MU_STATIC) {
        for (int i = 0; i < c->fm.nparam; i++)
            if (c->fm.par[i].target == P_MU && c->fm.par[i].joint == p->joint && x < c->pval[i]) {
                char mu[40];
                fmu_repr(c->pval[i], mu, sizeof mu);
                snprintf(why, sizeof why, "must be >= %s (%s), got %s", c->fm.par[i].name, mu, shown);
            }
    }
    if (why[0]) return fmu_log(c, fmi2Error, "%s: parameter %s = %s refused: %s", fn, p->name, shown, why), 0;
    c->pval[k] = x;
    c->pset[k] = 1;
    if (p->target == P_TOLERANCE) c->tol_source = 1;
    if (!p->tunable) c->sim_valid = c->have_outputs = 0;
    return 1;
}

static fmi2Status set_values(fmi2Component comp, const char *fn, const fmi2ValueReference vr[], size_t nvr,
                             const void *values, int type) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, fn, WRITABLE) || !check_refs(c, fn, vr, nvr, values, type)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const fmu_var *v = &c->fm.var[vr[i]];
        if (v->key != K_PARAM) {
            fmu_log(c, fmi2Error, "%s: value reference %u (%s) is %s (%s): it cannot be set", fn, vr[i], v->name,
                    causality_names[v->causality], variability_names[v->variability]);
            return fmi2Error;
        }
    }
    for (size_t i = 0; i < nvr; i++) {
        int k = c->fm.var[vr[i]].arg;
        double x = type == T_REAL ? ((const fmi2Real *)values)[i] : type == T_STRING ? 0.0
                                                                   : (double)((const fmi2Integer *)values)[i];
        if (type == T_BOOLEAN) x = x != 0.0;
        if (!set_param(c, fn, k, x, type == T_STRING ? ((const fmi2String *)values)[i] : NULL)) return fmi2Error;
    }
    return fmi2OK;
}

FMU_EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    return set_values(c, "fmi2SetReal", vr, nvr, value, T_REAL);
}
FMU_EXPORT fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                     const fmi2Integer value[]) {
    return set_values(c, "fmi2SetInteger", vr, nvr, value, T_INTEGER);
}
FMU_EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                     const fmi2Boolean value[]) {
    return set_values(c, "fmi2SetBoolean", vr, nvr, value, T_BOOLEAN);
}
FMU_EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                    const fmi2String value[]) {
    return set_values(c, "fmi2SetString", vr, nvr, value, T_STRING);
}

FMU_EXPORT fmi2Status fmi2Reset(fmi2Component comp) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2Reset", ANY_MODE)) return fmi2Error;
    fmu_init_fields(c);
    return fmi2OK;
}

/* fmi2Get*Status: fmi2LastSuccessfulTime (Real) and fmi2Terminated (Boolean) are known. */
static fmi2Status status_query(fmi2Component comp, const char *fn, int kind, void *value, int type) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, fn, ANY_MODE)) return fmi2Error;
    static const char *kinds[4] = {"fmi2DoStepStatus", "fmi2PendingStatus", "fmi2LastSuccessfulTime",
                                   "fmi2Terminated"};
    if (!value) return fmu_log(c, fmi2Error, "%s: %s: value is NULL", fn, fn), fmi2Error;
    if (type == T_REAL && kind == fmi2LastSuccessfulTime) return *(fmi2Real *)value = c->t, fmi2OK;
    if (type == T_BOOLEAN && kind == fmi2Terminated) return *(fmi2Boolean *)value = c->mode == M_ERROR, fmi2OK;
    char k[24];
    snprintf(k, sizeof k, "%d", kind);
    fmu_log(c, fmi2Error, "%s: %s(%s): not available (this FMU never returns fmi2Pending; known: fmi2GetRealStatus("
            "fmi2LastSuccessfulTime), fmi2GetBooleanStatus(fmi2Terminated))", fn, fn,
            kind >= 0 && kind < 4 ? kinds[kind] : k);
    return fmi2Error;
}

FMU_EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    return status_query(c, "fmi2GetStatus", s, value, -1);
}
FMU_EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    return status_query(c, "fmi2GetRealStatus", s, value, T_REAL);
}
FMU_EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    return status_query(c, "fmi2GetIntegerStatus", s, value, T_INTEGER);
}
FMU_EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    return status_query(c, "fmi2GetBooleanStatus", s, value, T_BOOLEAN);
}
FMU_EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    return status_query(c, "fmi2GetStringStatus", s, value, T_STRING);
}

static fmi2Status unsupported(fmi2Component comp, const char *fn) {
    fmu_inst *c = comp;
    if (!c) return fmi2Error;
    fmu_log(c, fmi2Error, "unsupported: %s is not supported by this FMU (no inputs, no derivatives, no asynchronous "
            "steps)", fn);
    return fmi2Error;
}

FMU_EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[],
                                                   size_t nUnknown, const fmi2ValueReference vKnown[], size_t nKnown,
                                                   const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    (void)vUnknown, (void)nUnknown, (void)vKnown, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    return unsupported(c, "fmi2GetDirectionalDerivative");
}
FMU_EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                                  const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr, (void)nvr, (void)order, (void)value;
    return unsupported(c, "fmi2SetRealInputDerivatives");
}
FMU_EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                                   const fmi2Integer order[], fmi2Real value[]) {
    (void)vr, (void)nvr, (void)order, (void)value;
    return unsupported(c, "fmi2GetRealOutputDerivatives");
}
FMU_EXPORT fmi2Status fmi2CancelStep(fmi2Component c) { return unsupported(c, "fmi2CancelStep"); }
