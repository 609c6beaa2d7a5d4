/* A run of the model in C: overcon.simulate.Simulation on the core's right-hand side, step for
 * step. The right-hand side warm-starts the friction solve as Simulation._rhs does (the friction
 * forces of the last two solves extrapolated to t, else the last multipliers); after every
 * accepted step the run checks, in Simulation.advance's order, that time advanced, the singularity
 * watch (watch.c; after a failed step, whether the elimination was expiring), keeps the energy
 * ledger when asked (energy.c), records the step-end friction forces and the constraint drift, and
 * the work budgets. The derived outputs at a point of the last step reuse the last evaluation when it
 * was at exactly that point, else solve once warm-started from the step-end forces, without
 * changing the run's state (Simulation.derived_outputs).
 *
 * A failure is a status with a message worded as the Python run's SimulationError; the numpy
 * path's fallbacks are not here: a status of ovk_evaluate stops the run (the caller decides). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "core.h"

double ovk_now(void) {
    struct timespec ts;
    if (timespec_get(&ts, TIME_UTC) != TIME_UTC) return 0.0;
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* The message of a stopped run: "<lead>: t = <t> s: <cause>" (the time added when the cause does
 * not start with one), as Simulation's "integration stopped: ..." and "cannot start: ...". */
static int stopped(ovk_sim *s, int status, const char *lead, double t) {
    char cause[OVK_MSG], when[48] = "";
    memcpy(cause, s->msg, sizeof cause);
    cause[OVK_MSG - 1] = '\0';
    if (strncmp(cause, "t = ", 4) != 0) snprintf(when, sizeof when, "t = %.9g s: ", t);
    size_t n = 0, parts = 4;
    const char *part[4] = {lead, ": ", when, cause};
    for (size_t k = 0; k < parts; k++)
        for (const char *c = part[k]; *c && n + 1 < sizeof s->msg; c++) s->msg[n++] = *c;
    s->msg[n] = '\0';
    /* the event at the time the cause names (a located instant), as Simulation's "stopped" (for
     * want of memory it is not recorded: the status and this message still say why the run stopped) */
    ovk_sim_push_event(s, when[0] ? t : strtod(cause + 4, NULL), OVK_EV_STOPPED, s->msg + strlen(lead) + 2);
    return status;
}

static void hist_push(ovk_hist *h, int nc, double t, const double *q) {
    if (!(h->count && h->t[0] == t)) { /* a new time: the newest becomes the older */
        if (h->count) {
            memcpy(h->q[1], h->q[0], (size_t)nc * sizeof(double));
            h->t[1] = h->t[0];
        }
        h->count = h->count ? 2 : 1;
    }
    memcpy(h->q[0], q, (size_t)nc * sizeof(double));
    h->t[0] = t;
}

/* The warm start at t (ncols), or 0 when the history is empty. */
static int hist_guess(const ovk_hist *h, int nc, double t, double *out) {
    if (!h->count) return 0;
    double t1 = h->t[0];
    if (h->count == 2 && fabs(t - t1) <= 2.0 * fabs(t1 - h->t[1])) {
        double r = (t - t1) / (t1 - h->t[1]);
        for (int i = 0; i < nc; i++) out[i] = h->q[0][i] + (h->q[0][i] - h->q[1][i]) * r;
    } else {
        memcpy(out, h->q[0], (size_t)nc * sizeof(double));
    }
    return 1;
}

/* One evaluation warm-started from the history h and the multipliers lam (Simulation._solve). */
int ovk_sim_solve(ovk_sim *s, double t, const double *y, const ovk_hist *h, const double *lam, double *ydot,
                  int *its) {
    int mode = 0, damped = 0;
    const double *g = s->guess;
    if (s->ncols && hist_guess(h, s->ncols, t, s->guess)) {
        mode = 1;
    } else if (lam) {
        mode = 2;
        g = lam;
    }
    int status = ovk_evaluate(s->M, s->d, t, y, mode, mode ? g : NULL, ydot, s->ev_lam, s->ev_qf, its, &damped);
    s->robust = 0;
    if (status == OVK_FRICTION) { /* the robust path, started from lam */
        int more = 0;
        status = ovk_evaluate_robust(s->M, s->d, y, lam, ydot, s->ev_lam, s->ev_qf, &more);
        *its += more;
        s->robust = 1;
    }
    if (status) snprintf(s->msg, sizeof s->msg, "t = %.9g s: %s", t, ovk_message(s->d));
    return status;
}

/* One right-hand side of the integration. Formulation AL under redundancy "eliminate" (pass mode):
 * a step that may take the direct solve (d->al_allow_direct, from the watch's r at its start) takes
 * it at every stage or, where a stage is too near a singular position for it, is taken again with
 * every stage interpolated (sim_pass.c; in_step, inside ovk_rk_step: s->refused is set and
 * OVK_SINGULAR returned to step_checked); a step that may not interpolates at every stage; the AL
 * iteration is the fallback where the interpolation finds no nodes. Outside a step (dop853's dense
 * stages, the step-end projection's new first stage) a refused state is interpolated at once: its
 * step is taken already, or the next one decides again (next_solve). Otherwise ovk_sim_solve. The
 * interpolation depends on (t, y) and the model alone, so the last one is kept (s->memo) and taken
 * again for the same bits within one step (step_checked): next_solve evaluates the step's end again
 * when the form changes, and a refused direct solve there meant sim_pass.c's whole search again. */
