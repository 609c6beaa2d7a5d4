/*
 * FMI 2.0 co-simulation binary of an overcon FMU: starts (or joins) a Python interpreter and
 * forwards every FMI call to the FMU's Python slave (overcon_<hash>.fmu.slave, in resources/).
 *
 * Compiled by overcon.fmu.build with the build machine's C compiler; not linked against libpython.
 * Every Python C-API function is resolved with dlsym() from the library handle in use, so the
 * shared object has no undefined Python symbols and loads in any host (dlopen RTLD_LOCAL, a clean
 * environment, a host that never heard of Python).
 *
 * Interpreter lookup, at the first fmi2Instantiate of the process:
 *   1. a Python already in the process (Py_IsInitialized in the global symbol scope: fmpy,
 *      libcosimpy, any Python host): used as it is; initialised if it is not yet;
 *   2. otherwise the Python named by the environment variable OVERCON_PYTHON (an executable): it
 *      is asked (resources/<package>/fmu/pyinfo.py) for its libpython, home and site-packages;
 *   3. otherwise the Python recorded at build time in resources/overcon_python.txt.
 * The libpython of 2./3. is loaded with dlopen(RTLD_NOW | RTLD_GLOBAL) (extension modules such as
 * numpy's need its symbols globally), initialised with Py_InitializeEx(0) (no signal handlers),
 * given the recorded site-packages (numpy, scipy) and left running: the interpreter is never
 * finalised, so the host may exit at any time. The GIL is released between calls; each call
 * takes it with PyGILState_Ensure/Release, from whichever thread the host calls.
 *
 * The slave implements the FMI state machine and the variable access; it returns an fmi2Status
 * for every call and logs through log_from_python() below, which applies fmi2SetDebugLogging's
 * categories. Error and fatal messages always reach the host's logger; warnings too unless the
 * host switched the category logStatusWarning off; the other categories only with debug logging on.
 *
 * Published values: a host reads the same outputs after every fmi2DoStep, and entering Python for
 * that (GIL, call) costs more than the copy. So the slave registers, once at fmi2Instantiate
 * (through register_published() below, whose address it gets like log_from_python's), arrays it
 * owns and keeps alive: two flags (positions valid, reactions/friction valid), per value reference
 * the slot of a Real output in the published output vector (or -1), the published outputs, and
 * per value reference the 0/1 value of a constant Boolean output (or -1). fmi2GetReal and
 * fmi2GetBoolean copy from there without the GIL when every requested reference is published and
 * its flag is set; anything else (a parameter, an unknown reference, a NULL array, nvr = 0, a flag
 * off) takes the Python call, which checks and reports as always. Every call of a slave method
 * other than a getter (get_*) clears both flags before entering Python, so after any such FMI call
 * the values are served by Python until the slave publishes again (after a successful fmi2DoStep
 * or fmi2ExitInitializationMode, or once it computed the reactions a host read).
 */
#define _GNU_SOURCE /* RTLD_DEFAULT, RTLD_NODELETE, dladdr */
#include <dlfcn.h>
#include <limits.h>
#include <pthread.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <wchar.h>

/* ---------------------------------------------------------------- FMI 2.0 types (fmi2TypesPlatform.h,
 * fmi2FunctionTypes.h of the standard) */
typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;
#define fmi2True 1
#define fmi2False 0
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;
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

#define EXPORT __attribute__((visibility("default")))
#define ADDR(p) ((unsigned long long)(uintptr_t)(p)) /* a pointer passed to Python as an int */

/* ---------------------------------------------------------------- Python C API, resolved at run time */
typedef struct _object PyObject; /* opaque here */
typedef ssize_t Py_ssize_t;
typedef int PyGILState_STATE;

static struct PythonApi {
    int (*Py_IsInitialized)(void);
    void (*Py_InitializeEx)(int);
    void *(*PyEval_SaveThread)(void);
    PyGILState_STATE (*PyGILState_Ensure)(void);
    void (*PyGILState_Release)(PyGILState_STATE);
    PyObject *(*PyImport_ImportModule)(const char *);
    PyObject *(*PyObject_GetAttrString)(PyObject *, const char *);
    PyObject *(*PyObject_CallObject)(PyObject *, PyObject *);
    PyObject *(*Py_VaBuildValue)(const char *, va_list);
    long (*PyLong_AsLong)(PyObject *);
    PyObject *(*PyErr_Occurred)(void);
    void (*PyErr_Fetch)(PyObject **, PyObject **, PyObject **);
    void (*PyErr_Clear)(void);
    PyObject *(*PyObject_Str)(PyObject *);
    const char *(*PyUnicode_AsUTF8)(PyObject *);
    void (*Py_DecRef)(PyObject *);
    void (*Py_SetPythonHome)(const wchar_t *); /* optional: gone from Python 3.13 */
    wchar_t *(*Py_DecodeLocale)(const char *, size_t *);
    int (*Py_IsFinalizing)(void);     /* optional: public from Python 3.13 */
    int (*Py_IsFinalizing_old)(void); /* optional: _Py_IsFinalizing, Python 3.7-3.12 */
} py;

