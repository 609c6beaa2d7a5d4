/* The run of an instance, whatever the FMI version: the parameters applied to the packed model and
 * the run's options, the run made when first needed (outputs read in initialization mode, leaving
 * initialization mode), the outputs at a communication point, the host tolerance rule, the end of
 * initialization and one communication step (overcon.fmu.slave: _ensure_sim, _host_tolerance,
 * _step). The FMI functions of each version (fmi2_run.c, fmi3_run.c) call these. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"

#define LIFE_MAX_STEPS 1000000   /* overcon.simulate.MAX_STEPS */
#define LIFE_MAX_WALL_TIME 3600.0 /* overcon.simulate.MAX_WALL_TIME */

int fmu_param_index(const fmu_model *fm, int target, int joint) {
    for (int k = 0; k < fm->nparam; k++)
        if (fm->par[k].target == target && fm->par[k].joint == joint) return k;
    return -1;
}

double fmu_param_value(const fmu_inst *c, int target) {
    int k = fmu_param_index(&c->fm, target, -1);
    return k < 0 ? 0.0 : c->pval[k];
}

const char *fmu_choice(const fmu_inst *c, int target) {
    int k = fmu_param_index(&c->fm, target, -1);
    if (k < 0) return "";
    const fmu_param *p = &c->fm.par[k];
    double x = c->pval[k]; /* checked before it converts: a value of a state is checked too (fmu_state.c) */
    return x >= 0 && x < p->nchoices ? p->choices[(int)x] : "";
}

/* The packed model with the parameters' values: the friction laws (jlawp), the Baumgarte
 * frequency and the friction solve's tolerance and iteration limit; 0 and the reason in c->msg
 * when a Stribeck law's mu_static is below its mu (overcon.params.check_mu_static). */
int fmu_apply_params(fmu_inst *c) {
    const fmu_model *fm = &c->fm;
    int red = fmu_param_index(fm, P_REDUNDANCY, -1); /* redundancy: the model of the method the parameter names */
    double code = red < 0 ? 0.0 : c->pval[red]; /* the choice's index, range-checked before it converts */
    c->M = *fmu_model_for(fm, code >= 0 && code < FMU_MAX_CHOICES ? (int)code - 1 : -1);
    memcpy(c->jlawp, fm->M.jlawp, (size_t)fm->M.nj * NLP * sizeof(double));
    for (int k = 0; k < fm->nparam; k++) {
        const fmu_param *p = &fm->par[k];
        if (p->target >= P_MU && p->target <= P_VSTRIBECK) {
            static const int slot[5] = {0, 0, 1, 3, 4};
            c->jlawp[p->joint * NLP + slot[p->target]] = c->pval[k];
        }
    }
    for (int j = 0; j < fm->M.nj; j++)
        if (fm->M.jlaw[j] == LAW_STRIBECK && c->jlawp[j * NLP + 3] < c->jlawp[j * NLP]) {
            int k = fmu_param_index(fm, P_MU_STATIC, j);
            char a[40], b[40];
            fmu_repr(c->jlawp[j * NLP], a, sizeof a);
            fmu_repr(c->jlawp[j * NLP + 3], b, sizeof b);
            snprintf(c->msg, sizeof c->msg, "parameter %s refused: must be >= mu (%s), got %s",
                     k >= 0 ? fm->par[k].name : "mu_static", a, b);
            return 0;
        }
    c->M.jlawp = c->jlawp;
    c->M.baumgarte = fmu_param_value(c, P_BAUMGARTE);
    c->M.tol = fmu_param_value(c, P_FRICTION_TOL);
    double iter = fmu_param_value(c, P_FRICTION_MAX_ITER); /* the rule's 1 to 1000, checked before it converts */
    c->M.max_iter = iter >= 1 && iter <= 1e6 ? (int)iter : fm->M.max_iter;
    return 1;
}

/* The outputs of the state alone (positions, quaternions as e / |e|, velocities) into out
 * (core/sim_out.c). */