static int sim_eval(ovk_sim *s, double t, const double *y, double *ydot, int *its, int in_step) {
    ovk_data *d = s->d;
    const double *lam = s->has_lam ? s->lam : NULL;
    if (s->M->formulation != OVK_FORM_AL || s->M->redundancy != OVK_ELIMINATE)
        return ovk_sim_solve(s, t, y, &s->warm, lam, ydot, its);
    if (d->al_allow_direct) {
        d->al_direct_only = 1;
        int status = ovk_sim_solve(s, t, y, &s->warm, lam, ydot, its);
        d->al_direct_only = 0;
        if (!(status == OVK_SINGULAR && d->al_refused)) return status;
        if (in_step) return s->refused = 1, status;
    }
    if (s->memo && t == s->memo_t && !memcmp(y, s->memo_y, (size_t)s->ny * sizeof(double))) {
        memcpy(ydot, s->memo_f, (size_t)s->ny * sizeof(double)); /* the same state interpolated again (memo) */
        memcpy(s->ev_lam, s->memo_lam, (size_t)s->m * sizeof(double));
        s->robust = 1;
        return OVK_OK;
    }
    if (!ovk_sim_passing(s, t, y, ydot)) {
        s->robust = 1; /* the friction forces of the last node: not a warm start for the next solve */
        s->memo = 1, s->memo_t = t;
        memcpy(s->memo_y, y, (size_t)s->ny * sizeof(double));
        memcpy(s->memo_f, ydot, (size_t)s->ny * sizeof(double));
        memcpy(s->memo_lam, s->ev_lam, (size_t)s->m * sizeof(double));
        return OVK_OK;
    }
    int allow = d->al_allow_direct;
    d->al_allow_direct = 0;
    int status = ovk_sim_solve(s, t, y, &s->warm, lam, ydot, its);
    d->al_allow_direct = allow;
    return status;
}

/* The integrator's right-hand side (Simulation._rhs). */
static int sim_rhs(void *ctx, double t, const double *y, double *ydot) {
    ovk_sim *s = ctx;
    int its = 0, status = sim_eval(s, t, y, ydot, &its, s->stepping);
    if (status) return status;
    if (s->M->nfj) {
        memcpy(s->lam, s->ev_lam, (size_t)s->m * sizeof(double));
        s->has_lam = 1;
        if (!s->robust) hist_push(&s->warm, s->ncols, t, s->ev_qf); /* the robust path hands on no forces */
    }
    s->friction_iterations += its;
    s->evaluations++;
    s->has_last = 1;
    s->last_t = t;
    memcpy(s->last_y, y, (size_t)s->ny * sizeof(double));
    memcpy(s->last_lam, s->ev_lam, (size_t)s->m * sizeof(double));
    return OVK_OK;
}

/* The right-hand side of dop853's dense stages (Simulation._rhs_dense): warm-started as sim_rhs,
 * leaving the warm starts and the counters alone; a failure's message into rk.dense_msg. */
static int sim_rhs_dense(void *ctx, double t, const double *y, double *ydot) {
    ovk_sim *s = ctx;
    int its = 0, status = sim_eval(s, t, y, ydot, &its, 0);
    if (status) memcpy(s->rk.dense_msg, s->msg, sizeof s->msg);
    return status;
}

/* Lays out the run's arrays in s->mem (sizes in ovk_sim_new). */
static void layout(ovk_sim *s) {
    double *p = s->mem;
    size_t m = (size_t)s->m, nc = (size_t)s->ncols, ny = (size_t)s->ny, nh = (size_t)s->nh;
    s->lam = p; p += m;
    s->warm.q[0] = p; p += nc;
    s->warm.q[1] = p; p += nc;
    s->step_warm.q[0] = p; p += nc;
    s->step_warm.q[1] = p; p += nc;
    s->last_y = p; p += ny;
    s->last_lam = p; p += m;
    s->ev_lam = p; p += m;
    s->ev_qf = p; p += nc;
    s->guess = p; p += m > nc ? m : nc;
    s->yout = p; p += ny;
    s->phi = p; p += m;
    s->gam = p; p += m;
    s->T = p; p += 2 * m;
    s->ywatch = p; p += ny;
    s->ystar = p; p += ny;
    s->qwatch = p; p += (size_t)s->n;
    s->qload = p; p += nh;
    s->pass_y = p; p += ny;
    s->pass_f = p; p += ny;
    s->pass_qd = p; p += (size_t)s->n;
    s->pass_acc = p; p += nh;
    s->pass_lam = p; p += m;
    s->memo_y = p; p += ny;
    s->memo_f = p; p += ny;
    s->memo_lam = p; p += m;
    s->rk.y = p; /* the integrator's block starts here: ovk_rk_start lays it out */
}

static int check_opts(ovk_sim *s, const ovk_sim_opts *o) {
    const ovk_rk_opts *r = &o->rk;
    int adaptive = r->method == OVK_METHOD_DOPRI5 || r->method == OVK_METHOD_DOP853 || r->method == OVK_METHOD_RADAU;
    if (r->method == OVK_METHOD_RK4 ? !(r->step > 0.0 && isfinite(r->step))
                                    : !adaptive || !(r->tolerance > 0.0) || !(r->max_step > 0.0) ||
                                          !isfinite(r->tolerance))
        return snprintf(s->msg, sizeof s->msg, "cannot start: method %d, tolerance %g, max_step %g, step %g: not "
                        "a method and settings the C integrators take", r->method, r->tolerance, r->max_step,
                        r->step), OVK_INVALID;
    if (!(o->ratio_tol >= 0.0))
        return snprintf(s->msg, sizeof s->msg, "cannot start: ratio_tol %g", o->ratio_tol), OVK_INVALID;
    return OVK_OK;
}

