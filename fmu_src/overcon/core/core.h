/* overcon core: one evaluation of Eq. 18 (direct dynamics with the scene's elimination and Coulomb
 * joint friction), the coordinate rates and the reported reactions, in C11 and libm.
 *
 * Shaped like MuJoCo's engine: a packed, read-only model (ovk_model, packed by overcon.kernel) and
 * a workspace per instance (ovk_data: every buffer of an evaluation, sized once from the model,
 * and the message of the last failure); stage functions that each do one job, one file each:
 *   frames.c            positions, rotations and velocities of the bodies (and the base)
 *   joints.c            the joint table: dispatch by type, and the assembly of Phi, Phi_h, gamma
 *   joints_planar.c     planar revolute, translational and point-on-line joints: rows, friction setup and forces
 *   joints_spherical.c  spatial spherical joints: the same
 *   joints_distance.c   distance joints (planar and spatial): the rows of a massless link
 *   joints_spatial.c    spatial axis joints (revolute, prismatic, cylindrical, universal, fixed) and the
 *                       spatial point-on-line joint: the
 *                       row primitives of overcon.joints.spatial_rows, reactions, friction
 *   loads.c             applied forces: gravity, gyroscopic, force, torque, spring
 *   kkt.c               the KKT solve with the scene's elimination (banded Cholesky of S) and h'
 *   kkt_minnorm.c       redundancy "min-norm": S^+ by a rank-revealing SVD in place of the Cholesky factor
 *   compliance.c        redundancy "compliant": spring-damper multipliers of compliant joints, rigid rest
 *   kkt_al.c            formulation AL: the augmented Lagrangian solve of the kept rows (banded Cholesky)
 *   project.c           formulation AL: mass-orthogonal projections of a state onto the constraints
 *   friction.c          friction laws, the reduced friction fixed point, Newton and damped Newton
 *   linalg.c            banded Cholesky, the band order of rows on two bodies, LU (fixed summation
 *                       order, no BLAS)
 *   lu.c                complex LU with partial pivoting (radau's complex Newton matrix)
 *   outputs.c           reported reactions and friction forces
 *   rates.c             coordinate rates q' from h
 *   integrate_rk.c      the explicit integrators: dopri5, dop853 (dense output), rk4
 *   integrate_radau.c   its implicit Radau IIA of order 5 (radau), collocation dense output
 *   sim.c               a run (overcon.simulate.Simulation): friction warm starts, step-end checks,
 *                       work budgets, derived outputs at any point of the last step
 *   sim_out.c           the output rows of a run: the model's output plan at a point, a whole grid
 *   svd.c               one-sided Jacobi SVD: singular values (the watch's rare whole-Jacobian checks)
 *   watch_eig.c         the watch's r: the kept rows' extreme singular values tracked from check to
 *                       check (inverse iterations on the banded G = W W^T)
 *   energy.c            the energy outputs: kinetic, potential, the work ledger of friction and loads
 *   watch_scale.c       the watch's rows equilibrated (the pre-check's rule, mass-free) and weighted
 *   watch.c             the singularity watch: r and dr/dt after each step, the
 *                       minimum of r inside a step, singular position or expired/degrading elimination;
 *                       the uniqueness along the motion and its events
 *   unique.c            the whole Jacobian's rank and each joint's reaction uniqueness (the pre-check's
 *                       one-factorisation rule)
 *   sim_state.c         a run's state as plain bytes (FMI get/set/serialize FMU state)
 *   rows_sparse.c       Phi and Phi_h by their nonzeros (the pre-check's Jacobian), exported
 *   api.c               the other exported entry points (ovk_*), the only symbols of the library
 * Units and signs: SI, the paper's conventions (those of overcon.joints and docs/scene-format.md).
 *
 * Every failure is a status (OVK_*) plus a message kept in the workspace (ovk_message); the core
 * never aborts or exits, and has no global mutable state (two workspaces never share memory).
 * A run (sim.c) finishes a friction solve that gave up by the robust path (friction_robust.c)
 * and stops with any other status, naming it.
 *
 * Arithmetic: a fixed summation order, no BLAS; compiled with -ffp-contract=off -fno-fast-math so
 * the results do not depend on the CPU's FMA support or the BLAS dispatch.
 */
#ifndef OVERCON_CORE_H
#define OVERCON_CORE_H

#include <stddef.h>

#include "libm_pins.h"

#define OVK_ABI 11 /* the layout of ovk_model and the entry points' signatures (overcon.kernel.ABI) */

enum {
    OVK_OK = 0,
    OVK_SINGULAR = 1,  /* S not positive definite: a singular position */
    OVK_FRICTION = 2,  /* Newton and damped Newton on the friction multipliers gave up */
    OVK_EULER = 3,     /* |sin beta| < SIN_BETA_MIN: z-x-z Euler angles singular */
    OVK_NONFINITE = 4, /* a non-finite number on the way */
    OVK_SPRING = 5,    /* a spring of positive free length whose points coincide */
    OVK_NOMEM = 6,     /* the workspace could not be allocated */
    OVK_INVALID = 7,   /* a model or argument outside what the core takes */
    OVK_STEP_SMALL = 8, /* integrator: the step size fell below the resolution of t */
    OVK_STIFF = 9,     /* integrator: dopri5's or dop853's step limited by stability (stiffness detected) */
    OVK_UNSTABLE = 10, /* integrator: rk4's fixed step beyond its stability boundary (stable_step) */
    OVK_BUDGET = 11,   /* simulation: the work budget (steps or wall time) ran out */
    OVK_SINGULAR_POSITION = 12, /* simulation: the kept Jacobian lost rank (singularity monitor) */
    OVK_STALLED = 13,  /* simulation: time does not advance, or the target was not reached */
    OVK_ELIMINATION = 14, /* simulation: the elimination expired where it decides the motion (or no other is found) */
    OVK_PROJECTION = 15  /* project.c: the positions did not reach the constraints within the corrections allowed */
};
enum { J_REVOLUTE = 1, J_TRANSLATIONAL = 2, J_SPHERICAL = 3 }; /* planar, planar, spatial */
enum { J_SREVOLUTE = 4, J_PRISMATIC = 5, J_CYLINDRICAL = 6, J_UNIVERSAL = 7, J_FIXED = 8 }; /* spatial axis */
enum { J_DRIVER = 9 }; /* a driver (drivers.c): one rheonomic equation on a joint's coordinate, planar or spatial */
enum { J_DISTANCE = 10 }; /* planar and spatial: a massless link (joints_distance.c), no friction */
enum { J_POINT_LINE = 11 }; /* planar (joints_planar.c) and spatial (joints_spatial.c): a point on a line, friction */
enum { LAW_NONE = 0, LAW_REGULARISED = 1, LAW_STRIBECK = 2 };
enum { LD_FORCE = 1, LD_TORQUE = 2, LD_SPRING = 3 };

