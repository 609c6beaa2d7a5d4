/* The output rows of a run: the outputs of a plan (ovk_out: positions, velocities, energies,
 * reactions, friction forces, in the model's output order, overcon.kernel.output_plan) at a point
 * of the last step, and a whole output grid in one call (overcon.simulate.run, check --along): the
 * run advanced from point to point, each row written by dense output into one array the caller
 * sized (rows x outputs), the events kept by the run as they happen. The FMUs' outputs are these
 * rows too (fmu_run.c, fmu_me.c).
 *
 * Positions report quaternions as e / |e| (the orientation the dynamics use); energies are
 * ovk_sim_energy's; reactions and friction forces ovk_sim_outputs' at the point (the last
 * evaluation's multipliers when it was at exactly this point, else one warm-started solve that
 * leaves the run's state alone), or with lam given (Model Exchange) those of lam. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"

/* Every entry of the plan is one the model has (numbers from outside: checked before they index). */
int ovk_plan_check(const ovk_model *M, const ovk_out *plan, int nout, char *msg) {
    int n = M->nb * M->nq_b, nh = M->nb * M->nh_b;
    if (nout < 0 || (nout && !plan))
        return snprintf(msg, OVK_MSG, "output plan: %d outputs%s", nout, plan ? "" : " without a plan"), OVK_INVALID;
    for (int k = 0; k < nout; k++) {
        const ovk_out *o = &plan[k];
        int ok = (o->kind == OVK_OUT_POSITION && o->a >= 0 && o->a < n) ||
                 (o->kind == OVK_OUT_STATE && o->a >= 0 && o->a < n + nh) ||
                 (o->kind == OVK_OUT_VELOCITY && o->a >= 0 && o->a < nh) ||
                 (o->kind == OVK_OUT_REACTION && o->a >= 0 && o->a < M->nj && o->b >= 0 && o->b < OVK_NREAC) ||
                 (o->kind == OVK_OUT_FRICTION && o->a >= 0 && o->a < M->nj) ||
                 (o->kind == OVK_OUT_ENERGY && o->a >= 0 && o->a < 4) ||
                 (o->kind == OVK_OUT_SENSOR && o->a >= 0 && o->a < M->nj && o->b >= 0 && o->b < 4);
        if (!ok)
            return snprintf(msg, OVK_MSG, "output plan: output %d (kind %d, %d, %d) is not one of this model (%d "
                            "coordinates, %d velocities, %d joints)", k, o->kind, o->a, o->b, n, nh, M->nj),
                   OVK_INVALID;
    }
    return OVK_OK;
}

/* The outputs of the state alone (positions, velocities, entries of y) of the plan into out (entries of other
 * kinds are left as they are). */
void ovk_state_outputs(const ovk_model *M, const ovk_out *plan, int nout, const double *y, double *out) {
    int n = M->nb * M->nq_b;
    for (int k = 0; k < nout; k++) {
        const ovk_out *o = &plan[k];
        if (o->kind == OVK_OUT_VELOCITY) {
            out[k] = y[n + o->a];
        } else if (o->kind == OVK_OUT_STATE) {
            out[k] = y[o->a];
        } else if (o->kind == OVK_OUT_POSITION && M->nq_b == 7 && o->a % 7 >= 3) {
            const double *e = y + (o->a / 7) * 7 + 3;
            out[k] = y[o->a] / sqrt(((e[0] * e[0] + e[1] * e[1]) + e[2] * e[2]) + e[3] * e[3]);
        } else if (o->kind == OVK_OUT_POSITION) {
            out[k] = y[o->a];
        }
    }
}

/* The energies, reactions and friction forces of the plan at (t, y) of the last step into out
 * (each computed only when an output needs it); lam: the multipliers of an evaluation at (t, y)
 * (NULL: ovk_sim_outputs'). reac, fric: scratch of nj x OVK_NREAC and nj. The status; the message
 * in the run's. */