ovk_sim *ovk_sim_new(const ovk_model *M, const ovk_sim_opts *o, double t0, const double *y0) {
    ovk_sim *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    if (!M || !o || !y0) {
        s->status = OVK_INVALID;
        snprintf(s->msg, sizeof s->msg, "cannot start: a null model, options or initial state");
        return s;
    }
    s->Mrun = *M; /* the run's own model: its kept set can be chosen again (ovk_sim_use_kept) */
    s->M = &s->Mrun;
    s->o = *o;
    if ((s->status = check_opts(s, o))) return s;
    if (M->nu && o->rk.method == OVK_METHOD_RK4) {
        s->status = OVK_INVALID;
        snprintf(s->msg, sizeof s->msg, "cannot start: rk4's fixed steps would step over the instants where the "
                 "inputs change: use dopri5, dop853 or radau with inputs");
        return s;
    }
    s->d = ovk_make_data(M);
    if (!s->d || ovk_data_status(s->d)) {
        s->status = s->d ? ovk_data_status(s->d) : OVK_NOMEM;
        snprintf(s->msg, sizeof s->msg, "cannot start: %s", ovk_message(s->d));
        return s;
    }
    s->n = M->nb * M->nq_b;
    s->nh = M->nb * M->nh_b;
    int kept = M->redundancy ? M->nwatch : M->nR; /* redundancy: the rows the watch judges (watch.c) */
    if (kept < 0) {
        s->status = OVK_INVALID;
        snprintf(s->msg, sizeof s->msg, "cannot start: the model carries no rows for the singularity watch under "
                 "redundancy %s (overcon.fmu.cmodel.watch_rows packs them)", M->redundancy == OVK_MIN_NORM ?
                 "'min-norm'" : "'compliant'");
        return s;
    }
    if (kept > s->nh) {
        s->status = OVK_INVALID;
        snprintf(s->msg, sizeof s->msg, "cannot start: %d kept rows for %d velocities", kept, s->nh);
        return s;
    }
    s->ny = s->n + s->nh;
    s->m = M->m;
    s->ncols = M->ncols;
    size_t m = (size_t)s->m, nc = (size_t)s->ncols, ny = (size_t)s->ny, nh = (size_t)s->nh;
    size_t need = 5 * m + 6 * nc + 4 * ny + (m > nc ? m : nc) + 2 * m + (size_t)s->n + nh +
                  (2 * ny + (size_t)s->n + nh + m) + (2 * ny + m) + ovk_rk_doubles(o->rk.method, s->ny);
    s->mem = calloc(need, sizeof(double));
    if (!s->mem) {
        s->status = OVK_NOMEM;
        snprintf(s->msg, sizeof s->msg, "cannot start: out of memory (%zu bytes)", need * sizeof(double));
        return s;
    }
    layout(s);
    s->min_ratio = INFINITY;
    s->t_prev = t0;
    s->t_comm = t0;
    s->t_changed = -INFINITY;
    s->along_unique = calloc(2 * (size_t)M->nj + 1, sizeof(int));
    s->cert_work = malloc(ovk_unique_cert_doubles(s->m, s->nh, M->nh_b) * sizeof(double) + 1);
    s->kept = calloc(8 * (size_t)s->m + 2 * OVK_MAXEQ * (size_t)M->nfj + (size_t)M->nj + 1, sizeof(int));
    s->y0 = malloc((size_t)s->ny * sizeof(double) + 1);
    if (!s->along_unique || !s->cert_work || !s->kept || !s->y0) {
        s->status = OVK_NOMEM;
        snprintf(s->msg, sizeof s->msg, "cannot start: out of memory (uniqueness along the motion)");
        return s;
    }
    if ((s->status = ovk_eig_make(s))) {
        snprintf(s->msg, sizeof s->msg, "cannot start: out of memory (the singularity watch)");
        return s;
    }
    memcpy(s->kept, M->retained, (size_t)M->nR * sizeof(int));
    memcpy(s->y0, y0, (size_t)s->ny * sizeof(double));
    int status = ovk_rk_start(&s->rk, &o->rk, s->ny, s->rk.y, t0, y0, sim_rhs, s, s->msg);
    s->rk.dense_fun = sim_rhs_dense, s->rk.dense_ctx = s;
    if (!status) status = ovk_sim_monitor(s, t0, s->rk.y, NULL, 1, s->msg);
    if (!status) status = ovk_sim_along_start(s, t0, s->rk.y, s->msg);
    if (!status) status = ovk_sim_energy_start(s, t0, s->rk.y);
    if (status) s->status = stopped(s, status, "cannot start", t0);
    return s;
}

void ovk_sim_free(ovk_sim *s) {
    if (!s) return;
    ovk_free_data(s->d);
    free(s->mem);
    free(s->along_unique);
    free(s->along_work);
    free(s->bsv_work);
    free(s->cert_work);
    free(s->dense);
    free(s->events);
    free(s->kept);
    free(s->y0);
    free(s->out_mem);
    ovk_eig_free(s->eig);
    free(s);
}

