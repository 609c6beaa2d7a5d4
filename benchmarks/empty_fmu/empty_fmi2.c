/* The smallest FMI 2.0 co-simulation FMU that a host can run: N_OUT Real, N_INT Integer and N_BOOL
 * Boolean outputs (value references 0, 1, ... per type) and a doStep that only advances time. It is the yardstick of the FMI overhead
 * benchmark (benchmarks/fmu_runtime.py --overhead): what a host pays per doStep and per output
 * for any FMU, so that overcon's per-step cost beyond it can be read off.
 *
 * Compile: cc -O2 -shared -fPIC -DN_OUT=<n> -DN_INT=<n> -DN_BOOL=<n> -o <identifier>.so empty_fmi2.c
 * The FMI 2.0 types are written out here (ABI: fmi2Component = void *, fmi2Real = double,
 * fmi2Integer = fmi2Boolean = int, fmi2Status an int-sized enum). */
#include <stdlib.h>
#include <string.h>

#ifndef N_OUT
#define N_OUT 1
#endif
#ifndef N_INT
#define N_INT 0
#endif
#ifndef N_BOOL
#define N_BOOL 0
#endif
#define EXPORT __attribute__((visibility("default")))

typedef void *fmi2Component;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef const char *fmi2String;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;

typedef struct {
    double t;
    double y[N_OUT];
    int k[N_INT + 1], b[N_BOOL + 1];
} empty;

EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }
EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c, (void)on, (void)n, (void)cat;
    return fmi2OK;
}
EXPORT fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                                     const void *functions, fmi2Boolean visible, fmi2Boolean logging) {
    (void)name, (void)guid, (void)res, (void)functions, (void)visible, (void)logging;
    if (type != fmi2CoSimulation) return NULL;
    return calloc(1, sizeof(empty));
}
EXPORT void fmi2FreeInstance(fmi2Component c) { free(c); }
EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_on, fmi2Real tol, fmi2Real t0,
                                      fmi2Boolean stop_on, fmi2Real stop) {
    (void)tol_on, (void)tol, (void)stop_on, (void)stop;
    ((empty *)c)->t = t0;
    return fmi2OK;
}
EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
EXPORT fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
EXPORT fmi2Status fmi2Reset(fmi2Component c) {
    memset(c, 0, sizeof(empty));
    return fmi2OK;
}
EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    const empty *e = c;
    for (size_t i = 0; i < n; i++) {
        if ((size_t)vr[i] + 1 > (size_t)N_OUT) return fmi2Error;
        v[i] = e->y[vr[i]];
    }
    return fmi2OK;
}
EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    const empty *e = c;
    for (size_t i = 0; i < n; i++) {
        if ((size_t)vr[i] + 1 > (size_t)N_INT) return fmi2Error;
        v[i] = e->k[vr[i]];
    }
    return fmi2OK;
}
EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    const empty *e = c;
    for (size_t i = 0; i < n; i++) {
        if ((size_t)vr[i] + 1 > (size_t)N_BOOL) return fmi2Error;
        v[i] = e->b[vr[i]];
    }
    return fmi2OK;
}
EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    (void)c, (void)vr, (void)v;
    return n ? fmi2Error : fmi2OK;
}
EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    (void)c, (void)vr, (void)v;
    return n ? fmi2Error : fmi2OK;
}
EXPORT fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    (void)c, (void)vr, (void)v;
    return n ? fmi2Error : fmi2OK;
}
EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    (void)c, (void)vr, (void)v;
    return n ? fmi2Error : fmi2OK;
}
EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    (void)c, (void)vr, (void)v;
    return n ? fmi2Error : fmi2OK;
}
EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c, (void)s; return fmi2Error; }
EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c, (void)s; return fmi2Error; }
EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c, (void)s; return fmi2Error; }
EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c, (void)s, (void)n;
    return fmi2Error;
}
EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, char b[], size_t n) {
    (void)c, (void)s, (void)b, (void)n;
    return fmi2Error;
}
EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const char b[], size_t n, fmi2FMUstate *s) {
    (void)c, (void)b, (void)n, (void)s;
    return fmi2Error;
}
EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                               const fmi2ValueReference z[], size_t nz, const fmi2Real dv[],
                                               fmi2Real dz[]) {
    (void)c, (void)u, (void)nu, (void)z, (void)nz, (void)dv, (void)dz;
    return fmi2Error;
}
EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                              const fmi2Integer order[], const fmi2Real v[]) {
    (void)c, (void)vr, (void)n, (void)order, (void)v;
    return fmi2Error;
}
EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                               const fmi2Integer order[], fmi2Real v[]) {
    (void)c, (void)vr, (void)n, (void)order, (void)v;
    return fmi2Error;
}
EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    (void)no_prior;
    ((empty *)c)->t = t + h;
    return fmi2OK;
}
EXPORT fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) {
    (void)c, (void)k, (void)v;
    return fmi2Error;
}
EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    if (k != fmi2LastSuccessfulTime) return fmi2Error;
    *v = ((empty *)c)->t;
    return fmi2OK;
}
EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) {
    (void)c, (void)k, (void)v;
    return fmi2Error;
}
EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) {
    (void)c, (void)k, (void)v;
    return fmi2Error;
}
EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) {
    (void)c, (void)k, (void)v;
    return fmi2Error;
}