#define NJC 34  /* doubles of constants per joint (joints_spatial.c: the axis joints' layout) */
#define OVK_MAXEQ 6 /* equations per joint at most (the fixed joint) */
#define OVK_NREAC 9 /* reported reaction entries per joint at most: 6 in the joint frame + 3 global */
#define NLP 5   /* doubles of friction law per joint: mu, v_reg, size, mu_static, v_stribeck */
#define NLD 11  /* doubles per load: value[3], s_i[3], s_j[3], stiffness, free_length */
#define NEWTON_MAX_ITER 12
#define NEWTON_REFRESH 1e-3
#define DAMPED_MAX_ITER 30
#define ARMIJO 1e-4
#define SIN_BETA_MIN 1e-3
#define QUAT_NORM_RATE 1.0 /* overcon.kinematics.QUAT_NORM_RATE: the quaternion norm stabilisation (1/s) */
#define OVK_PROJ_TOL 1e-11   /* m or rad: max |Phi| a run's step-end projection reaches (overcon.kernel.PROJECTION_TOL) */
#define OVK_PROJ_MAX_ITER 20 /* position corrections of that projection at most (overcon.kernel.PROJECTION_MAX_ITER) */
#define OVK_MSG 1024        /* bytes of the failure message, with its terminating zero */

/* OVK_EXPORT: the entry points of libovercore (loaded by overcon.kernel); inside an FMU binary
 * (compiled with -DOVK_FMU_BINARY) they are internal: the FMU exports the FMI API alone. */
#if defined(__GNUC__) && defined(OVK_FMU_BINARY)
#define OVK_EXPORT __attribute__((visibility("hidden")))
#define OVK_HIDDEN __attribute__((visibility("hidden")))
#elif defined(__GNUC__)
#define OVK_EXPORT __attribute__((visibility("default")))
#define OVK_HIDDEN __attribute__((visibility("hidden")))
#else
#define OVK_EXPORT
#define OVK_HIDDEN
#endif

/* The model, packed by overcon.kernel.Kernel (field order and types mirrored there). Read only.
 * Spatial orientation coordinates by nq_b: 6 = z-x-z Euler angles, 7 = a quaternion (scalar first). */
typedef struct {
    int dim, nb, nq_b, nh_b, m, nR, nj, nl;
    int nx, ncols, nfj, nfg;
    int max_iter;
    double baumgarte, tol;
    const int *retained;   /* nR */
    const double *Minv;    /* nb * nh_b */
    const double *mass;    /* nb */
    const double *inertia; /* nb * 3 (spatial) */
    const double *gravity; /* dim */
    const int *jtype, *jbi, *jbj, *jneq, *jrows; /* nj; jrows nj * OVK_MAXEQ (equation indices) */
    const double *jconst;  /* nj * NJC */
    const int *jlaw;       /* nj */
    const double *jlawp;   /* nj * NLP */
    const int *ltype, *lbi, *lbj; /* nl */
    const double *lp;      /* nl * NLD */
    const int *xrows;      /* nx: positions in lam_R of the friction rows */
    const int *cols;       /* ncols: velocity indices the friction forces act on */
    const int *fj;         /* nfj: friction joints, plan order (group by group) */
    const int *fgroup;     /* nfg + 1: start of each friction group in fj */
    const int *fx;         /* nfj * OVK_MAXEQ: x index per equation (nx = eliminated) */
    const int *fci, *fcj;  /* nfj * 6: index into cols per coordinate of body i, j (ncols = base) */
    const int *rbody;      /* nR * 2: the bodies (-1 base) of each retained row: Phi_h is zero elsewhere */
    /* redundancy (overcon.spec.REDUNDANCY_METHODS; kkt_minnorm.c, compliance.c): how the redundant
     * equations are handled, and the rows the singularity watch (watch.c) judges */
    int redundancy;        /* OVK_ELIMINATE, OVK_MIN_NORM (every row retained), OVK_COMPLIANT */
    int nrig, nax;         /* compliant: rigid retained rows; joints with per-axis values */
    int nwatch, nfull;     /* the watch: rows watched (kept, independent), rows of the whole rigid Jacobian
                            * (-1, -1: not packed; a model for evaluations only, sim.c refuses a run) */
    const int *ckind;      /* nR: per retained position 0 rigid, 1 compliant (scalar values), 2 per axis */
    const double *ck, *cd; /* m: stiffness (N/m, N.m/rad), damping (N.s/m, N.m.s/rad) of each scalar row */
    const int *rigpos, *rigrows, *rigbody; /* nrig, nrig, nrig * 2: the rigid rows' retained positions,
                            * equations and bodies (-1 base): the eliminated problem compliance.c solves */
    const int *axi;        /* nax * 10: bodies i, j; counts of translational, rotational rows; their
                            * retained positions (3 + 3, -1 unused) */
    const double *axp;     /* nax * 21: joint frame (3 x 3 row-major, columns the axes in body i's
                            * axes), k_t, d_t, k_r, d_r along its x, y, z */
    const int *watch;      /* nwatch: equations watched (SingularityMonitor.rows at the start) */
    const int *full;       /* nfull: equations of the whole Jacobian (the rigid ones) */
    int formulation;       /* OVK_FORM_*: the acceleration solve (solver.singular: "stop" eliminated, "pass" AL) */
    /* inputs (inputs.c; scene [[inputs]]): named slots the host writes (ovk_set_inputs, ovk_sim_set_inputs),
     * read where the loads are evaluated; 0 of them costs nothing */
    int nu;
    const int *ukind;      /* nu: OVK_IN_* */
    const int *uidx;       /* nu * 3: joint (-1 none), body i, body j (-1 base) */
    const double *up;      /* nu * OVK_NUP: direction[3] (unit), point[3] (body i axes), the direction's
                            * frame (0 global, 1 body i's axes, 2 body j's), start value */
} ovk_model;
enum { OVK_IN_JOINT_TORQUE = 1, OVK_IN_JOINT_FORCE = 2, OVK_IN_FORCE = 3, OVK_IN_TORQUE = 4 };
#define OVK_NUP 8 /* doubles per input (up) */
enum { OVK_ELIMINATE = 0, OVK_MIN_NORM = 1, OVK_COMPLIANT = 2 };
#define OVK_NAXI 10 /* ints per per-axis compliant joint (axi) */
#define OVK_NAXP 21 /* doubles per per-axis compliant joint (axp) */
enum { OVK_FORM_ELIMINATED = 0, OVK_FORM_AL = 1 };

/* Frames of the bodies, slot nb = the base. */
typedef struct {
    double t;              /* the time of the drivers' equations (drivers.c), set with the frames' users */
    double *r, *R, *v, *w; /* (nb + 1) slots: r, v dim; R dim*dim; w 1 (planar) or 3 */
    double *sb, *cb, *sg, *cg; /* Euler angles: sin/cos of beta and gamma per body (rates) */
} ovk_frames;

/* Per-evaluation constants of one friction joint (the friction setup of its type). */
typedef struct {
    double A[9], JiT[6]; /* planar: A_i (3 x 3), (J_X)_i^T (3 x 2) */
    double e[2], arm_i[2], arm_j[2], coef; /* translational: guide, arms, mu(v); revolute: size*mu */
    double Ri[9], RiT[9], omega[3], Rji[9]; /* spherical (RiT also the axis joints') */
    double JT[6 * OVK_MAXEQ]; /* axis joints: (J_X)_i^T (6 x neq) */
    double u[3], RjT[9], armj[3]; /* axis joints: the global axis, R_j^T, R_j^T (P_i - r_j) */
    double spin, slide, mu, mos; /* axis joints: omega_rel, v_rel, mu(v), mu(|s|)/|s| (cylindrical) */
} ovk_fctx;

