/* Variable access (fmi2Get*, fmi2Set*) with the checks of overcon.fmu.slave (_refs, _get, _set,
 * _set_param): an unknown reference or one of another type, a write to an output or constant, or
 * a parameter value outside its rule is fmi2Error with the reason, and nothing is set; and the
 * remaining calls: fmi2Reset, the status queries, the functions this FMU does not have. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"



static fmi2Status get_values(fmi2Component comp, const char *fn, const fmi2ValueReference vr[], size_t nvr,
                             void *values, int type) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, fn, FMU_READABLE(c)) || !fmu_check_refs(c, fn, vr, nvr, values, type)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const fmu_var *v = &c->fm.var[vr[i]];
        double x;
        if (!fmu_value_of(c, fn, v, &x)) return fmi2Error;
        if (type == T_REAL) ((fmi2Real *)values)[i] = x;
        else if (type == T_INTEGER) ((fmi2Integer *)values)[i] = (fmi2Integer)x;
        else if (type == T_BOOLEAN) ((fmi2Boolean *)values)[i] = x != 0.0;
        else {
            const fmu_param *p = v->key == K_PARAM ? &c->fm.par[v->arg] : NULL;
            int k = p && x >= 0 && x < p->nchoices ? (int)x : -1; /* an index checked before it converts */
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


static fmi2Status set_values(fmi2Component comp, const char *fn, const fmi2ValueReference vr[], size_t nvr,
                             const void *values, int type) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, fn, FMU_WRITABLE(c)) || !fmu_check_refs(c, fn, vr, nvr, values, type)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const fmu_var *v = &c->fm.var[vr[i]];
        if (v->key != K_PARAM && v->key != K_INPUT) {
            fmu_log(c, fmi2Error, "%s: value reference %u (%s) is %s (%s): it cannot be set", fn, vr[i], v->name,
                    fmu_causality_names[v->causality], fmu_variability_names[v->variability]);
            return fmi2Error;
        }
    }
    for (size_t i = 0; i < nvr; i++) {
        int k = c->fm.var[vr[i]].arg;
        double x = type == T_REAL ? ((const fmi2Real *)values)[i] : type == T_STRING ? 0.0
                                                                   : (double)((const fmi2Integer *)values)[i];
        if (type == T_BOOLEAN) x = x != 0.0;
        if (c->fm.var[vr[i]].key == K_INPUT) {
            if (!fmu_set_input(c, fn, k, x, 0)) return fmi2Error;
            continue;
        }
        if (!fmu_set_param(c, fn, k, x, type == T_STRING ? ((const fmi2String *)values)[i] : NULL)) return fmi2Error;
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
    if (!c || !fmu_allowed(c, "fmi2Reset", FMU_ANY_MODE(c))) return fmi2Error;
    fmu_init_fields(c);
    return fmi2OK;
}

/* fmi2Get*Status: fmi2LastSuccessfulTime (Real) and fmi2Terminated (Boolean) are known. */
static fmi2Status status_query(fmi2Component comp, const char *fn, int kind, void *value, int type) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, fn, FMU_ANY_MODE(c))) return fmi2Error;
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
/* Co-simulation: the first derivatives of inputs, for the next communication step (the input is
 * linear within it: canInterpolateInputs); order 1 only (maxInputDerivativeOrder is not raised). */
FMU_EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                                  const fmi2Integer order[], const fmi2Real value[]) {
    const char *fn = "fmi2SetRealInputDerivatives";
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, fn, FMU_WRITABLE(c)) || !fmu_check_refs(c, fn, vr, nvr, value, T_REAL)) return fmi2Error;
    if (c->me) return fmu_log(c, fmi2Error, "%s: a co-simulation call (this instance is for Model Exchange)", fn), fmi2Error;
    if (nvr && !order) return fmu_log(c, fmi2Error, "%s: order is NULL but nvr = %zu", fn, nvr), fmi2Error;
    for (size_t i = 0; i < nvr; i++) {
        const fmu_var *v = &c->fm.var[vr[i]];
        if (v->key != K_INPUT)
            return fmu_log(c, fmi2Error, "%s: value reference %u (%s) is no input", fn, vr[i], v->name), fmi2Error;
        if (order[i] != 1)
            return fmu_log(c, fmi2Error, "%s: %s: derivative order %d (this FMU takes first derivatives: the input "
                           "linear within the step)", fn, v->name, order[i]), fmi2Error;
    }
    for (size_t i = 0; i < nvr; i++)
        if (!fmu_set_input(c, fn, c->fm.var[vr[i]].arg, value[i], 1)) return fmi2Error;
    return fmi2OK;
}
FMU_EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                                   const fmi2Integer order[], fmi2Real value[]) {
    (void)vr, (void)nvr, (void)order, (void)value;
    return unsupported(c, "fmi2GetRealOutputDerivatives");
}
FMU_EXPORT fmi2Status fmi2CancelStep(fmi2Component c) { return unsupported(c, "fmi2CancelStep"); }