int ovk_sim_dense(ovk_sim *s, char *msg) {
    if (s->dense && s->along_work && s->bsv_work) return OVK_OK;
    size_t mn = (size_t)s->m * (size_t)s->nh, a = ovk_unique_doubles(s->m, s->nh), b = ovk_bsv_doubles(s->m, s->nh);
    if (!s->dense) s->dense = malloc(3 * mn * sizeof(double) + 1);
    if (!s->along_work) s->along_work = malloc(a * sizeof(double) + 1);
    if (!s->bsv_work) s->bsv_work = malloc(b * sizeof(double) + 1);
    if (!s->dense || !s->along_work || !s->bsv_work)
        return snprintf(msg, OVK_MSG, "out of memory: the singularity watch's whole-Jacobian factorisation needs %zu "
                        "bytes (%d equations x %d velocities, dense)", (3 * mn + a + b) * sizeof(double), s->m, s->nh),
               OVK_NOMEM;
    s->J = s->dense, s->W = s->dense + mn, s->W2 = s->dense + 2 * mn;
    return OVK_OK;
}

int ovk_sim_status(const ovk_sim *s) { return s ? s->status : OVK_NOMEM; }
const char *ovk_sim_message(const ovk_sim *s) { return s ? s->msg : "no simulation (out of memory)"; }

/* The budgets before a step is taken (Simulation._check_budget): this call's (steps since n0,
 * wall time since started), then the run's life. Checked before, not after, a step: every step
 * taken is accepted with its checks and its output points are delivered (a stopped run's CSV and
 * an FMU's last outputs end at the last step), and the run stops when it needs one more step than
 * the budget allows. */
static int check_budget(ovk_sim *s, double started, long long n0, long long call_steps, double call_wall) {
    const ovk_rk *rk = &s->rk;
    double spent = ovk_now() - started;
    if (call_steps >= 0 && rk->nsteps - n0 >= call_steps)
        return snprintf(s->msg, sizeof s->msg, "%lld internal steps > %lld allowed for this step, at t = %.9g s",
                        rk->nsteps - n0 + 1, call_steps, rk->t), OVK_BUDGET;
    if (call_wall > 0.0 && spent > call_wall)
        return snprintf(s->msg, sizeof s->msg, "%.3g s wall time > %g s allowed for this step, at t = %.9g s",
                        spent, call_wall, rk->t), OVK_BUDGET;
    if (s->o.max_steps > 0 && rk->nsteps >= s->o.max_steps)
        return snprintf(s->msg, sizeof s->msg, "work budget exhausted: %lld internal steps (max_steps = %lld) "
                        "reached t = %.9g s of %g s; raise the budget or use a larger step / looser tolerance",
                        rk->nsteps, s->o.max_steps, rk->t, s->o.stop_time), OVK_BUDGET;
    if (s->o.max_wall_time > 0.0 && s->wall_time + spent > s->o.max_wall_time)
        return snprintf(s->msg, sizeof s->msg, "work budget exhausted: wall time %.1f s (max_wall_time = %g s) "
                        "reached t = %.9g s of %g s after %lld steps; raise the budget or use a larger step / "
                        "looser tolerance", s->wall_time + spent, s->o.max_wall_time, rk->t, s->o.stop_time,
                        rk->nsteps), OVK_BUDGET;
    return OVK_OK;
}

/* Formulation AL (solver.singular = "pass"), after an accepted step: the state projected onto the
 * constraints (project.c) and the integrator's last derivative (dopri5's FSAL stage) evaluated
 * again at the projected state (Simulation._project). */
static int project_step(ovk_sim *s) {
    ovk_rk *rk = &s->rk;
    double drift = 0.0;
    int status = ovk_project(s->M, s->d, rk->t, rk->y, OVK_PROJ_TOL, OVK_PROJ_MAX_ITER, &drift);
    if (status) return snprintf(s->msg, sizeof s->msg, "%s", ovk_message(s->d)), status;
    if (drift > s->proj_drift) s->proj_drift = drift;
    rk->dense_ready = 0;
    return sim_rhs(s, rk->t, rk->y, rk->f);
}

/* Formulation AL: the watch found a singular position of the mechanism (its message in s->msg,
 * starting "t = <time> s"); the run passes it, counting it once per passage (not again while r
 * stayed below ratio_tol at the last step end, r_before), and the watch starts again from the
 * step's end (SingularityMonitor with Simulation's passing hook). */
static int pass_singular(ovk_sim *s, double r_before) {
    ovk_rk *rk = &s->rk;
    if (!(r_before < s->o.ratio_tol)) { /* a new passage: a 'singular' event, as the in-process run's */
        s->singular_passed++;
        s->last_singular = strncmp(s->msg, "t = ", 4) == 0 ? strtod(s->msg + 4, NULL) : rk->t;
        if (ovk_sim_push_event(s, s->last_singular, OVK_EV_SINGULAR, s->msg))
            return snprintf(s->msg, sizeof s->msg, "t = %.9g s: out of memory for the run's events", rk->t), OVK_NOMEM;
    }
    int status = ovk_sim_monitor(s, rk->t, rk->y, rk->f, 1, s->msg);
    if (status == OVK_SINGULAR_POSITION) { /* the step's end itself: the watch goes on from it */
        s->t_prev = rk->t;
        status = OVK_OK;
    }
    /* The rank and the verdicts were judged at the singular instant (a rank-change event there);
     * judged again at the step's end, past it, so that they do not keep the instant's values
     * until the next near-singular step (the watch evaluates them only where r < 1e-3), with the
     * bounds the watch's start just certified there (no search moved them: ovk_sim_along_start's
     * rule), so that a step end regular enough needs no factorisation (one a passage saves; at a
     * flat position of the N-four-bar N = 100 such a factorisation takes about 0.2 s). */
    if (!status) status = ovk_sim_along(s, rk->t, rk->y, 0, s->eig->smin_low, s->eig->smax_up, s->msg);
    return status;
}