/* Rows in band order (linalg.c ovk_band_order): order[k] the position (in retained order) of the
 * row at band position k, body[2 k], body[2 k + 1] its bodies (lower first, -1 none), band the
 * half bandwidth of S in that order. */
typedef struct {
    int band;
    int *order, *body;
} ovk_srows;

/* The workspace of one instance: every buffer of an evaluation, sized from the model by
 * ovk_make_data, and the last failure's message. */
typedef struct {
    ovk_frames f;
    double *J;     /* Phi_h by its nonzeros: m rows of 2 nh_b (OVK_JROW): row r's velocities of its
                    * joint's body i, then of body j (the order of rbody and al_rows; body j's slots
                    * unused when it is the base or body i, body i's when it is the base) */
    double *phi;   /* m */
    double *gam;   /* m */
    double *S;     /* S = J_R M^-1 J_R^T in band order (band storage of linalg.c: nR x (sb.band + 1)),
                    * then its banded Cholesky factor; min-norm: S^+ (nR x nR, kkt_minnorm.c) */
    ovk_srows sb;  /* the retained rows in band order (kkt.c), fixed per model */
    ovk_srows sb_rigid; /* compliant: the rigid retained rows in band order (compliance.c's view) */
    int *sb_mem;   /* the one allocation behind sb's and sb_rigid's arrays */
    double *Sx;    /* nR x max(ncols, 1): right-hand sides of S in band order (kkt.c) */
    double *g;     /* nR: gamma_R (with Baumgarte) */
    double *lamR;  /* nR: retained multipliers */
    double *Q;     /* nh: applied (and friction) forces */
    double *W;     /* nR x ncols: S^-1 J_R M^-1 [:, cols] */
    double *Jblk;  /* nj x 6 OVK_MAXEQ: every joint's (J_X)_i block, for the friction setup */
    double *work;  /* the friction solve's vectors and matrices */
    double *robust; /* the robust friction path's vectors and matrices (friction_robust.c) */
    int robust_ready; /* the last ovk_evaluate stopped at OVK_FRICTION: ovk_evaluate_robust may go on */
    ovk_fctx *ctx; /* nfj */
    double *flam, *Qi, *Qj; /* nfj x OVK_MAXEQ, nfj x 6, nfj x 6: the last friction force evaluation */
    double *mem;   /* the one allocation behind the double buffers above */
    int status;    /* nonzero: the workspace could not be made (every call returns it) */
    char msg[OVK_MSG];
    double *red;   /* redundancy: scratch of kkt_minnorm.c / compliance.c (ovk_redundancy_doubles) */
    double *al;    /* formulation AL: the band factor of M + alpha J_R^T J_R and the solve's vectors (kkt_al.c) */
    double al_alpha; /* the penalty alpha of the last factorisation (kg for unit-length rows; kkt_al.c) */
    int al_band;   /* the half bandwidth of M + alpha J_R^T J_R in velocity coordinates */
    int al_iterations; /* AL iterations of the last solve; al_stalled: it stopped on stagnation, not on tol */
    int al_stalled;
    int al_allow_direct; /* a run's step may take the AL form's direct solve (sim.c, OVK_DIRECT_RATIO) */
    int al_direct;     /* the last AL-form solve was kkt.c's direct one (its S factor stands; kkt_al.c) */
    int al_direct_only; /* sim_pass.c: the direct solve or OVK_SINGULAR with al_refused set, never the iteration */
    int al_refused;    /* the last solve under al_direct_only found the kept rows too near a singular position */
    double al_pivot_min; /* the direct solve's least pivot spread (0: OVK_PASS_REGULAR; kkt_al.c, sim_pass.c) */
    double al_spread;  /* the spread of S's squared pivots at the last direct attempt (0: none reached) */
    int *al_rows;  /* every equation (m), then its two bodies (2 m): the row set of ovk_project */
    int *piv;      /* nx: the row interchanges of the friction solves' LU (friction.c, friction_robust.c) */
    double *phit;  /* m: Phi_t of the drivers' equations (0 elsewhere), with Phi at d->f.t (joints.c) */
    double *u;     /* inputs: 2 nu + 1: the values at u_t, their slopes (per s), then u_t (inputs.c) */
} ovk_data;

/* Row r of Phi_h stored by its nonzeros (ovk_data.J, or a copy laid out alike): 2 nh_b doubles, slot s
 * (0, 1) the nh_b velocities of the row's body rbody[2 r + s] (joints.c writes them) */
#define OVK_JROW(M, J, r) ((J) + (size_t)(r) * 2 * (size_t)(M)->nh_b)
/* Row `row` of Phi_h stored by its nonzeros (Jb laid out as d->J), its bodies bi, bj (-1 the base),
 * written densely into out (nh doubles, zeros outside the two bodies) */
OVK_HIDDEN void ovk_row_dense(const ovk_model *M, const double *Jb, int row, int bi, int bj, double *out);

/* integrate_rk.c: the explicit integrators (dopri5, dop853, rk4);
 * integrate_radau.c: its implicit Radau IIA of order 5 (radau) */
enum { OVK_METHOD_DOPRI5 = 0, OVK_METHOD_RK4 = 1, OVK_METHOD_DOP853 = 2, OVK_METHOD_RADAU = 3 };
/* The right-hand side y' = f(t, y) of an integrator: a status (its message written by the callee). */
typedef int (*ovk_rhs_fn)(void *ctx, double t, const double *y, double *ydot);
typedef struct {
    int method;          /* OVK_METHOD_* */
    int detect_stiffness; /* dopri5, dop853: stop with OVK_STIFF on a stability-limited crawl */
    double tolerance, max_step, first_step; /* dopri5, dop853, radau: rtol = atol; first_step <= 0: 1e-4 */
    double step;         /* rk4: the fixed step */
} ovk_rk_opts;
/* The whole integrator state: the scalars here and the arrays in one block of ovk_rk_doubles(method,
 * n); sim_state.c saves the fields that are state (not the scratch, not the dense_* callback). */
