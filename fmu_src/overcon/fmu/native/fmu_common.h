/* The FMI layer of an overcon FMU without Python: the FMI functions over the C core's run
 * (core/sim.c), reading the model file resources/overcon_model.bin that overcon build writes
 * (overcon.fmu.cmodel: its docstring describes the layout). It behaves as the Python slave
 * (overcon.fmu.slave) for the models and methods it covers: states, variables, parameters and their
 * rules, the tolerance rule of fmi2SetupExperiment, the doStep work budget, lazy reactions, FMU
 * states bit for bit, the log categories. The code shared by the FMI versions:
 *   fmu_model.c    reads and checks the model file
 *   fmu_inst.c     instances: made from the resources folder, freed, logging, mode checks
 *   fmu_run.c      the run: parameters applied, outputs, tolerance rule, initialization, a step
 *   fmu_vars.c     variable access: references checked, values read, parameters and their rules
 *   fmu_state.c    FMU states: get, set, free, serialize, deserialize
 *   fmu_me.c       Model Exchange: continuous states, derivatives, the event that corrects them
 * and the FMI 2.0 functions over it:
 *   fmi2_core.c    instantiate, free, debug logging
 *   fmi2_run.c     fmi2SetupExperiment, initialization, fmi2DoStep
 *   fmi2_vars.c    fmi2Get*, fmi2Set*, reset, status queries
 *   fmi2_state.c   FMU states
 *   fmi2_me.c      Model Exchange
 * (the FMI 3.0 functions: fmi3_*.c, their types in fmi3_types.h).
 * The FMI 2.0 types below are the shared code's too (fmi3Status has fmi2Status's values).
 * C11 and libm; no global mutable state (every instance owns its memory). */
#ifndef OVERCON_FMU_COMMON_H
#define OVERCON_FMU_COMMON_H

#include <stddef.h>