int ovk_sim_derived_outputs(ovk_sim *s, const ovk_out *plan, int nout, double t, const double *y, const double *lam,
                            double *reac, double *fric, double *out) {
    int forces = 0, energy = 0, status = OVK_OK, sensed = -1;
    double en[4] = {0.0, 0.0, 0.0, 0.0}, sensor[4] = {0.0, 0.0, 0.0, 0.0};
    for (int k = 0; k < nout; k++) {
        forces |= plan[k].kind == OVK_OUT_REACTION || plan[k].kind == OVK_OUT_FRICTION;
        energy |= plan[k].kind == OVK_OUT_ENERGY;
    }
    if (energy) status = ovk_sim_energy(s, t, y, en);
    if (!status && forces && !lam) status = ovk_sim_outputs(s, t, y, reac, fric);
    if (!status && forces && lam && (status = ovk_outputs(s->M, s->d, y, lam, reac, fric)))
        snprintf(s->msg, sizeof s->msg, "%s", ovk_message(s->d));
    if (status) return status;
    for (int k = 0; k < nout; k++) {
        const ovk_out *o = &plan[k];
        if (o->kind == OVK_OUT_ENERGY) out[k] = en[o->a];
        else if (o->kind == OVK_OUT_REACTION) out[k] = reac[o->a * OVK_NREAC + o->b];
        else if (o->kind == OVK_OUT_FRICTION) out[k] = fric[o->a];
        else if (o->kind == OVK_OUT_SENSOR) { /* a joint's sensors, from the run's initial state (core/inputs.c) */
            if (o->a != sensed && (status = ovk_sensors(s->M, s->d, y, s->y0, o->a, sensor)))
                return snprintf(s->msg, sizeof s->msg, "%s", ovk_message(s->d)), status;
            sensed = o->a;
            out[k] = sensor[o->b];
        }
    }
    return OVK_OK;
}

/* The outputs' scratch, made once per run: a state (ny), the reactions (nj x OVK_NREAC) and the
 * friction forces (nj). */
static int out_scratch(ovk_sim *s) {
    if (s->out_mem) return OVK_OK;
    size_t nj = (size_t)s->Mrun.nj, need = (size_t)s->ny + nj * (OVK_NREAC + 1) + 1;
    s->out_mem = calloc(need, sizeof(double));
    if (!s->out_mem)
        return snprintf(s->msg, sizeof s->msg, "out of memory for the outputs (%zu bytes)", need * sizeof(double)),
               OVK_NOMEM;
    s->out_y = s->out_mem;
    s->out_reac = s->out_y + s->ny;
    s->out_fric = s->out_reac + nj * OVK_NREAC;
    return OVK_OK;
}

/* One output row of the plan at (t, y) of the last step (Simulation.outputs): the state's outputs
 * and the derived ones. The status; the message in the run's. */
int ovk_sim_output_row(ovk_sim *s, const ovk_out *plan, int nout, double t, const double *y, double *out) {
    if (!s) return OVK_NOMEM;
    if (s->status) return s->status;
    int status = ovk_plan_check(s->M, plan, nout, s->msg);
    if (!status && (!y || (nout && !out))) {
        snprintf(s->msg, sizeof s->msg, "output row: no state or no row");
        status = OVK_INVALID;
    }
    if (!status) status = out_scratch(s);
    if (status) return status;
    ovk_state_outputs(s->M, plan, nout, y, out);
    return ovk_sim_derived_outputs(s, plan, nout, t, y, NULL, s->out_reac, s->out_fric, out);
}

/* The run advanced through the times t[0..nt) (ascending, from the last step's start on) and the row of
 * the plan at each written into values (nt x nout, row-major; the caller's array of that size):
 * as ovk_sim_advance to each time and ovk_sim_output_row there, the run's budgets of its life
 * checked on the way. *rows: the rows written; a stop leaves the rows before it in values and its
 * status and message (the "stopped" event recorded) as ovk_sim_advance's. */
int ovk_sim_grid(ovk_sim *s, const ovk_out *plan, int nout, const double *times, long long nt, double *values,
                 long long *rows) {
    if (!s) return OVK_NOMEM;
    if (rows) *rows = 0;
    if (s->status) return s->status;
    int status = ovk_plan_check(s->M, plan, nout, s->msg);
    if (status) return status;
    if (nt < 0 || (nt && (!times || (nout && !values))) || !rows)
        return snprintf(s->msg, sizeof s->msg, "output grid: %lld points%s", nt,
                        rows ? " without times or an array for the rows" : " without a count of rows"), OVK_INVALID;
    for (long long k = 0; k < nt; k++)
        if (!isfinite(times[k]) || (k && !(times[k] > times[k - 1])))
            return snprintf(s->msg, sizeof s->msg, "output grid: time %lld (%.17g s) is not finite or not after the "
                            "one before", k, times[k]), OVK_INVALID;
    if (nt && times[0] < s->rk.t_old) /* the dense output answers inside the last step only */
        return snprintf(s->msg, sizeof s->msg, "output grid: time 0 (%.17g s) is before the run's last step (from "
                        "%.17g s)", times[0], s->rk.t_old), OVK_INVALID;
    if ((status = out_scratch(s))) return status;
    double *y = s->out_y;
    for (long long k = 0; k < nt; k++) {
        double *row = values + (size_t)k * (size_t)nout;
        if ((status = ovk_sim_advance(s, times[k], -1, 0.0, y))) return status;
        ovk_state_outputs(s->M, plan, nout, y, row);
        if ((status = ovk_sim_derived_outputs(s, plan, nout, times[k], y, NULL, s->out_reac, s->out_fric, row))) return status;
        *rows = k + 1;
    }
    return OVK_OK;
}