void fmu_state_outputs(const fmu_inst *c, const double *y, double *out) {
    ovk_state_outputs(&c->M, c->fm.out, c->fm.nstate_out, y, out);
}

/* The energies, reactions and friction forces at (t, y) into out (core/sim_out.c: each only when an
 * output needs it); with lam (Model Exchange) the reactions and friction forces of those
 * multipliers, the evaluation at (t, y) that gave the derivatives. A status on failure, its message
 * in the run's. */
int fmu_derived_outputs(fmu_inst *c, double t, const double *y, const double *lam, double *out) {
    const fmu_model *fm = &c->fm;
    return ovk_sim_derived_outputs(c->sim, fm->out + fm->nstate_out, fm->nout - fm->nstate_out, t, y, lam, c->reac,
                                   c->fric, out + fm->nstate_out);
}

int fmu_all_finite(const double *a, int n) {
    for (int k = 0; k < n; k++)
        if (!isfinite(a[k])) return 0;
    return 1;
}

/* A joint's law exerts no friction at all: mu = 0 and mu_static 0 (overcon.precheck.frictionless). */
static int frictionless(const double *lp) { return lp[0] == 0.0 && lp[3] == 0.0; }

/* The warning of a run whose parameters switch a joint's friction between mu = 0 and mu > 0: the
 * build's pre-check verdict (motion_unique) may not hold for it (overcon.fmu.slave._model_for). */
static void warn_switched(fmu_inst *c) {
    const fmu_model *fm = &c->fm;
    char names[FMU_MSG] = "";
    size_t len = 0;
    for (int k = 0; k < fm->nparam; k++) {
        const fmu_param *p = &fm->par[k];
        int j = p->joint;
        if (p->target != P_MU || frictionless(fm->M.jlawp + j * NLP) == frictionless(c->jlawp + j * NLP)) continue;
        size_t base = strlen(p->name) > 3 ? strlen(p->name) - 3 : 0; /* the joint's name: "<joint>.mu" */
        if (len + base + 3 < sizeof names)
            len += (size_t)snprintf(names + len, sizeof names - len, "%s%.*s", len ? ", " : "", (int)base, p->name);
    }
    if (len)
        fmu_log(c, fmi2Warning, "friction in joint(s) %s switched between mu = 0 and mu > 0 by the parameters: the "
                "constant motion_unique (the pre-check at the build's parameters) may not hold for this run; run "
                "overcon check with these values", names);
}

/* The run with the current parameters and start time (made if needed); with compute_outputs the
 * outputs at the current time too. 0 and the reason in c->msg on failure. */
int fmu_ensure_sim(fmu_inst *c, int compute_outputs) {
    const fmu_model *fm = &c->fm;
    if (!c->sim_valid) {
        ovk_sim_free(c->sim);
        c->sim = NULL;
        c->have_outputs = 0;
        if (!fmu_apply_params(c)) return 0;
        warn_switched(c);
        const char *method = fmu_choice(c, P_METHOD);
        int m = !strcmp(method, "dopri5") ? OVK_METHOD_DOPRI5 : !strcmp(method, "rk4") ? OVK_METHOD_RK4
              : !strcmp(method, "dop853") ? OVK_METHOD_DOP853 : !strcmp(method, "radau") ? OVK_METHOD_RADAU : -1;
        if (m < 0)
            return snprintf(c->msg, sizeof c->msg, "solver.method = '%s' is not available in this FMU (it runs "
                            "without Python: dopri5, dop853, rk4 and radau)", method), 0;
        ovk_sim_opts o = {{m, 1, fmu_param_value(c, P_TOLERANCE), fmu_param_value(c, P_MAX_STEP), 0.0, fmu_param_value(c, P_STEP)},
                          LIFE_MAX_STEPS, LIFE_MAX_WALL_TIME, 1e-6, fm->stop_time, fm->energy};
        c->sim = ovk_sim_new(&c->M, &o, c->start_time, fm->y0);
        if (!c->sim) return snprintf(c->msg, sizeof c->msg, "MemoryError: out of memory"), 0;
        if (ovk_sim_status(c->sim)) {
            snprintf(c->msg, sizeof c->msg, "SimulationError: %s", ovk_sim_message(c->sim));
            ovk_sim_free(c->sim);
            c->sim = NULL;
            return 0;
        }
        c->sim_valid = 1;
        c->u_dirty = 1; /* the inputs as set so far (their start values otherwise) */
        if (!fmu_apply_inputs(c, 1)) return 0;
        c->events_logged = 0;
        c->dx_valid = 0;
        c->t = c->start_time;
    }
    if (compute_outputs && !c->have_outputs) {
        int status = ovk_sim_advance(c->sim, c->t, -1, 0.0, c->y);
        fmu_state_outputs(c, c->y, c->outputs);
        if (!status) status = fmu_derived_outputs(c, c->t, c->y, NULL, c->outputs);
        if (status) return snprintf(c->msg, sizeof c->msg, "SimulationError: %s", ovk_sim_message(c->sim)), 0;
        if (!fmu_all_finite(c->outputs, fm->nout)) {
            char t[40];
            fmu_repr(c->t, t, sizeof t);
            return snprintf(c->msg, sizeof c->msg, "ArithmeticError: non-finite initial outputs at t = %s s", t), 0;
        }
        c->have_outputs = c->has_y = 1;
        c->derived_stale = 0;
    }
    return 1;
}

