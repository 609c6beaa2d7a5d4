/*
 * A seeded fuzzer of an overcon FMU (FMI 2.0 co-simulation) without Python: FMU states, model files
 * and FMI call sequences. A hand-written mutator (not libFuzzer): it knows the state's layout
 * (fmu_src/overcon/fmu/native/fmu_state.c), so it re-seals the CRC-32 after most mutations and
 * reaches the field checks behind the checksum, as a hostile writer of states would; it needs only
 * cc (the sanitize stage builds it with gcc's ASan/UBSan, where clang is not installed), and the
 * same seed gives the same cases on every machine (xorshift64*, no rand()).
 *
 *   fuzz_fmu MODE UNZIPDIR MODEL_ID GUID SEED CASES SECONDS [OPTIONS]
 *
 *   MODE     states: mutated serialized states of a run at t = 0.1 s, deserialized, set and
 *                    stepped (0.01 s); every state the FMU accepts must hold parameters within
 *                    their rules (-p) and its doStep must end within the budget (-b);
 *                    a state refused by fmi2SetFMUstate must leave the instance as it was (the
 *                    next doStep gives the same bits as the unmutated state's)
 *            model:  mutated copies of resources/overcon_model.bin, instantiated and stepped
 *            calls:  random FMI call sequences with hostile arguments
 *            replay: -r FILE: one state file (a regression input), deserialized, set, stepped
 *   CASES    at most this many cases; SECONDS: stop earlier when this much time has passed
 *   -p VR:LO:HI  a Real parameter and its rule's range (checked after every accepted state)
 *   -b VR        the solver.max_wall_time parameter: set to 0.5 s before each doStep of a
 *                mutated state; a doStep longer than 0.5 s + 10 s of slack is a hang (exit 6)
 *   -v VR        a Real output compared bit for bit after a refused state (default 0)
 *   -o DIR       write each mutated state that was accepted (or crashed: written before use) to
 *                DIR/last.bin; with -k also keep every accepted one as DIR/accepted-N.bin
 *
 * Exit: 0 ok (the counts printed), 1 usage, 2 loading, 5 a refused state changed the instance,
 * 6 a doStep over its budget, 7 an accepted state with a parameter outside its rule.
 * Build: cc -O2 -o fuzz_fmu fuzz_fmu.c -ldl -lm
 */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

typedef void *fmi2Component;
typedef unsigned int fmi2ValueReference;
typedef int fmi2Status;
typedef void *fmi2FMUstate;
typedef void (*fmi2CallbackLogger)(void *, const char *, fmi2Status, const char *, const char *, ...);
typedef struct {
    fmi2CallbackLogger logger;
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(void *, fmi2Status);
    void *componentEnvironment;
} fmi2CallbackFunctions;

typedef struct {
    fmi2Component (*instantiate)(const char *, int, const char *, const char *, const fmi2CallbackFunctions *, int,
                                 int);
    void (*free_instance)(fmi2Component);
    fmi2Status (*setup)(fmi2Component, int, double, double, int, double);
    fmi2Status (*enter_init)(fmi2Component), (*exit_init)(fmi2Component), (*terminate)(fmi2Component),
        (*reset)(fmi2Component);
    fmi2Status (*get_real)(fmi2Component, const fmi2ValueReference *, size_t, double *);
    fmi2Status (*set_real)(fmi2Component, const fmi2ValueReference *, size_t, const double *);
    fmi2Status (*get_integer)(fmi2Component, const fmi2ValueReference *, size_t, int *);
    fmi2Status (*set_integer)(fmi2Component, const fmi2ValueReference *, size_t, const int *);
    fmi2Status (*get_string)(fmi2Component, const fmi2ValueReference *, size_t, const char **);
    fmi2Status (*set_string)(fmi2Component, const fmi2ValueReference *, size_t, const char *const *);
    fmi2Status (*do_step)(fmi2Component, double, double, int);
    fmi2Status (*get_state)(fmi2Component, fmi2FMUstate *), (*set_state)(fmi2Component, fmi2FMUstate),
        (*free_state)(fmi2Component, fmi2FMUstate *);
    fmi2Status (*state_size)(fmi2Component, fmi2FMUstate, size_t *);
    fmi2Status (*serialize)(fmi2Component, fmi2FMUstate, char *, size_t);
    fmi2Status (*deserialize)(fmi2Component, const char *, size_t, fmi2FMUstate *);
    fmi2Status (*real_status)(fmi2Component, int, double *);
} api;