typedef struct {
    int method, n, detect_stiffness;
    int has_K, dense_ready; /* a step was taken (K, radau's Z valid); Q is current for that step */
    int dense_kept;      /* ovk_rk_restart kept the dense output of the step before it (has_K is 0) */
    int n_stiff, n_nonstiff, n_limited;
    int current_jac, has_lu, has_old; /* radau: J at the step's start; LU of lu_h; h_abs_old, error_norm_old */
    int nK, nQ;          /* rows of K and Q that are state (0: scratch only) */
    long long k, nfev, nsteps, stiff_steps, njev, nlu; /* k: rk4 steps (t = t0 + k step) */
    double rtol, max_step, step, newton_tol;
    double t, h, t0, t_old, h_old, stable_step; /* radau: h is its h_abs */
    double h_abs_old, error_norm_old, lu_h; /* radau: the last accepted step's size and error; the LU's h */
    double t_bound;  /* no step ends past it (sim.c: a communication point where inputs keep changing;
                      * INFINITY otherwise); not state */
    double *y, *f, *y_old, *f_old; /* n each */
    double *K;       /* the stages of the last step: dopri5 7 n; dop853 16 n (12 stages, f_new, 3 dense
                      * stages); rk4 rows 0-3 scratch */
    double *ynew, *ystage; /* n each: scratch */
    double *Q;       /* dense output coefficients: dopri5 4 n, dop853 7 n */
    double *J, *LU, *LUc, *Zs; /* radau: Jacobian, real LU (n n), complex LU (2 n n), the last step's Z (3 n) */
    int *piv, *pivc;           /* radau: the LUs' row interchanges (n each) */
    double *Z0, *Z, *W, *dW, *F, *cw, *err, *scale; /* radau scratch: 3 n x 6, then 2 n, n, n */
    ovk_rhs_fn dense_fun; /* dop853's 3 dense stages: a right-hand side that leaves the run's state alone */
    void *dense_ctx;
    int dense_status;     /* the dense stages failed: the status, until the next step; the message in */
    char dense_msg[OVK_MSG]; /* dense_msg (dense_fun writes it) */
} ovk_rk;
OVK_HIDDEN size_t ovk_rk_doubles(int method, int n);
OVK_HIDDEN int ovk_rk_start(ovk_rk *rk, const ovk_rk_opts *o, int n, double *mem, double t0, const double *y0,
                            ovk_rhs_fn fun, void *ctx, char *msg);
OVK_HIDDEN int ovk_rk_step(ovk_rk *rk, ovk_rhs_fn fun, void *ctx, char *msg);
OVK_HIDDEN int ovk_rk_dense(ovk_rk *rk, double t, double *out);
/* The last step's dense output coefficients made while its right-hand side is in force, then the
 * restart at its end that keeps them (integrate_rk.c) */
OVK_HIDDEN int ovk_rk_dense_prepare(ovk_rk *rk);
OVK_HIDDEN int ovk_rk_restart(ovk_rk *rk, const ovk_rk_opts *o, ovk_rhs_fn fun, void *ctx, char *msg);
OVK_HIDDEN size_t ovk_radau_doubles(int n);
OVK_HIDDEN void ovk_radau_layout(ovk_rk *rk, double *p);
OVK_HIDDEN int ovk_radau_start(ovk_rk *rk, ovk_rhs_fn fun, void *ctx, char *msg);
OVK_HIDDEN int ovk_radau_step(ovk_rk *rk, ovk_rhs_fn fun, void *ctx, char *msg);
OVK_HIDDEN void ovk_radau_dense(const ovk_rk *rk, double t, double *out);
OVK_HIDDEN int ovk_radau_constants(const char *name, const double **data, int *rows, int *cols);
/* The integrators' constants by method and name (dopri5: C A B E P; dop853: C A B E3 E5 D A_EXTRA
 * C_EXTRA; radau: C E T TI P MU (MU_REAL, Re and Im MU_COMPLEX)), so tests compare them with SciPy's
 * bit for bit: OVK_OK and a pointer to rows x cols doubles (row-major), else OVK_INVALID. */
OVK_EXPORT int ovk_integrator_constants(int method, const char *name, const double **data, int *rows, int *cols);

/* watch_eig.c: the extreme singular values of the watch's weighted kept rows W (nR x nh, unit-norm
 * rows J_R M^-1/2, each nonzero on its two bodies' columns only), tracked from check to check. */
typedef struct {
    int nR, kh, nb, band; /* rows, velocities per body, bodies, half bandwidth of G in the row order */
    int have;             /* umin, umax hold the vectors of a past estimate (state: sim_state.c) */
    int *order;           /* nR: positions in the kept list, in band order */
    int *rows;            /* nR: the kept equations the order was made for */
    int *body;            /* 2 nR: each ordered row's bodies, ascending (-1: none) */
    int *eqbody;          /* 2 m: each equation's two bodies (the joint table's) */
    int *span;            /* 2 nb: scratch (first, last ordered row touching a body) */
    long long *key;       /* nR: scratch (the sort) */
    double *w, *w2;       /* nR x 2 kh each: weighted rows on their bodies' columns (w2: the rate's) */
    double *scale;        /* nh: the column scaling of the last rows equilibrated (watch_scale.c) */
    double *scale_y;      /* nh: the scaling at the state whose certified bounds the watch passes on */
    double *fscale;       /* nh: the column scaling of the whole Jacobian's rows (watch.c) */
    double *sscr;         /* nh + m: watch_scale.c's scratch */
    double *umin, *umax;  /* nR: the tracked left singular vectors (state) */
    double *x, *z;        /* nR, nh: scratch */
    double *G, *F;        /* nR x nR each at most: the band of G, a shifted copy factored */
    double smin_low, smax_up; /* the last estimate's certified bounds: sigma_min >= smin_low (0: none), sigma_max <= smax_up */
    double *mem;
    int *imem;
} ovk_watch_eig;

/* sim.c: a run of the model (what overcon.simulate.Simulation and the FMUs run): the integrator
 * over ovk_evaluate with the friction warm starts, the step-end checks (singularity monitor,
 * constraint drift, work budgets) and the derived outputs at any point of the last step. */