static const struct {
    const char *name;
    size_t offset;
    int optional;
} py_symbols[] = {
#define SYM(n, opt) {#n, offsetof(struct PythonApi, n), opt}
    SYM(Py_IsInitialized, 0),       SYM(Py_InitializeEx, 0),   SYM(PyEval_SaveThread, 0),
    SYM(PyGILState_Ensure, 0),      SYM(PyGILState_Release, 0), SYM(PyImport_ImportModule, 0),
    SYM(PyObject_GetAttrString, 0), SYM(PyObject_CallObject, 0), SYM(Py_VaBuildValue, 0),
    SYM(PyLong_AsLong, 0),          SYM(PyErr_Occurred, 0),    SYM(PyErr_Fetch, 0),
    SYM(PyErr_Clear, 0),            SYM(PyObject_Str, 0),      SYM(PyUnicode_AsUTF8, 0),
    SYM(Py_DecRef, 0),              SYM(Py_SetPythonHome, 1),  SYM(Py_DecodeLocale, 0),
    SYM(Py_IsFinalizing, 1),        {"_Py_IsFinalizing", offsetof(struct PythonApi, Py_IsFinalizing_old), 1},
#undef SYM
};

/* ---------------------------------------------------------------- instances */
enum { CAT_EVENTS, CAT_WARNING, CAT_ERROR, CAT_FATAL, N_CATEGORIES };
/* must equal the LogCategories of modelDescription.xml (overcon.fmu.description.LOG_CATEGORIES,
 * checked by the tests); "logAll" switches every category */
static const char *category_names[N_CATEGORIES] = {"logEvents", "logStatusWarning", "logStatusError",
                                                   "logStatusFatal"};

typedef struct {
    PyObject *slave;
    char *name;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
    int enabled[N_CATEGORIES];
    /* published values (register_published; all NULL/0 until registered), owned by the slave */
    int *pub_flags;         /* [0]: positions and constants valid, [1]: reactions/friction valid */
    int n_real_map;         /* entries of real_slot (the number of value references) */
    const int *real_slot;   /* value reference -> slot in real_values, or -1 */
    const double *real_values;
    int n_pos;              /* slots < n_pos: positions (flag 0); others: reactions, friction (flag 1) */
    int n_bool_map;         /* entries of bool_value */
    const int *bool_value;  /* value reference -> 0/1 of a constant Boolean output, or -1 */
} Instance;

static void default_categories(Instance *c, int logging_on)
{
    for (int k = 0; k < N_CATEGORIES; k++)
        c->enabled[k] = logging_on || k != CAT_EVENTS;
}

static void host_log(Instance *c, fmi2Status status, int category, const char *fmt, ...)
{
    char msg[4096], esc[8192];
    va_list ap;
    if (c == NULL || c->logger == NULL)
        return;
    if (status < fmi2Error && !c->enabled[category])
        return;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    /* the host's logger takes the message as a printf format: double every % */
    size_t j = 0;
    for (const char *s = msg; *s && j + 2 < sizeof esc; s++) {
        esc[j++] = *s;
        if (*s == '%')
            esc[j++] = '%';
    }
    esc[j] = '\0';
    c->logger(c->env, c->name, status, category_names[category], esc);
}

static int category_of(fmi2Status status)
{
    return status == fmi2OK ? CAT_EVENTS : status <= fmi2Discard ? CAT_WARNING
                                       : status == fmi2Error     ? CAT_ERROR
                                                                 : CAT_FATAL;
}

/* called by the Python slave (through ctypes, with the component as first argument) */
static void log_from_python(void *component, int status, const char *message)
{
    host_log((Instance *)component, (fmi2Status)status, category_of((fmi2Status)status), "%s",
             message ? message : "");
}

