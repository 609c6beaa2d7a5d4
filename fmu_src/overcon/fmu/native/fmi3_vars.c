/* FMI 3.0 variable access of an overcon FMU without Python: fmi3Get/SetFloat64, Int32, Boolean and
 * String over the shared checks of fmu_vars.c (an unknown reference or one of another type, a write
 * to an output or constant, or a refused parameter value is fmi3Error with the reason, and nothing is
 * set); the array variables <joint>.reaction (K_ARRAY: the joint's consecutive reaction outputs)
 * read element by element; the types and functions this FMU has no use for return fmi3Error naming
 * themselves. */
#include <stdio.h>
#include <string.h>

#include "fmu_common.h"

/* The number of values of variable v: an array's elements (the reaction outputs of one joint from
 * v->arg on), else 1. */
static size_t var_size(const fmu_model *fm, const fmu_var *v) {
    if (v->key != K_ARRAY) return 1;
    size_t n = 0;
    const fmu_out *first = &fm->out[v->arg];
    for (int k = v->arg; k < fm->nout && fm->out[k].kind == first->kind && fm->out[k].a == first->a; k++) n++;
    return n;
}

/* The references checked (fmu_check_refs) and their values' count equal to nValues. */
static int refs_ok(fmu_inst *c, const char *fn, const fmi3ValueReference vr[], size_t nvr, const void *values,
                   size_t nValues, int type) {
    if (!fmu_check_refs(c, fn, vr, nvr, values, type)) return 0;
    size_t n = 0;
    for (size_t i = 0; i < nvr; i++) n += var_size(&c->fm, &c->fm.var[vr[i]]);
    if (n != nValues)
        return fmu_log(c, fmi2Error, "%s: nValues = %zu, but the %zu value references have %zu values", fn, nValues,
                       nvr, n), 0;
    return 1;
}

static fmi3Status get_values(fmi3Instance instance, const char *fn, const fmi3ValueReference vr[], size_t nvr,
                             void *values, size_t nValues, int type) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, fn, FMU_READABLE(c)) || !refs_ok(c, fn, vr, nvr, values, nValues, type))
        return fmi3Error;
    size_t j = 0;
    for (size_t i = 0; i < nvr; i++) {
        const fmu_var *v = &c->fm.var[vr[i]];
        size_t n = var_size(&c->fm, v);
        for (size_t e = 0; e < n; e++, j++) {
            fmu_var element = *v;
            if (v->key == K_ARRAY) element.key = K_OUTPUT, element.arg = v->arg + (int)e;
            double x;
            if (!fmu_value_of(c, fn, &element, &x)) return fmi3Error;
            if (type == T_REAL) ((fmi3Float64 *)values)[j] = x;
            else if (type == T_INTEGER) ((fmi3Int32 *)values)[j] = (fmi3Int32)x;
            else if (type == T_BOOLEAN) ((fmi3Boolean *)values)[j] = x != 0.0;
            else {
                const fmu_param *p = v->key == K_PARAM ? &c->fm.par[v->arg] : NULL;
                int k = p && x >= 0 && x < p->nchoices ? (int)x : -1; /* an index checked before it converts */
                ((fmi3String *)values)[j] = p && k >= 0 && k < p->nchoices ? p->choices[k] : "";
            }
        }
    }
    return fmi3OK;
}

static fmi3Status set_values(fmi3Instance instance, const char *fn, const fmi3ValueReference vr[], size_t nvr,
                             const void *values, size_t nValues, int type) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, fn, FMU_WRITABLE(c)) || !refs_ok(c, fn, vr, nvr, values, nValues, type))
        return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        const fmu_var *v = &c->fm.var[vr[i]];
        if (v->key != K_PARAM && v->key != K_INPUT) {
            fmu_log(c, fmi2Error, "%s: value reference %u (%s) is %s (%s): it cannot be set", fn, vr[i], v->name,
                    fmu_causality_names[v->causality], fmu_variability_names[v->variability]);
            return fmi3Error;
        }
    }
    for (size_t i = 0; i < nvr; i++) {
        int k = c->fm.var[vr[i]].arg;
        double x = type == T_REAL      ? ((const fmi3Float64 *)values)[i]
                   : type == T_INTEGER ? (double)((const fmi3Int32 *)values)[i]
                   : type == T_BOOLEAN ? (double)((const fmi3Boolean *)values)[i]
                                       : 0.0;
        if (c->fm.var[vr[i]].key == K_INPUT) {
            if (!fmu_set_input(c, fn, k, x, 0)) return fmi3Error;
            continue;
        }
        if (!fmu_set_param(c, fn, k, x, type == T_STRING ? ((const fmi3String *)values)[i] : NULL)) return fmi3Error;
    }
    return fmi3OK;
}