typedef struct {
    ovk_rk_opts rk;
    long long max_steps;  /* accepted steps over the run's life; <= 0: no limit */
    double max_wall_time; /* s spent in ovk_sim_advance over the run's life; <= 0: no limit */
    double ratio_tol;     /* singularity monitor: sigma_min / sigma_max below it stops the run */
    double stop_time;     /* the scene's stop time (s), named by the budget messages */
    int energy;           /* keep the work ledger of the energy outputs (two more evaluations a step) */
} ovk_sim_opts;
/* An event of a run (overcon.simulate.EVENT_KINDS, in that order): time (s), kind, detail. */
enum { OVK_EV_SINGULAR = 0, OVK_EV_RESELECTED = 1, OVK_EV_RANK = 2, OVK_EV_UNIQUENESS = 3, OVK_EV_STOPPED = 4 };
typedef struct {
    double t;
    int kind;
    char detail[OVK_MSG];
} ovk_event;
/* Friction forces of the last two solves at distinct times, newest first (simulate._ForcesHistory). */
typedef struct {
    int count;
    double t[2];
    double *q[2]; /* ncols each */
} ovk_hist;
typedef struct {
    const ovk_model *M;
    ovk_data *d;
    ovk_sim_opts o;
    ovk_rk rk;
    int n, ny, nh, m, ncols;
    int has_lam, has_last, robust; /* robust: the last solve needed the robust friction path */
    double *lam;                   /* m: the last solve's multipliers (friction warm start) */
    ovk_hist warm, step_warm;      /* the integration's solves; the latest ones at step ends */
    double last_t, *last_y, *last_lam; /* the last right-hand side's point and multipliers */
    long long friction_iterations, evaluations;
    double max_drift, min_ratio, t_prev, wall_time;
    double *ev_lam, *ev_qf, *guess, *yout; /* scratch: m, ncols, max(m, ncols), ny */
    double *phi, *gam;             /* scratch: m, m */
    /* the watch's rare whole-Jacobian paths (an expiring or reselected elimination, a rank or
     * uniqueness by factorisation: bandsvd.c, unique.c), which take the rows dense: m nh each,
     * allocated by ovk_sim_dense when first needed (a run that never needs them stays O(nonzeros)) */
    double *J, *W, *W2, *dense;    /* dense rows at a state, weighted rows, another set; their allocation */
    double *T;                     /* watch scratch: the tracked vectors kept aside (2 m) */
    double *ywatch, *ystar, *qwatch; /* watch scratch: states (ny each), coordinate rates (n) */
    double rate, ratio;            /* watch: dr/dt and r of the kept equations at the last check */
    double *qload;                 /* energy: the constant loads' Q (nh) */
    double *pass_y, *pass_f, *pass_qd, *pass_acc, *pass_lam; /* sim_pass.c scratch: ny, ny, n, nh, m */
    int stepping, refused;         /* sim.c: inside ovk_rk_step; a stage of that step refused the direct solve */
    double *memo_y, *memo_f, *memo_lam, memo_t; /* sim.c: the last interpolated y' at (memo_t, memo_y) and */
    int memo;                      /* its multipliers (ny, ny, m); memo: they hold, within one step_checked */
    double work_t[2], work_w[2][2], work_p[2][2]; /* energy ledger: (t, work, powers) at the last two step ends */
    double *mem;                   /* the one allocation behind the arrays above and the integrator's */
    int status;
    char msg[OVK_MSG];
    /* uniqueness along the motion (unique.c, evaluated by watch.c) and the run's events */
    int along_rank;                /* the whole Jacobian's rank at the last evaluation (pre-check rule) */
    int *along_unique;             /* nj: each joint's reaction unique there */
    double *along_work;            /* ovk_unique_doubles(m, nh) (ovk_sim_dense) */
    double *bsv_work;              /* ovk_bsv_doubles(m, nh): the watch's whole-Jacobian ranks (ovk_sim_dense) */
    double *cert_work;             /* ovk_unique_cert_doubles: the certified uniqueness (O(nonzeros)) */
    ovk_event *events;             /* nevents of cap_events, in the order they happened */
    int nevents, cap_events;
    /* the kept equations chosen again during the run (watch.c, sim.c) */
    ovk_model Mrun;                /* *M with the kept set below once chosen again; s->M points here */
    int *kept;                     /* retained (m) | xrows, fx (OVK_MAXEQ nfj each) | rbody (2 m) | scratch (5 m + nj) */
    double *y0;                    /* ny: the initial state (eliminations valid at the start and later) */
    int degrading;                 /* the step just accepted found the elimination degrading */
    double expired_t;              /* the instant the kept set expired (its state in ystar) */
    long long singular_passed;     /* formulation AL: singular positions the watch found and the run passed */
    double last_singular;          /* the time of the last of them (s; 0 while none) */
    double proj_drift;             /* formulation AL: max |Phi| after the step-end projections */
    ovk_watch_eig *eig;            /* the watch's tracked extreme singular values (watch_eig.c) */
    double watch_time;             /* s spent in the watch (ovk_sim_monitor), not state */
    long long watch_capped;        /* estimates of r that reached the iteration bound (watch_eig.c) */
    double along_time;             /* s spent in the uniqueness along the motion (ovk_sim_along), not state */
    long long along_certified;     /* its evaluations the watch's bounds decided (unique.c) */
    /* the output rows (sim_out.c): scratch made at the first row, not state */
    double *out_mem;               /* the one allocation behind out_y (ny), out_reac (nj OVK_NREAC), out_fric (nj) */
    double *out_y, *out_reac, *out_fric;
    double t_comm;                 /* inputs: the target of the last ovk_sim_advance (the host's communication
                                    * point, where ovk_sim_set_inputs changes them), the start before one */
    double t_changed;              /* inputs: the communication point where they last changed (-inf: never) */
} ovk_sim;
#define OVK_SIM_NINFO 18
OVK_HIDDEN int ovk_sim_passing(ovk_sim *s, double t, const double *y, double *ydot);
OVK_HIDDEN int ovk_sim_solve(ovk_sim *s, double t, const double *y, const ovk_hist *h, const double *lam,
                             double *ydot, int *its);
/* energy.c: the energy outputs' ledger */
OVK_HIDDEN int ovk_sim_energy_start(ovk_sim *s, double t0, const double *y0);
OVK_HIDDEN int ovk_sim_energy_step(ovk_sim *s);
OVK_HIDDEN int ovk_sim_energy_inputs(ovk_sim *s);
OVK_HIDDEN int ovk_sim_energy_rewind(ovk_sim *s, double t, const double *y, const double *w);
OVK_HIDDEN void ovk_sim_work_at(const ovk_sim *s, double t, double *out);
OVK_HIDDEN void ovk_compliant_energy(const ovk_model *M, ovk_data *d, const double *q, const double *h,
                                     double *elastic, double *damping);
/* watch.c: the singularity watch after each step; the expiry behind a failed step */
OVK_HIDDEN int ovk_sim_monitor(ovk_sim *s, double t, const double *y, const double *qdot, int first, char *msg);
OVK_HIDDEN int ovk_sim_expiring(ovk_sim *s, int failed, char *msg);
/* watch.c: uniqueness along the motion at (t, y), events when it changed; sim.c: an event recorded */
OVK_HIDDEN int ovk_sim_along(ovk_sim *s, double t, const double *y, int first, double wmin_low, double wmax_up,
                             char *msg);
OVK_HIDDEN int ovk_sim_push_event(ovk_sim *s, double t, int kind, const char *detail);
/* unique.c: rank and per-joint reaction uniqueness from the whole Jacobian (the pre-check's rule) */
OVK_HIDDEN size_t ovk_unique_doubles(int m, int nh);
OVK_HIDDEN size_t ovk_unique_cert_doubles(int m, int nh, int kh); /* ovk_unique_certified's work */
OVK_HIDDEN int ovk_unique_rows(const ovk_model *M, const double *J, double *work, int *rank, int *unique);
OVK_HIDDEN int ovk_choose_kept(const ovk_model *M, const double *J, double *work, int *iwork, int *kept, int *rank);
OVK_HIDDEN int ovk_unique_judged(const ovk_model *M);
OVK_HIDDEN int ovk_unique_certified(const ovk_model *M, const double *J, double *work, double wmin_low, double wmax_up,
                                    const double *scale);
/* sim.c: the run goes on from (t, y) under the kept equations `kept` (m flags), its integrator anew */
/* sim.c: the dense scratch of the watch's rare paths (J, W, W2, along_work, bsv_work), made on first
 * use; OVK_NOMEM with its size in msg when it cannot be */