/* called by the Python slave (through ctypes, once at construction) with the addresses of its
 * published arrays (see the header comment); flags NULL unregisters */
static void register_published(void *component, int *flags, int n_real_map, const int *real_slot,
                               const double *real_values, int n_pos, int n_bool_map,
                               const int *bool_value)
{
    Instance *c = (Instance *)component;
    if (c == NULL)
        return;
    int ok = flags && real_slot && real_values && bool_value && n_real_map >= 0 && n_bool_map >= 0;
    c->pub_flags = ok ? flags : NULL;
    c->n_real_map = ok ? n_real_map : 0;
    c->real_slot = ok ? real_slot : NULL;
    c->real_values = ok ? real_values : NULL;
    c->n_pos = ok ? n_pos : 0;
    c->n_bool_map = ok ? n_bool_map : 0;
    c->bool_value = ok ? bool_value : NULL;
}

/* fmi2GetReal from the published values: 1 if every reference is published and valid (values
 * copied), 0 otherwise (nothing written: the caller takes the Python call) */
static int published_reals(const Instance *c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    const int *flags = c->pub_flags;
    if (flags == NULL || !flags[0] || vr == NULL || value == NULL || nvr == 0)
        return 0;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= (fmi2ValueReference)c->n_real_map)
            return 0;
        int slot = c->real_slot[vr[i]];
        if (slot < 0 || (slot >= c->n_pos && !flags[1]))
            return 0;
    }
    for (size_t i = 0; i < nvr; i++)
        value[i] = c->real_values[c->real_slot[vr[i]]];
    return 1;
}

static int published_booleans(const Instance *c, const fmi2ValueReference vr[], size_t nvr,
                              fmi2Boolean value[])
{
    const int *flags = c->pub_flags;
    if (flags == NULL || !flags[0] || vr == NULL || value == NULL || nvr == 0)
        return 0;
    for (size_t i = 0; i < nvr; i++)
        if (vr[i] >= (fmi2ValueReference)c->n_bool_map || c->bool_value[vr[i]] < 0)
            return 0;
    for (size_t i = 0; i < nvr; i++)
        value[i] = c->bool_value[vr[i]] ? fmi2True : fmi2False;
    return 1;
}

/* ---------------------------------------------------------------- starting Python */
static pthread_mutex_t boot_lock = PTHREAD_MUTEX_INITIALIZER;
static int booted;      /* the py table is filled and an interpreter runs */
static int started_here; /* this binary initialised the interpreter */
static char boot_error[3 * PATH_MAX];
#define MAX_SITES 32
/* site-packages of the recorded Python, newline separated, for an interpreter started here */
static char site_dirs[MAX_SITES * (PATH_MAX + 1)];

typedef struct {
    char libpython[PATH_MAX], home[PATH_MAX], python[PATH_MAX], source[PATH_MAX + 128];
    char site[MAX_SITES][PATH_MAX];
    int n_site;
} PythonFacts;

static void strip_newline(char *s)
{
    size_t n = strlen(s);
    while (n > 0 && (s[n - 1] == '\n' || s[n - 1] == '\r'))
        s[--n] = '\0';
}

/* key=value lines (overcon.fmu.pyinfo): libpython, home, python, site (repeated) */
static void read_facts(FILE *f, PythonFacts *facts)
{
    char line[PATH_MAX + 32];
    while (fgets(line, sizeof line, f)) {
        strip_newline(line);
        char *eq = strchr(line, '=');
        if (line[0] == '#' || eq == NULL)
            continue;
        *eq = '\0';
        const char *key = line, *value = eq + 1;
        if (!strcmp(key, "libpython"))
            snprintf(facts->libpython, sizeof facts->libpython, "%s", value);
        else if (!strcmp(key, "home"))
            snprintf(facts->home, sizeof facts->home, "%s", value);
        else if (!strcmp(key, "python"))
            snprintf(facts->python, sizeof facts->python, "%s", value);
        else if (!strcmp(key, "site") && facts->n_site < MAX_SITES)
            snprintf(facts->site[facts->n_site++], PATH_MAX, "%s", value);
    }
}

static int read_package(const char *resources, char *package, size_t size)
{
    char path[PATH_MAX + 64], line[256];
    snprintf(path, sizeof path, "%s/overcon_package.txt", resources);
    FILE *f = fopen(path, "r");
    if (!f)
        return 0;
    int ok = fgets(line, sizeof line, f) != NULL;
    fclose(f);
    strip_newline(line);
    snprintf(package, size, "%s", ok ? line : "");
    return ok && line[0] != '\0';
}