/* Whether a step from the state the watch last judged (r = s->ratio) may take kkt_al.c's direct
 * solve: one rule for the step's start (step_checked) and its end (next_solve). */
static int direct_allowed(const ovk_sim *s) { return s->ratio >= OVK_DIRECT_RATIO; }

/* Formulation AL, at the end of an accepted step: the next step's right-hand side (kkt_al.c's
 * direct solve allowed or not, else sim_pass.c's interpolation: the watch's r at the step's end,
 * OVK_DIRECT_RATIO; step_checked sets the same again from the state, so a run taken from a saved
 * state goes on alike). The explicit pairs take the next step's first stage from f at the step's
 * end (FSAL; project_step's evaluation), made under this step's form: where it changes, that f is
 * evaluated again under the next one, after this step's dense output was made under its own, so
 * that every stage of a step, the first too, has the same right-hand side. Without it each change
 * (two per passage of a singular position, where the two forms differ by their round-off and
 * interpolation errors; with the stalled AL iteration before sim_pass.c, along the directions
 * losing rank) failed the next step's error estimate until its size fell to about 1e-9 s, from
 * where it had to grow again (N-four-bar N = 2, dop853, tolerance 1e-10 to 1e-12: 27-37% of the
 * evaluations over the 20 s, measured with the AL iteration; docs/benchmarks.md, "Error against
 * tolerance"). */
static int next_solve(ovk_sim *s) {
    ovk_rk *rk = &s->rk;
    int allow = direct_allowed(s), status;
    if (s->M->formulation != OVK_FORM_AL || allow == s->d->al_allow_direct ||
        !(rk->method == OVK_METHOD_DOPRI5 || rk->method == OVK_METHOD_DOP853))
        return OVK_OK;
    if ((status = ovk_rk_dense_prepare(rk))) return memcpy(s->msg, rk->dense_msg, sizeof s->msg), status;
    s->d->al_allow_direct = allow;
    return sim_rhs(s, rk->t, rk->y, rk->f);
}

/* One accepted step and its checks (the body of Simulation.advance's loop). */
static int step_body(ovk_sim *s, double started, long long n0, long long call_steps, double call_wall) {
    ovk_rk *rk = &s->rk;
    double t_before = rk->t;
    int status = check_budget(s, started, n0, call_steps, call_wall);
    s->d->al_allow_direct = direct_allowed(s); /* the step's solve, the same at every stage */
    if (status) return stopped(s, status, "integration stopped", rk->t);
    s->refused = 0, s->stepping = 1;
    status = ovk_rk_step(rk, sim_rhs, s, s->msg);
    s->stepping = 0;
    if (status == OVK_SINGULAR && s->refused) { /* a stage refused the direct solve: the step again, */
        s->refused = 0;                           /* every stage interpolated (sim_eval), its first too */
        s->d->al_allow_direct = 0;
        status = sim_rhs(s, rk->t, rk->y, rk->f);
        if (!status) status = ovk_rk_step(rk, sim_rhs, s, s->msg);
    }
    if (!status && !(rk->t > t_before)) {
        snprintf(s->msg, sizeof s->msg, "t = %.9g s: time does not advance (step below the resolution of t)",
                 t_before);
        status = OVK_STALLED;
    }
    int failed = status && status != OVK_STALLED;
    if (failed) status = ovk_sim_expiring(s, status, s->msg);
    s->degrading = 0;
    if (!status && s->M->formulation == OVK_FORM_AL) status = project_step(s);
    double r_before = s->ratio; /* r at the last step end */
    if (!status) status = ovk_sim_monitor(s, rk->t, rk->y, rk->f, 0, s->msg);
    if (status == OVK_SINGULAR_POSITION && s->M->formulation == OVK_FORM_AL) status = pass_singular(s, r_before);
    if (status == OVK_ELIMINATION) { /* the kept set expired: chosen again and the step taken anew, or the stop */
        status = ovk_sim_expired(s, failed ? rk->t : rk->t_old, failed ? rk->y : rk->y_old);
        if (!status) return OVK_OK;
    }
    if (!status) status = ovk_sim_energy_step(s);
    if (rk->dense_status) /* dop853's dense stages failed under the watch or the ledger: that is the cause */
        status = rk->dense_status, memcpy(s->msg, rk->dense_msg, sizeof s->msg);
    if (status) return stopped(s, status, "integration stopped", rk->t);
    if (s->warm.count) hist_push(&s->step_warm, s->ncols, rk->t, s->warm.q[0]);
    s->d->f.t = rk->t; /* the drivers' equations at the step's end */
    if ((status = ovk_rows_in(s->M, s->d, rk->y))) {
        snprintf(s->msg, sizeof s->msg, "%s", ovk_message(s->d));
        return stopped(s, status, "integration stopped", rk->t);
    }
    for (int r = 0; r < s->m; r++)
        if (fabs(s->d->phi[r]) > s->max_drift) s->max_drift = fabs(s->d->phi[r]);
    if (s->degrading && (status = ovk_sim_degraded(s))) return stopped(s, status, "integration stopped", rk->t);
    if ((status = next_solve(s))) return stopped(s, status, "integration stopped", rk->t);
    return OVK_OK;
}