FMU_EXPORT fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                     size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    return get_values(instance, "fmi3GetFloat64", valueReferences, nValueReferences, values, nValues, T_REAL);
}
FMU_EXPORT fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3Int32 values[], size_t nValues) {
    return get_values(instance, "fmi3GetInt32", valueReferences, nValueReferences, values, nValues, T_INTEGER);
}
FMU_EXPORT fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                     size_t nValueReferences, fmi3Boolean values[], size_t nValues) {
    return get_values(instance, "fmi3GetBoolean", valueReferences, nValueReferences, values, nValues, T_BOOLEAN);
}
FMU_EXPORT fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, fmi3String values[], size_t nValues) {
    return get_values(instance, "fmi3GetString", valueReferences, nValueReferences, (void *)values, nValues, T_STRING);
}
FMU_EXPORT fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                     size_t nValueReferences, const fmi3Float64 values[], size_t nValues) {
    return set_values(instance, "fmi3SetFloat64", valueReferences, nValueReferences, values, nValues, T_REAL);
}
FMU_EXPORT fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3Int32 values[], size_t nValues) {
    return set_values(instance, "fmi3SetInt32", valueReferences, nValueReferences, values, nValues, T_INTEGER);
}
FMU_EXPORT fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                     size_t nValueReferences, const fmi3Boolean values[], size_t nValues) {
    return set_values(instance, "fmi3SetBoolean", valueReferences, nValueReferences, values, nValues, T_BOOLEAN);
}
FMU_EXPORT fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3String values[], size_t nValues) {
    return set_values(instance, "fmi3SetString", valueReferences, nValueReferences, values, nValues, T_STRING);
}

/* A call this FMU does not support: fmi3Error naming it and why. */
static fmi3Status unsupported(fmi3Instance instance, const char *fn, const char *why) {
    fmu_inst *c = instance;
    if (!c) return fmi3Error;
    fmu_log(c, fmi2Error, "unsupported: %s is not supported by this FMU (%s)", fn, why);
    return fmi3Error;
}

#define NO_TYPE "its variables are Float64, Int32, Boolean and String"
/* The getters and setters of the types this FMU has no variables of. */
#define NO_VARIABLES(T)                                                                                                \
    FMU_EXPORT fmi3Status fmi3Get##T(fmi3Instance instance, const fmi3ValueReference valueReferences[],                \
                                     size_t nValueReferences, fmi3##T values[], size_t nValues) {                      \
        (void)valueReferences, (void)nValueReferences, (void)values, (void)nValues;                                    \
        return unsupported(instance, "fmi3Get" #T, NO_TYPE);                                                           \
    }                                                                                                                  \
    FMU_EXPORT fmi3Status fmi3Set##T(fmi3Instance instance, const fmi3ValueReference valueReferences[],                \
                                     size_t nValueReferences, const fmi3##T values[], size_t nValues) {                \
        (void)valueReferences, (void)nValueReferences, (void)values, (void)nValues;                                    \
        return unsupported(instance, "fmi3Set" #T, NO_TYPE);                                                           \
    }
NO_VARIABLES(Float32)
NO_VARIABLES(Int8)
NO_VARIABLES(UInt8)
NO_VARIABLES(Int16)
NO_VARIABLES(UInt16)
NO_VARIABLES(UInt32)
NO_VARIABLES(Int64)
NO_VARIABLES(UInt64)