/* single-quote a string for /bin/sh */
static void sh_quote(char *out, size_t size, const char *s)
{
    size_t j = 0;
    out[j++] = '\'';
    for (; *s && j + 5 < size; s++) {
        if (*s == '\'') {
            memcpy(out + j, "'\\''", 4);
            j += 4;
        } else {
            out[j++] = *s;
        }
    }
    out[j++] = '\'';
    out[j] = '\0';
}

static int find_facts(const char *resources, const char *package, PythonFacts *facts)
{
    const char *exe = getenv("OVERCON_PYTHON");
    memset(facts, 0, sizeof *facts);
    if (exe && *exe) {
        char qexe[2 * PATH_MAX], qscript[2 * PATH_MAX + 256], script[PATH_MAX + 256],
            cmd[4 * PATH_MAX + 512];
        snprintf(script, sizeof script, "%s/%s/fmu/pyinfo.py", resources, package);
        sh_quote(qexe, sizeof qexe, exe);
        sh_quote(qscript, sizeof qscript, script);
        snprintf(cmd, sizeof cmd, "%s -I %s 2>&1", qexe, qscript);
        FILE *p = popen(cmd, "r");
        if (p)
            read_facts(p, facts);
        int rc = p ? pclose(p) : -1;
        if (rc != 0 || !facts->libpython[0]) {
            snprintf(boot_error, sizeof boot_error,
                     "OVERCON_PYTHON=%s: could not ask this Python for its libpython (running %s "
                     "failed); it must be a Python executable with numpy and scipy",
                     exe, script);
            return 0;
        }
        snprintf(facts->source, sizeof facts->source, "OVERCON_PYTHON=%s", exe);
        return 1;
    }
    char path[PATH_MAX + 64];
    snprintf(path, sizeof path, "%s/overcon_python.txt", resources);
    FILE *f = fopen(path, "r");
    if (!f) {
        snprintf(boot_error, sizeof boot_error,
                 "no Python in the process, OVERCON_PYTHON not set and no %s", path);
        return 0;
    }
    read_facts(f, facts);
    fclose(f);
    snprintf(facts->source, sizeof facts->source, "the Python recorded at build time (%s)",
             facts->python[0] ? facts->python : path);
    if (!facts->libpython[0]) {
        snprintf(boot_error, sizeof boot_error, "%s names no libpython", path);
        return 0;
    }
    return 1;
}

static int resolve(void *handle, const char *where)
{
    for (size_t k = 0; k < sizeof py_symbols / sizeof py_symbols[0]; k++) {
        void *f = dlsym(handle, py_symbols[k].name);
        if (!f && !py_symbols[k].optional) {
            snprintf(boot_error, sizeof boot_error, "Python C API function %s not found in %s",
                     py_symbols[k].name, where);
            return 0;
        }
        memcpy((char *)&py + py_symbols[k].offset, &f, sizeof f);
    }
    return 1;
}

/* keep this binary loaded for the life of the process: the interpreter holds pointers into it
 * (the log function) and is never finalised */
static void pin_self(void)
{
    Dl_info info;
    if (dladdr((void *)&pin_self, &info) && info.dli_fname)
        dlopen(info.dli_fname, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);
}

static int boot_python(const char *resources, const char *package)
{
    if (booted)
        return 1;
    void *handle = RTLD_DEFAULT;
    PythonFacts facts;
    int have_facts = 0;
    const char *where = "the process";
    if (!dlsym(RTLD_DEFAULT, "Py_IsInitialized")) {
        if (!find_facts(resources, package, &facts))
            return 0;
        have_facts = 1;
        handle = dlopen(facts.libpython, RTLD_NOW | RTLD_GLOBAL);
        if (!handle) {
            snprintf(boot_error, sizeof boot_error,
                     "cannot load libpython %s of %s: %s (set OVERCON_PYTHON to a Python executable "
                     "with numpy and scipy, built with a shared libpython)",
                     facts.libpython, facts.source, dlerror());
            return 0;
        }
        where = facts.libpython;
    }
    if (!resolve(handle, where))
        return 0;
    pin_self();
    if (!py.Py_IsInitialized()) {
        if (!have_facts && find_facts(resources, package, &facts))
            have_facts = 1;
        if (have_facts && facts.home[0] && py.Py_SetPythonHome) {
            /* kept for the life of the process, as Py_SetPythonHome requires */
            wchar_t *home = py.Py_DecodeLocale(facts.home, NULL);
            if (home)
                py.Py_SetPythonHome(home);
        }
        py.Py_InitializeEx(0); /* 0: leave the host's signal handlers alone */
        started_here = 1;
        /* the site-packages are added by the slave's bootstrap module (boot.instantiate) */
        if (have_facts) {
            size_t j = 0;
            for (int k = 0; k < facts.n_site; k++)
                j += (size_t)snprintf(site_dirs + j, sizeof site_dirs - j, "%s%s", k ? "\n" : "",
                                      facts.site[k]);
        }
        py.PyEval_SaveThread(); /* release the GIL; every call takes it back */
    }
    booted = 1;
    return 1;
}

