/*
 * Minimal FMI 3.0 co-simulation host in C, knowing nothing about Python (no FMI headers needed:
 * the types it uses are declared below, as in the FMI 3.0 standard's fmi3FunctionTypes.h /
 * fmi3PlatformTypes.h). The FMI 3.0 counterpart of fmu_host.c.
 *
 * It dlopen()s <unzipdir>/binaries/<arch>-linux/<model_identifier>.so with RTLD_LOCAL (compiled for
 * Windows: LoadLibrary of binaries/<arch>-windows/<model_identifier>.dll, host_platform.h), instantiates
 * the FMU for co-simulation with the resource path <unzipdir>/resources/, enters initialization
 * mode with the experiment, steps from START to STOP with communication step STEP (grid points
 * START + k*STEP, the last one clamped to STOP, as fmpy.simulate_fmu does) and prints time and the
 * requested Float64 variables as CSV (header, values with 17 significant digits).
 *
 *   fmu_host3 [-q] [-w] [-n] [-S] UNZIPDIR MODEL_ID TOKEN START STOP STEP TOL VR:NAME [VR:NAME ...]
 *
 *   -q     debug logging off (the FMU still logs warnings and errors)
 *   -w     strict: any status but fmi3OK is a failure (exit 3)
 *   -n     no Python: after the last step, /proc/self/maps must name no libpython; exit 4 otherwise
 *   -S     FMU state: half-way, fmi3GetFMUState, fmi3SerializeFMUState, fmi3FreeFMUState and
 *          fmi3DeserializeFMUState; after the last step fmi3SetFMUState of that state and the second
 *          half again: the last values must be the same bits (exit 5 otherwise)
 *   -M     Model Exchange instead: fmi3InstantiateModelExchange, and the host integrates with explicit
 *          Euler at step STEP (fmi3SetTime, fmi3SetContinuousStates, fmi3GetContinuousStateDerivatives,
 *          fmi3CompletedIntegratorStep and the event it may ask for); the rows are its outputs
 *   TOL <= 0  no tolerance passed to fmi3EnterInitializationMode
 *
 * Exit status: 0 ok, 1 usage, 2 loading, 3 an FMI call returned an error status, 4 a libpython
 * mapped with -n, 5 a run from a restored state that differs (-S).
 * Build: cc -O2 -o fmu_host3 fmu_host3.c -ldl -lm
 */
#include "host_platform.h"
#include <limits.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef void *fmi3Instance;
typedef void *fmi3InstanceEnvironment;
typedef void *fmi3FMUState;
typedef uint32_t fmi3ValueReference;
typedef double fmi3Float64;
typedef bool fmi3Boolean;
typedef const char *fmi3String;
typedef uint8_t fmi3Byte;
typedef enum { fmi3OK, fmi3Warning, fmi3Discard, fmi3Error, fmi3Fatal } fmi3Status;

typedef void (*fmi3LogMessageCallback)(fmi3InstanceEnvironment, fmi3Status, fmi3String, fmi3String);
typedef void (*fmi3IntermediateUpdateCallback)(fmi3InstanceEnvironment, fmi3Float64, fmi3Boolean, fmi3Boolean,
                                               fmi3Boolean, fmi3Boolean, fmi3Boolean *, fmi3Float64 *);
typedef fmi3Instance (*fmi3InstantiateCoSimulationTYPE)(fmi3String, fmi3String, fmi3String, fmi3Boolean, fmi3Boolean,
                                                        fmi3Boolean, fmi3Boolean, const fmi3ValueReference[], size_t,
                                                        fmi3InstanceEnvironment, fmi3LogMessageCallback,
                                                        fmi3IntermediateUpdateCallback);
typedef void (*fmi3FreeInstanceTYPE)(fmi3Instance);
typedef fmi3Status (*fmi3EnterInitializationModeTYPE)(fmi3Instance, fmi3Boolean, fmi3Float64, fmi3Float64, fmi3Boolean,
                                                      fmi3Float64);