/* The host reads a reaction or friction output: computed at the current point if the last step
 * skipped them, and in every later step. 0 with the reason in c->msg on failure. */
int fmu_read_derived(fmu_inst *c) {
    c->derived_read = 1;
    if (!fmu_apply_inputs(c, 0)) return 0;
    if (!c->derived_stale) return 1;
    if (!c->sim) return snprintf(c->msg, sizeof c->msg, "reactions and friction forces: no run to compute them"), 0;
    int status = fmu_derived_outputs(c, c->t, c->y, NULL, c->outputs);
    if (status || !fmu_all_finite(c->outputs, c->fm.nout)) {
        char t[40];
        fmu_repr(c->t, t, sizeof t);
        return snprintf(c->msg, sizeof c->msg, "reactions and friction forces at t = %s s could not be computed: %s",
                        t, status ? ovk_sim_message(c->sim) : "ArithmeticError: non-finite values"), 0;
    }
    c->derived_stale = 0;
    return 1;
}

/* fmi2SetupExperiment's tolerance (overcon.fmu.slave._host_tolerance): the parameter set by the
 * host wins; one outside the parameter's range is not used (fmi2Warning). */
fmi2Status fmu_host_tolerance(fmu_inst *c, const char *fn, double tolerance) {
    int k = fmu_param_index(&c->fm, P_TOLERANCE, -1);
    char tol[40], cur[40];
    fmu_repr(tolerance, tol, sizeof tol);
    if (k < 0) return fmi2OK;
    const fmu_param *p = &c->fm.par[k];
    fmu_repr(c->pval[k], cur, sizeof cur);
    if (c->pset[k]) {
        fmu_log(c, fmi2OK, "%s: tolerance %s not used: the host set the parameter solver.tolerance "
                "= %s, which wins", fn, tol, cur);
        return fmi2OK;
    }
    if (!isfinite(tolerance) || tolerance < p->lo || tolerance > p->hi) {
        fmu_log(c, fmi2Warning, "%s: tolerance %s not used (%s %s, got %s%s%s%s); the integrator "
                "uses solver.tolerance = %s", fn, tol, isfinite(tolerance) ? "must be" : "must be finite,",
                isfinite(tolerance) ? p->range_text : "", tol, p->why[0] ? " (" : "", p->why, p->why[0] ? ")" : "",
                cur);
        return fmi2Warning;
    }
    c->pval[k] = tolerance;
    c->tol_source = 2;
    fmu_log(c, fmi2OK, "%s: tolerance %s used as solver.tolerance%s", fn, tol,
            !strcmp(fmu_choice(c, P_METHOD), "rk4") ? " (the fixed-step method rk4 does not use it)" : "");
    return fmi2OK;
}