static void quiet(void *env, const char *name, fmi2Status status, const char *cat, const char *msg, ...) {
    (void)env, (void)name, (void)status, (void)cat, (void)msg;
}
static const fmi2CallbackFunctions callbacks = {quiet, calloc, free, NULL, NULL};

static uint64_t rng_state;
static uint64_t next(void) { /* xorshift64* */
    rng_state ^= rng_state >> 12, rng_state ^= rng_state << 25, rng_state ^= rng_state >> 27;
    return rng_state * 2685821657736338717ULL;
}
static size_t below(size_t n) { return n ? (size_t)(next() % n) : 0; }

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static uint32_t crc32_of(const unsigned char *p, size_t n) { /* as fmu_state.c */
    uint32_t crc = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) {
        crc ^= p[i];
        for (int b = 0; b < 8; b++) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
    return crc ^ 0xFFFFFFFFu;
}

static void *sym(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) fprintf(stderr, "fuzz_fmu: %s not exported\n", name), exit(2);
    return f;
}

static const double specials[] = {NAN, INFINITY, -INFINITY, -5.0, 0.0, -0.0, 1e-300, -1.0, 1e300, 5e-324, 1.0, 2.0,
                                  1e17, -1e17, 86400.0, 1e8, 2147483648.0, -2147483649.0, 0.5, 3.0};
static const int ints[] = {-1, 0, 1, 2, 3, 4, 8, 16, 32, 64, 1000, 65536, INT_MAX, INT_MIN, -1000000, 1 << 24};
#define NSPECIAL (sizeof specials / sizeof specials[0])
#define NINTS (sizeof ints / sizeof ints[0])

typedef struct { fmi2ValueReference vr; double lo, hi; } prule;

/* One mutation of a state's bytes (payload from `payload`), re-sealed unless `seal` is 0; the
 * new size. */
static size_t mutate_state(unsigned char *b, size_t size, size_t cap, size_t payload, size_t crc_at, int seal) {
    size_t body = size - payload;
    switch (below(7)) {
    case 0: /* bit flips */
        for (size_t k = 1 + below(4); k--;) b[payload + below(body)] ^= (unsigned char)(1u << below(8));
        break;
    case 1: case 2: { /* an aligned int */
        size_t at = payload + 4 * below(body / 4);
        int v = ints[below(NINTS)];
        memcpy(b + at, &v, sizeof v);
        break;
    }
    case 3: case 4: { /* an aligned double */
        size_t at = payload + 4 * below(body / 4 - 1);
        double v = specials[below(NSPECIAL)];
        memcpy(b + at, &v, sizeof v);
        break;
    }
    case 5: /* a random byte run */
        for (size_t k = 1 + below(16), at = payload + below(body); k-- && at < size; at++) b[at] = (unsigned char)next();
        break;
    default: /* truncated, extended or a header field */
        switch (below(3)) {
        case 0: size -= 1 + below(size - payload < 64 ? size - payload : 64); break;
        case 1: { size_t add = 1 + below(64); if (size + add <= cap) memset(b + size, 0, add), size += add; } break;
        default: { size_t at = crc_at - 8 + 4 * below(6); int v = ints[below(NINTS)]; memcpy(b + at, &v, 4); seal = 0; }
        }
    }
    if (seal && size >= payload) {
        uint32_t crc = crc32_of(b + payload, size - payload);
        memcpy(b + crc_at, &crc, sizeof crc);
    }
    return size;
}

static int write_file(const char *path, const unsigned char *b, size_t n) {
    FILE *f = fopen(path, "wb");
    if (!f) return 0;
    int ok = fwrite(b, 1, n, f) == n;
    return fclose(f) == 0 && ok;
}

static unsigned char *read_file(const char *path, size_t *n) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *b = malloc(size > 0 ? (size_t)size : 1);
    *n = b && size > 0 ? fread(b, 1, (size_t)size, f) : 0;
    fclose(f);
    return b;
}

/* An instance initialized at 0 and stepped to 0.1 s (10 steps). */
static fmi2Component started(const api *A, const char *id, const char *guid, const char *uri) {
    fmi2Component c = A->instantiate(id, 1, guid, uri, &callbacks, 0, 0);
    if (!c) return NULL;
    if (A->setup(c, 0, 0.0, 0.0, 0, 0.0) || A->enter_init(c) || A->exit_init(c)) {
        A->free_instance(c);
        return NULL;
    }
    for (int k = 0; k < 10; k++)
        if (A->do_step(c, 0.01 * k, 0.01, 1) > 1) {
            A->free_instance(c);
            return NULL;
        }
    return c;
}