#include "../../core/core.h"
#include "fmi3_types.h"

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
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void *);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);
typedef struct {
    fmi2Boolean newDiscreteStatesNeeded, terminateSimulation, nominalsOfContinuousStatesChanged,
        valuesOfContinuousStatesChanged, nextEventTimeDefined;
    fmi2Real nextEventTime;
} fmi2EventInfo;
typedef struct {
    const fmi2CallbackLogger logger;
    const fmi2CallbackAllocateMemory allocateMemory;
    const fmi2CallbackFreeMemory freeMemory;
    const fmi2StepFinished stepFinished;
    const fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

/* The FMI functions, the only symbols an FMU binary exports (every other one is hidden: it is
 * compiled with -fvisibility=hidden -DOVK_FMU_BINARY, and linked with native/exports.map on ELF). */
#if defined(_WIN32)
#define FMU_EXPORT __declspec(dllexport)
#else
#define FMU_EXPORT __attribute__((visibility("default")))
#endif
#define FMU_HIDDEN __attribute__((visibility("hidden")))

enum { T_REAL = 0, T_INTEGER = 1, T_BOOLEAN = 2, T_STRING = 3 };
enum { K_OUTPUT = 0, K_CONSTANT = 1, K_PARAM = 2, K_STABLE_STEP = 3, K_STATE = 4, K_DERIVATIVE = 5, K_ARRAY = 6, K_TIME = 7 };
enum { K_ALONG = 8 }; /* arg 0 rank, 1 motion_unique, 2 + j joint j's reaction_unique, 2 + nj effort_unique */
enum { K_INPUT = 9 }; /* arg: the input's slot (ovk_model.nu) */
/* K_STATE, K_DERIVATIVE: entry arg of y = [q, h] and of its derivative (Model Exchange's continuous
 * states); K_ARRAY (FMI 3.0): the consecutive reaction outputs of one joint from output arg on; K_TIME (FMI 3.0):
 * the independent variable time. */
enum { V_CONTINUOUS = 0, V_CONSTANT = 1, V_FIXED = 2, V_TUNABLE = 3, V_DISCRETE = 4 };
enum { O_POSITION = OVK_OUT_POSITION, O_VELOCITY = OVK_OUT_VELOCITY, O_REACTION = OVK_OUT_REACTION,
       O_FRICTION = OVK_OUT_FRICTION, O_ENERGY = OVK_OUT_ENERGY, O_SENSOR = OVK_OUT_SENSOR }; /* the core's output plan (sim_out.c) */
enum { P_MU = 1, P_VREG = 2, P_MU_STATIC = 3, P_VSTRIBECK = 4, P_METHOD = 10, P_TOLERANCE = 11, P_STEP = 12,
       P_MAX_STEP = 13, P_BAUMGARTE = 14, P_FRICTION_TOL = 15, P_FRICTION_MAX_ITER = 16, P_KERNEL = 17,
       P_MAX_INTERNAL_STEPS = 18, P_MAX_WALL_TIME = 19, P_REDUNDANCY = 20 };
enum { RULE_REAL = 0, RULE_INT = 1, RULE_CHOICE = 2 };
#define FMU_MAX_CHOICES 8

typedef struct { const char *name; int type, causality, variability, key, arg; } fmu_var;
typedef struct {
    const char *name, *range_text, *why, *sdefault;
    int type, target, joint, rule, has_lo, has_hi, low_open, nchoices, tunable;
    double lo, hi, ddefault;
    const char *choices[FMU_MAX_CHOICES];
} fmu_param;
typedef ovk_out fmu_out;

/* The model file, read once per instance; strings point into the file's bytes (kept). */
typedef struct {
    unsigned char *bytes;
    size_t size;
    const char *guid;
    ovk_model M;
    void *arrays[38]; /* the 25 arrays of ovk_model, the 10 of its redundancy block, the 3 of its inputs */
    int nalt;         /* redundancy: the models of the parameter's other methods */
    int alt_code[2];  /* their OVK_ELIMINATE, OVK_MIN_NORM or OVK_COMPLIANT */
    ovk_model alt[2];
    void *alt_arrays[2][38];
    int n, nh, ny, quaternion;
    double start_time, stop_time, *y0;
    int me;               /* Model Exchange offered: the variables have the continuous states */
    int nout, nstate_out; /* outputs; the first nstate_out come from the state alone */
    int energy;           /* energy outputs: the run keeps the work ledger */
    fmu_out *out;
    int nvar, nparam, nmsg;
    fmu_var *var;
    fmu_param *par;
    int *msg_status;
    const char **msg;
} fmu_model;

FMU_HIDDEN int fmu_model_read(const char *path, fmu_model *fm, char *err, size_t errsize);
FMU_HIDDEN void fmu_model_free(fmu_model *fm);
FMU_HIDDEN const ovk_model *fmu_model_for(const fmu_model *fm, int code);

enum { M_INSTANTIATED = 1, M_INITIALIZATION = 2, M_STEPPING = 4, M_ERROR = 8, M_TERMINATED = 16, M_EVENT = 32,
       M_CONTINUOUS = 64 }; /* M_STEPPING: co-simulation; M_EVENT, M_CONTINUOUS: Model Exchange */
/* The modes in which a call is allowed: the co-simulation modes, or Model Exchange's in its place. */
#define FMU_RUNNING(c) ((c)->me ? M_EVENT | M_CONTINUOUS : M_STEPPING)
#define FMU_READABLE(c) (M_INITIALIZATION | FMU_RUNNING(c) | M_ERROR | M_TERMINATED)
#define FMU_WRITABLE(c) (M_INSTANTIATED | M_INITIALIZATION | FMU_RUNNING(c))
#define FMU_ANY_MODE(c) (M_INSTANTIATED | M_INITIALIZATION | FMU_RUNNING(c) | M_ERROR | M_TERMINATED)
enum { CAT_EVENTS, CAT_WARNING, CAT_ERROR, CAT_FATAL, N_CATEGORIES };
#define FMU_MSG 1024

/* Everything an FMU state holds: the mode, parameters, time, outputs and the run's bytes (their
 * layout, checks and copies: the table STATE_FIELDS of fmu_state.c, one line per field). */
typedef struct fmu_saved {
    struct fmu_saved *next;
    int mode, tol_source, have_outputs, derived_stale, has_y, has_sim, has_failed;
    double start_time, t, stable_step;
    double *pval;       /* nparam */
    int *pset;          /* nparam: set by the host */
    double *outputs, *y; /* nout, ny */
    double *uval;       /* 2 nu: the inputs as the host set them (fmu_inst.uval) */
    int u_dirty, u_pending; /* fmu_inst.u_dirty, u_pending */
    unsigned char *sim; /* the run's state bytes */
    size_t sim_size;
} fmu_saved;

typedef struct {
    fmu_model fm;
    char *name;
    fmi2CallbackLogger logger;
    fmi3LogMessageCallback log3; /* FMI 3.0's logger (instead of logger) */
    fmi2ComponentEnvironment env;
    int fmi3;           /* instantiated through the FMI 3.0 functions (their names in messages) */
    int me;             /* instantiated for Model Exchange: y is the host's state x at time t */
    int dx_valid;       /* dx (and, in Model Exchange, the outputs) belong to the current (t, y) */
    double *dx;         /* ny: the derivatives at (t, y) (fmu_me.c) */
    int *along;         /* nj: the joints' verdicts read by fmu_along_value (made once, not per read) */
    int enabled[N_CATEGORIES];
    ovk_model M;        /* fm.M with the parameters' values (jlawp, baumgarte, tol, max_iter) */
    double *jlawp;      /* nj x NLP: the friction laws with the parameters */
    ovk_sim *sim;
    int sim_valid;      /* sim was made with the current parameters and start time */
    double *pval;       /* nparam: numbers; strings as the index of the choice */
    int *pset;
    int tol_source;     /* 0 the scene, 1 the parameter, 2 fmi2SetupExperiment */
    int mode, have_outputs, derived_stale, derived_read, has_y, has_failed;
    double start_time, t, stable_step;
    double *outputs, *y, *reac, *fric; /* nout, ny, nj x OVK_NREAC, nj */
    const char **strings; /* fmi2GetString results (choices: static for the instance's life) */
    fmu_saved *states;
    char msg[FMU_MSG];
    int events_logged;  /* events of the run already logged (fmu_run.c) */
    double *uval;       /* 2 nu + 1: the inputs' values and first derivatives as the host set them (the
                         * derivatives for the next communication step only) */
    int u_dirty;        /* uval changed by the host since the run last took them (fmu_apply_inputs) */
    int u_pending;      /* co-simulation: the last step ran with derivatives, the next holds (fmu_do_step) */
} fmu_inst;

FMU_HIDDEN void fmu_log(fmu_inst *c, fmi2Status status, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
FMU_HIDDEN void fmu_repr(double x, char *buf, size_t size);
FMU_HIDDEN void fmu_init_fields(fmu_inst *c);
FMU_HIDDEN int fmu_apply_params(fmu_inst *c);
FMU_HIDDEN int fmu_read_derived(fmu_inst *c);
FMU_HIDDEN int fmu_ensure_sim(fmu_inst *c, int compute_outputs);
FMU_HIDDEN int fmu_allowed(fmu_inst *c, const char *fn, int modes);
FMU_HIDDEN int fmu_along_value(fmu_inst *c, int arg, double *out);

/* fmu_inst.c */
FMU_HIDDEN fmu_inst *fmu_checked(fmi2Component comp, const char *fn);
FMU_HIDDEN int fmu_resource_dir(const char *uri, char *out, size_t size);
FMU_HIDDEN fmu_inst *fmu_instantiate(const fmu_inst *tmp, const char *fn, const char *resources, const char *guid,
                                     int logging_on);
FMU_HIDDEN void fmu_free_inst(fmu_inst *c);
FMU_HIDDEN void fmu_default_categories(fmu_inst *c, int logging_on);
FMU_HIDDEN int fmu_set_debug_logging(fmu_inst *c, const char *fn, int logging_on, size_t n,
                                     const char *const categories[]);
/* fmu_run.c */
FMU_HIDDEN int fmu_param_index(const fmu_model *fm, int target, int joint);
FMU_HIDDEN double fmu_param_value(const fmu_inst *c, int target);
FMU_HIDDEN const char *fmu_choice(const fmu_inst *c, int target);
FMU_HIDDEN void fmu_state_outputs(const fmu_inst *c, const double *y, double *out);
FMU_HIDDEN int fmu_derived_outputs(fmu_inst *c, double t, const double *y, const double *lam, double *out);
FMU_HIDDEN int fmu_all_finite(const double *a, int n);
FMU_HIDDEN fmi2Status fmu_host_tolerance(fmu_inst *c, const char *fn, double tolerance);
FMU_HIDDEN fmi2Status fmu_setup(fmu_inst *c, const char *fn, int toleranceDefined, double tolerance, double startTime,
                                int stopTimeDefined, double stopTime);
FMU_HIDDEN fmi2Status fmu_exit_init(fmu_inst *c, const char *fn);
FMU_HIDDEN fmi2Status fmu_do_step(fmu_inst *c, const char *fn, double t, double h);
/* fmu_vars.c */
FMU_HIDDEN extern const char *fmu_causality_names[5];
FMU_HIDDEN extern const char *fmu_variability_names[5];
FMU_HIDDEN int fmu_check_refs(fmu_inst *c, const char *fn, const fmi2ValueReference vr[], size_t nvr,
                              const void *values, int type);
FMU_HIDDEN int fmu_value_of(fmu_inst *c, const char *fn, const fmu_var *v, double *out);
FMU_HIDDEN int fmu_set_param(fmu_inst *c, const char *fn, int k, double x, const char *s);
FMU_HIDDEN int fmu_set_input(fmu_inst *c, const char *fn, int k, double x, int order);
FMU_HIDDEN int fmu_apply_inputs(fmu_inst *c, int at_step);
FMU_HIDDEN int fmu_param_refuses(const fmu_param *p, double x, const char *shown, char *why, size_t size);
/* fmu_state.c */
FMU_HIDDEN void fmu_saved_free(fmu_saved *s);
/* fmu_me.c: Model Exchange (and the derivative variables in co-simulation) */
FMU_HIDDEN int fmu_me_eval(fmu_inst *c);
FMU_HIDDEN fmi2Status fmu_me_set_time(fmu_inst *c, const char *fn, double t);
FMU_HIDDEN fmi2Status fmu_me_set_states(fmu_inst *c, const char *fn, const double x[], size_t n);
FMU_HIDDEN fmi2Status fmu_me_get_states(fmu_inst *c, const char *fn, double x[], size_t n);
FMU_HIDDEN fmi2Status fmu_me_get_derivatives(fmu_inst *c, const char *fn, double dx[], size_t n);
FMU_HIDDEN fmi2Status fmu_me_get_nominals(fmu_inst *c, const char *fn, double x[], size_t n);
FMU_HIDDEN fmi2Status fmu_me_event_indicators(fmu_inst *c, const char *fn, double z[], size_t n);
FMU_HIDDEN int fmu_me_needs_correction(const fmu_inst *c);
FMU_HIDDEN int fmu_me_correct(fmu_inst *c);
FMU_HIDDEN fmi2Status fmu_state_get(fmu_inst *c, const char *fn, fmi2FMUstate *state);
FMU_HIDDEN fmi2Status fmu_state_set(fmu_inst *c, const char *fn, fmi2FMUstate state);
FMU_HIDDEN fmi2Status fmu_state_free(fmu_inst *c, const char *fn, fmi2FMUstate *state);
FMU_HIDDEN fmi2Status fmu_state_size(fmu_inst *c, const char *fn, fmi2FMUstate state, size_t *size);
FMU_HIDDEN fmi2Status fmu_state_serialize(fmu_inst *c, const char *fn, fmi2FMUstate state, fmi2Byte bytes[],
                                          size_t size);
FMU_HIDDEN fmi2Status fmu_state_deserialize(fmu_inst *c, const char *fn, const fmi2Byte bytes[], size_t size,
                                            fmi2FMUstate *state);

#endif
