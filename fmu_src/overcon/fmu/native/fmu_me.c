/* Model Exchange, whatever the FMI version: the continuous states are y = [q, h] of the core (q the
 * bodies' coordinates in m and rad, or quaternion components; h their velocities, planar [x', y',
 * phi'], spatial [v in the global frame, omega in the body's axes]), held in the instance's y at the
 * host's time t; their derivatives are one evaluation of Eq. 18 by the core (ovk_sim_solve).
 *
 * The friction solve of that evaluation starts cold (from the frictionless multipliers, no warm start)
 * at every (t, x): the derivative is a function of (t, x) alone, whatever the host evaluated before
 * (its step rejections, Jacobian perturbations, event iterations or restored FMU states). The outputs
 * (reactions, friction forces) are those of the same evaluation.
 *
 * No event indicators: the friction laws of the core (regularised, Stribeck) are continuous in the
 * sliding velocity (the law switches at no speed), so the right-hand side has no discontinuity to
 * locate. The quaternions' norm is held near 1 by the core's stabilisation term (QUAT_NORM_RATE);
 * fmi2/3CompletedIntegratorStep asks for an event once a norm is off by more than QUAT_RENORM_TOL,
 * and the event (fmu_me_correct) re-normalises them: continuous states change only in event mode. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fmu_common.h"

#define QUAT_RENORM_TOL 1e-6 /* | |e| - 1 | beyond which an event re-normalises a quaternion */
#define ME_DRIFT_TOL 1e-6    /* m or rad: max |Phi| beyond which an event projects the state onto the constraints
                              * (Baumgarte stabilisation keeps it far below at usual tolerances: rare events) */

/* The derivatives at (t, y) into dx, and in Model Exchange the outputs there; 0 with the reason
 * in c->msg. Computed once per (t, y). */
int fmu_me_eval(fmu_inst *c) {
    if (c->dx_valid) return 1;
    if (!c->sim_valid && !fmu_ensure_sim(c, 0)) return 0;
    if (!fmu_apply_inputs(c, 0)) return 0;
    const fmu_model *fm = &c->fm;
    ovk_hist cold = {0, {0.0, 0.0}, {NULL, NULL}}; /* no forces to extrapolate: a cold start */
    int its = 0, status = ovk_sim_solve(c->sim, c->t, c->y, &cold, NULL, c->dx, &its);
    if (status) return snprintf(c->msg, sizeof c->msg, "SimulationError: %s", ovk_sim_message(c->sim)), 0;
    if (c->me) {
        if (fm->energy)
            return snprintf(c->msg, sizeof c->msg, "the energy outputs are not available in Model Exchange "
                            "(build this scene with --kind cs)"), 0;
        fmu_state_outputs(c, c->y, c->outputs);
        if (fmu_derived_outputs(c, c->t, c->y, c->sim->ev_lam, c->outputs))
            return snprintf(c->msg, sizeof c->msg, "SimulationError: %s", ovk_sim_message(c->sim)), 0;
        if (!fmu_all_finite(c->outputs, fm->nout))
            return snprintf(c->msg, sizeof c->msg, "ArithmeticError: t = %.9g s: non-finite outputs", c->t), 0;
    }
    c->dx_valid = 1;
    return 1;
}

static int count_ok(fmu_inst *c, const char *fn, const void *a, size_t n, size_t want, const char *what) {
    if (n != want)
        return fmu_log(c, fmi2Error, "%s: %zu %s given, this FMU has %zu", fn, n, what, want), 0;
    if (n && !a) return fmu_log(c, fmi2Error, "%s: the array is NULL but n = %zu", fn, n), 0;
    return 1;
}

fmi2Status fmu_me_set_time(fmu_inst *c, const char *fn, double t) {
    if (!isfinite(t)) {
        char a[40];
        fmu_repr(t, a, sizeof a);
        return fmu_log(c, fmi2Error, "%s: time %s refused (not finite)", fn, a), fmi2Error;
    }
    if (t != c->t) c->dx_valid = 0;
    c->t = t;
    return fmi2OK;
}

fmi2Status fmu_me_set_states(fmu_inst *c, const char *fn, const double x[], size_t n) {
    if (!count_ok(c, fn, x, n, (size_t)c->fm.ny, "continuous states")) return fmi2Error;
    for (size_t i = 0; i < n; i++)
        if (!isfinite(x[i])) return fmu_log(c, fmi2Error, "%s: state %zu is not finite", fn, i), fmi2Error;
    if (memcmp(c->y, x, n * sizeof(double))) c->dx_valid = 0;
    memcpy(c->y, x, n * sizeof(double));
    c->has_y = 1;
    return fmi2OK;
}