int main(int argc, char **argv) {
    if (argc < 8) {
        fprintf(stderr, "usage: fuzz_fmu states|model|calls|replay UNZIPDIR MODEL_ID GUID SEED CASES SECONDS "
                "[-p VR:LO:HI]... [-b VR] [-o DIR] [-k] [-r FILE]\n");
        return 1;
    }
    const char *mode = argv[1], *dir = argv[2], *id = argv[3], *guid = argv[4], *out = NULL, *replay = NULL;
    rng_state = strtoull(argv[5], NULL, 10) * 0x9E3779B97F4A7C15ULL + 1;
    long cases = atol(argv[6]);
    double seconds = atof(argv[7]), t_start = now();
    prule rules[64];
    int nrules = 0, keep = 0;
    long budget_vr = -1;
    fmi2ValueReference probe_vr = 0;
    for (int i = 8; i < argc; i++) {
        if (!strcmp(argv[i], "-p") && i + 1 < argc && nrules < 64) {
            prule *r = &rules[nrules++];
            char *end;
            r->vr = (fmi2ValueReference)strtoul(argv[++i], &end, 10);
            r->lo = strtod(end + 1, &end);
            r->hi = strtod(end + 1, NULL);
        } else if (!strcmp(argv[i], "-b") && i + 1 < argc) budget_vr = atol(argv[++i]);
        else if (!strcmp(argv[i], "-o") && i + 1 < argc) out = argv[++i];
        else if (!strcmp(argv[i], "-r") && i + 1 < argc) replay = argv[++i];
        else if (!strcmp(argv[i], "-v") && i + 1 < argc) probe_vr = (fmi2ValueReference)strtoul(argv[++i], NULL, 10);
        else if (!strcmp(argv[i], "-k")) keep = 1;
        else return fprintf(stderr, "fuzz_fmu: unknown option %s\n", argv[i]), 1;
    }
    char path[4096], uri[4200];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, id);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) return fprintf(stderr, "fuzz_fmu: %s\n", dlerror()), 2;
    api A;
    *(void **)&A.instantiate = sym(lib, "fmi2Instantiate");
    *(void **)&A.free_instance = sym(lib, "fmi2FreeInstance");
    *(void **)&A.setup = sym(lib, "fmi2SetupExperiment");
    *(void **)&A.enter_init = sym(lib, "fmi2EnterInitializationMode");
    *(void **)&A.exit_init = sym(lib, "fmi2ExitInitializationMode");
    *(void **)&A.terminate = sym(lib, "fmi2Terminate");
    *(void **)&A.reset = sym(lib, "fmi2Reset");
    *(void **)&A.get_real = sym(lib, "fmi2GetReal");
    *(void **)&A.set_real = sym(lib, "fmi2SetReal");
    *(void **)&A.get_integer = sym(lib, "fmi2GetInteger");
    *(void **)&A.set_integer = sym(lib, "fmi2SetInteger");
    *(void **)&A.get_string = sym(lib, "fmi2GetString");
    *(void **)&A.set_string = sym(lib, "fmi2SetString");
    *(void **)&A.do_step = sym(lib, "fmi2DoStep");
    *(void **)&A.get_state = sym(lib, "fmi2GetFMUstate");
    *(void **)&A.set_state = sym(lib, "fmi2SetFMUstate");
    *(void **)&A.free_state = sym(lib, "fmi2FreeFMUstate");
    *(void **)&A.state_size = sym(lib, "fmi2SerializedFMUstateSize");
    *(void **)&A.serialize = sym(lib, "fmi2SerializeFMUstate");
    *(void **)&A.deserialize = sym(lib, "fmi2DeSerializeFMUstate");
    *(void **)&A.real_status = sym(lib, "fmi2GetRealStatus");
    snprintf(uri, sizeof uri, "file://%s/resources", dir);
    long n = 0, accepted = 0, refused_set = 0, refused_bytes = 0, steps_ok = 0;
    int code = 0;

    if (!strcmp(mode, "states") || !strcmp(mode, "replay")) {
        fmi2Component c = started(&A, id, guid, uri);
        if (!c) return fprintf(stderr, "fuzz_fmu: the FMU does not start\n"), 2;
        fmi2FMUstate good = NULL;
        size_t size = 0;
        A.get_state(c, &good);
        A.state_size(c, good, &size);
        size_t cap = size + 64, g = strlen(guid) + 1, crc_at = 8 + g + 8, payload = 8 + g + 24;
        unsigned char *orig = malloc(cap), *b = malloc(cap);
        A.serialize(c, good, (char *)orig, size);
        double t0 = 0.0, ref[1], got[1];
        fmi2ValueReference probe = probe_vr; /* a Real output: the same bits after a refused state */
        A.real_status(c, 2, &t0);
        A.do_step(c, t0, 0.01, 0);
        A.get_real(c, &probe, 1, ref);
        for (; n < cases && now() - t_start < seconds; n++) {
            size_t m = size;
            if (replay) {
                free(b);
                if (!(b = read_file(replay, &m))) return fprintf(stderr, "fuzz_fmu: cannot read %s\n", replay), 2;
                cases = 1;
            } else {
                memcpy(b, orig, size);
                m = mutate_state(b, size, cap, payload, crc_at, below(10) != 0);
            }
            if (out) { snprintf(path, sizeof path, "%s/last.bin", out); write_file(path, b, m); }
            A.set_state(c, good);
            fmi2FMUstate s = NULL;
            if (A.deserialize(c, (const char *)b, m, &s)) { refused_bytes++; continue; }
            if (A.set_state(c, s)) {
                refused_set++;
                double t = -1.0;
                A.real_status(c, 2, &t);
                if (t != t0 || A.do_step(c, t0, 0.01, 0) || A.get_real(c, &probe, 1, got) || got[0] != ref[0]) {
                    fprintf(stderr, "fuzz_fmu: case %ld: a refused state changed the instance\n", n);
                    code = 5;
                    break;
                }
                A.free_state(c, &s);
                continue;
            }
            accepted++;
            if (out && keep) { snprintf(path, sizeof path, "%s/accepted-%ld.bin", out, n); write_file(path, b, m); }
            for (int r = 0; r < nrules; r++) {
                double v = NAN;
                if (A.get_real(c, &rules[r].vr, 1, &v)) continue; /* not readable in the state's mode */
                if (!(v >= rules[r].lo && v <= rules[r].hi)) {
                    fprintf(stderr, "fuzz_fmu: case %ld: accepted state with parameter %u = %g outside [%g, %g]\n", n,
                            rules[r].vr, v, rules[r].lo, rules[r].hi);
                    code = 7;
                }
            }
            if (code) break;
            if (budget_vr >= 0) {
                fmi2ValueReference vr = (fmi2ValueReference)budget_vr;
                double half = 0.5;
                A.set_real(c, &vr, 1, &half);
            }
            double t = 0.0, before = now();
            A.real_status(c, 2, &t);
            if (A.do_step(c, t, 0.01, 0) == 0) steps_ok++;
            if (budget_vr >= 0 && now() - before > 10.5) {
                fprintf(stderr, "fuzz_fmu: case %ld: doStep took %.1f s over a 0.5 s budget\n", n, now() - before);
                code = 6;
                break;
            }
            A.free_state(c, &s);
        }
        A.free_state(c, &good);
        A.free_instance(c);
        free(orig), free(b);
        printf("fuzz_fmu states %s: %ld cases in %.1f s: %ld refused as bytes, %ld refused at set (the instance kept "
               "its state), %ld accepted (%ld stepped)\n", id, n, now() - t_start, refused_bytes, refused_set, accepted,
               steps_ok);
    } else if (!strcmp(mode, "model")) {
        size_t size = 0;
        snprintf(path, sizeof path, "%s/resources/overcon_model.bin", dir);
        unsigned char *orig = read_file(path, &size), *b = malloc(size + 64);
        if (!orig || !b || !out) return fprintf(stderr, "fuzz_fmu: model mode needs the model file and -o DIR\n"), 2;
        char res[4096], file[4200];
        snprintf(res, sizeof res, "%s/resources", out);
        mkdir(out, 0700), mkdir(res, 0700);
        snprintf(file, sizeof file, "%s/overcon_model.bin", res);
        snprintf(uri, sizeof uri, "file://%s", res);
        fmi2Component first = write_file(file, orig, size) ? A.instantiate(id, 1, guid, uri, &callbacks, 0, 0) : NULL;
        if (!first) return fprintf(stderr, "fuzz_fmu: the unmutated model file in %s does not instantiate\n", res), 2;
        A.free_instance(first);
        snprintf(file, sizeof file, "%s/overcon_model.bin", res);
        snprintf(uri, sizeof uri, "file://%s", res);
        for (; n < cases && now() - t_start < seconds; n++) {
            size_t m = size;
            memcpy(b, orig, size);
            switch (below(4)) {
            case 0: for (size_t k = 1 + below(4); k--;) b[below(size)] ^= (unsigned char)(1u << below(8)); break;
            case 1: { int v = ints[below(NINTS)]; memcpy(b + 4 * below(size / 4), &v, 4); } break;
            case 2: { double v = specials[below(NSPECIAL)]; memcpy(b + 4 * below(size / 4 - 1), &v, 8); } break;
            default: m = below(size);
            }
            write_file(file, b, m);
            fmi2Component c = A.instantiate(id, 1, guid, uri, &callbacks, 0, 0);
            if (!c) { refused_bytes++; continue; }
            accepted++;
            if (budget_vr >= 0) {
                fmi2ValueReference vr = (fmi2ValueReference)budget_vr;
                double half = 0.5;
                A.set_real(c, &vr, 1, &half);
            }
            if (!A.setup(c, 0, 0.0, 0.0, 0, 0.0) && !A.enter_init(c) && !A.exit_init(c)) {
                double before = now();
                for (int k = 0; k < 3; k++) if (!A.do_step(c, 0.01 * k, 0.01, 0)) steps_ok++;
                if (now() - before > 3 * 10.5) {
                    fprintf(stderr, "fuzz_fmu: model case %ld: doSteps over their budget\n", n);
                    code = 6;
                }
            }
            A.free_instance(c);
            if (code) break;
        }
        free(orig), free(b);
        printf("fuzz_fmu model %s: %ld cases in %.1f s: %ld refused, %ld instantiated (%ld steps)\n", id, n,
               now() - t_start, refused_bytes, accepted, steps_ok);
    } else if (!strcmp(mode, "calls")) {
        fmi2Component c = A.instantiate(id, 1, guid, uri, &callbacks, 0, 0);
        if (!c) return fprintf(stderr, "fuzz_fmu: the FMU does not instantiate\n"), 2;
        fmi2FMUstate states[4] = {NULL, NULL, NULL, NULL};
        static const char *strings[] = {"dopri5", "rk4", "radau", "dop853", "", "x", "numpy", "auto"};
        double before_calls = now();
        for (; n < cases && now() - t_start < seconds; n++) {
            fmi2ValueReference vr = (fmi2ValueReference)below(200);
            double x = specials[below(NSPECIAL)], t = 0.0, v[4];
            int iv = ints[below(NINTS)];
            fmi2FMUstate *st = &states[below(4)];
            if (budget_vr >= 0) {
                fmi2ValueReference b = (fmi2ValueReference)budget_vr;
                double half = 0.5;
                A.set_real(c, &b, 1, &half);
            }
            switch (below(16)) {
            case 0: A.setup(c, (int)below(2), x, below(2) ? 0.0 : x, (int)below(2), specials[below(NSPECIAL)]); break;
            case 1: A.enter_init(c); break;
            case 2: A.exit_init(c); break;
            case 3: case 4: {
                A.real_status(c, 2, &t);
                double before = now();
                A.do_step(c, below(3) ? t : x, below(2) ? 0.01 : specials[below(NSPECIAL)] * 1e-3, 0);
                if (budget_vr >= 0 && now() - before > 10.5) {
                    fprintf(stderr, "fuzz_fmu: call case %ld: doStep over its budget\n", n);
                    code = 6;
                }
                break;
            }
            case 5: A.set_real(c, &vr, 1, &x); break;
            case 6: A.get_real(c, &vr, 1, v); break;
            case 7: A.set_integer(c, &vr, 1, &iv); break;
            case 8: A.get_integer(c, &vr, 1, &iv); break;
            case 9: { const char *s = strings[below(8)]; A.set_string(c, &vr, 1, &s); } break;
            case 10: { const char *s = NULL; A.get_string(c, &vr, 1, &s); } break;
            case 11: A.get_state(c, st); break;
            case 12: A.set_state(c, *st); break;
            case 13: A.free_state(c, st); break;
            case 14: {
                size_t size = 0;
                if (*st && !A.state_size(c, *st, &size)) {
                    char *bytes = malloc(size + 1);
                    fmi2FMUstate copy = NULL;
                    if (bytes && !A.serialize(c, *st, bytes, size) && !A.deserialize(c, bytes, size - below(2), &copy))
                        A.free_state(c, &copy);
                    free(bytes);
                }
                break;
            }
            default: if (below(2)) A.reset(c); else A.terminate(c);
            }
            if (code) break;
        }
        for (int k = 0; k < 4; k++) A.free_state(c, &states[k]);
        A.free_instance(c);
        printf("fuzz_fmu calls %s: %ld calls in %.1f s\n", id, n, now() - before_calls);
    } else {
        return fprintf(stderr, "fuzz_fmu: unknown mode %s\n", mode), 1;
    }
    dlclose(lib);
    return code;
}