typedef fmi3Status (*fmi3InstanceTYPE)(fmi3Instance); /* exit init, terminate */
typedef fmi3Status (*fmi3GetFloat64TYPE)(fmi3Instance, const fmi3ValueReference[], size_t, fmi3Float64[], size_t);
typedef fmi3Status (*fmi3DoStepTYPE)(fmi3Instance, fmi3Float64, fmi3Float64, fmi3Boolean, fmi3Boolean *,
                                     fmi3Boolean *, fmi3Boolean *, fmi3Float64 *);
typedef fmi3Status (*fmi3GetFMUStateTYPE)(fmi3Instance, fmi3FMUState *);
typedef fmi3Status (*fmi3SetFMUStateTYPE)(fmi3Instance, fmi3FMUState);
typedef fmi3Status (*fmi3SerializedFMUStateSizeTYPE)(fmi3Instance, fmi3FMUState, size_t *);
typedef fmi3Status (*fmi3SerializeFMUStateTYPE)(fmi3Instance, fmi3FMUState, fmi3Byte[], size_t);
typedef fmi3Status (*fmi3DeserializeFMUStateTYPE)(fmi3Instance, const fmi3Byte[], size_t, fmi3FMUState *);
typedef fmi3Instance (*fmi3InstantiateModelExchangeTYPE)(fmi3String, fmi3String, fmi3String, fmi3Boolean, fmi3Boolean,
                                                         fmi3InstanceEnvironment, fmi3LogMessageCallback);
typedef fmi3Status (*fmi3GetNumberOfContinuousStatesTYPE)(fmi3Instance, size_t *);
typedef fmi3Status (*fmi3ArrayTYPE)(fmi3Instance, fmi3Float64[], size_t); /* get states, derivatives */
typedef fmi3Status (*fmi3SetContinuousStatesTYPE)(fmi3Instance, const fmi3Float64[], size_t);
typedef fmi3Status (*fmi3SetTimeTYPE)(fmi3Instance, fmi3Float64);
typedef fmi3Status (*fmi3CompletedIntegratorStepTYPE)(fmi3Instance, fmi3Boolean, fmi3Boolean *, fmi3Boolean *);
typedef fmi3Status (*fmi3UpdateDiscreteStatesTYPE)(fmi3Instance, fmi3Boolean *, fmi3Boolean *, fmi3Boolean *,
                                                   fmi3Boolean *, fmi3Boolean *, fmi3Float64 *);

static const char *status_name(fmi3Status s) {
    static const char *names[] = {"ok", "warning", "discard", "error", "fatal"};
    return (s >= fmi3OK && s <= fmi3Fatal) ? names[s] : "?";
}

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
    (void)env;
    fprintf(stderr, "[%s] %s: %s\n", status_name(status), category ? category : "", message ? message : "");
}

static void *sym(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "fmu_host3: symbol %s not found: %s\n", name, dlerror());
        exit(2);
    }
    return f;
}

/* worst: the worst status accepted (fmi3Warning; fmi3OK with -w) */
static void check(fmi3Status worst, fmi3Status s, const char *what) {
    if (s > worst) {
        fprintf(stderr, "fmu_host3: %s returned %s\n", what, status_name(s));
        exit(3);
    }
}

static int isclose(double a, double b) { return fabs(a - b) <= 1e-9 * fmax(fabs(a), fabs(b)); }

/* -S: the state of c through its bytes (get, serialize, free, deserialize). */
static fmi3FMUState state_through_bytes(void *lib, fmi3Instance c, fmi3Status worst) {
    fmi3FMUState s = NULL, back = NULL;
    size_t size = 0;
    check(worst, ((fmi3GetFMUStateTYPE)sym(lib, "fmi3GetFMUState"))(c, &s), "fmi3GetFMUState");
    check(worst, ((fmi3SerializedFMUStateSizeTYPE)sym(lib, "fmi3SerializedFMUStateSize"))(c, s, &size),
          "fmi3SerializedFMUStateSize");
    fmi3Byte *bytes = malloc(size ? size : 1);
    if (!bytes) {
        fprintf(stderr, "fmu_host3: out of memory\n");
        exit(3);
    }
    check(worst, ((fmi3SerializeFMUStateTYPE)sym(lib, "fmi3SerializeFMUState"))(c, s, bytes, size),
          "fmi3SerializeFMUState");
    check(worst, ((fmi3GetFMUStateTYPE)sym(lib, "fmi3FreeFMUState"))(c, &s), "fmi3FreeFMUState");
    check(worst, ((fmi3DeserializeFMUStateTYPE)sym(lib, "fmi3DeserializeFMUState"))(c, bytes, size, &back),
          "fmi3DeserializeFMUState");
    free(bytes);
    return back;
}