/* ---------------------------------------------------------------- calling the slave */
static void python_error(Instance *c, const char *fn)
{
    PyObject *type = NULL, *value = NULL, *tb = NULL;
    py.PyErr_Fetch(&type, &value, &tb);
    const char *text = NULL, *kind = NULL;
    PyObject *s = value ? py.PyObject_Str(value) : NULL;
    PyObject *name = type ? py.PyObject_GetAttrString(type, "__name__") : NULL;
    if (s)
        text = py.PyUnicode_AsUTF8(s);
    if (name)
        kind = py.PyUnicode_AsUTF8(name);
    if (!text || !kind)
        py.PyErr_Clear();
    host_log(c, fmi2Error, CAT_ERROR, "%s: Python raised %s: %s", fn, kind ? kind : "an exception",
             text ? text : "(no message)");
    if (s)
        py.Py_DecRef(s);
    if (name)
        py.Py_DecRef(name);
    if (type)
        py.Py_DecRef(type);
    if (value)
        py.Py_DecRef(value);
    if (tb)
        py.Py_DecRef(tb);
}

/* call obj.method(*Py_BuildValue(fmt, ...)); fmt must describe a tuple ("(...)"). Returns a new
 * reference or NULL (the error is logged). The GIL must be held. */
static PyObject *call_object(Instance *c, const char *fn, PyObject *obj, const char *method,
                             const char *fmt, va_list ap)
{
    PyObject *f = py.PyObject_GetAttrString(obj, method);
    if (!f) {
        python_error(c, fn);
        return NULL;
    }
    PyObject *args = py.Py_VaBuildValue(fmt, ap);
    PyObject *res = args ? py.PyObject_CallObject(f, args) : NULL;
    if (!res)
        python_error(c, fn);
    if (args)
        py.Py_DecRef(args);
    py.Py_DecRef(f);
    return res;
}

static PyObject *py_method(Instance *c, const char *fn, PyObject *obj, const char *method,
                           const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    PyObject *r = call_object(c, fn, obj, method, fmt, ap);
    va_end(ap);
    return r;
}

static Instance *checked(fmi2Component comp, const char *fn)
{
    if (comp == NULL) {
        fprintf(stderr, "overcon FMU: %s called with a NULL component\n", fn);
        return NULL;
    }
    return (Instance *)comp;
}

/* The interpreter has shut down, or is shutting down. A Python host may free its FMU instances
 * after that (OMSimulator's Python API does, at exit); PyGILState_Ensure would then crash the
 * process, so no call enters Python any more: fmi2FreeInstance frees the C side only (the slave
 * went with the interpreter) and every other call returns fmi2Error with the reason. */
static int python_gone(void)
{
    return !py.Py_IsInitialized() || (py.Py_IsFinalizing && py.Py_IsFinalizing()) ||
           (!py.Py_IsFinalizing && py.Py_IsFinalizing_old && py.Py_IsFinalizing_old());
}

static const char gone_message[] = "%s: the Python interpreter of this process has shut down (or is "
                                   "shutting down); this FMU runs in it and cannot be called any more";

/* every slave method returns an fmi2Status */
static fmi2Status call(fmi2Component comp, const char *fn, const char *method, const char *fmt, ...)
{
    Instance *c = checked(comp, fn);
    if (!c)
        return fmi2Error;
    if (c->pub_flags && strncmp(method, "get_", 4) != 0)
        c->pub_flags[0] = c->pub_flags[1] = 0; /* published values invalid until published again */
    if (python_gone()) {
        host_log(c, fmi2Error, CAT_ERROR, gone_message, fn);
        return fmi2Error;
    }
    PyGILState_STATE g = py.PyGILState_Ensure();
    va_list ap;
    va_start(ap, fmt);
    PyObject *res = call_object(c, fn, c->slave, method, fmt, ap);
    va_end(ap);
    fmi2Status status = fmi2Error;
    if (res) {
        long s = py.PyLong_AsLong(res);
        if (s == -1 && py.PyErr_Occurred())
            python_error(c, fn);
        else if (s >= fmi2OK && s <= fmi2Fatal)
            status = (fmi2Status)s;
        py.Py_DecRef(res);
    }
    py.PyGILState_Release(g);
    return status;
}