FMU_EXPORT fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                                    size_t nValues) {
    (void)valueReferences, (void)nValueReferences, (void)valueSizes, (void)values, (void)nValues;
    return unsupported(instance, "fmi3GetBinary", NO_TYPE);
}
FMU_EXPORT fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const size_t valueSizes[], const fmi3Binary values[],
                                    size_t nValues) {
    (void)valueReferences, (void)nValueReferences, (void)valueSizes, (void)values, (void)nValues;
    return unsupported(instance, "fmi3SetBinary", NO_TYPE);
}
FMU_EXPORT fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3Clock values[]) {
    (void)valueReferences, (void)nValueReferences, (void)values;
    return unsupported(instance, "fmi3GetClock", "no clocks");
}
FMU_EXPORT fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3Clock values[]) {
    (void)valueReferences, (void)nValueReferences, (void)values;
    return unsupported(instance, "fmi3SetClock", "no clocks");
}
FMU_EXPORT fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                                          size_t *nDependencies) {
    (void)valueReference, (void)nDependencies;
    return unsupported(instance, "fmi3GetNumberOfVariableDependencies", "the dependencies are in modelDescription.xml");
}
FMU_EXPORT fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                                  size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                                  size_t elementIndicesOfIndependents[],
                                                  fmi3DependencyKind dependencyKinds[], size_t nDependencies) {
    (void)dependent, (void)elementIndicesOfDependent, (void)independents, (void)elementIndicesOfIndependents,
        (void)dependencyKinds, (void)nDependencies;
    return unsupported(instance, "fmi3GetVariableDependencies", "the dependencies are in modelDescription.xml");
}
FMU_EXPORT fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                                   size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                                   const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                                   size_t nSensitivity) {
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity,
        (void)nSensitivity;
    return unsupported(instance, "fmi3GetDirectionalDerivative", "providesDirectionalDerivatives is false");
}
FMU_EXPORT fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                               size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                               const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                               size_t nSensitivity) {
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed, (void)sensitivity,
        (void)nSensitivity;
    return unsupported(instance, "fmi3GetAdjointDerivative", "providesAdjointDerivatives is false");
}
FMU_EXPORT fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                               size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                               size_t nValues) {
    (void)valueReferences, (void)nValueReferences, (void)orders, (void)values, (void)nValues;
    return unsupported(instance, "fmi3GetOutputDerivatives", "maxOutputDerivativeOrder is 0");
}
FMU_EXPORT fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterConfigurationMode", "no structural parameters");
}
FMU_EXPORT fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3ExitConfigurationMode", "no structural parameters");
}
FMU_EXPORT fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    return unsupported(instance, "fmi3EvaluateDiscreteStates", "no discrete states, no event mode in co-simulation");
}
FMU_EXPORT fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                             size_t nValueReferences, fmi3Float64 intervals[],
                                             fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences, (void)nValueReferences, (void)intervals, (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalDecimal", "no clocks");
}
FMU_EXPORT fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                              size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                              fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions, (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalFraction", "no clocks");
}
FMU_EXPORT fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                          size_t nValueReferences, fmi3Float64 shifts[]) {
    (void)valueReferences, (void)nValueReferences, (void)shifts;
    return unsupported(instance, "fmi3GetShiftDecimal", "no clocks");
}
FMU_EXPORT fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                           size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return unsupported(instance, "fmi3GetShiftFraction", "no clocks");
}
FMU_EXPORT fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                             size_t nValueReferences, const fmi3Float64 intervals[]) {
    (void)valueReferences, (void)nValueReferences, (void)intervals;
    return unsupported(instance, "fmi3SetIntervalDecimal", "no clocks");
}
FMU_EXPORT fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                              size_t nValueReferences, const fmi3UInt64 counters[],
                                              const fmi3UInt64 resolutions[]) {
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return unsupported(instance, "fmi3SetIntervalFraction", "no clocks");
}
FMU_EXPORT fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                          size_t nValueReferences, const fmi3Float64 shifts[]) {
    (void)valueReferences, (void)nValueReferences, (void)shifts;
    return unsupported(instance, "fmi3SetShiftDecimal", "no clocks");
}
FMU_EXPORT fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                           size_t nValueReferences, const fmi3UInt64 counters[],
                                           const fmi3UInt64 resolutions[]) {
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return unsupported(instance, "fmi3SetShiftFraction", "no clocks");
}
FMU_EXPORT fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                                 fmi3Float64 activationTime) {
    (void)clockReference, (void)activationTime;
    return unsupported(instance, "fmi3ActivateModelPartition", "no clocks");
}