/* step_body with sim_eval's memo held within it only: between two steps the host may set inputs or
 * parameters, restore a state or start again, and only within one step nothing but (t, y) changes
 * what the interpolation gives (the kept set chosen again clears it too, watch.c). */
static int step_checked(ovk_sim *s, double started, long long n0, long long call_steps, double call_wall) {
    s->memo = 0;
    int status = step_body(s, started, n0, call_steps, call_wall);
    s->memo = 0;
    return status;
}

int ovk_sim_step(ovk_sim *s) {
    if (!s) return OVK_NOMEM;
    if (s->status) return s->status;
    double started = ovk_now();
    int status = step_checked(s, started, s->rk.nsteps, -1, 0.0);
    s->wall_time += ovk_now() - started;
    return status;
}

/* Integrates until t_target and writes y(t_target) (dense output) into y (Simulation.advance);
 * max_steps < 0 and max_wall_time <= 0: no budget of this call. */
int ovk_sim_advance(ovk_sim *s, double t_target, long long max_steps, double max_wall_time, double *y) {
    if (!s) return OVK_NOMEM;
    if (s->status) return s->status;
    ovk_rk *rk = &s->rk;
    double eps = 1e-12 * (fabs(t_target) > 1.0 ? fabs(t_target) : 1.0), started = ovk_now();
    long long n0 = rk->nsteps;
    int status = OVK_OK;
    /* inputs that changed where this interval starts are likely to change where it ends: its steps
     * end there (exactly, as a host's grid); otherwise they run past it, and a change there takes
     * the run back (ovk_sim_set_inputs) */
    if (s->M->nu && s->t_changed == s->t_comm && t_target > rk->t) rk->t_bound = t_target;
    while (!status && rk->t < t_target - eps) status = step_checked(s, started, n0, max_steps, max_wall_time);
    rk->t_bound = INFINITY;
    s->wall_time += ovk_now() - started;
    if (status) return status;
    if (rk->t - t_target < -eps || !isfinite(t_target))
        return snprintf(s->msg, sizeof s->msg, "could not reach t = %.17g", t_target), OVK_STALLED;
    if (fabs(rk->t - t_target) > eps) {
        if ((status = ovk_rk_dense(rk, t_target, y)))
            return memcpy(s->msg, rk->dense_msg, sizeof s->msg), stopped(s, status, "integration stopped", rk->t);
    } else
        memcpy(y, rk->y, (size_t)s->ny * sizeof(double));
    s->t_comm = t_target;
    return OVK_OK;
}

void ovk_sim_state_vector(const ovk_sim *s, double *y) { memcpy(y, s->rk.y, (size_t)s->ny * sizeof(double)); }

/* t, the next step size, accepted steps, evaluations of the integrator, of the right-hand side,
 * friction force evaluations, max drift, min ratio, stiff steps, rk4's stable step, wall time,
 * singular positions passed (formulation AL), the time of the last one (0 while none), the largest
 * max |Phi| left by the step-end projections, the wall time of the singularity watch (s), its
 * estimates of r that reached their iteration bound (watch_eig.c), the wall time of the uniqueness
 * along the motion (s; at the start and within the watch's) and how many of its evaluations the
 * watch's certified bounds decided without a factorisation (unique.c, ovk_unique_certified). */
void ovk_sim_info(const ovk_sim *s, double *info) {
    const ovk_rk *rk = &s->rk;
    double v[OVK_SIM_NINFO] = {rk->t, rk->method == OVK_METHOD_RK4 ? rk->step : rk->h, (double)rk->nsteps,
                               (double)rk->nfev, (double)s->evaluations, (double)s->friction_iterations,
                               s->max_drift, s->min_ratio, (double)rk->stiff_steps, rk->stable_step, s->wall_time,
                               (double)s->singular_passed, s->last_singular, s->proj_drift, s->watch_time,
                               (double)s->watch_capped, s->along_time, (double)s->along_certified};
    memcpy(info, v, sizeof v);
}

/* Reactions (nj x OVK_NREAC) and friction outputs (nj) at (t, y) of the last step
 * (Simulation.derived_outputs): the run's state is left as it was. */
int ovk_sim_outputs(ovk_sim *s, double t, const double *y, double *reac, double *fric) {
    if (!s) return OVK_NOMEM;
    if (s->status) return s->status;
    const double *lam = s->last_lam;
    int same = s->has_last && s->last_t == t;
    for (int i = 0; same && i < s->ny; i++) same = s->last_y[i] == y[i];
    if (!same) {
        int its = 0, status = ovk_sim_solve(s, t, y, s->step_warm.count ? &s->step_warm : &s->warm,
                                    s->has_lam ? s->lam : NULL, s->yout, &its);
        if (status) return status;
        lam = s->ev_lam;
    }
    int status = ovk_outputs(s->M, s->d, y, lam, reac, fric);
    if (status) snprintf(s->msg, sizeof s->msg, "%s", ovk_message(s->d));
    return status;
}

/* Records an event (detail cut at OVK_MSG bytes); OVK_NOMEM when the list cannot grow (the event
 * is then lost and the caller stops the run, saying so). */