fmi2Status fmu_me_get_states(fmu_inst *c, const char *fn, double x[], size_t n) {
    if (!count_ok(c, fn, x, n, (size_t)c->fm.ny, "continuous states")) return fmi2Error;
    if (!c->has_y && !fmu_ensure_sim(c, 1)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), fmi2Error;
    memcpy(x, c->y, n * sizeof(double));
    return fmi2OK;
}

fmi2Status fmu_me_get_derivatives(fmu_inst *c, const char *fn, double dx[], size_t n) {
    if (!count_ok(c, fn, dx, n, (size_t)c->fm.ny, "derivatives")) return fmi2Error;
    if (!c->has_y && !fmu_ensure_sim(c, 1)) return fmu_log(c, fmi2Error, "%s: %s", fn, c->msg), fmi2Error;
    if (!fmu_me_eval(c)) {
        char t[40];
        fmu_repr(c->t, t, sizeof t);
        return fmu_log(c, fmi2Error, "%s: the derivatives at t = %s s cannot be computed: %s", fn, t, c->msg),
               fmi2Error;
    }
    memcpy(dx, c->dx, n * sizeof(double));
    return fmi2OK;
}

/* Nominal values 1 (m, rad, m/s, rad/s, quaternion components): the scenes' lengths are of order
 * 1 m, and the co-simulation's integrator uses atol = rtol, which a host's atol = rtol x nominal
 * then matches. */
fmi2Status fmu_me_get_nominals(fmu_inst *c, const char *fn, double x[], size_t n) {
    if (!count_ok(c, fn, x, n, (size_t)c->fm.ny, "nominals")) return fmi2Error;
    for (size_t i = 0; i < n; i++) x[i] = 1.0;
    return fmi2OK;
}

fmi2Status fmu_me_event_indicators(fmu_inst *c, const char *fn, double z[], size_t n) {
    (void)z;
    return count_ok(c, fn, z, n, 0, "event indicators") ? fmi2OK : fmi2Error;
}

/* The constraint drift max |Phi| at the host's state (every equation; 0 under "compliant", whose
 * compliant equations are springs, not constraints, and when the rows cannot be evaluated: the
 * next derivative then says why). */
static double drift(const fmu_inst *c) {
    ovk_sim *s = c->sim;
    if (!s || s->M->redundancy == OVK_COMPLIANT || ovk_rows_in(s->M, s->d, c->y)) return 0.0;
    double worst = 0.0;
    for (int i = 0; i < s->M->m; i++) worst = fabs(s->d->phi[i]) > worst ? fabs(s->d->phi[i]) : worst;
    return worst;
}

/* 1 if a quaternion's norm is off by more than QUAT_RENORM_TOL, or the constraints by more than
 * ME_DRIFT_TOL (an event is to correct it). */
int fmu_me_needs_correction(const fmu_inst *c) {
    const fmu_model *fm = &c->fm;
    for (int b = 0; fm->quaternion && b < fm->M.nb; b++) {
        const double *e = c->y + b * 7 + 3;
        if (fabs(sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3]) - 1.0) > QUAT_RENORM_TOL) return 1;
    }
    return drift(c) > ME_DRIFT_TOL;
}

/* The correction of the continuous states in event mode, the one place for it: the quaternions
 * re-normalised (e / |e|), then, when the constraints drifted beyond ME_DRIFT_TOL, the
 * mass-orthogonal projection of positions and velocities onto every constraint (core/project.c,
 * as a run under solver.singular = "pass" does after each step). 1 if a state changed. */
int fmu_me_correct(fmu_inst *c) {
    const fmu_model *fm = &c->fm;
    int changed = 0;
    if (!fmu_me_needs_correction(c)) return 0;
    for (int b = 0; fm->quaternion && b < fm->M.nb; b++) {
        double *e = c->y + b * 7 + 3, norm = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3]);
        if (norm == 1.0 || !(norm > 0.0)) continue;
        for (int k = 0; k < 4; k++) e[k] /= norm;
        changed = 1;
    }
    if (drift(c) > ME_DRIFT_TOL) {
        double left = 0.0; /* a projection that stops short leaves the state as corrected so far: the
                            * next derivative and the drift carry on from it */
        ovk_project(c->sim->M, c->sim->d, c->t, c->y, OVK_PROJ_TOL, OVK_PROJ_MAX_ITER, &left);
        changed = 1;
    }
    if (changed) c->dx_valid = 0;
    return changed;
}