/* ---------------------------------------------------------------- resource location */
static int hexval(int ch)
{
    return ch >= '0' && ch <= '9' ? ch - '0' : ch >= 'a' && ch <= 'f' ? ch - 'a' + 10
                                           : ch >= 'A' && ch <= 'F' ? ch - 'A' + 10
                                                                    : -1;
}

/* file:///abs/path, file:/abs/path, file://localhost/abs/path (percent-decoded); a plain
 * absolute path is accepted too */
static int resource_dir(const char *uri, char *out, size_t size)
{
    const char *p = uri;
    if (!strncmp(p, "file://localhost/", 17))
        p += 16;
    else if (!strncmp(p, "file:///", 8))
        p += 7;
    else if (!strncmp(p, "file:/", 6))
        p += 5;
    else if (p[0] != '/')
        return 0;
    /* hosts that write "file:///" + an absolute path give four slashes; one is the path's root */
    while (p[0] == '/' && p[1] == '/')
        p++;
    size_t j = 0;
    for (; *p && j + 1 < size; p++) {
        if (*p == '%' && hexval(p[1]) >= 0 && hexval(p[2]) >= 0) {
            out[j++] = (char)(hexval(p[1]) * 16 + hexval(p[2]));
            p += 2;
        } else {
            out[j++] = *p;
        }
    }
    while (j > 1 && out[j - 1] == '/')
        j--;
    out[j] = '\0';
    return 1;
}

/* ---------------------------------------------------------------- FMI functions */
EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String guid,
                                     fmi2String resourceLocation,
                                     const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                                     fmi2Boolean loggingOn)
{
    (void)visible;
    Instance tmp = {0};
    tmp.name = (char *)(instanceName ? instanceName : "");
    if (functions) {
        tmp.logger = functions->logger;
        tmp.env = functions->componentEnvironment;
    }
    default_categories(&tmp, loggingOn);
    if (instanceName == NULL || instanceName[0] == '\0') {
        host_log(&tmp, fmi2Error, CAT_ERROR, "fmi2Instantiate: instanceName is empty");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        host_log(&tmp, fmi2Error, CAT_ERROR,
                 "fmi2Instantiate: this FMU supports co-simulation only (fmuType %d given)", (int)fmuType);
        return NULL;
    }
    char resources[PATH_MAX], package[256];
    if (resourceLocation == NULL || !resource_dir(resourceLocation, resources, sizeof resources)) {
        host_log(&tmp, fmi2Error, CAT_ERROR,
                 "fmi2Instantiate: fmuResourceLocation %s is not a file: URI of the FMU's resources folder",
                 resourceLocation ? resourceLocation : "(NULL)");
        return NULL;
    }
    if (!read_package(resources, package, sizeof package)) {
        host_log(&tmp, fmi2Error, CAT_ERROR,
                 "fmi2Instantiate: %s/overcon_package.txt is missing: fmuResourceLocation must be the "
                 "resources folder of the unzipped FMU", resources);
        return NULL;
    }
    pthread_mutex_lock(&boot_lock);
    int ok = boot_python(resources, package);
    pthread_mutex_unlock(&boot_lock);
    if (!ok) {
        host_log(&tmp, fmi2Fatal, CAT_FATAL, "fmi2Instantiate: cannot start Python: %s", boot_error);
        return NULL;
    }
    if (python_gone()) {
        host_log(&tmp, fmi2Fatal, CAT_FATAL, gone_message, "fmi2Instantiate");
        return NULL;
    }
    Instance *c = calloc(1, sizeof *c);
    if (!c || !(c->name = strdup(tmp.name))) {
        free(c);
        host_log(&tmp, fmi2Error, CAT_ERROR, "fmi2Instantiate: out of memory");
        return NULL;
    }
    c->logger = tmp.logger;
    c->env = tmp.env;
    default_categories(c, loggingOn);

    PyGILState_STATE g = py.PyGILState_Ensure();
    PyObject *res = NULL, *sys = py.PyImport_ImportModule("sys");
    PyObject *path = sys ? py.PyObject_GetAttrString(sys, "path") : NULL;
    if (path) { /* sys.path.insert(0, resources) unless there */
        PyObject *n = py_method(c, "fmi2Instantiate", path, "count", "(s)", resources);
        long count = n ? py.PyLong_AsLong(n) : -1;
        PyObject *r = count == 0 ? py_method(c, "fmi2Instantiate", path, "insert", "(is)", 0, resources) : NULL;
        if (r)
            py.Py_DecRef(r);
        if (n)
            py.Py_DecRef(n);
        py.Py_DecRef(path);
    }
    if (sys)
        py.Py_DecRef(sys);
    /* the package's bootstrap module (stdlib only): in an interpreter started here it adds the
     * recorded site-packages first, then imports the slave and creates the instance */
    char module[300];
    snprintf(module, sizeof module, "%s.fmu.boot", package);
    PyObject *boot = py.PyImport_ImportModule(module);
    if (boot) {
        res = py_method(c, "fmi2Instantiate", boot, "instantiate", "(sssKKisK)", c->name,
                        guid ? guid : "", resources, ADDR(&log_from_python), ADDR(c),
                        loggingOn ? 1 : 0, started_here ? site_dirs : "", ADDR(&register_published));
        py.Py_DecRef(boot);
    }
    if (py.PyErr_Occurred())
        python_error(c, "fmi2Instantiate");
    py.PyGILState_Release(g);
    if (!res) {
        free(c->name);
        free(c);
        return NULL;
    }
    c->slave = res;
    return c;
}