/* The outputs at t_new after a successful advance; 0 with the reason in c->msg. */
static int step_outputs(fmu_inst *c, double t_new, const double *y, double *out) {
    const fmu_model *fm = &c->fm;
    memcpy(out, c->outputs, (size_t)fm->nout * sizeof(double));
    fmu_state_outputs(c, y, out);
    if ((c->derived_read || fm->nout == fm->nstate_out) && fmu_derived_outputs(c, t_new, y, NULL, out))
        return snprintf(c->msg, sizeof c->msg, "SimulationError: %s", ovk_sim_message(c->sim)), 0;
    if (!fmu_all_finite(out, fm->nout)) {
        size_t len = (size_t)snprintf(c->msg, sizeof c->msg, "ArithmeticError: t = %.9g s: non-finite outputs", t_new);
        for (int k = 0, first = 1; k < fm->nout && len < sizeof c->msg; k++)
            if (!isfinite(out[k]))
                for (int v = 0; v < fm->nvar; v++)
                    if (fm->var[v].key == K_OUTPUT && fm->var[v].arg == k) {
                        len += (size_t)snprintf(c->msg + len, sizeof c->msg - len, "%s%s", first ? " " : ", ",
                                                fm->var[v].name);
                        first = 0;
                    }
        return 0;
    }
    return 1;
}

/* The value of a variable of key K_ALONG (arg: 0 rank, 1 motion_unique, 2 + j joint j's
 * reaction_unique): the run's last judgement of the uniqueness along the motion (core/watch.c),
 * the run made first when there is none; 0 with the reason in c->msg. */
int fmu_along_value(fmu_inst *c, int arg, double *out) {
    if (!c->sim_valid && !fmu_ensure_sim(c, 0)) return 0;
    int nj = c->fm.M.nj, rank = 0, motion = ovk_sim_uniqueness(c->sim, &rank, c->along);
    *out = arg == 0 ? rank : arg == 1 ? motion : arg - 2 < nj ? c->along[arg - 2]
           : ovk_sim_effort_unique(c->sim) == 1; /* 2 + nj: effort_unique */
    return 1;
}

/* The core's text with its "joints[k]" (a friction joint, numbered) named by the joint's
 * "<joint>.reaction_unique" variable, as the Python runtime words it. */
static void named(const fmu_inst *c, const char *in, char *out, size_t size) {
    size_t len = 0;
    for (const char *p = in; *p && len + 1 < size;) {
        int j = -1, used = 0, done = 0;
        if (sscanf(p, "joints[%d]%n", &j, &used) == 1 && used > 0 && p[used - 1] == ']')
            for (int v = 0; v < c->fm.nvar && !done; v++)
                if (c->fm.var[v].key == K_ALONG && c->fm.var[v].arg == 2 + j) {
                    const char *name = c->fm.var[v].name;
                    int n = (int)(strlen(name) - strlen(".reaction_unique"));
                    int w = snprintf(out + len, size - len, "%.*s", n, name);
                    len = w < 0 || (size_t)w >= size - len ? size - 1 : len + (size_t)w;
                    p += used;
                    done = 1;
                }
        if (!done) out[len++] = *p++;
    }
    out[len] = '\0';
}

/* Logs the run's events not logged yet (category logEvents, as overcon.fmu.slave._log_events:
 * "t = <t> s: event <kind>: <detail>"); the stop of a failed step is logged with its error. */
static void log_events(fmu_inst *c) {
    static const char *kinds[5] = {"singular", "elimination-reselected", "rank-change", "uniqueness-change",
                                   "stopped"};
    int count = ovk_sim_events(c->sim);
    for (; c->events_logged < count; c->events_logged++) {
        double t = 0.0;
        int kind = 0;
        const char *detail = ovk_sim_event(c->sim, c->events_logged, &t, &kind);
        if (!detail || kind < 0 || kind > 4 || kind == OVK_EV_STOPPED) continue;
        char text[FMU_MSG];
        named(c, detail, text, sizeof text);
        fmu_log(c, fmi2OK, "t = %.9g s: event %s: %s", t, kinds[kind], text);
    }
}