OVK_HIDDEN int ovk_sim_dense(ovk_sim *s, char *msg);
/* watch.c: the uniqueness along the motion at the run's start (certified where it can be) */
OVK_HIDDEN int ovk_sim_along_start(ovk_sim *s, double t0, const double *y0, char *msg);
OVK_HIDDEN int ovk_sim_restart(ovk_sim *s, const int *kept, double t, const double *y);
OVK_HIDDEN int ovk_sim_use_kept(ovk_sim *s, const int *retained);
/* watch.c: an expired elimination chosen again (or the stop), a degrading one chosen again */
OVK_HIDDEN int ovk_sim_expired(ovk_sim *s, double t_from, const double *y_from);
OVK_HIDDEN int ovk_sim_degraded(ovk_sim *s);
/* watch_eig.c: the tracked extremes (status; their message in msg) */
OVK_HIDDEN int ovk_eig_make(ovk_sim *s);
OVK_HIDDEN void ovk_eig_free(ovk_watch_eig *e);
OVK_HIDDEN int ovk_eig_rows(ovk_sim *s, const double *y, const int *rows, double *w, int fresh, char *msg);
OVK_HIDDEN int ovk_eig_extremes(ovk_sim *s, const double *w, double *smin, double *smax);
OVK_HIDDEN void ovk_eig_order(ovk_watch_eig *e, const int *rows);
OVK_HIDDEN void ovk_sim_watch_adopt(ovk_sim *s);
OVK_HIDDEN double ovk_eig_rate(const ovk_sim *s, const double *u, double sigma, double dt);
OVK_HIDDEN double ovk_now(void);
/* watch_scale.c: the watch's rows equilibrated (rows of `width` values; body NULL: dense, else two
 * bodies' kh columns each), their column scaling into scale (nh; work: nh + k doubles), or a given
 * scaling applied; rows to unit 2-norm */
OVK_HIDDEN void ovk_watch_scale(double *w, int k, int width, const int *body, int kh, int nh, double *scale,
                                double *work);
OVK_HIDDEN void ovk_watch_apply(double *w, int k, int width, const int *body, int kh, const double *scale);
/* svd.c: one-sided Jacobi */
OVK_HIDDEN int ovk_jacobi_rows(double *B, int k, int r, double *Q);
/* bandsvd.c: the singular values and trailing right singular vectors of rows with narrow windows */
typedef struct {
    int k, rows, w;        /* rows given, A's rows (max(n, k)), R's upper band */
    double *A, *d, *e;     /* A = Q R (R in A's upper triangle, columns in `order`), the bidiagonal */
    double *basis, *v;     /* scratch of ovk_bsv_null */
    int *order;            /* order[c]: the given row that is A's column c */
    double bound;          /* an upper bound of sigma_1 (Gershgorin on the Golub-Kahan matrix) */
} ovk_bsv;
OVK_HIDDEN size_t ovk_bsv_doubles(int k, int n);
OVK_HIDDEN int ovk_bsv_factor(const double *B, int k, int n, double *work, ovk_bsv *f);
OVK_HIDDEN int ovk_bsv_below(const ovk_bsv *f, double x);
OVK_HIDDEN double ovk_bsv_value(const ovk_bsv *f, int i);
OVK_HIDDEN void ovk_bsv_null(ovk_bsv *f, int p, double mu, double *N);
OVK_EXPORT int ovk_band_svd(const double *B, int k, int n, int p, double mu, double *sv, double *N);

/* failures: the status, with its message written into d->msg (printf format) */
OVK_HIDDEN int ovk_fail(ovk_data *d, int status, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
/* The friction joints as "joints[a], joints[b], ..." into out (size bytes, cut there; the
 * bindings put the names in), for the messages of a friction solve that failed. */
OVK_HIDDEN void ovk_friction_joint_list(const ovk_model *M, char *out, size_t size);

/* frames.c */
OVK_HIDDEN int ovk_slot(const ovk_model *M, int b);
/* drivers.c: a planar translational joint's slide at the frames (the drivers' displacement and the
 * sensors', one formula): its points' offsets ai = R_i s_A, bv = R_j s_B, the guide's normal u =
 * R_j g (g = Omega^T v / |v|) and its rate, the gap dd = r_i + ai - r_j - bv and its rate, the bodies'
 * angular velocities; the displacement is dd . u */
typedef struct {
    double ai[2], bv[2], u[2], udot[2], dd[2], ddot[2], wi, wj;
} ovk_slide;
OVK_HIDDEN void ovk_planar_slide(const ovk_model *M, const ovk_frames *f, int j, ovk_slide *s);
OVK_HIDDEN void ovk_frames_build(const ovk_model *M, const double *q, const double *h, ovk_frames *f);

/* joints.c: the joint table */
OVK_HIDDEN void ovk_joint_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                               double *gam);
OVK_HIDDEN void ovk_constraint_rows(const ovk_model *M, ovk_data *d, const double *q);
OVK_HIDDEN void ovk_joint_friction_setup(const ovk_model *M, const ovk_frames *f, int j, const double *Ji,
                                         ovk_fctx *cx);
OVK_HIDDEN void ovk_joint_friction_forces(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam,
                                          double *Qi, double *Qj);
OVK_HIDDEN void ovk_joint_friction_jac(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam,
                                       double *dQi, double *dQj);
OVK_HIDDEN double ovk_joint_friction_output(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam);

/* joints_planar.c */
OVK_HIDDEN void ovk_revolute_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji,
                                  double *Jj, double *gam);
OVK_HIDDEN void ovk_translational_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji,
                                       double *Jj, double *gam);
OVK_HIDDEN void ovk_planar_friction_setup(const ovk_model *M, const ovk_frames *f, int j, const double *Ji,
                                          ovk_fctx *cx);
OVK_HIDDEN void ovk_planar_paux(const ovk_fctx *cx, const double *lam, double *p);
OVK_HIDDEN void ovk_planar_friction_forces(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam,
                                           double *Qi, double *Qj);
OVK_HIDDEN void ovk_planar_friction_jac(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam,
                                        double *dQi, double *dQj);
OVK_HIDDEN double ovk_planar_friction_output(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam);
OVK_HIDDEN void ovk_line_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                              double *gam);
OVK_HIDDEN void ovk_line_friction_setup(const ovk_model *M, const ovk_frames *f, int j, ovk_fctx *cx);
OVK_HIDDEN void ovk_line_friction_forces(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *Qi,
                                         double *Qj);
OVK_HIDDEN void ovk_line_friction_jac(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam, double *dQi,
                                      double *dQj);
OVK_HIDDEN double ovk_line_friction_output(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam);

/* joints_distance.c */
OVK_HIDDEN void ovk_distance_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji,
                                  double *Jj, double *gam);

/* joints_spherical.c */
OVK_HIDDEN void ovk_spherical_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji,
                                   double *Jj, double *gam);
OVK_HIDDEN void ovk_spherical_friction_setup(const ovk_model *M, const ovk_frames *f, int j, ovk_fctx *cx);
OVK_HIDDEN void ovk_spherical_friction_forces(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam,
                                              double *Qi, double *Qj);
OVK_HIDDEN void ovk_spherical_friction_jac(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam,
                                           double *dQi, double *dQj);
OVK_HIDDEN double ovk_spherical_friction_output(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam);

/* drivers.c */
OVK_HIDDEN void ovk_driver_motion(const double *c, double t, double *out);
OVK_HIDDEN void ovk_driver_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                                double *gam);
OVK_HIDDEN double ovk_driver_phit(const ovk_model *M, int j, double t);

/* joints_spatial.c */
OVK_HIDDEN void ovk_axis_rows(const ovk_model *M, const ovk_frames *f, int j, double *phi, double *Ji, double *Jj,
                              double *gam);
OVK_HIDDEN int ovk_axis_reaction(const ovk_model *M, const ovk_frames *f, int j, const double *fi, double *out);
OVK_HIDDEN void ovk_axis_friction_setup(const ovk_model *M, const ovk_frames *f, int j, const double *Ji,
                                        ovk_fctx *cx);