static int python_mapped(void) {
    FILE *f = fopen("/proc/self/maps", "r");
    char line[PATH_MAX + 256];
    int found = 0;
    if (!f) return -1;
    while (fgets(line, sizeof line, f))
        if (strstr(line, "libpython")) {
            fprintf(stderr, "fmu_host3: libpython mapped: %s", line);
            found = 1;
        }
    fclose(f);
    return found;
}

static void do_step(void *lib, fmi3Instance c, fmi3Status worst, double t, double h, const char *what) {
    fmi3Boolean event = false, terminate = false, early = false;
    fmi3Float64 last = 0.0;
    check(worst, ((fmi3DoStepTYPE)sym(lib, "fmi3DoStep"))(c, t, h, true, &event, &terminate, &early, &last), what);
}

/* -M: the host's explicit Euler from start to stop at step h, printing the outputs at every step. */
static int model_exchange(void *lib, fmi3Instance c, fmi3Status worst, double start, double stop, double h,
                          const fmi3ValueReference *vr, int nvr, fmi3Float64 *values) {
    size_t n = 0;
    check(worst, ((fmi3GetNumberOfContinuousStatesTYPE)sym(lib, "fmi3GetNumberOfContinuousStates"))(c, &n),
          "fmi3GetNumberOfContinuousStates");
    fmi3Float64 *x = calloc(n ? n : 1, sizeof *x), *dx = calloc(n ? n : 1, sizeof *dx);
    if (!x || !dx) return 3;
    fmi3Boolean need = false, term = false, nominals = false, changed = false, next_defined = false;
    fmi3Float64 next_time = 0.0;
    fmi3UpdateDiscreteStatesTYPE update = (fmi3UpdateDiscreteStatesTYPE)sym(lib, "fmi3UpdateDiscreteStates");
    check(worst, update(c, &need, &term, &nominals, &changed, &next_defined, &next_time), "fmi3UpdateDiscreteStates");
    check(worst, ((fmi3InstanceTYPE)sym(lib, "fmi3EnterContinuousTimeMode"))(c), "fmi3EnterContinuousTimeMode");
    check(worst, ((fmi3ArrayTYPE)sym(lib, "fmi3GetContinuousStates"))(c, x, n), "fmi3GetContinuousStates");
    fmi3GetFloat64TYPE get = (fmi3GetFloat64TYPE)sym(lib, "fmi3GetFloat64");
    fmi3ArrayTYPE derivatives = (fmi3ArrayTYPE)sym(lib, "fmi3GetContinuousStateDerivatives");
    fmi3SetContinuousStatesTYPE set_states = (fmi3SetContinuousStatesTYPE)sym(lib, "fmi3SetContinuousStates");
    fmi3SetTimeTYPE set_time = (fmi3SetTimeTYPE)sym(lib, "fmi3SetTime");
    fmi3CompletedIntegratorStepTYPE completed = (fmi3CompletedIntegratorStepTYPE)sym(lib, "fmi3CompletedIntegratorStep");
    for (long k = 0;; k++) {
        double t = start + (double)k * h;
        check(worst, get(c, vr, (size_t)nvr, values, (size_t)nvr), "fmi3GetFloat64");
        printf("%.17g", t);
        for (int j = 0; j < nvr; j++) printf(",%.17g", values[j]);
        printf("\n");
        if (t > stop || isclose(t, stop)) break;
        check(worst, derivatives(c, dx, n), "fmi3GetContinuousStateDerivatives");
        for (size_t j = 0; j < n; j++) x[j] += h * dx[j];
        check(worst, set_time(c, start + (double)(k + 1) * h), "fmi3SetTime");
        check(worst, set_states(c, x, n), "fmi3SetContinuousStates");
        fmi3Boolean event = false;
        check(worst, completed(c, true, &event, &term), "fmi3CompletedIntegratorStep");
        if (event) {
            check(worst, ((fmi3InstanceTYPE)sym(lib, "fmi3EnterEventMode"))(c), "fmi3EnterEventMode");
            check(worst, update(c, &need, &term, &nominals, &changed, &next_defined, &next_time),
                  "fmi3UpdateDiscreteStates");
            check(worst, ((fmi3InstanceTYPE)sym(lib, "fmi3EnterContinuousTimeMode"))(c), "fmi3EnterContinuousTimeMode");
            if (changed) check(worst, ((fmi3ArrayTYPE)sym(lib, "fmi3GetContinuousStates"))(c, x, n), "fmi3GetContinuousStates");
        }
    }
    free(x), free(dx);
    return 0;
}

