/*
 * Minimal FMI 2.0 co-simulation host in C, knowing nothing about Python (no FMI headers needed:
 * the types it uses are declared below, as in the FMI 2.0 standard's fmi2FunctionTypes.h /
 * fmi2TypesPlatform.h).
 *
 * It dlopen()s <unzipdir>/binaries/linux64/<model_identifier>.so with RTLD_LOCAL (compiled for
 * Windows: LoadLibrary of binaries/win64/<model_identifier>.dll, host_platform.h), instantiates the
 * FMU with the resource location file://<unzipdir>/resources, sets up the experiment, steps from
 * START to STOP with communication step STEP (grid points START + k*STEP, the last one clamped to
 * STOP, as fmpy.simulate_fmu does) and prints time and the requested Real variables as CSV (FMI
 * cross-check style header, values with 17 significant digits).
 *
 *   fmu_host [-q] [-x] [-w] [-s NAME=VALUE]... UNZIPDIR MODEL_ID GUID START STOP STEP TOL VR:NAME [VR:NAME ...]
 *
 *   -q            debug logging off (the FMU still logs warnings and errors)
 *   -x            exit right after the last step: no fmi2Terminate, fmi2FreeInstance or dlclose
 *   -4            write the resource URI as "file:///" + the absolute path (four slashes), as some
 *                 hosts do, instead of "file://" + the path
 *   -w            strict, as OMSimulator: any status but fmi2OK is a failure (exit 3)
 *   -s VR=VALUE   fmi2SetReal of value reference VR before initialization (repeatable)
 *   -n            no Python: after the last step, /proc/self/maps must name no libpython (an FMU
 *                 without Python); exit 4 naming the mapping otherwise
 *   -S            FMU state: half-way, fmi2GetFMUstate, fmi2SerializeFMUstate, fmi2FreeFMUstate and
 *                 fmi2DeSerializeFMUstate; after the last step fmi2SetFMUstate of that state and the
 *                 second half again: the last values must be the same bits (exit 5 otherwise)
 *   TOL <= 0      no tolerance passed to fmi2SetupExperiment
 *
 * Exit status: 0 ok, 1 usage, 2 loading, 3 an FMI call returned an error status, 4 a libpython
 * mapped with -n, 5 a run from a restored state that differs (-S).
 * Build: cc -O2 -o fmu_host fmu_host.c -ldl -lm
 */
#include "host_platform.h"
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Boolean;
typedef const char *fmi2String;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
#define fmi2True 1
#define fmi2False 0

typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String,
                                   fmi2String, ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void *);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);
typedef struct {
    const fmi2CallbackLogger logger;
    const fmi2CallbackAllocateMemory allocateMemory;
    const fmi2CallbackFreeMemory freeMemory;
    const fmi2StepFinished stepFinished;
    const fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

typedef fmi2Component (*fmi2InstantiateTYPE)(fmi2String, fmi2Type, fmi2String, fmi2String,
                                             const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
typedef void (*fmi2FreeInstanceTYPE)(fmi2Component);
typedef fmi2Status (*fmi2SetupExperimentTYPE)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real,
                                              fmi2Boolean, fmi2Real);
typedef fmi2Status (*fmi2ComponentTYPE)(fmi2Component); /* enter/exit init, terminate */
typedef fmi2Status (*fmi2GetRealTYPE)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Real[]);
typedef fmi2Status (*fmi2SetRealTYPE)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Real[]);
typedef fmi2Status (*fmi2DoStepTYPE)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
typedef void *fmi2FMUstate;
typedef fmi2Status (*fmi2GetFMUstateTYPE)(fmi2Component, fmi2FMUstate *);
typedef fmi2Status (*fmi2SetFMUstateTYPE)(fmi2Component, fmi2FMUstate);
typedef fmi2Status (*fmi2SerializedFMUstateSizeTYPE)(fmi2Component, fmi2FMUstate, size_t *);
typedef fmi2Status (*fmi2SerializeFMUstateTYPE)(fmi2Component, fmi2FMUstate, char[], size_t);
typedef fmi2Status (*fmi2DeSerializeFMUstateTYPE)(fmi2Component, const char[], size_t, fmi2FMUstate *);

static const char *status_name(fmi2Status s)
{
    static const char *names[] = {"ok", "warning", "discard", "error", "fatal", "pending"};
    return (s >= 0 && s <= fmi2Pending) ? names[s] : "?";
}

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    va_list ap;
    (void)env;
    fprintf(stderr, "[%s] %s %s: ", status_name(status), instance ? instance : "",
            category ? category : "");
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}

static void *sym(void *lib, const char *name)
{
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "fmu_host: symbol %s not found: %s\n", name, dlerror());
        exit(2);
    }
    return f;
}

/* worst: the worst status accepted (fmi2Warning; fmi2OK with -w) */
static void check(fmi2Status worst, fmi2Status s, const char *what)
{
    if (s > worst) {
        fprintf(stderr, "fmu_host: %s returned %s\n", what, status_name(s));
        exit(3);
    }
}