OVK_HIDDEN void ovk_axis_friction_forces(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam,
                                         double *Qi, double *Qj);
OVK_HIDDEN void ovk_axis_friction_jac(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam,
                                      double *dQi, double *dQj);
OVK_HIDDEN double ovk_axis_friction_output(const ovk_model *M, int j, const ovk_fctx *cx, const double *lam);

/* loads.c */
OVK_HIDDEN int ovk_loads(const ovk_model *M, ovk_data *d, double t);
/* inputs.c: the inputs' generalized forces at t added to Q (nh; frames of d built), the sensors */
OVK_HIDDEN void ovk_input_forces(const ovk_model *M, const ovk_data *d, double t, double *Q);
OVK_EXPORT int ovk_set_inputs(const ovk_model *M, ovk_data *d, const double *u, const double *du, double t_ref);
OVK_EXPORT int ovk_sensors(const ovk_model *M, ovk_data *d, const double *y, const double *y0, int j, double *out);
OVK_EXPORT int ovk_sim_set_inputs(ovk_sim *s, const double *u, const double *du);
/* drivers.c: the time of the drivers' equations for the rows that follow (ovk_rows, ovk_rows_sparse),
 * and Phi_t (m) of the last rows evaluated in d */
OVK_EXPORT int ovk_set_time(ovk_data *d, double t);
OVK_EXPORT int ovk_phi_t(const ovk_model *M, const ovk_data *d, double *out);
OVK_HIDDEN void ovk_spring_points(const ovk_model *M, const ovk_frames *f, const double *lp, int bi, int bj,
                                  double *pi, double *pj);

/* kkt.c */
OVK_HIDDEN void ovk_kkt_rhs(const ovk_model *M, ovk_data *d, const double *h);
OVK_HIDDEN int ovk_kkt_solve(const ovk_model *M, ovk_data *d);
OVK_HIDDEN void ovk_kkt_friction_columns(const ovk_model *M, ovk_data *d);
OVK_HIDDEN void ovk_kkt_refine(const ovk_model *M, ovk_data *d, double *r);
OVK_HIDDEN void ovk_kkt_accelerations(const ovk_model *M, ovk_data *d, double *lam, double *hdot);

/* kkt_minnorm.c, compliance.c: redundancy "min-norm" and "compliant" */
OVK_HIDDEN size_t ovk_redundancy_doubles(const ovk_model *M);
OVK_HIDDEN int ovk_check_redundancy(const ovk_model *M, ovk_data *d);
OVK_HIDDEN int ovk_minnorm_factor(const ovk_model *M, ovk_data *d);
OVK_HIDDEN void ovk_minnorm_solve_many(const ovk_model *M, ovk_data *d, double *B, int nc);
OVK_HIDDEN int ovk_compliant_solve(const ovk_model *M, ovk_data *d, const double *h);
OVK_HIDDEN void ovk_compliant_columns(const ovk_model *M, ovk_data *d);
OVK_HIDDEN double ovk_row_rate(const ovk_model *M, const ovk_data *d, int p, const double *h);
OVK_HIDDEN int ovk_axis_group(const ovk_model *M, const ovk_data *d, int a, int rot, const double *h, double FU[3][3],
                              double *phi, double *rate);
OVK_HIDDEN int ovk_kkt_al_solve(const ovk_model *M, ovk_data *d);
OVK_HIDDEN void ovk_kkt_al_columns(const ovk_model *M, ovk_data *d);

/* kkt_al.c: the augmented Lagrangian solve over the kept rows (formulation AL), banded */
typedef struct { int n; const int *rows, *rbody; } ovk_rowset; /* rows of Phi_h, each with its two bodies */
OVK_HIDDEN ovk_rowset ovk_al_kept(const ovk_model *M);
OVK_HIDDEN void ovk_rowset_times(const ovk_model *M, const ovk_data *d, const ovk_rowset *rs, const double *v,
                                 double *y); /* y = Phi_h v over the rows of rs (their two bodies) */
OVK_HIDDEN ovk_rowset ovk_al_all(const ovk_model *M, const ovk_data *d);
OVK_HIDDEN void ovk_al_make_rows(const ovk_model *M, ovk_data *d);
OVK_HIDDEN int ovk_al_half_band(const ovk_model *M);
OVK_HIDDEN size_t ovk_al_doubles(const ovk_model *M);
enum { OVK_AL_SLOT_BASE, OVK_AL_SLOT_RHS, OVK_AL_SLOT_X, OVK_AL_SLOT_UNIT, OVK_AL_SLOT_RES, OVK_AL_SLOT_LAMC,
       OVK_AL_SLOT_ZERO, OVK_AL_SLOT_P1, OVK_AL_SLOT_P2, OVK_AL_SLOT_P3, OVK_AL_SLOT_PR1, OVK_AL_SLOT_PR2,
       OVK_AL_SLOT_END };
OVK_HIDDEN double *ovk_al_slot(const ovk_model *M, const ovk_data *d, int which);
#define OVK_AL_ALPHA_PROJ 1e6 /* the projections' penalty, relative to M over J^T J (kkt_al.c) */
#define OVK_DIRECT_RATIO 1e-3 /* sim.c: the watch's r at a step's start above which kkt_al.c may solve directly */
#define OVK_PASS_REGULAR 2e-5 /* kkt_al.c: least spread of S's squared pivots for the direct solve (sim_pass.c) */
#define OVK_PASS_AT_STATE 1e-4 /* sim_pass.c: that spread at a state's projection for its own direct solve */
#define OVK_PROJ_SLACK 10.0   /* project.c: |Phi| up to this times tol is accepted once the corrections stall */
OVK_HIDDEN int ovk_al_factor(const ovk_model *M, ovk_data *d, const ovk_rowset *rs, double alpha_rel);
OVK_HIDDEN void ovk_al_solve(const ovk_model *M, ovk_data *d, const ovk_rowset *rs, const double *Q, const double *g,
                             double *x, double *lam);

/* friction.c */
OVK_HIDDEN double ovk_law_magnitude(const double *lp, int law, double speed);
OVK_HIDDEN double ovk_law_coefficient(const double *lp, int law, double v);
OVK_HIDDEN double ovk_law_mu_over_speed(const double *lp, int law, double s);
OVK_HIDDEN double ovk_law_mu_over_speed_slope(const double *lp, int law, double s);
OVK_EXPORT int ovk_law_eval(const double *lp, int law, double s, double *mu_over_s, double *slope);
OVK_HIDDEN int ovk_friction(const ovk_model *M, ovk_data *d, int guess_mode, const double *guess, double *qf,
                            int *iterations, int *damped);
OVK_HIDDEN void ovk_forces_reduced(const ovk_model *M, ovk_data *d, const double *x, double *qf);

/* friction_robust.c: the fixed point and finite-difference Newton after Newton gave up */
OVK_HIDDEN size_t ovk_robust_doubles(int nx, int nc);
OVK_HIDDEN int ovk_friction_robust(const ovk_model *M, ovk_data *d, const double *start, double *qf, int *iterations);

/* linalg.c */
OVK_HIDDEN int ovk_band_order(int n, int nb, const int *bodies, const int *rows, int keep, int *order, int *obody,
                              long long *key, int *span);