int ovk_sim_push_event(ovk_sim *s, double t, int kind, const char *detail) {
    if (s->nevents == s->cap_events) {
        int cap = s->cap_events ? 2 * s->cap_events : 8;
        ovk_event *grown = cap > 0 ? realloc(s->events, (size_t)cap * sizeof *grown) : NULL;
        if (!grown) return OVK_NOMEM;
        s->events = grown;
        s->cap_events = cap;
    }
    ovk_event *e = &s->events[s->nevents++];
    e->t = t;
    e->kind = kind;
    snprintf(e->detail, sizeof e->detail, "%s", detail);
    return OVK_OK;
}

int ovk_sim_events(const ovk_sim *s) { return s ? s->nevents : 0; }

/* Event k (0-based): its detail, with its time and kind; NULL when there is no event k. */
const char *ovk_sim_event(const ovk_sim *s, int k, double *t, int *kind) {
    if (!s || k < 0 || k >= s->nevents) return NULL;
    *t = s->events[k].t;
    *kind = s->events[k].kind;
    return s->events[k].detail;
}

/* The last evaluation of the uniqueness along the motion: the rank and each joint's verdict (nj)
 * into rank and unique; returns motion_unique (every friction joint with a nonzero law unique,
 * the paper's Eq. 17), or -1 without a run. */
int ovk_sim_uniqueness(const ovk_sim *s, int *rank, int *unique) {
    if (!s || !s->along_unique) return -1;
    const ovk_model *M = s->M;
    int motion = 1;
    *rank = s->along_rank;
    memcpy(unique, s->along_unique, (size_t)M->nj * sizeof(int));
    for (int k = 0; k < M->nfj; k++) {
        const double *lp = M->jlawp + (size_t)M->fj[k] * NLP;
        if (!(lp[0] == 0.0 && lp[3] == 0.0) && !s->along_unique[M->fj[k]]) motion = 0;
    }
    int drivers = 0;
    for (int j = 0; j < M->nj; j++) drivers += M->jtype[j] == J_DRIVER;
    if (drivers && s->along_rank == s->nh) motion = 1; /* fully driven (DOF 0): the motion is prescribed */
    return motion;
}

/* Every driver's effort is unique at the last evaluation of the uniqueness along the motion
 * (overcon.precheck.effort_verdicts): its own reaction unique and no friction acting on a joint
 * whose reaction is not unique; 1 without drivers, -1 without a run. */
int ovk_sim_effort_unique(const ovk_sim *s) {
    if (!s || !s->along_unique) return -1;
    const ovk_model *M = s->M;
    for (int j = 0; j < M->nj; j++)
        if (M->jtype[j] == J_DRIVER && !s->along_unique[j]) return 0;
    for (int k = 0; k < M->nfj; k++) {
        const double *lp = M->jlawp + (size_t)M->fj[k] * NLP;
        if (!(lp[0] == 0.0 && lp[3] == 0.0) && !s->along_unique[M->fj[k]]) {
            for (int j = 0; j < M->nj; j++)
                if (M->jtype[j] == J_DRIVER) return 0;
        }
    }
    return 1;
}

/* The run's kept equations become `retained` (M->nR of them, ascending): the packed arrays of the
 * kept set made again in the run's own memory (ovk_pack_kept, as overcon.kernel packs them) and a
 * workspace for them (the number of friction multipliers may change). The status. */
int ovk_sim_use_kept(ovk_sim *s, const int *retained) {
    ovk_model *R = &s->Mrun;
    int m = s->m, nfj = R->nfj, *own = s->kept, *xrows = own + m, *fx = xrows + OVK_MAXEQ * nfj;
    int *rbody = fx + OVK_MAXEQ * nfj, *iwork = rbody + 2 * m;
    if (retained != own) memmove(own, retained, (size_t)R->nR * sizeof(int));
    int nx = ovk_pack_kept(R, own, R->nR, xrows, fx, rbody, iwork);
    ovk_model next = *R;
    next.retained = own, next.xrows = xrows, next.fx = fx, next.rbody = rbody, next.nx = nx;
    ovk_data *d = ovk_make_data(&next);
    if (!d || ovk_data_status(d)) {
        int status = d ? ovk_data_status(d) : OVK_NOMEM;
        snprintf(s->msg, sizeof s->msg, "the kept equations chosen again: %s", d ? ovk_message(d) : "out of memory");
        ovk_free_data(d);
        return status;
    }
    memcpy(d->u, s->d->u, (2 * (size_t)R->nu + 1) * sizeof(double)); /* the inputs' values stay */
    ovk_free_data(s->d);
    s->d = d;
    *R = next;
    return OVK_OK;
}

/* The run taken back to (t, y) inside its last step (y: its dense output there, not in the
 * integrator's arrays): the integrator started anew there with its step size and counters kept,
 * the friction warm starts kept (their histories interpolate back to t), the ledger's work
 * interpolated to t (ovk_sim_energy_rewind). */