int main(int argc, char **argv) {
    int logging = 1, i = 1, no_python = 0, state_check = 0, me = 0;
    fmi3Status worst = fmi3Warning;
    while (i < argc && argv[i][0] == '-') {
        if (!strcmp(argv[i], "-q")) logging = 0;
        else if (!strcmp(argv[i], "-w")) worst = fmi3OK;
        else if (!strcmp(argv[i], "-S")) state_check = 1;
        else if (!strcmp(argv[i], "-n")) no_python = 1;
        else if (!strcmp(argv[i], "-M")) me = 1;
        else break;
        i++;
    }
    if (argc - i < 8) {
        fprintf(stderr, "usage: %s [-q] [-w] [-n] [-S] [-M] UNZIPDIR MODEL_ID TOKEN START STOP STEP TOL VR:NAME "
                        "[VR:NAME ...]\n", argv[0]);
        return 1;
    }
    const char *dir = argv[i], *id = argv[i + 1], *token = argv[i + 2];
    double start = atof(argv[i + 3]), stop = atof(argv[i + 4]), step = atof(argv[i + 5]), tol = atof(argv[i + 6]);
    int nvr = argc - (i + 7);
    fmi3ValueReference *vr = calloc((size_t)nvr, sizeof *vr);
    const char **names = calloc((size_t)nvr, sizeof *names);
    fmi3Float64 *values = calloc((size_t)nvr, sizeof *values), *again = calloc((size_t)nvr, sizeof *again);
    if (!vr || !names || !values || !again) return 3;
    for (int k = 0; k < nvr; k++) {
        char *arg = argv[i + 7 + k], *colon = strchr(arg, ':');
        if (!colon) {
            fprintf(stderr, "fmu_host3: expected VR:NAME, got %s\n", arg);
            return 1;
        }
        vr[k] = (fmi3ValueReference)strtoul(arg, NULL, 10);
        names[k] = colon + 1;
    }
    char absdir[PATH_MAX], so[PATH_MAX + 256], resources[PATH_MAX + 16];
    if (!realpath(dir, absdir)) {
        fprintf(stderr, "fmu_host3: no such directory %s\n", dir);
        return 2;
    }
#if defined(__x86_64__)
    const char *arch = "x86_64";
#elif defined(__aarch64__)
    const char *arch = "aarch64";
#else
    const char *arch = "unknown";
#endif
    snprintf(so, sizeof so, "%s/binaries/%s-" HOST_FMI3_OS "/%s" HOST_SUFFIX, absdir, arch, id);
    snprintf(resources, sizeof resources, "%s/resources/", absdir);
    void *lib = dlopen(so, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "fmu_host3: cannot load %s: %s\n", so, dlerror());
        return 2;
    }
    fmi3Instance c = me ? ((fmi3InstantiateModelExchangeTYPE)sym(lib, "fmi3InstantiateModelExchange"))(
                              "c_host3", token, resources, false, logging, NULL, logger)
                        : ((fmi3InstantiateCoSimulationTYPE)sym(lib, "fmi3InstantiateCoSimulation"))(
                              "c_host3", token, resources, false, logging, false, false, NULL, 0, NULL, logger, NULL);
    if (!c) {
        fprintf(stderr, "fmu_host3: fmi3InstantiateCoSimulation failed\n");
        return 3;
    }
    check(worst, ((fmi3EnterInitializationModeTYPE)sym(lib, "fmi3EnterInitializationMode"))(
                     c, tol > 0, tol > 0 ? tol : 0.0, start, true, stop), "fmi3EnterInitializationMode");
    check(worst, ((fmi3InstanceTYPE)sym(lib, "fmi3ExitInitializationMode"))(c), "fmi3ExitInitializationMode");
    fmi3GetFloat64TYPE get = (fmi3GetFloat64TYPE)sym(lib, "fmi3GetFloat64");

    printf("\"time\"");
    for (int k = 0; k < nvr; k++) printf(",\"%s\"", names[k]);
    printf("\n");
    if (me) {
        int rc = model_exchange(lib, c, worst, start, stop, step, vr, nvr, values);
        if (rc) return rc;
        check(worst, ((fmi3InstanceTYPE)sym(lib, "fmi3Terminate"))(c), "fmi3Terminate");
        ((fmi3FreeInstanceTYPE)sym(lib, "fmi3FreeInstance"))(c);
        dlclose(lib);
        free(vr), free(names), free(values), free(again);
        return 0;
    }
    double time = start, saved_time = start;
    long half = lround((stop - start) / step) / 2, saved_n = 0;
    fmi3FMUState saved = NULL;
    for (long n = 0;; n++) {
        if (state_check && n == half) {
            saved = state_through_bytes(lib, c, worst);
            saved_time = time, saved_n = n;
        }
        check(worst, get(c, vr, (size_t)nvr, values, (size_t)nvr), "fmi3GetFloat64");
        printf("%.17g", time);
        for (int k = 0; k < nvr; k++) printf(",%.17g", values[k]);
        printf("\n");
        if (time > stop || isclose(time, stop)) break;
        double next = start + (double)(n + 1) * step;
        if (next > stop && !isclose(next, stop)) next = stop;
        do_step(lib, c, worst, time, next - time, "fmi3DoStep");
        time = next;
    }
    fflush(stdout);
    if (saved) { /* the second half again from the restored state: the same bits at the end */
        check(worst, ((fmi3SetFMUStateTYPE)sym(lib, "fmi3SetFMUState"))(c, saved), "fmi3SetFMUState");
        double t = saved_time;
        for (long n = saved_n; !(t > stop || isclose(t, stop)); n++) {
            double next = start + (double)(n + 1) * step;
            if (next > stop && !isclose(next, stop)) next = stop;
            do_step(lib, c, worst, t, next - t, "fmi3DoStep (restored)");
            t = next;
        }
        check(worst, get(c, vr, (size_t)nvr, again, (size_t)nvr), "fmi3GetFloat64 (restored)");
        check(worst, ((fmi3GetFMUStateTYPE)sym(lib, "fmi3FreeFMUState"))(c, &saved), "fmi3FreeFMUState");
        if (t != time || memcmp(again, values, (size_t)nvr * sizeof *values)) {
            fprintf(stderr, "fmu_host3: -S: the run from the restored state ends elsewhere\n");
            return 5;
        }
    }
    if (no_python && python_mapped() != 0) {
        fprintf(stderr, "fmu_host3: -n: a libpython is in the process (or /proc/self/maps unreadable)\n");
        return 4;
    }
    check(worst, ((fmi3InstanceTYPE)sym(lib, "fmi3Terminate"))(c), "fmi3Terminate");
    ((fmi3FreeInstanceTYPE)sym(lib, "fmi3FreeInstance"))(c);
    dlclose(lib);
    free(vr), free(names), free(values), free(again);
    return 0;
}