/* The step itself (overcon.fmu.slave._step): 0 with the reason in c->msg. */
static int step(fmu_inst *c, double t, double h, double *y) {
    char a[40], b[40]; /* the numbers of a message, formatted only when there is one (a repr costs µs) */
    if (!(isfinite(t) && isfinite(h) && h >= 0))
        return snprintf(c->msg, sizeof c->msg, "the communication step must be finite and >= 0"), 0;
    if (fabs(t - c->t) > 1e-9 * (fabs(c->t) > 1.0 ? fabs(c->t) : 1.0)) {
        fmu_repr(t, a, sizeof a);
        fmu_repr(c->t, b, sizeof b);
        return snprintf(c->msg, sizeof c->msg, "communication point %s s is not the end of the previous step (%s s)",
                        a, b), 0;
    }
    if (h > 0 && t + h == t) { /* the step would return OK without advancing */
        fmu_repr(t, a, sizeof a);
        fmu_repr(h, b, sizeof b);
        return snprintf(c->msg, sizeof c->msg, "the communication step %s s is below the resolution of the time %s s "
                        "(t + h rounds to t)", b, a), 0;
    }
    if (!c->sim_valid && !fmu_ensure_sim(c, 1)) return 0;
    double steps = fmu_param_value(c, P_MAX_INTERNAL_STEPS); /* the rule's 1 to 1e8: range-checked before it converts */
    long long max_steps = steps >= 0 && steps <= 1e15 ? (long long)steps : 0;
    double max_wall = fmu_param_value(c, P_MAX_WALL_TIME);
    if (c->events_logged > ovk_sim_events(c->sim)) c->events_logged = ovk_sim_events(c->sim); /* a restored state */
    int status = ovk_sim_advance(c->sim, t + h, max_steps, max_wall, y);
    log_events(c);
    if (status == OVK_BUDGET) {
        const char *m = ovk_sim_message(c->sim), *lead = "integration stopped: ";
        if (!strncmp(m, lead, strlen(lead))) m += strlen(lead);
        fmu_repr(max_wall, b, sizeof b);
        return snprintf(c->msg, sizeof c->msg, "BudgetExhausted: work budget exhausted in this doStep "
                        "(solver.max_internal_steps = %lld, solver.max_wall_time = %s s): %s; raise them or use "
                        "shorter communication steps", max_steps, b, m), 0;
    }
    if (status == OVK_UNSTABLE) {
        double info[OVK_SIM_NINFO];
        ovk_sim_info(c->sim, info);
        c->stable_step = info[9];
    }
    if (status) {
        char text[FMU_MSG];
        named(c, ovk_sim_message(c->sim), text, sizeof text);
        return snprintf(c->msg, sizeof c->msg, "SimulationError: %.1000s", text), 0; /* cut as the core cuts its own */
    }
    return 1;
}

/* The experiment's start time, stop time and tolerance (fn: fmi2SetupExperiment,
 * fmi3EnterInitializationMode): a start time that is not finite or a stop time before it refused. */
fmi2Status fmu_setup(fmu_inst *c, const char *fn, int toleranceDefined, double tolerance, double startTime,
                     int stopTimeDefined, double stopTime) {
    char a[40], b[40];
    fmu_repr(startTime, a, sizeof a);
    fmu_repr(stopTime, b, sizeof b);
    if (!isfinite(startTime)) {
        fmu_log(c, fmi2Error, "%s: start time %s refused (not finite)", fn, a);
        return fmi2Error;
    }
    if (stopTimeDefined && !(stopTime >= startTime)) {
        fmu_log(c, fmi2Error, "%s: stop time %s is before the start time %s", fn, b, a);
        return fmi2Error;
    }
    c->start_time = startTime;
    c->sim_valid = c->have_outputs = 0;
    return toleranceDefined ? fmu_host_tolerance(c, fn, tolerance) : fmi2OK;
}