EXPORT void fmi2FreeInstance(fmi2Component comp)
{
    Instance *c = checked(comp, "fmi2FreeInstance");
    if (!c)
        return;
    if (python_gone()) {
        host_log(c, fmi2OK, CAT_EVENTS, "fmi2FreeInstance: the Python interpreter has shut down; its "
                 "objects of this instance went with it, the C side is freed");
        free(c->name);
        free(c);
        return;
    }
    PyGILState_STATE g = py.PyGILState_Ensure();
    PyObject *r = py_method(c, "fmi2FreeInstance", c->slave, "free_instance", "()");
    if (r)
        py.Py_DecRef(r);
    c->pub_flags = NULL; /* the slave's arrays go with it */
    py.Py_DecRef(c->slave);
    py.PyGILState_Release(g);
    free(c->name);
    free(c);
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories,
                                      const fmi2String categories[])
{
    Instance *c = checked(comp, "fmi2SetDebugLogging");
    if (!c)
        return fmi2Error;
    if (nCategories == 0) {
        default_categories(c, loggingOn);
        return fmi2OK;
    }
    if (categories == NULL) {
        host_log(c, fmi2Error, CAT_ERROR, "fmi2SetDebugLogging: categories is NULL but nCategories = %zu",
                 nCategories);
        return fmi2Error;
    }
    for (size_t i = 0; i < nCategories; i++) {
        const char *name = categories[i] ? categories[i] : "(NULL)";
        int found = 0;
        for (int k = 0; k < N_CATEGORIES; k++) {
            if (!strcmp(name, category_names[k]) || !strcmp(name, "logAll")) {
                c->enabled[k] = loggingOn ? 1 : 0;
                found = 1;
            }
        }
        if (!found) {
            host_log(c, fmi2Error, CAT_ERROR,
                     "fmi2SetDebugLogging: unknown log category \"%s\" (categories: logEvents, "
                     "logStatusWarning, logStatusError, logStatusFatal, logAll)", name);
            return fmi2Error;
        }
    }
    return fmi2OK;
}

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                                      fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    return call(c, "fmi2SetupExperiment", "setup_experiment", "(idddd)", toleranceDefined ? 1 : 0,
                tolerance, startTime, stopTimeDefined ? 1.0 : 0.0, stopTime);
}

EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    return call(c, "fmi2EnterInitializationMode", "enter_initialization_mode", "()");
}

EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    return call(c, "fmi2ExitInitializationMode", "exit_initialization_mode", "()");
}

EXPORT fmi2Status fmi2Terminate(fmi2Component c) { return call(c, "fmi2Terminate", "terminate", "()"); }
EXPORT fmi2Status fmi2Reset(fmi2Component c) { return call(c, "fmi2Reset", "reset", "()"); }