static int rewind_to(ovk_sim *s, double t, const double *y) {
    ovk_rk *rk = &s->rk;
    double w[2] = {0.0, 0.0}, h = rk->h;
    if (s->o.energy) ovk_sim_work_at(s, t, w);
    long long nsteps = rk->nsteps, nfev = rk->nfev, stiff = rk->stiff_steps, njev = rk->njev, nlu = rk->nlu;
    s->has_last = 0;
    int status = ovk_rk_start(rk, &s->o.rk, s->ny, rk->y, t, y, sim_rhs, s, s->msg);
    rk->nsteps = nsteps, rk->nfev += nfev, rk->stiff_steps = stiff, rk->njev += njev, rk->nlu += nlu;
    if (h > 0.0 && isfinite(h)) rk->h = h < rk->max_step ? h : rk->max_step;
    s->t_prev = t;
    if (!status) status = ovk_sim_energy_rewind(s, t, rk->y, w);
    return status;
}

/* The inputs' values u (nu) and slopes du (nu, per s; NULL: held) from the host's communication
 * point on (inputs.c; t_comm: the target of the last ovk_sim_advance, the start before one).
 * Equal values cost nothing: the run goes on as it was, its steps free to span communication
 * points. When they change, the run goes on from the communication point with them: from the step
 * end there, the first stage of the next step and the ledger's powers evaluated again; from inside
 * the last step (the integrator stepped past it), taken back to its dense output there
 * (rewind_to). Either way the outputs read there after the change see the new values. Inputs
 * that keep changing (changed at the last communication point) make the next advance end its
 * steps at its target (ovk_sim_advance), so a host changing them at every point costs no rewinds. */
int ovk_sim_set_inputs(ovk_sim *s, const double *u, const double *du) {
    if (!s) return OVK_NOMEM;
    if (s->status) return s->status;
    const ovk_model *M = s->M;
    int nu = M->nu, same = 1;
    if (!nu) return OVK_OK;
    double *cur = s->d->u, t = s->t_comm;
    for (int k = 0; k < nu && same; k++) {
        double now = cur[k] + cur[nu + k] * (t - cur[2 * nu]);
        same = now == u[k] && cur[nu + k] == (du ? du[k] : 0.0);
    }
    if (same) return OVK_OK;
    int status = ovk_set_inputs(M, s->d, u, du, t);
    if (status) return snprintf(s->msg, sizeof s->msg, "%s", ovk_message(s->d)), status;
    s->t_changed = t;
    double eps = 1e-12 * (fabs(t) > 1.0 ? fabs(t) : 1.0);
    if (fabs(s->rk.t - t) <= eps) { /* at the step's end (advance gave its state there) */
        status = sim_rhs(s, s->rk.t, s->rk.y, s->rk.f);
        s->rk.dense_ready = 0;
        if (!status) status = ovk_sim_energy_inputs(s);
    } else if (t < s->rk.t_old - eps || t > s->rk.t) { /* a step taken since the advance (ovk_sim_step) */
        status = OVK_INVALID;
        snprintf(s->msg, sizeof s->msg, "inputs: the run stands at t = %.9g s, past the communication point t = "
                 "%.9g s where they were set (set inputs after ovk_sim_advance)", s->rk.t, t);
    } else if (!(status = ovk_rk_dense(&s->rk, t, s->ystar))) {
        status = rewind_to(s, t, s->ystar);
    } else {
        memcpy(s->msg, s->rk.dense_msg, sizeof s->msg);
    }
    if (status) s->status = stopped(s, status, "inputs", t);
    return status;
}

/* Goes on from (t, y) under the kept equations `kept` (m flags; as many as before) as
 * Simulation._restart: a new integrator with the same settings and step counters, no warm
 * starts, the watch started anew there. From the end of the last accepted step (the elimination
 * chosen again there, ovk_sim_degraded) the integrator keeps that step's dense output, made under
 * the kept equations of the step, so output points inside the step come from the trajectory that
 * was accepted. The status (its message in s->msg). */
int ovk_sim_restart(ovk_sim *s, const int *kept, double t, const double *y) {
    int nR = 0, *retained = s->kept + 5 * s->m + 2 * OVK_MAXEQ * s->Mrun.nfj; /* scratch: m ints */
    for (int r = 0; r < s->m; r++)
        if (kept[r]) retained[nR++] = r;
    if (nR != s->Mrun.nR)
        return snprintf(s->msg, sizeof s->msg, "t = %.9g s: %d equations chosen to keep, the run keeps %d", t, nR,
                        s->Mrun.nR), OVK_INVALID;
    int at_end = t == s->rk.t && !memcmp(y, s->rk.y, (size_t)s->ny * sizeof(double)), status = OVK_OK;
    if (at_end && (status = ovk_rk_dense_prepare(&s->rk))) /* under the step's kept equations */
        return memcpy(s->msg, s->rk.dense_msg, sizeof s->msg), status;
    if ((status = ovk_sim_use_kept(s, retained))) return status;
    memmove(s->ystar, y, (size_t)s->ny * sizeof(double)); /* y may lie in the integrator's arrays */
    long long nsteps = s->rk.nsteps, nfev = s->rk.nfev;
    s->has_lam = s->has_last = 0;
    s->warm.count = s->step_warm.count = 0;
    status = at_end ? ovk_rk_restart(&s->rk, &s->o.rk, sim_rhs, s, s->msg)
                    : ovk_rk_start(&s->rk, &s->o.rk, s->ny, s->rk.y, t, s->ystar, sim_rhs, s, s->msg);
    s->rk.nsteps = nsteps, s->rk.nfev = nfev;
    s->min_ratio = INFINITY; /* a new watch (SingularityMonitor) */
    s->t_prev = t;
    if (!status) status = ovk_sim_monitor(s, t, s->rk.y, NULL, 1, s->msg);
    return status;
}