static int isclose(double a, double b) /* Python's math.isclose with its defaults */
{
    return fabs(a - b) <= 1e-9 * fmax(fabs(a), fabs(b));
}

/* -S: the state of c through its bytes (get, serialize, free, deserialize): a state made from
 * bytes only, as a host that stored it on disk would have. */
static fmi2FMUstate state_through_bytes(void *lib, fmi2Component c, fmi2Status worst)
{
    fmi2FMUstate s = NULL, back = NULL;
    size_t size = 0;
    check(worst, ((fmi2GetFMUstateTYPE)sym(lib, "fmi2GetFMUstate"))(c, &s), "fmi2GetFMUstate");
    check(worst, ((fmi2SerializedFMUstateSizeTYPE)sym(lib, "fmi2SerializedFMUstateSize"))(c, s, &size),
          "fmi2SerializedFMUstateSize");
    char *bytes = malloc(size ? size : 1);
    if (!bytes) {
        fprintf(stderr, "fmu_host: out of memory\n");
        exit(3);
    }
    check(worst, ((fmi2SerializeFMUstateTYPE)sym(lib, "fmi2SerializeFMUstate"))(c, s, bytes, size),
          "fmi2SerializeFMUstate");
    check(worst, ((fmi2GetFMUstateTYPE)sym(lib, "fmi2FreeFMUstate"))(c, &s), "fmi2FreeFMUstate");
    check(worst, ((fmi2DeSerializeFMUstateTYPE)sym(lib, "fmi2DeSerializeFMUstate"))(c, bytes, size, &back),
          "fmi2DeSerializeFMUstate");
    free(bytes);
    return back;
}

#define MAX_SETS 64

/* 1 if /proc/self/maps names a libpython (printed to stderr), 0 if not, -1 if unreadable. */
static int python_mapped(void)
{
    FILE *f = fopen("/proc/self/maps", "r");
    char line[PATH_MAX + 256];
    int found = 0;
    if (!f)
        return -1;
    while (fgets(line, sizeof line, f))
        if (strstr(line, "libpython")) {
            fprintf(stderr, "fmu_host: libpython mapped: %s", line);
            found = 1;
        }
    fclose(f);
    return found;
}