#define GET(Type, ctype, method)                                                                    \
    EXPORT fmi2Status fmi2Get##Type(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,     \
                                    ctype value[])                                                  \
    {                                                                                               \
        return call(c, "fmi2Get" #Type, "get_" method, "(KKK)", ADDR(vr), (unsigned long long)nvr, \
                    ADDR(value));                                                                   \
    }
/* fmi2GetReal and fmi2GetBoolean answer published values without Python when they can */
#define GET_PUBLISHED(Type, ctype, method, published)                                               \
    EXPORT fmi2Status fmi2Get##Type(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,     \
                                    ctype value[])                                                  \
    {                                                                                               \
        if (c != NULL && published((const Instance *)c, vr, nvr, value))                           \
            return fmi2OK;                                                                          \
        return call(c, "fmi2Get" #Type, "get_" method, "(KKK)", ADDR(vr), (unsigned long long)nvr, \
                    ADDR(value));                                                                   \
    }
#define SET(Type, ctype, method)                                                                    \
    EXPORT fmi2Status fmi2Set##Type(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,     \
                                    const ctype value[])                                            \
    {                                                                                               \
        return call(c, "fmi2Set" #Type, "set_" method, "(KKK)", ADDR(vr), (unsigned long long)nvr, \
                    ADDR(value));                                                                   \
    }
GET_PUBLISHED(Real, fmi2Real, "real", published_reals)
GET(Integer, fmi2Integer, "integer")
GET_PUBLISHED(Boolean, fmi2Boolean, "boolean", published_booleans)
GET(String, fmi2String, "string")
SET(Real, fmi2Real, "real")
SET(Integer, fmi2Integer, "integer")
SET(Boolean, fmi2Boolean, "boolean")
SET(String, fmi2String, "string")

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    return call(c, "fmi2GetFMUstate", "get_fmu_state", "(K)", ADDR(state));
}
EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    return call(c, "fmi2SetFMUstate", "set_fmu_state", "(K)", ADDR(state));
}
EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    return call(c, "fmi2FreeFMUstate", "free_fmu_state", "(K)", ADDR(state));
}
EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    return call(c, "fmi2SerializedFMUstateSize", "serialized_fmu_state_size", "(KK)", ADDR(state), ADDR(size));
}
EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    return call(c, "fmi2SerializeFMUstate", "serialize_fmu_state", "(KKK)", ADDR(state), ADDR(bytes),
                (unsigned long long)size);
}
EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                          fmi2FMUstate *state)
{
    return call(c, "fmi2DeSerializeFMUstate", "deserialize_fmu_state", "(KKK)", ADDR(bytes),
                (unsigned long long)size, ADDR(state));
}

EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[],
                                               size_t nUnknown, const fmi2ValueReference vKnown[],
                                               size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown, (void)nUnknown, (void)vKnown, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    return call(c, "fmi2GetDirectionalDerivative", "unsupported", "(s)", "fmi2GetDirectionalDerivative");
}

EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                              const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    return call(c, "fmi2SetRealInputDerivatives", "unsupported", "(s)", "fmi2SetRealInputDerivatives");
}

EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                               const fmi2Integer order[], fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    return call(c, "fmi2GetRealOutputDerivatives", "unsupported", "(s)", "fmi2GetRealOutputDerivatives");
}

EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                             fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    return call(c, "fmi2DoStep", "do_step", "(ddi)", currentCommunicationPoint, communicationStepSize,
                noSetFMUStatePriorToCurrentPoint ? 1 : 0);
}

EXPORT fmi2Status fmi2CancelStep(fmi2Component c)
{
    return call(c, "fmi2CancelStep", "unsupported", "(s)", "fmi2CancelStep");
}

EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    return call(c, "fmi2GetStatus", "get_status", "(siK)", "fmi2GetStatus", (int)s, ADDR(value));
}
EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    return call(c, "fmi2GetRealStatus", "get_status", "(siK)", "fmi2GetRealStatus", (int)s, ADDR(value));
}
EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    return call(c, "fmi2GetIntegerStatus", "get_status", "(siK)", "fmi2GetIntegerStatus", (int)s, ADDR(value));
}
EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    return call(c, "fmi2GetBooleanStatus", "get_status", "(siK)", "fmi2GetBooleanStatus", (int)s, ADDR(value));
}
EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    return call(c, "fmi2GetStringStatus", "get_status", "(siK)", "fmi2GetStringStatus", (int)s, ADDR(value));
}
