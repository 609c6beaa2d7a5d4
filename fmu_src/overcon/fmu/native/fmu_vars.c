/* Variable access shared by the FMI versions, with the checks of overcon.fmu.slave (_refs, _get,
 * _set_param): an unknown reference or one of another type, or a parameter value outside its rule,
 * is refused with the reason, and nothing is set. fmi2_vars.c and fmi3_vars.c convert the values
 * of their version's types. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"

static const char *type_names[4] = {"Real", "Integer", "Boolean", "String"};
const char *fmu_causality_names[5] = {"output", "parameter", "local", "independent", "input"};
const char *fmu_variability_names[5] = {"continuous", "constant", "fixed", "tunable", "discrete"};

/* The references checked: each exists and has type `type`; 0 with the refusal logged. */
int fmu_check_refs(fmu_inst *c, const char *fn, const fmi2ValueReference vr[], size_t nvr, const void *values,
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
int fmu_value_of(fmu_inst *c, const char *fn, const fmu_var *v, double *out) {
    if (v->key == K_OUTPUT && c->me && (c->mode & (M_EVENT | M_CONTINUOUS | M_TERMINATED | M_ERROR))) {
        if (!fmu_me_eval(c)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), 0;
        *out = c->outputs[v->arg];
    } else if (v->key == K_STATE) {
        if (!c->has_y && !fmu_ensure_sim(c, 1)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), 0;
        *out = c->y[v->arg];
    } else if (v->key == K_DERIVATIVE) {
        if (!c->has_y && !fmu_ensure_sim(c, 1)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), 0;
        if (!fmu_me_eval(c)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), 0;
        *out = c->dx[v->arg];
    } else if (v->key == K_OUTPUT) {
        if (!c->have_outputs && !fmu_ensure_sim(c, 1)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), 0;
        if (v->arg >= c->fm.nstate_out && !fmu_read_derived(c)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), 0;
        *out = c->outputs[v->arg];
    } else if (v->key == K_CONSTANT) {
        *out = v->arg;
    } else if (v->key == K_TIME) {
        *out = c->t;
    } else if (v->key == K_STABLE_STEP) {
        *out = c->stable_step;
    } else if (v->key == K_INPUT) {
        *out = c->uval[v->arg];
    } else if (v->key == K_ALONG) {
        if (!fmu_along_value(c, v->arg, out)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), 0;
    } else {
        *out = c->pval[v->arg];
    }
    return 1;
}

/* Input k set to x (order 0) or its first derivative (order 1, co-simulation: over the next
 * communication step); the run takes them when it next needs them (fmu_apply_inputs). 0 with the
 * refusal logged: a value that is not finite. */
int fmu_set_input(fmu_inst *c, const char *fn, int k, double x, int order) {
    int nu = c->fm.M.nu;
    if (!isfinite(x)) {
        char shown[40];
        fmu_repr(x, shown, sizeof shown);
        for (int v = 0; v < c->fm.nvar; v++)
            if (c->fm.var[v].key == K_INPUT && c->fm.var[v].arg == k)
                return fmu_log(c, fmi2Error, "%s: input %s = %s refused: must be finite", fn, c->fm.var[v].name,
                               shown), 0;
        return fmu_log(c, fmi2Error, "%s: input %d = %s refused: must be finite", fn, k, shown), 0;
    }
    c->uval[order ? nu + k : k] = x;
    c->u_dirty = 1;
    if (c->have_outputs) c->derived_stale = c->fm.nout > c->fm.nstate_out; /* outputs that depend on them */
    c->dx_valid = 0;
    return 1;
}

/* The inputs as the host set them given to the run (Model Exchange: at the current time, held;
 * co-simulation: from the current communication point, with the derivatives set for the step),
 * when the host set any since the run last took them, or at_step (fmi2DoStep) after a step that
 * ran with derivatives: the next holds the values unless new derivatives are set. Reading outputs
 * between steps takes only the host's new values (the outputs after a step see the step's).
 * 0 with the reason in c->msg. */
int fmu_apply_inputs(fmu_inst *c, int at_step) {
    int nu = c->fm.M.nu;
    if (!nu || !c->sim || !(c->u_dirty || (at_step && c->u_pending))) return 1;
    int status = c->me ? ovk_set_inputs(&c->M, c->sim->d, c->uval, NULL, c->t)
                       : ovk_sim_set_inputs(c->sim, c->uval, c->uval + nu);
    if (status)
        return snprintf(c->msg, sizeof c->msg, "SimulationError: %s", c->me ? ovk_message(c->sim->d)
                                                                             : ovk_sim_message(c->sim)), 0;
    c->u_dirty = c->u_pending = 0;
    return 1;
}

/* The one rule check of a parameter's value (overcon.params.Rule.check), shared by the setters
 * (fmu_set_param) and the FMU state's validator (fmu_state.c): a number not finite or outside its
 * range, an Integer that is not integral, a choice whose index (strings are held as the index of
 * the choice) is none of the choices. The reason into why (shown: the value as the caller words
 * it), 1; or 0 when the rule accepts x. The cross rule mu_static >= mu is checked by the setter of
 * mu_static and, for any source of values, when the run is made (fmu_apply_params). */
int fmu_param_refuses(const fmu_param *p, double x, const char *shown, char *why, size_t size) {
    if (p->rule == RULE_CHOICE) {
        if (x >= 0 && x < p->nchoices && x == floor(x)) return 0;
        size_t len = (size_t)snprintf(why, size, "must be one of ");
        for (int i = 0; i < p->nchoices && len < size; i++)
            len += (size_t)snprintf(why + len, size - len, "%s%s", i ? ", " : "", p->choices[i]);
        if (len < size) snprintf(why + len, size - len, ", got %s", shown);
        return 1;
    }
    if (!isfinite(x)) return snprintf(why, size, "must be finite, got %s", shown), 1;
    if ((p->type == T_INTEGER || p->rule == RULE_INT) && (x != floor(x) || x < -2147483648.0 || x > 2147483647.0))
        return snprintf(why, size, "must be an integer, got %s", shown), 1;
    int low = p->has_lo && (p->low_open ? x <= p->lo : x < p->lo), high = p->has_hi && x > p->hi;
    if (!low && !high) return 0;
    snprintf(why, size, "must be %s, got %s%s%s%s", p->range_text, shown, p->why[0] ? " (" : "", p->why,
             p->why[0] ? ")" : "");
    return 1;
}

/* One parameter set to x (strings: the text s) as overcon.fmu.slave._set_param; 0 with the
 * refusal logged. */
int fmu_set_param(fmu_inst *c, const char *fn, int k, double x, const char *s) {
    const fmu_param *p = &c->fm.par[k];
    char shown[600], why[900] = "";
    if (p->rule == RULE_CHOICE) snprintf(shown, sizeof shown, "'%s'", s ? s : "None");
    else if (p->type == T_INTEGER && x >= -2147483648.0 && x <= 2147483647.0) snprintf(shown, sizeof shown, "%d", (int)x);
    else fmu_repr(x, shown, sizeof shown);
    if ((c->mode & (M_STEPPING | M_EVENT | M_CONTINUOUS)) && !p->tunable)
        snprintf(why, sizeof why, "variability fixed: it cannot change after initialization (%sReset first)",
                 c->fmi3 ? "fmi3" : "fmi2");
    else if (p->rule == RULE_CHOICE && !s)
        snprintf(why, sizeof why, "a value is required");
    else {
        if (p->rule == RULE_CHOICE) {
            int found = -1;
            for (int i = 0; i < p->nchoices; i++)
                if (!strcmp(s, p->choices[i])) found = i;
            x = found;
        }
        if (!fmu_param_refuses(p, x, shown, why, sizeof why) && p->target == P_MU_STATIC)
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