int main(int argc, char **argv)
{
    int logging = fmi2True, quick_exit = 0, nset = 0, i = 1, no_python = 0, state_check = 0;
    fmi2Status worst = fmi2Warning;
    int four_slashes = 0;
    fmi2ValueReference set_vr[MAX_SETS];
    fmi2Real set_value[MAX_SETS];
    while (i < argc && argv[i][0] == '-') {
        if (!strcmp(argv[i], "-q")) {
            logging = fmi2False;
            i += 1;
        } else if (!strcmp(argv[i], "-4")) {
            four_slashes = 1;
            i++;
        } else if (!strcmp(argv[i], "-w")) {
            worst = fmi2OK;
            i++;
        } else if (!strcmp(argv[i], "-S")) {
            state_check = 1;
            i++;
        } else if (!strcmp(argv[i], "-n")) {
            no_python = 1;
            i++;
        } else if (!strcmp(argv[i], "-x")) {
            quick_exit = 1;
            i += 1;
        } else if (!strcmp(argv[i], "-s") && i + 1 < argc && nset < MAX_SETS && strchr(argv[i + 1], '=')) {
            set_vr[nset] = (fmi2ValueReference)strtoul(argv[i + 1], NULL, 10);
            set_value[nset++] = atof(strchr(argv[i + 1], '=') + 1);
            i += 2;
        } else {
            break;
        }
    }
    if (argc - i < 8) {
        fprintf(stderr, "usage: %s [-q] [-x] [-w] [-n] [-4] [-s VR=VALUE]... UNZIPDIR MODEL_ID GUID START STOP STEP TOL "
                        "VR:NAME [VR:NAME ...]\n", argv[0]);
        return 1;
    }
    const char *dir = argv[i], *id = argv[i + 1], *guid = argv[i + 2];
    double start = atof(argv[i + 3]), stop = atof(argv[i + 4]), step = atof(argv[i + 5]);
    double tol = atof(argv[i + 6]);
    int nvr = argc - (i + 7);
    fmi2ValueReference *vr = calloc(nvr, sizeof *vr);
    const char **names = calloc(nvr, sizeof *names);
    fmi2Real *values = calloc(nvr, sizeof *values);
    for (int k = 0; k < nvr; k++) {
        char *arg = argv[i + 7 + k], *colon = strchr(arg, ':');
        if (!colon) {
            fprintf(stderr, "fmu_host: expected VR:NAME, got %s\n", arg);
            return 1;
        }
        vr[k] = (fmi2ValueReference)strtoul(arg, NULL, 10);
        names[k] = colon + 1;
    }

    char absdir[PATH_MAX], so[PATH_MAX + 256], uri[3 * PATH_MAX + 32];
    if (!realpath(dir, absdir)) {
        fprintf(stderr, "fmu_host: no such directory %s\n", dir);
        return 2;
    }
    snprintf(so, sizeof so, "%s/binaries/" HOST_FMI2_FOLDER "/%s" HOST_SUFFIX, absdir, id);
    void *lib = dlopen(so, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "fmu_host: cannot load %s: %s\n", so, dlerror());
        return 2;
    }
    /* file:// URI of the resources folder; spaces percent-encoded */
    char *u = uri + sprintf(uri, four_slashes ? "file:///" : HOST_URI_PREFIX);
    for (const char *c = absdir; *c; c++)
        u += (*c == ' ') ? sprintf(u, "%%20") : sprintf(u, "%c", *c);
    sprintf(u, "/resources");

    fmi2InstantiateTYPE instantiate = (fmi2InstantiateTYPE)sym(lib, "fmi2Instantiate");
    fmi2FreeInstanceTYPE free_instance = (fmi2FreeInstanceTYPE)sym(lib, "fmi2FreeInstance");
    fmi2SetupExperimentTYPE setup = (fmi2SetupExperimentTYPE)sym(lib, "fmi2SetupExperiment");
    fmi2ComponentTYPE enter_init = (fmi2ComponentTYPE)sym(lib, "fmi2EnterInitializationMode");
    fmi2ComponentTYPE exit_init = (fmi2ComponentTYPE)sym(lib, "fmi2ExitInitializationMode");
    fmi2ComponentTYPE terminate = (fmi2ComponentTYPE)sym(lib, "fmi2Terminate");
    fmi2GetRealTYPE get_real = (fmi2GetRealTYPE)sym(lib, "fmi2GetReal");
    fmi2SetRealTYPE set_real = (fmi2SetRealTYPE)sym(lib, "fmi2SetReal");
    fmi2DoStepTYPE do_step = (fmi2DoStepTYPE)sym(lib, "fmi2DoStep");

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("c_host", fmi2CoSimulation, guid, uri, &callbacks, fmi2False, logging);
    if (!c) {
        fprintf(stderr, "fmu_host: fmi2Instantiate failed\n");
        return 3;
    }
    check(worst, setup(c, tol > 0 ? fmi2True : fmi2False, tol > 0 ? tol : 0.0, start, fmi2True, stop),
          "fmi2SetupExperiment");
    for (int k = 0; k < nset; k++)
        check(worst, set_real(c, &set_vr[k], 1, &set_value[k]), "fmi2SetReal");
    check(worst, enter_init(c), "fmi2EnterInitializationMode");
    check(worst, exit_init(c), "fmi2ExitInitializationMode");

    printf("\"time\"");
    for (int k = 0; k < nvr; k++)
        printf(",\"%s\"", names[k]);
    printf("\n");
    double time = start, saved_time = start;
    long half = lround((stop - start) / step) / 2, saved_n = 0;
    fmi2FMUstate saved = NULL;
    for (long n = 0;; n++) {
        if (state_check && n == half) {
            saved = state_through_bytes(lib, c, worst);
            saved_time = time, saved_n = n;
        }
        check(worst, get_real(c, vr, nvr, values), "fmi2GetReal");
        printf("%.17g", time);
        for (int k = 0; k < nvr; k++)
            printf(",%.17g", values[k]);
        printf("\n");
        if (time > stop || isclose(time, stop))
            break;
        double next = start + (n + 1) * step;
        if (next > stop && !isclose(next, stop))
            next = stop;
        check(worst, do_step(c, time, next - time, fmi2True), "fmi2DoStep");
        time = next;
    }
    fflush(stdout);
    if (saved) { /* the second half again from the restored state: the same bits at the end */
        fmi2Real *again = calloc(nvr ? nvr : 1, sizeof *again);
        check(worst, ((fmi2SetFMUstateTYPE)sym(lib, "fmi2SetFMUstate"))(c, saved), "fmi2SetFMUstate");
        double t = saved_time;
        for (long n = saved_n; !(t > stop || isclose(t, stop)); n++) {
            double next = start + (n + 1) * step;
            if (next > stop && !isclose(next, stop))
                next = stop;
            check(worst, do_step(c, t, next - t, fmi2True), "fmi2DoStep (restored)");
            t = next;
        }
        check(worst, get_real(c, vr, nvr, again), "fmi2GetReal (restored)");
        check(worst, ((fmi2GetFMUstateTYPE)sym(lib, "fmi2FreeFMUstate"))(c, &saved), "fmi2FreeFMUstate");
        if (t != time || memcmp(again, values, (size_t)nvr * sizeof *values)) {
            fprintf(stderr, "fmu_host: -S: the run from the restored state ends elsewhere\n");
            return 5;
        }
        free(again);
    }
    if (no_python && python_mapped() != 0) {
        fprintf(stderr, "fmu_host: -n: a libpython is in the process (or /proc/self/maps unreadable)\n");
        return 4;
    }
    if (quick_exit)
        return 0; /* the FMU must survive a host that just exits */
    check(worst, terminate(c), "fmi2Terminate");
    free_instance(c);
    dlclose(lib);
    free(vr);
    free(names);
    free(values);
    return 0;
}