OVK_HIDDEN int ovk_band_cholesky(double *A, int n, int p);
OVK_HIDDEN void ovk_band_solve(const double *U, int n, int p, double *b);
OVK_HIDDEN void ovk_band_solve_many(const double *U, int n, int p, double *B, int nc);
OVK_HIDDEN int ovk_lu_factor(double *A, int n, int *piv);
OVK_HIDDEN void ovk_lu_solve(const double *A, int n, const int *piv, double *b);

/* lu.c: complex LU with partial pivoting (entries as (re, im) pairs, row-major) */
OVK_HIDDEN int ovk_zlu_factor(double *A, int n, int *piv);
OVK_HIDDEN void ovk_zlu_solve(const double *A, int n, const int *piv, double *b);

/* outputs.c */
OVK_HIDDEN void ovk_reported(const ovk_model *M, ovk_data *d, const double *y, const double *lam, double *reac,
                             double *fric);

/* rates.c */
OVK_HIDDEN int ovk_rates(const ovk_model *M, ovk_data *d, const double *q, const double *h, double *qdot);

/* api.c: the library's entry points */
OVK_EXPORT int ovk_abi(void);
OVK_EXPORT ovk_data *ovk_make_data(const ovk_model *M);
OVK_EXPORT void ovk_free_data(ovk_data *d);
OVK_EXPORT const char *ovk_message(const ovk_data *d);
OVK_EXPORT int ovk_data_status(const ovk_data *d);
OVK_EXPORT int ovk_evaluate(const ovk_model *M, ovk_data *d, double t, const double *y, int guess_mode,
                            const double *guess, double *ydot, double *lam, double *qf, int *iterations, int *damped);
OVK_EXPORT int ovk_rows(const ovk_model *M, ovk_data *d, const double *y, double *phi, double *J, double *gam);
/* ovk_rows without the copies: Phi, Phi_h, gamma at y left in d->phi, d->J, d->gam (until the next
 * evaluation in d), for the core's own callers that read them at once */
OVK_HIDDEN int ovk_rows_in(const ovk_model *M, ovk_data *d, const double *y);
/* rows_sparse.c: Phi (m) and Phi_h at y as m x 2 nh_b entries (columns, -1 unused; values): the
 * equations' two bodies' columns, the values of ovk_rows */
OVK_EXPORT int ovk_rows_sparse(const ovk_model *M, ovk_data *d, const double *y, double *phi, int *cols, double *vals);
OVK_EXPORT int ovk_evaluate_robust(const ovk_model *M, ovk_data *d, const double *y, const double *start, double *ydot,
                                   double *lam, double *qf, int *iterations);
OVK_EXPORT int ovk_friction_joint_at(const ovk_model *M, ovk_data *d, const double *y, int n, const double *lam,
                                     double *Q, double *dQ);
OVK_EXPORT int ovk_outputs(const ovk_model *M, ovk_data *d, const double *y, const double *lam, double *reac,
                           double *fric);

/* project.c: the mass-orthogonal projection of a state onto Phi = 0 and Phi_h h = 0 (every equation) */
OVK_EXPORT int ovk_project(const ovk_model *M, ovk_data *d, double t, double *y, double tol, int max_iter,
                           double *drift);

/* sim.c, sim_state.c: a run in C (see ovk_sim above) */
OVK_EXPORT ovk_sim *ovk_sim_new(const ovk_model *M, const ovk_sim_opts *o, double t0, const double *y0);
OVK_EXPORT void ovk_sim_free(ovk_sim *s);
OVK_EXPORT int ovk_sim_status(const ovk_sim *s);
OVK_EXPORT const char *ovk_sim_message(const ovk_sim *s);
OVK_EXPORT int ovk_sim_step(ovk_sim *s);
OVK_EXPORT int ovk_sim_advance(ovk_sim *s, double t_target, long long max_steps, double max_wall_time, double *y);
OVK_EXPORT void ovk_sim_state_vector(const ovk_sim *s, double *y);
OVK_EXPORT void ovk_sim_info(const ovk_sim *s, double *info);
OVK_EXPORT int ovk_sim_outputs(ovk_sim *s, double t, const double *y, double *reac, double *fric);
OVK_EXPORT int ovk_sim_energy(ovk_sim *s, double t, const double *y, double *out);
/* sim_out.c: the output rows of a run. An output: kind (OVK_OUT_*), a, b: a position's index into q,
 * a velocity's into h, a state entry's into y = [q, h] (as it is: quaternions not normalised), an energy's 0-3 (kinetic, potential, dissipated, applied), a reaction's joint
 * and entry (< OVK_NREAC), a friction output's joint (overcon.kernel.output_plan, the FMUs' plan). */
enum { OVK_OUT_POSITION = 1, OVK_OUT_VELOCITY = 2, OVK_OUT_STATE = 3, OVK_OUT_REACTION = 5, OVK_OUT_FRICTION = 6, OVK_OUT_ENERGY = 7,
       OVK_OUT_SENSOR = 8 };
typedef struct { int kind, a, b; } ovk_out;
OVK_EXPORT int ovk_plan_check(const ovk_model *M, const ovk_out *plan, int nout, char *msg);
OVK_EXPORT void ovk_state_outputs(const ovk_model *M, const ovk_out *plan, int nout, const double *y, double *out);
OVK_EXPORT int ovk_sim_derived_outputs(ovk_sim *s, const ovk_out *plan, int nout, double t, const double *y,
                                       const double *lam, double *reac, double *fric, double *out);
OVK_EXPORT int ovk_sim_output_row(ovk_sim *s, const ovk_out *plan, int nout, double t, const double *y, double *out);
OVK_EXPORT int ovk_sim_grid(ovk_sim *s, const ovk_out *plan, int nout, const double *times, long long nt,
                            double *values, long long *rows);
OVK_EXPORT size_t ovk_sim_state_size(const ovk_sim *s);
OVK_EXPORT int ovk_sim_get_state(ovk_sim *s, unsigned char *buf, size_t size);
OVK_EXPORT int ovk_sim_set_state(ovk_sim *s, const unsigned char *buf, size_t size);
/* watch_eig.c: the watch's sigma_min, sigma_max of the kept rows at y into out[2], warm-started from
 * the run's tracked vectors (cold = 0) or from the fixed start (1); the run is left as it was */
OVK_EXPORT int ovk_sim_watch_extremes(ovk_sim *s, const double *y, int cold, double *out);
/* unique.c, sim.c: uniqueness along the motion; the run's events */
OVK_EXPORT int ovk_unique(const ovk_model *M, ovk_data *d, const double *y, int *rank, int *unique);
OVK_EXPORT int ovk_pack_kept(const ovk_model *M, const int *retained, int nR, int *xrows, int *fx, int *rbody,
                             int *iwork);
OVK_EXPORT int ovk_sim_uniqueness(const ovk_sim *s, int *rank, int *unique);
OVK_EXPORT int ovk_sim_events(const ovk_sim *s);
OVK_EXPORT int ovk_sim_effort_unique(const ovk_sim *s);
OVK_EXPORT const char *ovk_sim_event(const ovk_sim *s, int k, double *t, int *kind);

#endif