/* The end of initialization (fn: the FMI call): the run made and the outputs computed, the choice of
 * tolerance logged; fmi2Error with the reason when the run cannot start. */
fmi2Status fmu_exit_init(fmu_inst *c, const char *fn) {
    if (!fmu_ensure_sim(c, 1)) {
        c->mode = M_ERROR;
        fmu_log(c, fmi2Error, "%s: initialization failed: %s", fn, c->msg);
        return fmi2Error;
    }
    c->mode = c->me ? M_EVENT : M_STEPPING;
    const char *sources[3] = {"the scene", "the parameter solver.tolerance",
                              c->fmi3 ? "fmi3EnterInitializationMode" : "fmi2SetupExperiment"};
    char t[40], tol[40];
    fmu_repr(c->t, t, sizeof t);
    fmu_repr(fmu_param_value(c, P_TOLERANCE), tol, sizeof tol);
    if (c->me)
        fmu_log(c, fmi2OK, "initialized at t = %s s for Model Exchange: the host integrates; right-hand side: the "
                "compiled core in this FMU's binary (no Python), the friction solve started cold at every (t, x)", t);
    else
        fmu_log(c, fmi2OK, "initialized at t = %s s: method %s, tolerance %s (from %s); right-hand side and "
                "integrator: the compiled core in this FMU's binary (no Python)", t, fmu_choice(c, P_METHOD), tol,
                sources[c->tol_source]);
    if (strcmp(fmu_choice(c, P_KERNEL), "numpy") == 0)
        fmu_log(c, fmi2Warning, "solver.kernel = 'numpy' cannot be honoured: this FMU runs without Python, on the "
                "compiled core");
    return fmi2OK;
}

/* One communication step from currentCommunicationPoint over communicationStepSize (fn: the FMI
 * call): the run advanced and the outputs computed; on failure the instance in the error mode and
 * the reason logged. */
fmi2Status fmu_do_step(fmu_inst *c, const char *fn, double currentCommunicationPoint, double communicationStepSize) {
    const fmu_model *fm = &c->fm;
    double t_new = currentCommunicationPoint + communicationStepSize;
    double *y = malloc(((size_t)fm->ny + (size_t)fm->nout + 1) * sizeof(double));
    int ok = y != NULL;
    if (!ok) snprintf(c->msg, sizeof c->msg, "MemoryError: out of memory");
    ok = ok && fmu_apply_inputs(c, 1) && step(c, currentCommunicationPoint, communicationStepSize, y);
    double *out = y ? y + fm->ny : NULL;
    ok = ok && step_outputs(c, t_new, y, out);
    if (!ok) {
        char a[40], b[40], t[40];
        fmu_repr(currentCommunicationPoint, a, sizeof a);
        fmu_repr(communicationStepSize, b, sizeof b);
        fmu_repr(c->t, t, sizeof t);
        c->mode = M_ERROR;
        c->has_failed = 1;
        fmu_log(c, fmi2Error, "%s(%s, %s): %s; the run stopped at t = %s s (the outputs keep their values "
                "there; %s to continue)", fn, a, b, c->msg, t,
                c->fmi3 ? "fmi3SetFMUState or fmi3Reset" : "fmi2SetFMUstate or fmi2Reset");
        free(y);
        return fmi2Error;
    }
    memcpy(c->outputs, out, (size_t)fm->nout * sizeof(double));
    memcpy(c->y, y, (size_t)fm->ny * sizeof(double));
    c->t = t_new;
    c->dx_valid = 0;
    c->have_outputs = c->has_y = 1;
    c->derived_stale = !c->derived_read && fm->nout > fm->nstate_out;
    for (int k = 0; k < fm->M.nu; k++) /* the derivatives were for this step: the next holds unless set again */
        if (c->uval[fm->M.nu + k] != 0.0) {
            c->uval[fm->M.nu + k] = 0.0;
            c->u_pending = 1;
        }
    free(y);
    return fmi2OK;
}
