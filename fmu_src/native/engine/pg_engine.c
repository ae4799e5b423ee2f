/* See pg_engine.h. Each function names the Python method it follows (simulator.py); the order of
 * the floating-point operations is that of the Python code, so both give the same bits. */
#include "pg_engine.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pg_support.h"

/* the last step's segment, and the one the next step builds (the two change places when it is taken:
 * no copy of a segment a step) */
#define SEG(e) (&(e)->segs[(e)->seg_i])
#define NEXT_SEG(e) (&(e)->segs[!(e)->seg_i])

/* the model's numbers of states, discrete entries and outputs: constants in a native FMU (PG_N,
 * pg_pairs.h) */
#define NX(e) PG_N((e)->nx)
#if defined(PG_NQ) && defined(PG_NY)
#define NQ(e) PG_NQ
#define NY(e) PG_NY
#else
#define NQ(e) ((e)->nq)
#define NY(e) ((e)->model->ny)
#endif

/* the model: in a native FMU (PG_ONE_MODEL, its pg_sizes.h) the one it is built for, by name, so that
 * the compiler calls its functions directly and inlines them (a link-time optimized build: the flow
 * into the stages, the outputs into the serving; the same operations, the same bits); else any
 * model, through the engine's pointer */
#ifdef PG_ONE_MODEL
extern const PgModel PG_ONE_MODEL;
#define MODEL(e) (&PG_ONE_MODEL)
#else
#define MODEL(e) ((e)->model)
#endif

#define EPS 2.220446049250313e-16
#define SAFETY 0.9
#define MIN_FACTOR 0.2
#define MAX_FACTOR 10.0
#define MIN_STEP_ULPS 10
#define START_STEP_ULPS 100
#define BUDGET_WINDOW 1.0
#define BUDGET_WARN_FRACTION 0.2
#define MIN_TIME_SCALE 1e-9
#define UNBOUNDED_STEP_FACTOR 10.0
#define STORM_EVENTS 5
#define ABS_TOL_MAX_FRACTION 1e-3
#define DOMAIN_SLACK 10.0
/* a guard is at zero within BAND_ULPS roundings of its states and time (guard_band); its direction
 * there is its change along the flow over RATE_STEP max(|t|, 1) each way (guard_change) */
#define BAND_ULPS 8.0
#define RATE_STEP 1.4901161193847656e-08
/* an event that fires this many times in a row from zero, its guard never leaving its band in
 * between, is an accumulation (Zeno): the storm error */
#define ZERO_REFIRES 5
/* a time event is due at t when its instant is within this many ulps of max(|t|, 1) */
#define TIME_EVENT_ULPS 16.0
/* method = 0: DOPRI5's stiffness test (Hairer-Wanner II, IV.10; dopri5.f): h*rho > STIFF_H_RHO in
 * STIFF_STEPS accepted steps (CALM_RESET steps below it in a row forget them) switches to Rodas5P;
 * h*rho < STIFF_H_RHO in CALM_STEPS accepted Rodas5P steps in a row (rho from the Jacobian) back.
 * dopri5.f tests 3.25; this engine's step control (no PI term) settles a stability-bound DOPRI5
 * at h*rho = 3.13 ... 3.17 (the Penetrator's contacts), below it: hence 3.0 */
#define STIFF_H_RHO 3.0
#define STIFF_STEPS 15
#define CALM_RESET 6
#define CALM_STEPS 15
#define M_RODAS 1
#define M_DOPRI5 5
#define M_DOP853 8

/* an error of the model's own (PG_RAISE) or of its arithmetic (PG_ARITH), as raised in Python */
#define TRY(call) do { int rc_ = (call); if (rc_) return rc_; } while (0)

static int rearm(PgEngine *e, const signed char *was, int own, double own_g, const double *x_pre, const double *q_pre);
static int time_events_init(PgEngine *e, double t0);

static double pmax(double a, double b) { return b > a ? b : a; } /* Python's max(a, b) */
static double pmin(double a, double b) { return b < a ? b : a; } /* Python's min(a, b) */

static const char *event_name(const PgEngine *e, int i)
{
    return i < MODEL(e)->ne ? MODEL(e)->event_names[i] : MODEL(e)->time_event_names[i - MODEL(e)->ne];
}

/* ---- messages ------------------------------------------------------------------------------ */
static int raise_text(PgEngine *e, const char *text)
{
    pg_msg_clear(&e->msg);
    pg_msg_str(&e->msg, text);
    return PG_RAISE;
}

static void param_repr(const PgEngine *e, int i, PgMsg *m)
{
    pg_msg_value(m, e->p[i], MODEL(e)->parameter_kinds[i], "r");
}

static int param_index(const PgEngine *e, const char *name)
{
    for (int i = 0; i < e->np; ++i)
        if (strcmp(MODEL(e)->parameter_names[i], name) == 0) return i;
    return -1;
}

/* "m = 1.0, g = 9.81" for the names of a scale */
static void named_values(const PgEngine *e, const PgScale *sc, PgMsg *m)
{
    for (int j = 0; j < sc->n_names; ++j) {
        if (j) pg_msg_str(m, ", ");
        pg_msg_str(m, sc->names[j]);
        pg_msg_str(m, " = ");
        int i = param_index(e, sc->names[j]);
        if (i >= 0) param_repr(e, i, m);
    }
}

/* _extreme_parameters: the parameters of the most extreme magnitude */
static void extreme_parameters(const PgEngine *e, PgMsg *m)
{
    int idx[PG_MAX_P], n = 0;
    double mag[PG_MAX_P];
    for (int i = 0; i < e->np; ++i) {
        double v = e->p[i];
        if (v == 0.0 || !isfinite(v)) continue;
        mag[n] = fabs(log10(fabs(v)));
        idx[n++] = i;
    }
    /* sorted by (magnitude, name, value), largest first, as Python sorts the tuples */
    for (int a = 1; a < n; ++a) {
        for (int b = a; b > 0; --b) {
            int i = idx[b - 1], j = idx[b];
            double mi = mag[b - 1], mj = mag[b];
            int c = strcmp(MODEL(e)->parameter_names[i], MODEL(e)->parameter_names[j]);
            int less = mi < mj || (mi == mj && (c < 0 || (c == 0 && e->p[i] < e->p[j])));
            if (!less) break;
            idx[b - 1] = j, idx[b] = i, mag[b - 1] = mj, mag[b] = mi;
        }
    }
    pg_msg_str(m, "the values exceed floating-point range");
    if (n) pg_msg_str(m, "; parameters of the most extreme magnitude: ");
    for (int k = 0; k < n && k < 3; ++k) {
        if (k) pg_msg_str(m, ", ");
        pg_msg_str(m, MODEL(e)->parameter_names[idx[k]]);
        pg_msg_str(m, " = ");
        param_repr(e, idx[k], m);
    }
}

/* _arithmetic_error: a floating-point failure in the model, with where it happened */
static int arithmetic_error(PgEngine *e, const PgMsg *detail, const char *where_prefix, double where_t,
                            const char *where_suffix)
{
    const char *kind = detail->arith == PG_ZERO_DIVISION ? "division by zero"
                       : detail->arith == PG_OVERFLOW    ? "overflow"
                                                         : "domain error";
    char text[PG_MSG_MAX];
    snprintf(text, sizeof text, "%s", detail->text);
    PgMsg *m = &e->msg;
    pg_msg_clear(m);
    pg_msg_printf(m, "floating-point %s in the model at %s", kind, where_prefix);
    if (where_suffix) {
        pg_msg_value(m, where_t, 'f', "r");
        pg_msg_str(m, where_suffix);
    }
    pg_msg_printf(m, " (%s): ", text);
    extreme_parameters(e, m);
    return PG_RAISE;
}

/* a PG_ARITH of a model call becomes the DomainError text (the binding raises DomainError); PG_RAISE stays */
static int at_time(PgEngine *e, int rc, const char *prefix, double t, const char *suffix)
{
    if (rc == PG_ARITH) return arithmetic_error(e, &e->msg, prefix, t, suffix);
    return rc;
}

/* "the flow failed at t = 0.3 s (state h = 0.5, v = -2.9): " ("the guard of event bounce ...") */
static void function_failed_at(const PgEngine *e, PgMsg *m, const char *function, int event, double t,
                               const double *x)
{
    pg_msg_str(m, function);
    if (event >= 0) {
        pg_msg_str(m, " of event ");
        pg_msg_str(m, event_name(e, event));
    }
    pg_msg_str(m, " failed at t = ");
    pg_msg_value(m, t, 'f', "r");
    pg_msg_str(m, " s");
    for (int i = 0; i < NX(e); ++i) {
        pg_msg_str(m, i ? ", " : " (state ");
        pg_msg_str(m, MODEL(e)->state_names[i]);
        pg_msg_str(m, " = ");
        pg_msg_value(m, x[i], 'f', "r");
    }
    pg_msg_str(m, NX(e) ? "): " : ": ");
}

/* every v[i] finite: the plain sum is finite if they all are (a non-finite value makes it inf or NaN),
 * one addition a value; a sum that overflows from finite values is rare and checked value by value */
static inline int all_finite(const double *v, int n)
{
    double acc = 0.0;
    for (int i = 0; i < n; ++i) acc += v[i];
    if (isfinite(acc)) return 1;
    for (int i = 0; i < n; ++i)
        if (!isfinite(v[i])) return 0;
    return 1;
}

/* One call of a function of the model during the run — `function` ("the flow", "the guard", "the
 * jump", "the outputs") of `event` (or -1) at (t, x) — with its result code `rc` and the n values it
 * returned (value i named by the format `label` of names[i]; names NULL: one unnamed value). PG_OK with finite
 * values passes. A model error (the Python binding's text carries the exception's type, file and
 * line), an arithmetic failure or a non-finite value at a finite state ends the run with one
 * message (PG_RAISE, in m) naming the function, the time, the state and the cause. (A non-finite
 * state is left to the engine's own checks: a trial stage that overflowed, a singular W.) */
static int model_failed(const PgEngine *e, PgMsg *m, int rc, const char *function, int event, double t,
                        const double *x, const double *v, int n, const char *label, const char *const *names);

/* the fast path of model_failed, inline: a call that returned finite values passes */
static inline int model_call(const PgEngine *e, PgMsg *m, int rc, const char *function, int event, double t,
                             const double *x, const double *v, int n, const char *label, const char *const *names)
{
    if (rc == PG_OK && all_finite(v, n)) return PG_OK;
    return model_failed(e, m, rc, function, event, t, x, v, n, label, names);
}

/* the index of the first value that is not finite, or -1 */
static int first_non_finite(const double *v, int n)
{
    for (int i = 0; i < n; ++i)
        if (!isfinite(v[i])) return i;
    return -1;
}

static int model_failed(const PgEngine *e, PgMsg *m, int rc, const char *function, int event, double t,
                        const double *x, const double *v, int n, const char *label, const char *const *names)
{
    if (rc == PG_NO_JVP) return rc;
    int bad = -1;
    if (rc == PG_OK) {
        bad = first_non_finite(v, n);
        if (bad < 0) return PG_OK;
        for (int i = 0; i < NX(e); ++i)
            if (!isfinite(x[i])) return PG_OK;
    }
    char cause[PG_MSG_MAX];
    snprintf(cause, sizeof cause, "%s", m->text);
    int arith = m->arith;
    pg_msg_clear(m);
    function_failed_at(e, m, function, event, t, x);
    if (rc == PG_OK) {
        pg_msg_str(m, "it returned ");
        if (names) {
            pg_msg_printf(m, label, names[bad]);
            pg_msg_str(m, " = ");
        }
        pg_msg_value(m, v[bad], 'f', "r");
        pg_msg_str(m, " (a model function must return finite numbers)");
    } else if (rc == PG_ARITH) {
        pg_msg_printf(m, "floating-point %s (%s)", arith == PG_ZERO_DIVISION ? "division by zero"
                                                   : arith == PG_OVERFLOW    ? "overflow"
                                                                             : "domain error", cause);
        if (arith == PG_OVERFLOW) {
            pg_msg_str(m, "; ");
            extreme_parameters(e, m);
        }
    } else {
        pg_msg_str(m, cause);
    }
    m->arith = 0;
    return PG_RAISE;
}

/* A flow that returns a non-finite rate at a finite state (a trial stage): the step is rejected as
 * before (a wild trial may recover at a smaller step), and the failure is noted; if the step size
 * then collapses, the note is the run's message: the flow named, with its time, state and value. */
#define NOTE_NEAR 1e-3 /* a stage this near the step's start state (relative to 1 + its magnitude) */
/* a stage's state y near the step's start: a wild trial of a stiff or singular step (a state far out,
 * the rate overflowing) is the step size's problem, told by the collapse's own message */
static int near_start(const PgEngine *e, const double *y)
{
    for (int i = 0; i < NX(e); ++i)
        if (!isfinite(y[i]) || fabs(y[i] - e->x[i]) > NOTE_NEAR * (1.0 + fabs(e->x[i]))) return 0;
    return 1;
}

static void note_flow(PgEngine *e, double t, const double *y, const double *dy)
{
    int bad = first_non_finite(dy, NX(e));
    if (bad < 0 || !near_start(e, y)) return;
    PgMsg *m = &e->note;
    pg_msg_clear(m);
    function_failed_at(e, m, "the flow", -1, t, y);
    pg_msg_printf(m, "it returned d%s/dt = ", MODEL(e)->state_names[bad]);
    pg_msg_value(m, dy[bad], 'f', "r");
    pg_msg_str(m, " (a model function must return finite numbers)");
    e->has_note = 1;
}

/* ---- the model, in the current (q, u) ----------------------------------------------------- */
/* the inputs at time t: held (e->u, today's arithmetic untouched) or on their line from t_u */
static const double *u_at(PgEngine *e, double t)
{
    if (!e->has_du) return e->u;
    double dt = t - e->t_u;
    for (int i = 0; i < e->nu; ++i) e->u_t[i] = e->u[i] + e->du[i] * dt;
    return e->u_t;
}

static PG_NOINLINE int model_fun_checked(PgEngine *e, double t, const double *y, double *dy, PgMsg *m);

static int model_fun(void *ctx, double t, const double *y, double *dy, PgMsg *m)
{
    PgEngine *e = ctx;
    /* the steps with held inputs: the flow as it is, a tail call (6 to 12 a step) */
    if (!e->probe && !e->has_du) return MODEL(e)->flow(t, y, e->q, e->u, e->p, dy, m);
    return model_fun_checked(e, t, y, dy, m);
}

/* model_fun with inputs on their line, or in probe_step */
static PG_NOINLINE int model_fun_checked(PgEngine *e, double t, const double *y, double *dy, PgMsg *m)
{
    if (!e->probe) return MODEL(e)->flow(t, y, e->q, u_at(e, t), e->p, dy, m); /* the steps: as it is */
    /* probe_step: the same step again, each value of the flow checked, a failure named */
    int rc = MODEL(e)->flow(t, y, e->q, u_at(e, t), e->p, dy, m);
    if (rc == PG_OK) {
        if (!all_finite(dy, NX(e))) note_flow(e, t, y, dy);
        return PG_OK;
    }
    int overflow = rc == PG_ARITH && m->arith == PG_OVERFLOW;
    rc = model_failed(e, m, rc, "the flow", -1, t, y, dy, NX(e), "d%s/dt", MODEL(e)->state_names);
    if (overflow && near_start(e, y)) e->note = *m, e->has_note = 1; /* (a trial's overflow: step()) */
    return rc;
}

/* guard i at the state x of time t (with the inputs of t) */
static int guard_at(PgEngine *e, int i, double t, const double *x, double *g)
{
    int rc = MODEL(e)->guard(i, t, x, e->q, u_at(e, t), e->p, g, &e->msg);
    return model_call(e, &e->msg, rc, "the guard", i, t, x, g, 1, "%s", NULL);
}

/* ---- the Jacobian (Rodas5P) ---------------------------------------------------------------- */
static const double NO_INPUT_MOVE[PG_MAX_U];
#define CBRT_EPS 6.055454452393343e-06 /* cbrt(EPS) */

/* J = d flow / dx at (t, y) and dT = d flow / dt, unless they are kept for this point: exact columns
 * from the model's flow_jvp (dual numbers) where it has one, central differences otherwise, and
 * from the first PG_NO_JVP of its flow_jvp on (the whole Jacobian again, by differences); dT by a
 * forward difference (exactly 0 for a flow that does not read t) */
static int jacobian(PgEngine *e, double t, const double *y, const double *f)
{
    int n = NX(e);
    size_t nb = sizeof(double) * (size_t)n;
    if (e->jac_ok && e->jac_t == t && memcmp(e->jac_y, y, nb) == 0) return PG_OK;
    double col[PG_MAX_X], yp[PG_MAX_X];
    for (int j = 0; j < n; ++j) {
        if (MODEL(e)->flow_jvp && !e->jvp_off) {
            double sx[PG_MAX_X] = {0};
            sx[j] = 1.0;
            int rc = MODEL(e)->flow_jvp(t, y, e->q, u_at(e, t), e->p, sx, NO_INPUT_MOVE, col, &e->msg);
            if (rc == PG_NO_JVP) {
                e->jvp_off = 1;
                j = -1; /* every column again, by differences */
                continue;
            }
            TRY(rc);
            for (int i = 0; i < n; ++i) e->J[i * PG_MAX_X + j] = col[i];
        } else { /* central differences: a Rosenbrock method's order rests on the Jacobian */
            double col_m[PG_MAX_X];
            memcpy(yp, y, nb);
            double d = CBRT_EPS * pmax(1e-5, fabs(y[j]));
            yp[j] = y[j] + d;
            double up = yp[j];
            TRY(model_fun(e, t, yp, col, &e->msg));
            yp[j] = y[j] - d;
            double width = up - yp[j]; /* the step as represented */
            TRY(model_fun(e, t, yp, col_m, &e->msg));
            for (int i = 0; i < n; ++i) e->J[i * PG_MAX_X + j] = (col[i] - col_m[i]) / width;
        }
    }
    double dt = sqrt(EPS) * pmax(fabs(t), 1.0);
    dt = (t + dt) - t;
    TRY(model_fun(e, t + dt, y, col, &e->msg));
    for (int i = 0; i < n; ++i) e->dT[i] = (col[i] - f[i]) / dt;
    /* rho <= min(|J|_inf, |J|_1): a bound of the spectral radius, for the switch back */
    double r_inf = 0.0, r_one = 0.0;
    for (int i = 0; i < n; ++i) {
        double a = 0.0, b = 0.0;
        for (int j = 0; j < n; ++j) a += fabs(e->J[i * PG_MAX_X + j]), b += fabs(e->J[j * PG_MAX_X + i]);
        r_inf = pmax(r_inf, a), r_one = pmax(r_one, b);
    }
    e->jac_rho = pmin(r_inf, r_one);
    e->jac_t = t;
    memcpy(e->jac_y, y, nb);
    e->jac_ok = 1;
    e->n_jacobians += 1;
    return PG_OK;
}

/* one step of the method `method` (5, 8 or 1) from (t, y) with f = flow(t, y) */
static int pair_step_of(PgEngine *e, int method, double t, const double *y, const double *f, double h,
                        double *y_new, double *f_new, double *K)
{
    if (method == M_DOP853) return pg_dop853_step(model_fun, e, t, y, f, h, NX(e), y_new, f_new, K, &e->msg);
    if (method == M_RODAS) {
        int singular = 0;
        TRY(jacobian(e, t, y, f));
        return pg_rodas_step(model_fun, e, t, y, f, h, NX(e), e->J, e->dT, y_new, f_new, K, &singular, &e->msg);
    }
    return pg_dopri5_step(model_fun, e, t, y, f, h, NX(e), y_new, f_new, K, &e->msg);
}

static int pair_step(PgEngine *e, double t, const double *y, const double *f, double h, double *y_new,
                     double *f_new, double *K)
{
    return pair_step_of(e, e->cur, t, y, f, h, y_new, f_new, K);
}

static double error_norm(const PgEngine *e, const double *K, double h, const double *y, const double *y_new)
{
    if (e->cur == M_DOP853) return pg_dop853_error_norm(K, h, y, y_new, e->atol, e->rtol, NX(e));
    if (e->cur == M_RODAS) {
        for (int i = 0; i < NX(e); ++i)
            if (!isfinite(y_new[i])) return INFINITY; /* W singular at this h: a smaller step */
        return pg_rodas_error_norm(K, y, y_new, e->atol, e->rtol, NX(e));
    }
    return pg_dopri5_error_norm(K, h, y, y_new, e->atol, e->rtol, NX(e));
}

static double error_exponent(const PgEngine *e) { return e->cur == M_DOP853 ? -1.0 / 8.0 : -1.0 / 5.0; }
static int pair_order(const PgEngine *e) { return e->cur == M_DOP853 ? 8 : 5; }
/* err^(error exponent) of the step control, for a finite err > 0: pow itself, for pg_pow (Python's
 * float ** float) has nothing to report here (no domain error, and no overflow: err^(-1/5) is at
 * most 4.9e-324^(-1/5) < 1e65) and would return this same value after its checks */
static double control_pow(const PgEngine *e, double err) { return pow(err, error_exponent(e)); }

/* DOPRI5's stiffness estimate h*rho = h |k7 - k6| / |y_new - Y6| (Hairer-Wanner II, IV.10): the
 * stages 6 and 7 are both at t + h, on Y6 and y_new; y_new - Y6 = h sum_j (b_j - a6j) k_j */
static double dopri5_h_rho(const PgEngine *e, const double *K, double h)
{
    static const double bma[6] = {35.0 / 384 - 9017.0 / 3168, 355.0 / 33, 500.0 / 1113 - 46732.0 / 5247,
                                  125.0 / 192 - 49.0 / 176, -2187.0 / 6784 + 5103.0 / 18656, 11.0 / 84};
    double num = 0.0, den = 0.0;
    for (int i = 0; i < NX(e); ++i) {
        double dk = K[6 * PG_MAX_X + i] - K[5 * PG_MAX_X + i], dy = 0.0;
        for (int j = 0; j < 6; ++j) dy += bma[j] * K[j * PG_MAX_X + i];
        dy *= h;
        num += dk * dk, den += dy * dy;
    }
    return den > 0.0 ? h * sqrt(num / den) : 0.0;
}

/* method = 0: after an accepted step of size h, the stiffness test of the method in use; a switch
 * is made before the next step */
static void stiffness_test(PgEngine *e, const double *K, double h)
{
    if (e->method != 0) {
        if (e->method == M_DOPRI5) e->h_rho = dopri5_h_rho(e, K, h); /* (the estimate only, for explicit_hint) */
        return;
    }
    if (e->cur == M_DOPRI5) {
        double hr = dopri5_h_rho(e, K, h);
        e->h_rho = hr;
        if (hr > STIFF_H_RHO) {
            e->calm_n = 0;
            if (++e->stiff_n >= STIFF_STEPS) e->switch_to = M_RODAS;
        } else if (++e->calm_n >= CALM_RESET) {
            e->stiff_n = 0;
        }
    } else {
        double hr = h * e->jac_rho;
        e->h_rho = hr;
        if (hr < STIFF_H_RHO) {
            if (++e->calm_n >= CALM_STEPS) e->switch_to = M_DOPRI5;
        } else {
            e->calm_n = 0;
        }
    }
}

/* an error's advice where an explicit method is integrating a problem that may be stiff (DOPRI5's
 * latest steps near its stability bound, or DOP853, which has no estimate): its solution dithers
 * across a level and its steps stay small at any tolerance — the stiff method is the remedy (a relay
 * on a lag of 1e-5 s under DOPRI5 at rel_tol 1e-4 ended in an "event storm ... Zeno behaviour" that
 * Rodas5P does not have; a user's audit, 2026-12-07) */
static void explicit_hint(const PgEngine *e, PgMsg *m)
{
    if (!(e->cur == M_DOP853 || (e->cur == M_DOPRI5 && e->h_rho > 1.0))) return;
    pg_msg_printf(m, ". The explicit method in use (%s) may be integrating a stiff problem here: method = 1 "
                     "(Rodas5P) is the stiff method", e->cur == M_DOP853 ? "DOP853" : "DOPRI5");
}

static void make_switch(PgEngine *e)
{
    int from = e->cur, to = e->switch_to;
    e->switch_to = 0;
    e->cur = to;
    e->stiff_n = e->calm_n = 0;
    e->n_switches += 1;
    if (e->on_switch) e->on_switch(e->hook_ctx, e, e->t, from, to, e->h_rho);
}

/* _Segment.__call__: the step's end points exactly, the dense output in between */
static int seg_at(PgEngine *e, PgSeg *seg, double t, double *out)
{
    if (t == seg->t1) {
        memcpy(out, seg->y1, sizeof(double) * (size_t)NX(e));
        return PG_OK;
    }
    if (t == seg->t0) {
        memcpy(out, seg->y0, sizeof(double) * (size_t)NX(e));
        return PG_OK;
    }
    double h = seg->t1 - seg->t0;
    if (!seg->dense_built) {
        if (seg->method == M_DOP853) {
            TRY(pg_dop853_dense(model_fun, e, seg->t0, seg->y0, seg->y1, h, seg->K, NX(e), seg->Q, &e->msg));
        } else if (seg->method == M_RODAS) {
            pg_rodas_dense(seg->K, NX(e), seg->Q);
        } else {
            pg_dopri5_dense(seg->K, NX(e), seg->Q);
        }
        seg->dense_built = 1;
    }
    if (seg->method == M_DOP853) pg_dop853_eval(seg->Q, seg->t0, h, seg->y0, t, NX(e), out);
    else if (seg->method == M_RODAS) pg_rodas_eval(seg->Q, seg->t0, h, seg->y0, seg->y1, t, NX(e), out);
    else pg_dopri5_eval(seg->Q, seg->t0, h, seg->y0, t, NX(e), out);
    return PG_OK;
}

static void make_seg(PgEngine *e, PgSeg *seg, double t0, double t1, const double *y0, const double *y1,
                     const double *f0, const double *K)
{
    size_t n = sizeof(double) * (size_t)NX(e);
    seg->t0 = t0, seg->t1 = t1;
    memmove(seg->y0, y0, n);
    memmove(seg->y1, y1, n);
    memmove(seg->f0, f0, n);
    /* the stages the method has (its dense output reads no other) */
    int stages = e->cur == M_DOP853 ? PG_MAX_STAGES : e->cur == M_RODAS ? PG_RODAS_STAGES : 7;
    if (K != seg->K) /* (a step's stages are computed in its segment) */
        for (int j = 0; j < stages; ++j) memmove(seg->K + j * PG_MAX_X, K + j * PG_MAX_X, n);
    seg->dense_built = 0;
    seg->method = e->cur;
}

static double sgn_of(const PgEngine *e, int i) { return MODEL(e)->event_direction[i] == PG_FALLING ? -1.0 : 1.0; }

/* ---- time scales and tolerances (prepare, _stiffness_text) -------------------------------- */
static int time_scales(PgEngine *e, PgScale *out, int *n, int filtered)
{
    *n = 0;
    if (!MODEL(e)->has_time_scales) return PG_OK;
    TRY(MODEL(e)->time_scales(e->p, out, n, &e->msg));
    if (filtered) {
        int k = 0;
        for (int i = 0; i < *n; ++i)
            if (out[i].value > 0 && isfinite(out[i].value)) out[k++] = out[i];
        *n = k;
    }
    return PG_OK;
}

static int stiffness_text(PgEngine *e, PgMsg *m) /* returns the number of time scales named */
{
    PgScale sc[PG_MAX_SCALES];
    int n = 0;
    PgMsg keep = e->msg;
    if (time_scales(e, sc, &n, 1) != PG_OK) n = 0;
    e->msg = keep;
    if (!n) {
        pg_msg_str(m, "the error control forces steps this small");
        return 0;
    }
    /* sorted(scales, key=value)[:2]: a stable sort */
    for (int a = 1; a < n; ++a)
        for (int b = a; b > 0 && sc[b].value < sc[b - 1].value; --b) {
            PgScale tmp = sc[b];
            sc[b] = sc[b - 1], sc[b - 1] = tmp;
        }
    pg_msg_str(m, "fastest time scales of the model: ");
    for (int k = 0; k < n && k < 2; ++k) {
        if (k) pg_msg_str(m, "; ");
        pg_msg_str(m, sc[k].label);
        pg_msg_str(m, " = ");
        pg_msg_value(m, sc[k].value, 'f', ".3g");
        pg_msg_str(m, " s (");
        named_values(e, &sc[k], m);
        pg_msg_str(m, ")");
    }
    return n;
}

/* _check_time_scales */
static int check_time_scales(PgEngine *e)
{
    PgScale sc[PG_MAX_SCALES];
    int n = 0;
    TRY(time_scales(e, sc, &n, 0));
    for (int k = 0; k < n; ++k) {
        if (!(sc[k].value >= MIN_TIME_SCALE)) {
            PgMsg *m = &e->msg;
            pg_msg_clear(m);
            pg_msg_str(m, sc[k].n_names > 1 ? "parameters " : "parameter ");
            named_values(e, &sc[k], m);
            pg_msg_str(m, sc[k].n_names > 1 ? " violate the rule: the time scale " : " violates the rule: the time scale ");
            pg_msg_str(m, sc[k].label);
            pg_msg_str(m, " = ");
            pg_msg_value(m, sc[k].value, 'f', ".3g");
            pg_msg_str(m, " s must be >= 1e-09 s (faster dynamics are beyond the solver's resolution)");
            return PG_RAISE;
        }
    }
    return PG_OK;
}

/* check_inputs: the inputs (slopes = 0) or their slopes (set_inputs) finite, the first other one named */
static int check_finite_inputs(PgEngine *e, const double *u, int slopes)
{
    for (int i = 0; i < e->nu; ++i) {
        if (!isfinite(u[i])) {
            PgMsg *m = &e->msg;
            const char *name = MODEL(e)->input_names[i];
            pg_msg_clear(m);
            pg_msg_printf(m, slopes ? "input derivative d%s/dt = " : "input %s = ", name);
            pg_msg_value(m, u[i], 'f', "r");
            pg_msg_printf(m, slopes ? " violates the rule: d%s/dt must be finite" : " violates the rule: %s must be finite",
                          name);
            return PG_RAISE;
        }
    }
    return PG_OK;
}

static int check_inputs(PgEngine *e, const double *u) { return check_finite_inputs(e, u, 0); }

/* check_abs_tol */
static int check_abs_tol(PgEngine *e)
{
    PgScale sc[PG_MAX_SCALES];
    int n = 0;
    if (MODEL(e)->has_error_scales) {
        TRY(MODEL(e)->error_scales(e->p, sc, &n, &e->msg));
        int k = 0;
        for (int i = 0; i < n; ++i)
            if (sc[i].value > 0 && isfinite(sc[i].value)) sc[k++] = sc[i];
        n = k;
    }
    int big_i = -1; /* (the state of that magnitude, named: the user finds what started it) */
    if (!n) {
        double big = 0.0;
        for (int i = 0; i < NX(e); ++i) {
            double a = fabs(e->x[i]);
            if (i == 0 || a > big) big = a, big_i = i;
        }
        if (!(big > 0)) return PG_OK;
        sc[0].label = "the largest initial state magnitude";
        sc[0].n_names = 0;
        sc[0].value = big;
        n = 1;
    }
    int best = 0;
    for (int i = 1; i < n; ++i)
        if (sc[i].value < sc[best].value) best = i;
    double limit = ABS_TOL_MAX_FRACTION * sc[best].value;
    if (e->s[PG_S_ABS_TOL] > limit) {
        PgMsg *m = &e->msg;
        pg_msg_clear(m);
        pg_msg_str(m, "parameter abs_tol = ");
        pg_msg_value(m, e->s[PG_S_ABS_TOL], 'f', "r");
        pg_msg_str(m, " violates the rule: abs_tol <= 0.001 x ");
        pg_msg_str(m, sc[best].label);
        pg_msg_str(m, " (");
        if (big_i >= 0) pg_msg_printf(m, "%s = ", MODEL(e)->state_names[big_i]);
        pg_msg_value(m, sc[best].value, 'f', ".6g");
        if (big_i >= 0) pg_msg_str(m, " at the start");
        if (sc[best].n_names) {
            pg_msg_str(m, " with ");
            named_values(e, &sc[best], m);
        }
        pg_msg_str(m, ") = ");
        pg_msg_value(m, limit, 'f', ".3g");
        pg_msg_str(m, "; a larger absolute tolerance lets the local error be as large as the motion itself and "
                      "controls nothing");
        return PG_RAISE;
    }
    return PG_OK;
}

/* ---- domain ------------------------------------------------------------------------------- */
/* _domain_violation: 0 inside, 1 outside (the condition's text in e->msg, its first time in *t_v) */
static int domain_violation(PgEngine *e, double t, const double *x, PgSeg *seg, double *t_v, int *rc)
{
    *rc = PG_OK;
    int r = MODEL(e)->domain(t, x, e->q, u_at(e, t), e->p, e->s, &e->msg);
    if (r == PG_ARITH) {
        *rc = r;
        return 0;
    }
    if (r == PG_OK) {
        int bad = 0;
        for (int i = 0; i < NX(e); ++i) bad |= !isfinite(x[i]);
        if (bad) {
            PgMsg *m = &e->msg;
            pg_msg_clear(m);
            pg_msg_str(m, "the state became non-finite at t = ");
            pg_msg_value(m, t, 'f', ".15g");
            pg_msg_str(m, " s (");
            int first = 1;
            for (int i = 0; i < NX(e); ++i) {
                if (isfinite(x[i])) continue;
                if (!first) pg_msg_str(m, ", ");
                first = 0;
                pg_msg_str(m, MODEL(e)->state_names[i]);
                pg_msg_str(m, " = ");
                pg_msg_value(m, x[i], 'f', "r");
            }
            pg_msg_str(m, "): ");
            extreme_parameters(e, m);
            *rc = PG_RAISE;
        }
        return 0;
    }
    PgMsg condition = e->msg;
    if (seg) {
        double a = seg->t0, b = t, y[PG_MAX_X];
        for (int k = 0; k < 60; ++k) {
            double c = 0.5 * (a + b);
            int s1 = seg_at(e, seg, c, y);
            if (s1) {
                *rc = s1;
                return 0;
            }
            int d = MODEL(e)->domain(c, y, e->q, u_at(e, c), e->p, e->s, &e->scratch);
            if (d == PG_ARITH) {
                e->msg = e->scratch;
                *rc = d;
                return 0;
            }
            if (d == PG_OK) a = c;
            else b = c;
        }
        t = b;
    }
    e->msg = condition;
    *t_v = t;
    return 1;
}

static int domain_error(PgEngine *e, double t_v)
{
    char condition[PG_MSG_MAX];
    snprintf(condition, sizeof condition, "%s", e->msg.text);
    pg_msg_clear(&e->msg);
    pg_msg_str(&e->msg, "the trajectory left the model's domain at t = ");
    pg_msg_value(&e->msg, t_v, 'f', ".10g");
    pg_msg_str(&e->msg, " s: ");
    pg_msg_str(&e->msg, condition);
    return PG_RAISE;
}

static int check_domain(PgEngine *e, double t, const double *x)
{
    double t_v;
    int rc;
    if (domain_violation(e, t, x, NULL, &t_v, &rc)) return domain_error(e, t_v);
    return rc;
}

/* ---- binding, the first step -------------------------------------------------------------- */
static int rebind(PgEngine *e)
{
    e->n_active = 0;
    for (int i = 0; i < MODEL(e)->ne; ++i) {
        int on = 0;
        TRY(MODEL(e)->active(i, e->q, &on, &e->msg));
        if (on) e->active[e->n_active++] = i;
    }
    return PG_OK;
}

static int bind(PgEngine *e)
{
    TRY(rebind(e));
    e->jac_ok = 0; /* a new mode or new inputs: another flow */
    TRY(MODEL(e)->flow(e->t, e->x, e->q, u_at(e, e->t), e->p, e->f, &e->msg));
    for (int k = 0; k < e->n_active; ++k) TRY(guard_at(e, e->active[k], e->t, e->x, &e->g[k]));
    e->has_g_prev = 0;
    return PG_OK;
}

static double rms(const double *v, int n)
{
    if (!n) return 0.0;
    double acc = 0.0;
    for (int i = 0; i < n; ++i) acc += v[i] * v[i];
    return sqrt(acc / n);
}

/* _initial_step: Hairer's starting step, never below START_STEP_ULPS ulps */
static int initial_step(PgEngine *e, double *out)
{
    double t = e->t;
    const double *y = e->x, *f = e->f;
    int n = NX(e);
    double floor_ = pmin(START_STEP_ULPS * EPS * pmax(fabs(t), 1.0), e->max_step);
    if (!n) {
        *out = isfinite(e->max_step) ? e->max_step : 1.0;
        return PG_OK;
    }
    double scale[PG_MAX_X], v[PG_MAX_X], y1[PG_MAX_X] = {0}, f1[PG_MAX_X] = {0};
    for (int i = 0; i < n; ++i) scale[i] = e->atol + fabs(y[i]) * e->rtol;
    for (int i = 0; i < n; ++i) v[i] = y[i] / scale[i];
    double d0 = rms(v, n);
    for (int i = 0; i < n; ++i) v[i] = f[i] / scale[i];
    double d1 = rms(v, n);
    double h0 = !(d0 >= 1e-5 && d1 >= 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    if (!(h0 >= floor_)) h0 = floor_;
    h0 = pmin(h0, e->max_step);
    for (int i = 0; i < n; ++i) y1[i] = y[i] + h0 * f[i];
    TRY(model_fun(e, t + h0, y1, f1, &e->msg));
    for (int i = 0; i < n; ++i) v[i] = (f1[i] - f[i]) / scale[i];
    double d2 = rms(v, n) / h0;
    double h1;
    if (d1 <= 1e-15 && d2 <= 1e-15) {
        h1 = pmax(1e-6, h0 * 1e-3);
    } else {
        double d = pmax(d1, d2);
        if (isfinite(d)) {
            if (pg_pow(0.01 / d, 1.0 / pair_order(e), &h1, &e->msg)) return PG_ARITH;
        } else {
            h1 = 0.0;
        }
    }
    double h = pmin(pmin(100 * h0, h1), e->max_step);
    *out = h >= floor_ ? h : floor_;
    return PG_OK;
}

static int check_initial_rates(PgEngine *e)
{
    int bad = first_non_finite(e->f, NX(e));
    if (bad < 0) return PG_OK;
    /* the flow named with the start's time and state, as a failing flow is during the run; an infinite
     * rate, with the parameters of the most extreme magnitude (a NaN from finite values is the
     * model's own, not an overflow's) */
    PgMsg *m = &e->msg;
    pg_msg_clear(m);
    function_failed_at(e, m, "the flow", -1, e->t, e->x);
    pg_msg_printf(m, "it returned d%s/dt = ", MODEL(e)->state_names[bad]);
    pg_msg_value(m, e->f[bad], 'f', "r");
    if (isnan(e->f[bad])) {
        pg_msg_str(m, " (a model function must return finite numbers)");
    } else {
        pg_msg_str(m, ": ");
        extreme_parameters(e, m);
    }
    return PG_RAISE;
}

/* ---- Simulator.__init__ -------------------------------------------------------------------- */
static int prepare(PgEngine *e)
{
    const PgModel *md = MODEL(e);
    TRY(md->check_settings(e->s, &e->msg));
    TRY(md->check(e->p, &e->msg));
    TRY(check_inputs(e, e->u));
    TRY(check_time_scales(e));
    TRY(md->initial(e->p, e->x, e->q, &e->msg));
    TRY(check_abs_tol(e));
    return PG_OK;
}

int pg_engine_init(PgEngine *e, const PgModel *model, const double *p, const double *s, const double *u,
                   double t0, double t_stop)
{
    PgEventHook on_event = e->on_event;
    PgWarnHook on_warning = e->on_warning;
    PgSwitchHook on_switch = e->on_switch;
    void *ctx = e->hook_ctx;
    memset(e, 0, sizeof *e);
    e->on_event = on_event, e->on_warning = on_warning, e->on_switch = on_switch, e->hook_ctx = ctx;
    e->model = model;
    e->nx = model->nx, e->nq = model->nq, e->nu = model->nu, e->np = model->np;
    const struct { const char *what, *name; int n, limit; } sizes[] = {
        {"states", "PG_MAX_X", model->nx, PG_MAX_X},      {"discrete state entries", "PG_MAX_Q", model->nq, PG_MAX_Q},
        {"inputs", "PG_MAX_U", model->nu, PG_MAX_U},      {"parameters", "PG_MAX_P", model->np, PG_MAX_P},
        {"events", "PG_MAX_EVENTS", model->ne, PG_MAX_EVENTS}, {"outputs", "PG_MAX_Y", model->ny, PG_MAX_Y}};
    for (size_t i = 0; i < sizeof sizes / sizeof sizes[0]; i++)
        if (sizes[i].n > sizes[i].limit) {
            pg_msg_clear(&e->msg);
            pg_msg_printf(&e->msg, "the model has %d %s; the engine takes at most %d (%s)", sizes[i].n, sizes[i].what,
                          sizes[i].limit, sizes[i].name);
            return PG_RAISE;
        }
#if defined(PG_NX) && defined(PG_NQ) && defined(PG_NY)
    if (model->nx != PG_NX || model->nq != PG_NQ || model->ny != PG_NY) { /* (a native FMU's sizes are its model's) */
        pg_msg_clear(&e->msg);
        pg_msg_printf(&e->msg, "the model has %d states, %d discrete state entries and %d outputs; this engine was "
                      "built for exactly %d, %d and %d (PG_NX, PG_NQ, PG_NY)", model->nx, model->nq, model->ny, PG_NX,
                      PG_NQ, PG_NY);
        return PG_RAISE;
    }
#endif
#ifdef PG_ONE_MODEL
    if (model != &PG_ONE_MODEL) { /* (a native FMU's engine calls its one model's functions by name) */
        pg_msg_clear(&e->msg);
        pg_msg_printf(&e->msg, "the model %s is not the one this engine was built for (%s, PG_ONE_MODEL)",
                      model->name ? model->name : "(unnamed)", PG_ONE_MODEL.name ? PG_ONE_MODEL.name : "(unnamed)");
        return PG_RAISE;
    }
#endif
    if (model->ns != PG_NS) {
        pg_msg_clear(&e->msg);
        pg_msg_printf(&e->msg, "the model has %d solver settings; the engine takes exactly %d (PG_NS)", model->ns, PG_NS);
        return PG_RAISE;
    }
    memcpy(e->p, p, sizeof(double) * (size_t)e->np);
    memcpy(e->s, s, sizeof(double) * PG_NS);
    memcpy(e->u, u, sizeof(double) * (size_t)e->nu);
    int rc = prepare(e);
    if (rc) return at_time(e, rc, "initialization", 0, NULL);
    e->method = (int)s[PG_S_METHOD];
    e->cur = e->method == 0 ? M_DOPRI5 : e->method; /* automatic: explicit until found stiff */
    e->rtol = s[PG_S_REL_TOL];
    e->atol = s[PG_S_ABS_TOL];
    e->max_step = s[PG_S_MAX_STEP] == 0.0 ? INFINITY : s[PG_S_MAX_STEP];
    e->t_stop = t_stop;
    e->zeno_max_events = 200;
    e->zeno_window = 1e-6;
    e->t = e->t_out = t0;
    rc = time_events_init(e, t0);
    if (rc) return at_time(e, rc, "initialization", 0, NULL);
    e->keep_history = s[PG_S_LOG_EVENTS] != 0.0;
    e->budget = s[PG_S_MAX_STEPS_PER_SECOND] * BUDGET_WINDOW;
    e->win_t0 = e->t, e->win_n = 0, e->warned = 0;
    e->warn_n = BUDGET_WARN_FRACTION * e->budget;
    memcpy(e->x_out, e->x, sizeof e->x);
    memcpy(e->q_out, e->q, sizeof e->q);
    e->stateless = NX(e) == 0;
    e->n_xy = 0;
#ifndef PG_STATE_OUTPUTS_EXACT /* (a native FMU whose generated outputs are the states themselves: no check) */
    for (int i = 0; i < NX(e); ++i)
        for (int k = 0; k < NY(e); ++k)
            if (!strcmp(MODEL(e)->state_names[i], MODEL(e)->output_names[k])) {
                e->xy_y[e->n_xy] = k, e->xy_x[e->n_xy++] = i;
                break;
            }
#endif
    rc = check_domain(e, e->t, e->x);
    if (!rc) rc = bind(e);
    if (!rc) rc = check_initial_rates(e);
    if (!rc) {
        double is = s[PG_S_INITIAL_STEP];
        if (is > 0) e->h = pmax(is, START_STEP_ULPS * EPS * pmax(fabs(e->t), 1.0));
        else rc = initial_step(e, &e->h);
    }
    if (!rc && !e->stateless) rc = rearm(e, NULL, -1, 0.0, NULL, NULL); /* a guard at zero heading across fires at the start */
    if (rc) return at_time(e, rc, "initialization", 0, NULL);
    return PG_OK;
}

/* ---- the work budget (_spend) -------------------------------------------------------------- */
static int spend(PgEngine *e, double t, double h)
{
    if (t - e->win_t0 >= BUDGET_WINDOW) e->win_t0 = t, e->win_n = 1;
    long n = e->win_n;
    if (n < e->warn_n) return PG_OK;
    double elapsed = pmax(t + h - e->win_t0, 0.0);
    PgMsg *m = &e->msg;
    if (n >= e->budget) {
        pg_msg_clear(m);
        pg_msg_printf(m, "work budget exhausted: %ld internal steps within ", n);
        pg_msg_value(m, elapsed, 'f', ".3g");
        pg_msg_str(m, " s of simulated time up to t = ");
        pg_msg_value(m, t, 'f', ".10g");
        pg_msg_str(m, " s (max_steps_per_second = ");
        pg_msg_value(m, e->s[PG_S_MAX_STEPS_PER_SECOND], 'f', "g");
        pg_msg_str(m, "; mean step ");
        pg_msg_value(m, elapsed / n, 'f', ".3g");
        pg_msg_str(m, " s, latest ");
        pg_msg_value(m, h, 'f', ".3g");
        pg_msg_str(m, " s). The model is stiff here: ");
        int named = stiffness_text(e, m);
        pg_msg_str(m, ". To change: ");
        if (named) pg_msg_str(m, "make the fastest time scale slower (the parameters named above), ");
        if (e->cur != M_RODAS) pg_msg_str(m, "use the stiff method (method = 1, Rodas5P), ");
        pg_msg_str(m, "or raise max_steps_per_second to let the run go on slowly");
        return PG_RAISE;
    }
    if (!e->warned) {
        e->warned = 1;
        PgMsg w;
        pg_msg_clear(&w);
        pg_msg_printf(&w, "stiff: %ld internal steps within ", n);
        pg_msg_value(&w, elapsed, 'f', ".3g");
        pg_msg_str(&w, " s of simulated time up to t = ");
        pg_msg_value(&w, t, 'f', ".10g");
        pg_msg_str(&w, " s (mean step ");
        pg_msg_value(&w, elapsed / n, 'f', ".3g");
        pg_msg_str(&w, " s); the run stops at max_steps_per_second = ");
        pg_msg_value(&w, e->s[PG_S_MAX_STEPS_PER_SECOND], 'f', "g");
        pg_msg_str(&w, " steps per simulated second. ");
        stiffness_text(e, &w);
        if (e->cur != M_RODAS) pg_msg_str(&w, "; method = 1 (Rodas5P) is the stiff method");
        if (e->on_warning) e->on_warning(e->hook_ctx, w.text);
    }
    return PG_OK;
}

static int recent_count(const PgEngine *e) { return e->recent_n; }

/* the k-th latest recorded event (0: the latest) */
static double recent_time(const PgEngine *e, int k)
{
    int i = (e->recent_head - 1 - k + PG_RECENT) % PG_RECENT;
    return e->recent_t[i];
}

static int recent_index(const PgEngine *e, int k)
{
    int i = (e->recent_head - 1 - k + PG_RECENT) % PG_RECENT;
    return e->recent_i[i];
}

/* _collapse_error */
static int collapse_error(PgEngine *e, double t, double h)
{
    PgMsg *m = &e->msg;
    pg_msg_clear(m);
    if (e->has_note) { /* the cause: the flow returned a non-finite rate at a finite state */
        pg_msg_str(m, e->note.text);
        pg_msg_str(m, "; no step past it (the step size collapsed to ");
        pg_msg_value(m, h, 'f', ".3g");
        pg_msg_str(m, " s at t = ");
        pg_msg_value(m, t, 'f', ".15g");
        pg_msg_str(m, " s)");
        return PG_RAISE;
    }
    if (e->has_last && e->last.time == t) {
        int count = 0;
        double oldest = t;
        for (int k = 0; k < recent_count(e); ++k) count += t - recent_time(e, k) <= e->zeno_window;
        /* in the deque's order (oldest first), the first of the events in the window */
        for (int k = recent_count(e) - 1; k >= 0; --k) {
            double tk = recent_time(e, k);
            if (t - tk <= e->zeno_window) {
                oldest = tk;
                break;
            }
        }
        if (count >= STORM_EVENTS) {
            pg_msg_str(m, "event storm: the step size collapsed to ");
            pg_msg_value(m, h, 'f', ".3g");
            pg_msg_printf(m, " s right after event %ld (%s) at t = ", e->n_events, event_name(e, e->last.index));
            pg_msg_value(m, t, 'f', ".15g");
            pg_msg_printf(m, " s, the latest %d events within ", count);
            pg_msg_value(m, t - oldest, 'f', ".3g");
            pg_msg_str(m, " s: the events accumulate (Zeno behaviour)");
            return PG_RAISE;
        }
        pg_msg_str(m, "step size collapsed to ");
        pg_msg_value(m, h, 'f', ".3g");
        pg_msg_printf(m, " s right after event %ld (%s) at t = ", e->n_events, event_name(e, e->last.index));
        pg_msg_value(m, t, 'f', ".15g");
        pg_msg_str(m, " s: the dynamics after the event are too fast to resolve or singular (");
        stiffness_text(e, m);
        pg_msg_str(m, ")");
        return PG_RAISE;
    }
    pg_msg_str(m, "step size collapsed to ");
    pg_msg_value(m, h, 'f', ".3g");
    pg_msg_str(m, " s at t = ");
    pg_msg_value(m, t, 'f', ".15g");
    pg_msg_str(m, " s: the error estimate cannot be met with rel_tol = ");
    pg_msg_value(m, e->s[PG_S_REL_TOL], 'f', "r");
    pg_msg_str(m, ", abs_tol = ");
    pg_msg_value(m, e->s[PG_S_ABS_TOL], 'f', "r");
    pg_msg_str(m, " (the model is stiff or singular here, or the tolerances lie below the rounding error of the "
                  "states)");
    return PG_RAISE;
}

/* ---- arming the guards (docs/solver.md, "Event semantics") --------------------------------- */
/* model exchange: the inputs put on the line of the importer's motion about its point (me_input_rate)
 * while a rule of arming asks how a guard moves at t, the importer's latest sample: 1 if it did (undo
 * with inputs_held) */
static int inputs_on_line(PgEngine *e, double t)
{
    if (e->has_du || !e->me_has_du || t != e->me_t_last) return 0;
    memcpy(e->du, e->me_du, sizeof(double) * (size_t)e->nu), e->has_du = 1;
    return 1;
}

static void inputs_held(PgEngine *e, int line)
{
    if (line) memset(e->du, 0, sizeof(double) * (size_t)e->nu), e->has_du = 0;
}

/* The rounding band of guard i at (t, x): how far the guard moves when each state moves by
 * BAND_ULPS of its own magnitude, and time by as many ulps at the guard's rate along the flow (the
 * rate dg over 2 d: where the crossing is located) and at its own rate in time (t's rounding where
 * the guard reads t, or an input's slope: a wall moving at 0.5 m/s blurs a guard by 0.5 m/s times
 * t's ulps however slowly a ball moves against it). A guard within its band after a jump, a start
 * or an input change is "at zero": the offset of a guard (x - d against x) changes the band,
 * never the outcome. */
static int guard_band(PgEngine *e, int i, double t, const double *x, double g, double rate, double *z)
{
    double xp[PG_MAX_X], gp, gm, acc = 0.0;
    memcpy(xp, x, sizeof(double) * (size_t)NX(e));
    for (int j = 0; j < NX(e); ++j) {
        if (x[j] == 0.0) continue;
        xp[j] = x[j] + BAND_ULPS * EPS * x[j];
        TRY(guard_at(e, i, t, xp, &gp));
        xp[j] = x[j];
        if (isfinite(gp)) acc += fabs(gp - g);
    }
    double d = RATE_STEP * pmax(fabs(t), 1.0); /* the rate in time at fixed x: 0 for a guard that reads no time */
    int line = inputs_on_line(e, t);
    int rc = guard_at(e, i, t + d, x, &gp);
    if (!rc) rc = guard_at(e, i, t - d, x, &gm);
    inputs_held(e, line);
    TRY(rc);
    double own = (gp - gm) / (2 * d);
    double zt = BAND_ULPS * EPS * fabs(t) * (fabs(rate) + (isfinite(own) ? fabs(own) : 0.0));
    *z = isfinite(zt) ? acc + zt : acc;
    return PG_OK;
}

/* the guard's change along the flow f through (t, x), in its direction: sgn (g(t + d, x + d f) -
 * g(t - d, x - d f)) with d = RATE_STEP max(|t|, 1); positive: it heads to its after side */
static int guard_change_of(PgEngine *e, int i, double t, const double *x, const double *f, int inputs_move,
                           double *dg, double *d_out)
{
    double d = RATE_STEP * pmax(fabs(t), 1.0), xp[PG_MAX_X], gp, gm;
    int line = inputs_move && inputs_on_line(e, t);
    for (int j = 0; j < NX(e); ++j) xp[j] = x[j] + d * f[j];
    int rc = guard_at(e, i, t + d, xp, &gp);
    for (int j = 0; !rc && j < NX(e); ++j) xp[j] = x[j] - d * f[j];
    if (!rc) rc = guard_at(e, i, t - d, xp, &gm);
    inputs_held(e, line);
    TRY(rc);
    *dg = sgn_of(e, i) * (gp - gm);
    *d_out = d;
    return PG_OK;
}

static int guard_change(PgEngine *e, int i, double t, const double *x, const double *f, double *dg, double *d_out)
{
    return guard_change_of(e, i, t, x, f, 1, dg, d_out);
}

/* guard i's motion at (t, x) along the flow f, valued g there: its change dg over 2 d (guard_change)
 * and its rounding band z at that rate (guard_band) — what every rule of arming asks */
static int guard_motion(PgEngine *e, int i, double t, const double *x, const double *f, double g, double *dg,
                        double *d, double *z)
{
    TRY(guard_change(e, i, t, x, f, dg, d));
    return guard_band(e, i, t, x, g, *dg / (2 * *d), z);
}

/* guard i at the jump's point (e->t, x_pre) under the modes before the jump (q_pre), the flow there
 * too: its value g and its change dg over 2 d, and its band z unless z is NULL */
static int guard_before_jump(PgEngine *e, int i, const double *x_pre, const double *q_pre, double *g, double *dg,
                             double *d, double *z)
{
    double q_post[PG_MAX_Q], f[PG_MAX_X];
    size_t nq = sizeof(double) * (size_t)e->nq;
    memcpy(q_post, e->q, nq), memcpy(e->q, q_pre, nq); /* (the guard and the flow read e->q) */
    int rc = MODEL(e)->flow(e->t, x_pre, e->q, u_at(e, e->t), e->p, f, &e->msg);
    if (!rc) rc = guard_at(e, i, e->t, x_pre, g);
    if (!rc) rc = z ? guard_motion(e, i, e->t, x_pre, f, *g, dg, d, z) : guard_change(e, i, e->t, x_pre, f, dg, d);
    memcpy(e->q, q_post, nq);
    return rc;
}

/* *still: guard i reads no state and no time (a guard of inputs or modes: no flow ever moves it),
 * tried by moving each state, and time, by RATE_STEP of its magnitude (at least RATE_STEP) */
static int guard_still(PgEngine *e, int i, double t, const double *x, double g, int *still)
{
    double xp[PG_MAX_X], gp;
    *still = 0;
    memcpy(xp, x, sizeof(double) * (size_t)NX(e));
    for (int j = 0; j < NX(e); ++j) {
        xp[j] = x[j] + RATE_STEP * pmax(fabs(x[j]), 1.0);
        TRY(guard_at(e, i, t, xp, &gp));
        xp[j] = x[j];
        if (!(gp == g)) return PG_OK;
    }
    int line = inputs_on_line(e, t);
    int rc = guard_at(e, i, t + RATE_STEP * pmax(fabs(t), 1.0), x, &gp);
    inputs_held(e, line);
    TRY(rc);
    *still = gp == g;
    return PG_OK;
}

/* guard i, armed, crossed by a restart: the first such (in priority order) fires now; each later one
 * stays armed, so that the restart of the first's jump fires it in turn at this same instant (unless
 * that jump took it back to its before side) — a cascade is never lost behind another */
static void crossed_now(PgEngine *e, int i, int *fire)
{
    if (*fire < 0) *fire = i;
    else e->armed[i] = 1;
}

/* *with: guard i crossed at this instant together with the event that jumped — at the jump's point
 * (t, x_pre) under the modes before it (q_pre), its guard was on its after side beyond its band, or
 * at zero within its band heading across (its change along the flow there above twice its band).
 * Only asked for an armed guard that the jump left at zero and not heading across (arm_guards): a
 * rebound there, unless it was crossing with the event itself (two events on one guard, an impact
 * listed before a counter of impacts: the impact's jump turns the flow back at zero, and the
 * counter, crossed at the same instant, still fires after it). A guard with no first-order
 * direction at the jump's point (armed at zero there, a plastic impact's v = 0) was not crossing. */
static int crossed_with(PgEngine *e, int i, const double *x_pre, const double *q_pre, int *with)
{
    double g, dg, d, z;
    *with = 0;
    TRY(guard_before_jump(e, i, x_pre, q_pre, &g, &dg, &d, &z));
    if (e->own_carry) z = pmax(z, e->zband[i]); /* (the band it was armed with at this instant: arm_guards) */
    double G = sgn_of(e, i) * g;
    *with = G > z || (G >= -z && dg > 2 * z);
    return PG_OK;
}

/* The event that has just jumped, its guard left at zero and still heading across: its crossing goes on
 * (a net the ball passes through, slowed by it), as for a counter. When the jump changed the states
 * and, with them, the guard's rate along the flow (beyond twice its band), a warning says so, once per
 * event and run: a bounce whose jump does not turn the motion back lets the trajectory through its
 * guard, as the model says — and the user is told (it passed in silence until 2026-12-07: a user's
 * audit). dg, d, z: the guard's change along the new flow over 2 d, and its band. */
static int warn_through(PgEngine *e, int i, double dg, double d, double z, const double *x_pre, const double *q_pre)
{
    if (!x_pre || e->through_warned[i] || !e->on_warning) return PG_OK;
    int same_x = 1;
    for (int k = 0; k < NX(e); ++k) same_x &= x_pre[k] == e->x[k];
    if (same_x) return PG_OK;
    double g_pre, dg_pre, d_pre;
    TRY(guard_before_jump(e, i, x_pre, q_pre, &g_pre, &dg_pre, &d_pre, NULL));
    if (!(fabs(dg - dg_pre) > 2 * z)) return PG_OK; /* (the jump left the guard's motion as it was) */
    e->through_warned[i] = 1;
    double sgn = sgn_of(e, i);
    PgMsg w;
    pg_msg_clear(&w);
    pg_msg_printf(&w, "event %s at t = ", event_name(e, i));
    pg_msg_value(&w, e->t, 'f', ".15g");
    pg_msg_str(&w, " s: its jump left its guard at zero still heading across (its rate ");
    pg_msg_value(&w, sgn * dg / (2 * d), 'f', ".6g");
    pg_msg_str(&w, " /s after the jump, ");
    pg_msg_value(&w, sgn * dg_pre / (2 * d_pre), 'f', ".6g");
    pg_msg_str(&w, " /s before): the crossing goes on through the guard, and the event is armed again only once "
                   "its guard is back on its before side. If the jump was to turn the motion back (an impact), "
                   "it did not: the trajectory passes through");
    e->on_warning(e->hook_ctx, w.text);
    return PG_OK;
}

/* An input change that puts guard i, armed at zero heading to its before side (a rebound: zarm 1), on
 * its after side at G while the flow under the new inputs still carries it to its before side did not
 * carry the trajectory across: it moved the guard's zero. (An importer that locates an event on an
 * input's line and then sets, at that instant, the source's value there, off the line by the line's
 * error: the ball on a platform whose position is that input bounced twice at one instant, the second
 * jump turning it into the platform, and fell through it, in the SSP master's default `--inputs
 * interpolate`, until 2026-12-07: a user's audit.) It stays armed at zero, its band widened to where
 * it now is: it fires where it comes back past that band, and is an ordinary armed guard once it has
 * left it to its before side. */
static void zero_moved(PgEngine *e, int i, double G, double z)
{
    e->zarm[i] = 1, e->armed[i] = 1, e->zband[i] = G + z, e->me_seen[i] = 0, e->me_prov[i] = 0;
}

/* Arm every active guard at (e->t, e->x) after a restart: a jump of event `own`, the start or an
 * input change (own = -1). was[i] says what guard i was just before: 1 armed, 0 active and not
 * armed, -1 not active or no before (the start); at an input change 2: armed at zero heading to its
 * before side, a rebound (zero_moved). x_pre, q_pre: the states and modes at the jump's
 * point before it (NULL for the start and an input change). A guard
 *   - on its before side beyond its band is armed;
 *   - at zero (within its band) is armed at zero, unless the flow carries it to its after side:
 *     then it fires now if it was armed or unknown and is not the event that just jumped (that
 *     event's own crossing goes on), and is disarmed otherwise; a guard other than the event that
 *     just jumped, armed before and left at zero by the jump heading to its before side or with
 *     no direction, fires now too if it was crossing at the jump's point (crossed_with: two events
 *     on one guard) — the extra guard values only there;
 *   - on its after side beyond its band fires now if it was armed (the restart crossed it: a
 *     cascade, or simultaneous events), and is disarmed otherwise;
 *   - reading no state and no time (guard_still), at zero is on its after side.
 * Of several that fire now, the later stay armed and fire in turn (crossed_now).
 * The event that jumped sits at its located crossing: if its jump left its guard where it was
 * (own_g, within the band), that value is its zero, however far floating point resolves it. If its
 * jump changed q only (a counter) at a point a step of the flow reached (e->own_kept), its guard at
 * zero with no direction to first order is its crossing going on too (a tangency: the curvature that
 * fired it carries it on), disarmed — armed at zero, it would fire again in place at the same point.
 * *fire: the first event (in priority order, the model's) that fires now, -1 for none. */
static int arm_guards(PgEngine *e, const signed char *was, int own, double own_g, const double *x_pre,
                      const double *q_pre, int *fire)
{
    *fire = -1;
    for (int k = 0; k < e->n_active; ++k) {
        int i = e->active[k];
        double G = sgn_of(e, i) * e->g[k], z, dg, d;
        int still = 0;
        TRY(guard_motion(e, i, e->t, e->x, e->f, e->g[k], &dg, &d, &z));
        double z0 = z; /* (the rounding band, before its widening to the located zero) */
        if (i == own && fabs(e->g[k] - own_g) <= z) z += fabs(G);
        else if (e->own_carry) z = pmax(z, e->zband[i]); /* (the band it was armed with at this instant) */
        int before = was ? was[i] : -1, rebound = before == 2;
        if (rebound) before = 1;
        e->zarm[i] = 0, e->armed[i] = 0, e->zband[i] = z, e->kept[i] = 0, e->me_seen[i] = 0, e->me_prov[i] = 0;
        if (G > z) {
            if (before == 1 && i != own && rebound && dg < -2 * z) zero_moved(e, i, G, z);
            else if (before == 1 && i != own) crossed_now(e, i, fire);
        } else if (G >= -z) {
            if (!(dg > 2 * z) && !(dg < -2 * z)) TRY(guard_still(e, i, e->t, e->x, e->g[k], &still));
            if (still) { /* the flow never moves it off zero: zero is its after side (G >= 0; an input that
                          * lands exactly on its level): a crossing if it was armed, else disarmed there */
                if (before == 1 && i != own) crossed_now(e, i, fire);
            } else if (i == own && e->own_kept && fabs(G) <= 2 * z0 && !(dg > 2 * z)) {
                /* a counter's jump at a point the flow reached, its guard within the rounding of a crossing
                 * located at zero or at its band's edge (2 z0; not only within the band widened to a
                 * located zero beyond rounding), with no direction to first order (a tangency): its
                 * crossing goes on, disarmed, and its dither within its band is that crossing's rounding
                 * (kept), not a new crossing */
                e->kept[i] = 1;
            } else if (dg > 2 * z || (i == own && e->own_same)) { /* (a jump that changed nothing: its crossing goes on) */
                if (i == own && dg > 2 * z) TRY(warn_through(e, i, dg, d, z, x_pre, q_pre));
                /* armed before: the restart crossed it (a cascade) and it fires now; of unknown arming (the
                 * start, a newly active guard): it fires where the step shows it leave zero (at its start) */
                if (i != own && before == -1) e->zarm[i] = 2, e->armed[i] = 1;
                else if (i != own && before == 1) crossed_now(e, i, fire);
            } else { /* 2: no direction to first order (it leaves zero by its curvature: where it was at
                      * zero); 1: heading to its before side (a rebound: where it returns past its band) —
                      * unless, armed before, it was crossing at the jump's point: it fires now */
                int with = 0;
                if (i != own && before == 1 && x_pre) TRY(crossed_with(e, i, x_pre, q_pre, &with));
                if (with) crossed_now(e, i, fire);
                else e->zarm[i] = dg >= -2 * z ? 2 : 1, e->armed[i] = 1;
                /* (model exchange, a rebound that is a guess about the inputs: just after an input's step,
                 * its rate unknown; or one made by the inputs' secant alone, the guard still along the flow
                 * with the inputs held — the importer's next samples may turn the inputs back, as at a
                 * vertex of its input table, where a falling counter on an input that touched its level
                 * from below fired as the input fell, until 2026-12-07. A guard the states move too (a
                 * ball on a platform the importer moves) keeps its rebound: its hop may be shorter than
                 * the importer's step. The importer's samples, me_has_ua, exist only in model exchange) */
                if (e->zarm[i] == 1 && e->me_has_ua && e->t == e->me_t_last) {
                    int guess = !e->me_has_du;
                    if (!guess) {
                        double dg_held, d_held;
                        TRY(guard_change_of(e, i, e->t, e->x, e->f, 0, &dg_held, &d_held));
                        guess = fabs(dg_held) <= 2 * z;
                    }
                    e->me_prov[i] = (signed char)guess;
                }
            }
        } else {
            e->armed[i] = 1;
        }
    }
    return PG_OK;
}

/* guard i is armed at time t: armed by a restart, or, in model exchange, seen on its before side at or
 * before t. The importer's observations come out of time order: its root search tries a point beyond a root, then
 * comes back to the root. A guard seen on its before side only at such a later point was not armed at
 * the root: it crossed the other way there (a rising guard falling through zero just after another
 * event's root in the same step fired as that event's cascade; a guard on an input fired where the
 * input fell through its level, the importer having set the later point's input first; a user's
 * audit, 2026-12-07) */
static int armed_at(const PgEngine *e, int i, double t)
{
    return e->armed[i] && !(e->me_seen[i] && e->me_seen_t[i] > t);
}

/* what each event's guard was before a restart (arm_guards' was): 1 armed, 0 active and not, -1 inactive */
static void arming_before(const PgEngine *e, signed char *was)
{
    for (int i = 0; i < MODEL(e)->ne; ++i) was[i] = -1;
    for (int k = 0; k < e->n_active; ++k) was[e->active[k]] = e->armed[e->active[k]];
}

/* the event ``index`` pending at e->t, its states before the jump ``x`` (PG_MAX_X of them); located: found
 * on a crossing of its guard (1) or fired by a restart's arming, a time event or an input change (0);
 * zero_hit, in_place: its guard hit from zero, and at the restart point itself (the rules of
 * apply_pending_event). Every place that makes an event pending goes through here, so that no flag of
 * an earlier one is left behind. */
static void set_pending(PgEngine *e, int index, int located, const double *x, int zero_hit, int in_place)
{
    e->has_pending = 1, e->pending_index = index, e->pending_located = located;
    e->zero_hit = zero_hit, e->zero_in_place = in_place;
    memcpy(e->pending_x, x, sizeof e->pending_x);
}

/* a restart's arming, and the event it fires now (pending at e->t) */
static int rearm(PgEngine *e, const signed char *was, int own, double own_g, const double *x_pre, const double *q_pre)
{
    int fire;
    TRY(arm_guards(e, was, own, own_g, x_pre, q_pre, &fire));
    if (fire >= 0) set_pending(e, fire, 0, e->x, 0, 0);
    return PG_OK;
}

/* ZERO_REFIRES events in a row from zero: the storm error naming the event */
static int zero_storm(PgEngine *e, int i)
{
    if (!e->zero_hit) {
        e->zrun = 0;
        return PG_OK;
    }
    e->zrun = i == e->zrun_event ? e->zrun + 1 : 1;
    e->zrun_event = i;
    e->zero_hit = 0;
    if (e->zrun < ZERO_REFIRES) return PG_OK;
    PgMsg *m = &e->msg;
    pg_msg_clear(m);
    pg_msg_printf(m, "event storm: %s happens again within the rounding of its own location at t = ", event_name(e, i));
    pg_msg_value(m, e->t, 'f', ".15g");
    pg_msg_printf(m, " s (%d times in a row from zero, its guard never leaving its rounding band |guard| <= ", e->zrun);
    pg_msg_value(m, e->zband[i], 'f', ".3g");
    pg_msg_str(m, ") in between: the events accumulate faster than floating point resolves them (Zeno "
                  "behaviour, e.g. a bouncing ball coming to rest). Model the rest (a mode without this event once "
                  "the motion is small), or stop before this time");
    explicit_hint(e, m);
    return PG_RAISE;
}

/* after a step committed without an event, the guards g (at its end): armed on the before side;
 * at zero still while within the band */
/* guard i, at G < 0 (its before side) at a step's start, is the crossing its own jump continued
 * (located a rounding short of zero), not a new one: disarmed, and within its band */
static int continues_own_crossing(const PgEngine *e, int i, double G)
{
    return G < 0.0 && !e->armed[i] && G >= -e->zband[i];
}

static void armed_after_step(PgEngine *e, const double *g)
{
    for (int k = 0; k < e->n_active; ++k) {
        int i = e->active[k];
        double G = sgn_of(e, i) * g[k];
        if ((e->zarm[i] || e->kept[i]) && G >= -e->zband[i] && G <= e->zband[i]) continue;
        e->kept[i] = 0;
        if (e->zarm[i] && i == e->zrun_event) e->zrun = 0; /* it left zero: no accumulation */
        e->zarm[i] = 0;
        e->armed[i] = G < 0.0;
    }
}

/* ---- time events ----------------------------------------------------------------------------- */
/* each time event's instants from the parameters, the first at or after t0 */
static int time_events_init(PgEngine *e, double t0)
{
    const PgModel *md = MODEL(e);
    if (md->nte > PG_MAX_TIME_EVENTS) {
        pg_msg_clear(&e->msg);
        pg_msg_printf(&e->msg, "the model has %d time events; the engine takes at most %d (PG_MAX_TIME_EVENTS)",
                      md->nte, PG_MAX_TIME_EVENTS);
        return PG_RAISE;
    }
    for (int k = 0; k < md->nte; ++k) {
        double at = 0, every = 0;
        TRY(md->time_event(k, e->p, &at, &every, &e->msg));
        if (isnan(at) || at == -INFINITY || !isfinite(every) || every < 0.0) {
            PgMsg *m = &e->msg;
            pg_msg_clear(m);
            pg_msg_printf(m, "time event %s: at = ", md->time_event_names[k]);
            pg_msg_value(m, at, 'f', "r");
            pg_msg_str(m, " s, every = ");
            pg_msg_value(m, every, 'f', "r");
            pg_msg_str(m, " s violate the rule: at is a time (inf: never), every is finite and >= 0 (0: once)");
            return PG_RAISE;
        }
        long n = 0;
        if (at < t0 && every > 0.0) n = (long)ceil((t0 - at) / every);
        double next = at + (double)n * every;
        if (next < t0) next = every > 0.0 ? at + (double)(++n) * every : INFINITY;
        e->te_at[k] = at, e->te_every[k] = every, e->te_count[k] = n, e->te_next[k] = next;
    }
    return PG_OK;
}

double pg_engine_next_time_event(const PgEngine *e)
{
    double t = INFINITY;
    for (int k = 0; k < MODEL(e)->nte; ++k) t = pmin(t, e->te_next[k]);
    return t;
}

/* the first time event whose instant is at or before `reach` */
static int time_event_by(const PgEngine *e, double reach)
{
    for (int k = 0; k < MODEL(e)->nte; ++k)
        if (e->te_next[k] <= reach) return MODEL(e)->ne + k;
    return -1;
}

/* an importer's time t (a communication point, the time of its solver) meets the instants up to
 * TIME_EVENT_ULPS after it: its grid and the model's instants differ by rounding (0.41 against
 * 41 * 0.01 = 0.41000000000000003), not in meaning. Between communication points the steps land on
 * the instants exactly. */
static double reach_of(double t) { return t + TIME_EVENT_ULPS * EPS * pmax(fabs(t), 1.0); }

int pg_engine_time_event_due(const PgEngine *e, double t) { return time_event_by(e, reach_of(t)); }

/* a time event due by `reach` becomes the pending event at e->t (state events pending first) */
static void time_event_pending(PgEngine *e, double reach)
{
    if (e->has_pending) return;
    int i = time_event_by(e, reach);
    if (i < 0) return;
    set_pending(e, i, 0, e->x, 0, 0);
}

/* ---- locating events ------------------------------------------------------------------------ */
/* _locate: earliest time in [a, b] where guard i crosses zero in its direction */
static int locate_level(PgEngine *e, PgSeg *seg, int i, double level, double a, double ga, double gb,
                        const double *b_in, double *out)
{
    double sgn = sgn_of(e, i);
    double b = b_in ? *b_in : seg->t1;
    double fa = sgn * ga - level, fb = sgn * gb - level;
    int side = 0;
    double tol = 4 * EPS * pmax(pmax(fabs(a), fabs(b)), 1e-300);
    double y[PG_MAX_X];
    for (int k = 0; k < 200; ++k) {
        if (b - a <= tol) break;
        if (fb - fa == 0.0) return pg_arith(&e->msg, PG_ZERO_DIVISION);
        double c = b - fb * (b - a) / (fb - fa);
        if (!(a < c && c < b)) c = 0.5 * (a + b);
        double gc;
        TRY(seg_at(e, seg, c, y));
        TRY(guard_at(e, i, c, y, &gc));
        double fc = sgn * gc - level;
        if (fc >= 0.0) {
            b = c, fb = fc;
            if (side == 1) fa *= 0.5;
            side = 1;
        } else {
            a = c, fa = fc;
            if (side == -1) fb *= 0.5;
            side = -1;
        }
        if (fc == 0.0) break;
    }
    *out = b;
    return PG_OK;
}

static int locate(PgEngine *e, PgSeg *seg, int i, double a, double ga, double gb, const double *b_in, double *out)
{
    return locate_level(e, seg, i, 0.0, a, ga, gb, b_in, out);
}

/* _locate_from_zero: *found = 0 for "None" */
static int locate_from_zero(PgEngine *e, PgSeg *seg, int i, double g1, int at_start, double *out, int *found)
{
    static const double fracs[5] = {1e-7, 1e-4, 1e-2, 0.1, 0.5};
    double sgn = sgn_of(e, i), h = seg->t1 - seg->t0, y[PG_MAX_X];
    *found = 0;
    for (int k = 0; k < 5; ++k) {
        double tp = seg->t0 + fracs[k] * h, gp;
        TRY(seg_at(e, seg, tp, y));
        TRY(guard_at(e, i, tp, y, &gp));
        if (sgn * gp < 0.0) {
            *found = 1;
            return locate(e, seg, i, tp, gp, g1, NULL, out);
        }
        if (gp != 0.0) {
            if (at_start) *found = 1, *out = seg->t0;
            return PG_OK;
        }
    }
    if (at_start && g1 != 0.0) *found = 1, *out = seg->t0;
    return PG_OK;
}

/* _turning_point: *found = 0 for "None" */
static int turning_point(PgEngine *e, PgSeg *seg, int i, double sgn, double g0, double g1, const double *f1,
                         double *tp_out, double *gp_out, int *found)
{
    double t0 = seg->t0, h = seg->t1 - seg->t0;
    double eps = 1e-6 * h, y[PG_MAX_X], ga, gb;
    *found = 0;
    if (eps == 0.0) return pg_arith(&e->msg, PG_ZERO_DIVISION);
    for (int k = 0; k < NX(e); ++k) y[k] = seg->y0[k] + eps * seg->f0[k];
    TRY(guard_at(e, i, t0 + eps, y, &ga));
    double d0 = sgn * (ga - g0) / eps * h;
    if (!(d0 > 0.0)) return PG_OK;
    for (int k = 0; k < NX(e); ++k) y[k] = seg->y1[k] + eps * f1[k];
    TRY(guard_at(e, i, seg->t1 + eps, y, &gb));
    double d1 = sgn * (gb - g1) / eps * h;
    if (!(d1 < 0.0)) return PG_OK;
    double G0 = sgn * g0, G1 = sgn * g1;
    double A = 6 * G0 + 3 * d0 - 6 * G1 + 3 * d1;
    double B = -6 * G0 - 4 * d0 + 6 * G1 - 2 * d1;
    double lo = 0.0, hi = 1.0;
    for (int k = 0; k < 40; ++k) {
        double mid = 0.5 * (lo + hi);
        if ((A * mid + B) * mid + d0 > 0.0) lo = mid;
        else hi = mid;
    }
    (void)hi;
    double tp = t0 + lo * h;
    if (!(t0 < tp && tp < seg->t1)) return PG_OK;
    TRY(seg_at(e, seg, tp, y));
    TRY(guard_at(e, i, tp, y, gp_out));
    *tp_out = tp;
    *found = 1;
    return PG_OK;
}

/* _hidden_crossing */
static int hidden_crossing(PgEngine *e, PgSeg *seg, int i, double sgn, double g0, double g1, const double *f1,
                           double *out, int *found)
{
    double tp = 0, gp = 0;
    TRY(turning_point(e, seg, i, sgn, g0, g1, f1, &tp, &gp, found));
    if (!*found) return PG_OK;
    if (sgn * gp < 0.0) {
        *found = 0;
        return PG_OK;
    }
    return locate(e, seg, i, seg->t0, g0, gp, &tp, out);
}

/* _hidden_return */
static int hidden_return(PgEngine *e, PgSeg *seg, int i, double sgn, double g0, double g1, const double *f1,
                         double below, double *out, int *found)
{
    double tp = 0, gp = 0;
    TRY(turning_point(e, seg, i, -sgn, g0, g1, f1, &tp, &gp, found));
    if (!*found) return PG_OK;
    if (sgn * gp < -below) return locate(e, seg, i, tp, gp, g1, NULL, out);
    *found = 0;
    return PG_OK;
}

/* _land_on_event: redo the step exactly up to the event, secant on exact steps */
static int land_on_event(PgEngine *e, PgSeg *seg, int i, double level, double te, double *te_out, double *y_out,
                         double *f_out, double *K_out)
{
    double off = sgn_of(e, i) * level; /* the guard's value at the crossing sought: 0, or the band's edge */
    double t0 = seg->t0, t1 = seg->t1;
    double y_a[PG_MAX_X], f_a[PG_MAX_X], y_b[PG_MAX_X], f_b[PG_MAX_X], yd[PG_MAX_X];
    double K_a_local[PG_MAX_STAGES * PG_MAX_X], K_b_local[PG_MAX_STAGES * PG_MAX_X];
    size_t n = sizeof(double) * (size_t)NX(e);
    double g_a, g_b, g_te, g_d;
    TRY(pair_step(e, t0, seg->y0, seg->f0, te - t0, y_a, f_a, K_a_local));
    TRY(guard_at(e, i, te, y_a, &g_a));
    g_a -= off;
    double best = fabs(g_a), best_t = te;
    memcpy(y_out, y_a, n), memcpy(f_out, f_a, n), memcpy(K_out, K_a_local, sizeof K_a_local);
    double d = 1e-3 * (te - t0);
    TRY(seg_at(e, seg, te, yd));
    TRY(guard_at(e, i, te, yd, &g_te));
    TRY(seg_at(e, seg, te - d, yd));
    TRY(guard_at(e, i, te - d, yd, &g_d));
    g_te -= off, g_d -= off;
    if (d == 0.0) return pg_arith(&e->msg, PG_ZERO_DIVISION);
    double slope = (g_te - g_d) / d;
    double ta = te, tb = slope != 0.0 ? te - g_a / slope : te;
    double tol = 4 * EPS * pmax(fabs(te), 1.0);
    for (int k = 0; k < 8; ++k) {
        if (g_a == 0.0 || !(t0 < tb && tb < t1) || fabs(tb - ta) <= tol) break;
        TRY(pair_step(e, t0, seg->y0, seg->f0, tb - t0, y_b, f_b, K_b_local));
        TRY(guard_at(e, i, tb, y_b, &g_b));
        g_b -= off;
        if (fabs(g_b) < best) {
            best = fabs(g_b), best_t = tb;
            memcpy(y_out, y_b, n), memcpy(f_out, f_b, n), memcpy(K_out, K_b_local, sizeof K_b_local);
        }
        if (g_b == g_a) break;
        double tb_new = tb - g_b * (tb - ta) / (g_b - g_a);
        ta = tb, g_a = g_b, tb = tb_new;
    }
    *te_out = best_t;
    return PG_OK;
}

/* ---- committing a step ---------------------------------------------------------------------- */
/* _end_step: *cut = 1 if the step was cut at t_target; PG_RAISE for a domain error */
static int end_step(PgEngine *e, PgSeg *seg, double t_target, int *cut)
{
    double t_v;
    int rc;
    *cut = 0;
    if (!domain_violation(e, seg->t1, seg->y1, seg, &t_v, &rc)) return rc;
    if (t_v > t_target && t_target > seg->t0) {
        double y_c[PG_MAX_X], f_c[PG_MAX_X];
        double K_c[PG_MAX_STAGES * PG_MAX_X];
        double t = seg->t0, y0[PG_MAX_X], f0[PG_MAX_X];
        memcpy(y0, seg->y0, sizeof y0), memcpy(f0, seg->f0, sizeof f0);
        TRY(pair_step(e, t, y0, f0, t_target - t, y_c, f_c, K_c));
        make_seg(e, SEG(e), t, t_target, y0, y_c, f0, K_c);
        e->has_seg = 1;
        e->t = t_target, e->flow_reached = 1;
        memcpy(e->x, y_c, sizeof y_c), memcpy(e->f, f_c, sizeof f_c);
        for (int k = 0; k < e->n_active; ++k) TRY(guard_at(e, e->active[k], t_target, y_c, &e->g[k]));
        e->has_g_prev = 0;
        armed_after_step(e, e->g);
        *cut = 1;
        return PG_OK;
    }
    return domain_error(e, t_v);
}

/* A step once more with the flow's values checked (model_fun's probe path): a raise or an arithmetic
 * error of the flow is named; a rate that is not finite at a stage near the step's start is noted
 * (note_flow), the message if the step size then collapses. Only after a step failed or was
 * rejected with a non-finite error: the steps that succeed pay nothing for it. */
static int pair_step(PgEngine *e, double t, const double *y, const double *f, double h, double *y_new,
                     double *f_new, double *K);
static int probe_step(PgEngine *e, double t, const double *y, const double *f, double h, double *y_new,
                      double *f_new, double *K)
{
    e->probe = 1;
    int rc = pair_step(e, t, y, f, h, y_new, f_new, K);
    e->probe = 0;
    return rc;
}

/* at a step's end on a time event's instant: the first armed guard (in priority order) that is
 * within its rounding band short of zero and heading across — the state event of this same instant
 * to rounding, which fires before the time events (docs/solver.md: at one instant the state events
 * come first); k_now its index in active[], -1 for none */
static int crossing_at(PgEngine *e, int *k_now)
{
    *k_now = -1;
    for (int k = 0; k < e->n_active; ++k) {
        int i = e->active[k];
        double G = sgn_of(e, i) * e->g[k], z, dg, d;
        if (!e->armed[i] || e->zarm[i] || G >= 0.0) continue;
        TRY(guard_motion(e, i, e->t, e->x, e->f, e->g[k], &dg, &d, &z));
        if (G >= -z && dg > 2 * z) {
            *k_now = k;
            return PG_OK;
        }
    }
    return PG_OK;
}

/* _step */
static int step(PgEngine *e, double t_target)
{
    if (e->switch_to) make_switch(e);
    double t = e->t, y[PG_MAX_X], f[PG_MAX_X];
    memcpy(y, e->x, sizeof y), memcpy(f, e->f, sizeof f);
    double h = pmin(pmin(e->h, e->max_step), UNBOUNDED_STEP_FACTOR * pmax(fabs(t), 1.0));
    int rejected = 0;
    double t_new, y_new[PG_MAX_X], f_new[PG_MAX_X];
    double *K = NEXT_SEG(e)->K; /* the stages, where the step's segment keeps them */
    double t_time = pg_engine_next_time_event(e); /* the steps land on it exactly */
    if (t_time > t_target && t_time <= reach_of(t_target)) t_time = t_target; /* (at the point asked for) */
    double h_prop = h;                               /* the step the error control asked for */
    int on_time = 0;
    for (;;) {
        t_new = t + h;
        if (t_new >= e->t_stop && e->t_stop > t + 10 * EPS * pmax(fabs(t), 1.0)) t_new = e->t_stop;
        on_time = t_new >= t_time;
        if (on_time) t_new = t_time;
        h = t_new - t;
        if (h <= MIN_STEP_ULPS * EPS * pmax(fabs(t), 1.0) && !(on_time && h > 0.0)) return collapse_error(e, t, h);
        int rc = pair_step(e, t, y, f, h, y_new, f_new, K);
        if (rc) {
            if (rc == PG_ARITH && e->msg.arith == PG_OVERFLOW) {
                /* the flow overflowed at a trial stage: as a rate that is not finite, a wild trial of a
                 * stiff step, given smaller steps (x**3 raises where x*x*x gives inf: a stiff Van der Pol
                 * written with ** ended at its first explicit trial step, naming a state of 1e165 that was
                 * never on its trajectory; a user's audit, 2026-12-07); noted near the step's start, the
                 * collapse's message if no step gets past it */
                (void)probe_step(e, t, y, f, h, y_new, f_new, K);
                e->n_rejected += 1;
                rejected = 1;
                h *= MIN_FACTOR;
                continue;
            }
            /* the flow failed (raised, or an arithmetic error): the same step again, to name it */
            if (rc == PG_ARITH || rc == PG_RAISE) rc = probe_step(e, t, y, f, h, y_new, f_new, K);
            return rc;
        }
        long n = e->win_n = e->win_n + 1;
        if (n >= e->warn_n || t - e->win_t0 >= BUDGET_WINDOW) TRY(spend(e, t, h));
        double err = error_norm(e, K, h, y, y_new);
        if (err < 1.0) {
            double factor;
            if (err == 0.0) {
                factor = MAX_FACTOR;
            } else {
                factor = pmin(MAX_FACTOR, SAFETY * control_pow(e, err));
            }
            if (rejected) factor = pmin(1.0, factor);
            e->h = pmin(h * factor, e->max_step);
            /* a step shortened to land on a time event does not shrink the next one */
            if (on_time && h < h_prop) e->h = pmin(pmax(e->h, h_prop), e->max_step);
            break;
        }
        e->n_rejected += 1;
        rejected = 1;
        if (!isfinite(err)) {
            PgMsg keep = e->msg; /* (the rejected step's buffers are free for the probe) */
            (void)probe_step(e, t, y, f, h, y_new, f_new, K); /* a non-finite rate: noted, for the message */
            e->msg = keep;
            h *= MIN_FACTOR;
        } else {
            h *= pmax(MIN_FACTOR, SAFETY * control_pow(e, err)); /* (err >= 1, finite) */
        }
    }
    e->n_steps += 1;
    e->has_note = 0; /* (a trial's non-finite rate that a smaller step avoided) */
    stiffness_test(e, K, h);
    PgSeg *seg = NEXT_SEG(e);
    make_seg(e, seg, t, t_new, y, y_new, f, K);
    double g_new[PG_MAX_EVENTS];
    for (int k = 0; k < e->n_active; ++k) TRY(guard_at(e, e->active[k], t_new, y_new, &g_new[k]));
    int hit = -1, hit_in_place = 0;
    double hit_t = 0, hit_level = 0.0;
    for (int k = 0; k < e->n_active; ++k) {
        int i = e->active[k];
        double g0 = e->g[k], g1 = g_new[k], te = 0, level = 0.0;
        double sgn = sgn_of(e, i);
        int found = 1, in_place = 0;
        if (e->zarm[i]) { /* at zero after a restart: fires once the flow carries it past its band */
            double z = e->zband[i];
            /* past its band; or, with no direction to first order, off zero and moving away from it */
            int leaves = e->zarm[i] == 2 && sgn * g1 > 0.0 && sgn * g1 > sgn * g0;
            if (!(sgn * g1 > z) && !leaves) continue;
            /* a dip to the before side resolved inside the step: the crossing is the return's */
            TRY(hidden_return(e, seg, i, sgn, g0, g1, f_new, z, &te, &found));
            if (!found) { /* it left zero without a dip floating point resolves */
                level = z;
                if (e->zarm[i] == 2) te = t, in_place = 1; /* no first-order direction: it leaves zero where it was */
                else TRY(locate_level(e, seg, i, z, t, g0, g1, NULL, &te)); /* after a jump: the return */
            }
        } else if (sgn * g1 < 0.0) {
            if (sgn * g0 >= 0.0 || (e->has_g_prev && sgn * (g0 - e->g_prev[k]) < 0.0)) continue;
            /* (the crossing its own jump continued, located a rounding short of zero: the turning point
             * inside the step is that crossing's, not a new one — a counter fired twice at one crossing,
             * 3e-16 s apart, where the located point was 1 ulp short of its level and the step after it
             * spanned the whole excursion; a user's audit, 2026-12-07) */
            if (continues_own_crossing(e, i, sgn * g0)) continue;
            TRY(hidden_crossing(e, seg, i, sgn, g0, g1, f_new, &te, &found));
            if (!found) continue;
        } else if (sgn * g0 < 0.0) {
            if (continues_own_crossing(e, i, sgn * g0)) continue;
            TRY(locate(e, seg, i, t, g0, g1, NULL, &te));
        } else if (g0 == 0.0 && !e->kept[i]) {
            TRY(locate_from_zero(e, seg, i, g1, 0, &te, &found));
            if (!found) continue;
        } else {
            TRY(hidden_return(e, seg, i, sgn, g0, g1, f_new, e->kept[i] ? e->zband[i] : 0.0, &te, &found));
            if (!found) continue;
        }
        if (hit < 0 || te < hit_t) hit = k, hit_t = te, hit_level = level, hit_in_place = in_place;
    }
    if (hit < 0) {
        int rc = MODEL(e)->domain(t_new, y_new, e->q, u_at(e, t_new), e->p, e->s, &e->msg);
        if (rc == PG_ARITH) return rc;
        int finite = 1;
        for (int i = 0; i < NX(e); ++i) finite &= isfinite(y_new[i]) != 0;
        int cut = 0;
        if (!(rc == PG_OK && finite)) TRY(end_step(e, seg, t_target, &cut));
        if (!cut) {
            e->seg_i = !e->seg_i, e->has_seg = 1;
            e->t = t_new, e->flow_reached = 1;
            memcpy(e->x, y_new, sizeof y_new), memcpy(e->f, f_new, sizeof f_new);
            memcpy(e->g_prev, e->g, sizeof e->g), e->has_g_prev = 1;
            memcpy(e->g, g_new, sizeof g_new);
            armed_after_step(e, g_new);
            if (on_time) { /* landed on it: a state event at this instant to rounding fires first */
                int k_now;
                TRY(crossing_at(e, &k_now));
                if (k_now >= 0) {
                    set_pending(e, e->active[k_now], 1, e->x, 0, 0);
                } else {
                    time_event_pending(e, t_new == t_target ? reach_of(t_new) : t_new);
                }
            }
        }
        return PG_OK;
    }
    int i = e->active[hit];
    double te = hit_t;
    if (te == t) {
        e->has_seg = 0;
        memcpy(e->x, y, sizeof y), memcpy(e->f, f, sizeof f);
        set_pending(e, i, 1, y, hit_level > 0.0, hit_in_place);
        return PG_OK;
    }
    double y_e[PG_MAX_X], f_e[PG_MAX_X];
    if (te < t_new) {
        double K_e[PG_MAX_STAGES * PG_MAX_X];
        TRY(land_on_event(e, seg, i, hit_level, te, &te, y_e, f_e, K_e));
        make_seg(e, seg, t, te, y, y_e, f, K_e);
    } else {
        memcpy(y_e, y_new, sizeof y_e), memcpy(f_e, f_new, sizeof f_e);
    }
    int cut = 0;
    TRY(end_step(e, seg, t_target, &cut));
    if (!cut) {
        e->seg_i = !e->seg_i, e->has_seg = 1;
        e->t = te, e->flow_reached = 1;
        memcpy(e->x, y_e, sizeof y_e), memcpy(e->f, f_e, sizeof f_e);
        /* the event's point ends this accepted step: a disarmed guard seen there on its before side is
         * armed, as at any step's end — it came back within the step behind the event's crossing (a
         * counter's level that the mass passes just before another event whose jump crosses it again) */
        for (int k = 0; k < e->n_active; ++k) {
            int j = e->active[k];
            if (j == i || e->armed[j] || e->zarm[j]) continue;
            double g;
            TRY(guard_at(e, j, te, y_e, &g));
            if (sgn_of(e, j) * g < 0.0) e->armed[j] = 1;
        }
        set_pending(e, i, 1, y_e, hit_level > 0.0, 0);
    }
    return PG_OK;
}

/* ---- events --------------------------------------------------------------------------------- */
static int check_zeno(PgEngine *e)
{
    int n = e->zeno_max_events;
    if (e->n_events >= n) {
        double first = recent_time(e, n - 1);
        if (e->t - first <= e->zeno_window) {
            /* the names of the latest n events, sorted, each once */
            const char *names[PG_MAX_EVENTS];
            int k = 0;
            for (int j = 0; j < n; ++j) {
                const char *nm = event_name(e, recent_index(e, j));
                int seen = 0;
                for (int a = 0; a < k; ++a) seen |= strcmp(names[a], nm) == 0;
                if (!seen && k < PG_MAX_EVENTS) names[k++] = nm;
            }
            for (int a = 1; a < k; ++a)
                for (int b = a; b > 0 && strcmp(names[b], names[b - 1]) < 0; --b) {
                    const char *tmp = names[b];
                    names[b] = names[b - 1], names[b - 1] = tmp;
                }
            PgMsg *m = &e->msg;
            pg_msg_clear(m);
            pg_msg_printf(m, "event storm: %d events (", n);
            for (int a = 0; a < k; ++a) {
                if (a) pg_msg_str(m, ", ");
                pg_msg_str(m, names[a]);
            }
            pg_msg_str(m, ") within ");
            pg_msg_value(m, e->t - first, 'f', ".3g");
            pg_msg_str(m, " s up to t = ");
            pg_msg_value(m, e->t, 'f', ".15g");
            pg_msg_printf(m, " s (Zeno behaviour; limit %d events per ", n);
            pg_msg_value(m, e->zeno_window, 'f', "g");
            pg_msg_str(m, " s)");
            explicit_hint(e, m);
            return PG_RAISE;
        }
    }
    return PG_OK;
}

/* apply_pending_event */
static int apply_pending_event(PgEngine *e)
{
    int i = e->pending_index, located = e->pending_located; /* (a cascade's set_pending overwrites them) */
    double x_new[PG_MAX_X], q_new[PG_MAX_Q], x_pre[PG_MAX_X], q_pre[PG_MAX_Q];
    signed char was[PG_MAX_EVENTS];
    arming_before(e, was);
    /* its guard at the located crossing, before the jump: its zero (NaN, no zero to keep, for an event
     * fired beyond it by an input change or a jump) */
    double own_g = NAN;
    int ne = MODEL(e)->ne;
    int same_instant = e->armed_at_ok && e->armed_at_t == e->t; /* (the last re-arming was at this instant) */
    int at_zero = e->zero_at_ok && same_instant;
    if (i < ne) {
        if (located || at_zero) TRY(guard_at(e, i, e->t, e->x, &own_g));
        /* (fired by a cascade at the point of a crossing located at this instant: its zero there only if
         * its guard reads the same value as the located one's, the same guard; else beyond its zero) */
        if (!located && !(own_g == e->zero_at_g)) own_g = NAN;
        TRY(model_call(e, &e->msg, MODEL(e)->jump(i, e->t, e->x, e->q, u_at(e, e->t), e->p, x_new, q_new, &e->msg),
                       "the jump", i, e->t, e->x, x_new, NX(e), "%s", MODEL(e)->state_names));
    } else {
        int k = i - ne;
        TRY(model_call(e, &e->msg, MODEL(e)->time_jump(k, e->t, e->x, e->q, u_at(e, e->t), e->p, x_new, q_new, &e->msg),
                       "the jump", i, e->t, e->x, x_new, NX(e), "%s", MODEL(e)->state_names));
        e->te_count[k] += 1; /* the next instant counted from the first: no drift over many periods */
        e->te_next[k] = e->te_every[k] > 0.0 ? e->te_at[k] + (double)e->te_count[k] * e->te_every[k] : INFINITY;
    }
    size_t nx = sizeof(double) * (size_t)NX(e);
    e->last.time = e->t, e->last.index = i;
    memcpy(e->last.x_before, e->pending_x, nx);
    memcpy(e->last.x_after, x_new, nx);
    e->has_last = 1;
    e->n_events += 1;
    e->recent_t[e->recent_head] = e->t, e->recent_i[e->recent_head] = i;
    e->recent_head = (e->recent_head + 1) % PG_RECENT;
    if (e->recent_n < PG_RECENT) e->recent_n += 1;
    if (e->keep_history && e->on_event) e->on_event(e->hook_ctx, e, &e->last, e->n_events);
    e->has_pending = 0;
    int in_place = e->zero_in_place;
    e->zero_in_place = 0;
    TRY(zero_storm(e, i));
    int same_x = 1, same = 1;
    for (int k = 0; k < NX(e); ++k) same_x &= x_new[k] == e->x[k];
    for (int k = 0; k < e->nq; ++k) same &= q_new[k] == e->q[k];
    same &= same_x;
    memcpy(x_pre, e->x, nx), memcpy(q_pre, e->q, sizeof(double) * (size_t)e->nq); /* (the jump's point: crossed_with) */
    memcpy(e->x, x_new, nx);
    memcpy(e->q, q_new, sizeof(double) * (size_t)e->nq);
    TRY(check_zeno(e));
    TRY(check_domain(e, e->t, e->x));
    TRY(bind(e));
    double h0;
    TRY(initial_step(e, &h0));
    e->h = pmin(e->h, h0);
    /* a jump that changed nothing lets its own crossing go on (a counter, a marker) — unless the event
     * fired in place (armed at zero with no first-order direction, at the restart point itself): then
     * nothing at all has changed since that restart, and it stays armed at zero, to fire again once the
     * flow carries it past its band (a plastic impact pressed on, a ball at rest on its floor: the storm,
     * never through the guard; a guard that only dithers within its band, as a marker at a resting
     * record, does not fire again while it stays within it) */
    e->own_same = same && !in_place;
    /* a jump that changed q only (a counter) at a point a step of the flow reached: at a tangency (no
     * direction to first order) its crossing goes on too, in place or not — armed at zero, it fired again
     * in place at that same point on the same curvature until the storm (two counters up and down on
     * one level at a projectile's apex). A body the start or a jump put on its guard (at rest on a
     * floor, after a plastic impact) is not at such a point: its in-place fires keep the rules above */
    e->own_kept = same_x && !same && e->flow_reached;
    if (!same_x) e->flow_reached = 0;
    /* a jump that left x as it was at the instant of the last re-arming (a counter after an impact that
     * kept h where it was located, 1e-15 beyond the counter's band): each guard keeps the band it was
     * armed with there — else the impact's guard, at its located zero, is seen beyond the counter's
     * band on its after side and the impact fires again at this instant, sending the ball through its
     * floor with both guards disarmed */
    e->own_carry = same_x && same_instant;
    int rc = rearm(e, was, i, own_g, x_pre, q_pre); /* a guard the jump left crossed fires at this instant (a cascade) */
    if (in_place && same && e->zarm[i] == 2) e->zarm[i] = 1;
    e->own_same = 0, e->own_kept = 0, e->own_carry = 0;
    e->armed_at_t = e->t, e->armed_at_ok = 1;
    if (i < ne && located && isfinite(own_g)) e->zero_at_g = own_g, e->zero_at_ok = same_x;
    else e->zero_at_ok = same_x && at_zero;
    return rc;
}

/* _run */
/* _call_budget_error */
static int call_budget_error(PgEngine *e, double t_target)
{
    PgMsg *m = &e->msg;
    pg_msg_clear(m);
    pg_msg_str(m, "max_steps_per_call = ");
    pg_msg_value(m, e->s[PG_S_MAX_STEPS_PER_CALL], 'f', "g");
    pg_msg_str(m, " internal steps taken in one call, from t = ");
    pg_msg_value(m, e->t_out, 'f', ".10g");
    pg_msg_str(m, " s to t = ");
    pg_msg_value(m, e->t, 'f', ".10g");
    pg_msg_str(m, " s of a call up to t = ");
    pg_msg_value(m, t_target, 'f', ".10g");
    pg_msg_str(m, " s. To change: use shorter communication steps, or raise the parameter max_steps_per_call "
                  "to let one call take longer");
    return PG_RAISE;
}

/* At an instant where a time event is due: a guard armed at zero that leaves it to its after side to
 * first order (zarm 2 with a direction: of unknown arming at the start, or newly active, heading across)
 * is the state event the next step would find at its start, in place; it is made pending as that step
 * makes it, so that it fires before the time events of this instant (state events first). (A tick at
 * the start fired before the start's own state event, until 2026-12-07: a user's audit.) A guard at
 * zero with no direction to first order is left to the step: its curvature decides. */
static int leaving_zero_now(PgEngine *e)
{
    for (int k = 0; k < e->n_active; ++k) {
        int i = e->active[k];
        if (e->zarm[i] != 2) continue;
        double dg, d, z;
        TRY(guard_motion(e, i, e->t, e->x, e->f, e->g[k], &dg, &d, &z));
        if (!(dg > 2 * z)) continue;
        e->has_seg = 0;
        set_pending(e, i, 1, e->x, e->zband[i] > 0.0, 1);
        return PG_OK;
    }
    return PG_OK;
}

/* _run: at most max_steps_per_call step attempts (accepted and rejected) in one run */
static int run(PgEngine *e, double t_target, int apply_events)
{
    double limit = (double)(e->n_steps + e->n_rejected) + e->s[PG_S_MAX_STEPS_PER_CALL];
    for (;;) {
        if (e->has_pending) {
            if (!apply_events) return PG_OK;
            if (t_target >= e->t) {
                int rc = apply_pending_event(e);
                if (rc) return at_time(e, rc, "t = ", e->t, " s");
                continue;
            }
        }
        double reach = e->t == t_target ? reach_of(e->t) : e->t;
        if (e->t <= t_target && time_event_by(e, reach) >= 0) { /* due now (several at one, the start) */
            TRY(at_time(e, leaving_zero_now(e), "t = ", e->t, " s")); /* (a state event of this instant first) */
            if (!e->has_pending) time_event_pending(e, reach);
            continue;
        }
        if (t_target <= e->t) return PG_OK;
        if ((double)(e->n_steps + e->n_rejected) >= limit) return call_budget_error(e, t_target);
        int rc = step(e, t_target);
        if (rc) return at_time(e, rc, "t = ", e->t, " s");
    }
}

/* ---- public ---------------------------------------------------------------------------------- */
/* a point inside the last step: served from its segment (most points: the steps run ahead of them) */
static int serve_in_step(PgEngine *e, double t_target)
{
    if (t_target == SEG(e)->t0) {
        memcpy(e->x_out, SEG(e)->y0, sizeof(double) * (size_t)NX(e));
    } else {
        int rc = seg_at(e, SEG(e), t_target, e->x_out);
        if (rc) return at_time(e, rc, "t = ", e->t, " s");
    }
    e->t_out = t_target;
    memcpy(e->q_out, e->q, sizeof(double) * (size_t)NQ(e));
    return PG_OK;
}

static PG_NOINLINE int advance(PgEngine *e, double t_target);

int pg_engine_advance(PgEngine *e, double t_target)
{
    if (e->t_out <= t_target && t_target < e->t) return serve_in_step(e, t_target);
    return advance(e, t_target);
}

static PG_NOINLINE int advance(PgEngine *e, double t_target)
{
    size_t nx = sizeof(double) * (size_t)NX(e), nq = sizeof(double) * (size_t)NQ(e);
    if (t_target < e->t_out) {
        pg_msg_clear(&e->msg);
        pg_msg_str(&e->msg, "cannot go back in time: t = ");
        pg_msg_value(&e->msg, t_target, 'f', "r");
        pg_msg_str(&e->msg, " < ");
        pg_msg_value(&e->msg, e->t_out, 'f', "r");
        return PG_RAISE;
    }
    if (e->stateless) {
        for (;;) { /* events its inputs caused, and time events, each at its instant */
            if (!e->has_pending) {
                double tt = pg_engine_next_time_event(e);
                if (!(tt <= reach_of(t_target))) break;
                e->t = pmax(e->t, pmin(tt, t_target));
                time_event_pending(e, reach_of(e->t));
            }
            if (!(e->has_pending && t_target >= e->t)) break;
            int rc = apply_pending_event(e);
            if (rc) return at_time(e, rc, "t = ", e->t, " s");
        }
        e->t = e->t_out = pmax(e->t, t_target);
        memcpy(e->q_out, e->q, nq);
        return PG_OK;
    }
    TRY(run(e, t_target, 1));
    e->t_out = t_target;
    if (t_target == e->t) {
        memcpy(e->x_out, e->x, nx);
    } else {
        int rc = seg_at(e, SEG(e), t_target, e->x_out);
        if (rc) return at_time(e, rc, "t = ", e->t, " s");
    }
    memcpy(e->q_out, e->q, nq);
    return PG_OK;
}

int pg_engine_advance_to_event(PgEngine *e, double t_target, int *stopped)
{
    *stopped = 0;
    if (t_target < e->t_out) return pg_engine_advance(e, t_target); /* (the same refusal) */
    if ((MODEL(e)->ne == 0 && MODEL(e)->nte == 0) || e->stateless) return pg_engine_advance(e, t_target);
    TRY(run(e, t_target, 0));
    if (e->has_pending && e->t <= t_target) {
        e->t_out = e->t;
        memcpy(e->x_out, e->x, sizeof e->x);
        memcpy(e->q_out, e->q, sizeof e->q);
        *stopped = 1;
        return PG_OK;
    }
    return pg_engine_advance(e, t_target);
}

int pg_engine_event_due(const PgEngine *e) { return e->has_pending && e->t == e->t_out; }

/* _crossed_in: the first active event whose guard went from its before side to its after side */
static int crossed_in(PgEngine *e, double t0, const double *y0, double t1, const double *y1, int *index)
{
    int disarmed = e->has_last && e->last.time == SEG(e)->t0 ? e->last.index : -1;
    *index = -1;
    for (int k = 0; k < e->n_active; ++k) {
        int i = e->active[k];
        double sgn = sgn_of(e, i), a, b;
        TRY(guard_at(e, i, t0, y0, &a));
        TRY(guard_at(e, i, t1, y1, &b));
        double g0 = sgn * a, g1 = sgn * b;
        if (continues_own_crossing(e, i, g0)) continue; /* (as in step) */
        if (g1 >= 0.0 && (g0 < 0.0 || (g0 == 0.0 && 0.0 < g1 && i != disarmed))) {
            *index = i;
            return PG_OK;
        }
    }
    return PG_OK;
}

int pg_engine_set_input(PgEngine *e, const double *u) { return pg_engine_set_inputs(e, u, NULL); }

int pg_engine_set_inputs(PgEngine *e, const double *u, const double *du)
{
    int sloped = 0;
    if (du)
        for (int i = 0; i < e->nu; ++i) sloped |= du[i] != 0.0;
    int same = 1;
    for (int i = 0; i < e->nu; ++i) same &= u[i] == e->u[i];
    if (sloped || e->has_du) { /* the same line only if the same value and slope from the same point */
        same &= sloped && e->has_du && e->t_u == e->t_out;
        for (int i = 0; same && i < e->nu; ++i) same &= du[i] == e->du[i];
    }
    if (same) return PG_OK;
    TRY(check_inputs(e, u));
    if (sloped) TRY(check_finite_inputs(e, du, 1));
    int early = e->t == e->t_out && !e->has_pending; /* (the state event of this instant: below) */
    e->flow_reached = 0, e->armed_at_ok = 0; /* (an input change may put a guard at zero: not a point the flow reached) */
    int crossed = -1;
    if (e->t > e->t_out) {
        double x[PG_MAX_X];
        if (e->t_out == SEG(e)->t0) {
            memcpy(x, SEG(e)->y0, sizeof x);
        } else {
            double f_c[PG_MAX_X];
            double K_c[PG_MAX_STAGES * PG_MAX_X];
            int rc = pair_step_of(e, SEG(e)->method, SEG(e)->t0, SEG(e)->y0, SEG(e)->f0, e->t_out - SEG(e)->t0, x,
                                  f_c, K_c);
            if (!rc) rc = crossed_in(e, SEG(e)->t0, SEG(e)->y0, e->t_out, x, &crossed);
            if (rc) return at_time(e, rc, "the input change at t = ", e->t_out, " s");
        }
        e->t = e->t_out;
        memcpy(e->x, x, sizeof x);
        e->has_pending = 0, e->zero_in_place = 0;
        e->has_seg = 0;
        if (crossed < 0 && !e->stateless) { /* (the flow and the guards at this point, for the rule below) */
            int rc = bind(e);
            if (rc) return at_time(e, rc, "the input change at t = ", e->t, " s");
            early = 1;
        }
    }
    if (early && !e->stateless) {
        /* an armed guard within its rounding band short of zero and heading across here, where the inputs
         * change: the state event of this instant to rounding (located an ulp or two past it, or a step
         * landed an ulp short of it) fires first, under the inputs before the change — as before a time
         * event at its instant (a sawtooth that reached its level at the instant the level stepped lost
         * that reset, in every co-simulation kind, until 2026-12-07) */
        int k_now;
        int rc = crossing_at(e, &k_now);
        if (!rc && k_now >= 0) {
            set_pending(e, e->active[k_now], 1, e->x, 0, 0);
            rc = apply_pending_event(e);
            memcpy(e->x_out, e->x, sizeof e->x);
            memcpy(e->q_out, e->q, sizeof e->q);
        }
        if (rc) return at_time(e, rc, "t = ", e->t, " s");
    }
    /* each guard's arming at (t, x) with the inputs before the change: a guard armed there that the
     * new inputs put on its after side fires at this instant (an event caused by an input) */
    signed char was[PG_MAX_EVENTS];
    arming_before(e, was);
    for (int k = 0; k < e->n_active; ++k) {
        int i = e->active[k];
        double g;
        int rc = guard_at(e, i, e->t, e->x, &g);
        if (rc) return at_time(e, rc, "the input change at t = ", e->t, " s");
        double G = sgn_of(e, i) * g;
        int at_zero = e->zarm[i] && G >= -e->zband[i] && G <= e->zband[i];
        was[i] = at_zero && e->zarm[i] == 1 ? 2 : G < 0.0 || at_zero; /* (2: armed at zero, a rebound: zero_moved) */
    }
    memcpy(e->u, u, sizeof(double) * (size_t)e->nu);
    e->has_du = sloped;
    e->t_u = e->t;
    if (sloped) memcpy(e->du, du, sizeof(double) * (size_t)e->nu);
    else memset(e->du, 0, sizeof(double) * (size_t)e->nu);
    int rc = bind(e);
    double h0 = 0;
    if (!rc) rc = initial_step(e, &h0);
    if (rc) return at_time(e, rc, "the input change at t = ", e->t, " s");
    if (e->n_steps == 0 && e->n_rejected == 0 && e->n_events == 0) {
        /* nothing integrated yet (an input set after the initialization, before the first step): the
         * start's own first step, as if the value had been set in Initialization Mode — the same bits */
        if (!(e->s[PG_S_INITIAL_STEP] > 0)) e->h = h0;
    } else {
        e->h = pmin(e->h, h0);
    }
    if (crossed >= 0) {
        set_pending(e, crossed, 0, e->x, 0, 0);
    }
    int fire = -1;
    rc = arm_guards(e, was, -1, 0.0, NULL, NULL, &fire);
    if (rc) return at_time(e, rc, "the input change at t = ", e->t, " s");
    if (fire >= 0 && !e->has_pending) {
        set_pending(e, fire, 0, e->x, 0, 0);
    }
    return PG_OK;
}

int pg_engine_apply_event(PgEngine *e, int index, double t, const double *x)
{
    /* located: the importer found its guard at its zero (a root of its indicator; that value is its
     * zero after the jump) — unless the engine made it pending at this instant itself (a cascade, the
     * start, an input change of a model without states: as it said) or an input change carried its
     * guard past zero here (pg_engine_restart_at): then it fired beyond its zero, as in co-simulation */
    int located = e->has_pending && e->t == t && e->pending_index == index
                      ? e->pending_located
                      : !(index < MODEL(e)->ne && e->me_input_crossed[index]);
    memset(e->me_input_crossed, 0, sizeof e->me_input_crossed); /* (the restart re-arms every guard) */
    for (int k = 0; k < e->n_active; ++k) /* (seen on its before side only after t: not armed at t) */
        if (!armed_at(e, e->active[k], t)) e->armed[e->active[k]] = 0;
    e->t = e->t_out = t;
    memcpy(e->x, x, sizeof(double) * (size_t)NX(e));
    e->has_seg = 0, e->flow_reached = 0; /* (the importer's point) */
    /* (e->zero_hit: as pg_engine_me_fired found this event, from zero or not: the storm rule counts it) */
    set_pending(e, index, located, e->x, e->zero_hit, e->zero_in_place);
    int rc = apply_pending_event(e);
    if (rc) return at_time(e, rc, "t = ", e->t, " s");
    memcpy(e->x_out, e->x, sizeof e->x);
    memcpy(e->q_out, e->q, sizeof e->q);
    return PG_OK;
}

/* ---- model exchange: the importer integrates, the engine arms (docs/solver.md, "Event semantics") --
 * The arming of each guard is the one co-simulation uses (armed[], zarm[], zband[], set by arm_guards
 * at the start, after each jump and at each input change): an indicator evaluation at (t, x) is an
 * observation of the trajectory, as the end of an accepted step is in co-simulation. The states come
 * from the importer's interpolant, whose error is its tolerance, not the rounding: an event fires
 * only where its guard is not carried back to its before side by the flow (pg_engine_me_fired). */
#define ME_UNARMED_FLOOR 1e-300 /* the least magnitude an unarmed indicator is reported with */
#define ME_ROOT_TIME 1e-9 /* an importer's located root lies within this (times max(|t|, 1)) of the zero */

/* the importer located guard i at its threshold and the flow carried it back, no event: as many
 * times as the storm bound (zeno_max_events) within zeno_window, of one event and none firing, is an
 * accumulation below the importer's resolution: the storm error naming the event */
static int me_decline_storm(PgEngine *e, int i, double t)
{
    if (e->me_decl_n && e->me_decl_event == i && t == e->me_decl_t) return PG_OK; /* (the same point again) */
    if (e->me_decl_n == 0 || e->me_decl_event != i || t - e->me_decl_t0 > e->zeno_window)
        e->me_decl_event = i, e->me_decl_t0 = t, e->me_decl_n = 0;
    e->me_decl_t = t;
    if (++e->me_decl_n < e->zeno_max_events) return PG_OK;
    PgMsg *m = &e->msg;
    pg_msg_clear(m);
    pg_msg_printf(m, "event storm: %s happens again within the rounding of its own location at t = ", event_name(e, i));
    pg_msg_value(m, t, 'f', ".15g");
    pg_msg_printf(m, " s (the integrator located its guard at zero %d times within ", e->me_decl_n);
    pg_msg_value(m, t - e->me_decl_t0, 'f', ".3g");
    pg_msg_str(m, " s, the flow carrying it back each time: the events accumulate below the integrator's resolution "
                  "(Zeno behaviour, e.g. a bouncing ball coming to rest). Model the rest (a mode without this event "
                  "once the motion is small), or stop before this time");
    e->me_decl_n = 0;
    return PG_RAISE;
}

int pg_engine_me_indicators(PgEngine *e, double t, const double *x, double *z)
{
    for (int i = 0; i < MODEL(e)->ne; ++i) z[i] = 1.0; /* inactive: a value that cannot cross zero */
    for (int k = 0; k < e->n_active; ++k) {
        int i = e->active[k];
        double g, sgn = sgn_of(e, i);
        TRY(guard_at(e, i, t, x, &g)); /* (the model's own message, as the adapters gave it) */
        double G = sgn * g, band = e->zband[i];
        if (G < -band) e->me_input_crossed[i] = 0; /* seen on its before side: no input change carries it past now */
        int after_event = !(e->has_last && t == e->last.time); /* (at the event's instant: see below) */
        if (e->zarm[i] && G < -band && after_event) { /* it left zero to its before side: an ordinary armed guard */
            if (i == e->zrun_event) e->zrun = 0; /* no accumulation */
            e->zarm[i] = 0, e->me_prov[i] = 0;
        } else if (!e->armed[i] && G < 0.0 && !(t == e->t && G >= -band) && after_event) {
            /* seen on its before side (beyond the rounding of the restart point), after the instant of
             * the last event: at that instant the restart decided its arming, and the trajectory has not
             * moved since (an importer that sets the inputs' values from before the event again there,
             * as fmpy's model exchange does at the start of each integration, does not arm it) */
            e->armed[i] = 1, e->me_seen[i] = 1, e->me_seen_t[i] = t;
        } else if (e->me_seen[i] && G < 0.0 && t < e->me_seen_t[i] && !(t == e->t && G >= -band)) {
            e->me_seen_t[i] = t; /* seen on its before side earlier than before: armed from here */
        }
        if (e->zarm[i]) { /* a sign change where it leaves its band to its after side */
            double r = G - band;
            z[i] = r == 0.0 ? -sgn * ME_UNARMED_FLOOR : sgn * r;
        } else if (g == 0.0) {
            /* a guard exactly 0 is reported on the side before its crossing: no indicator of a new mode
             * starts at zero (an importer that does not restart its integrator after an event that
             * changed no state meets no root at the restart point), and an armed one meets its root
             * where it is past zero (CVODE tries each indicator a rounding after its restart point: an
             * armed guard 0 there, the rebound of a counter on the level another counter's crossing
             * just fired at, was a root at each try, 200 times in a row, and ended in a false storm;
             * a user's audit, 2026-12-07) */
            z[i] = -sgn * ME_UNARMED_FLOOR;
        } else {
            z[i] = g;
        }
    }
    return PG_OK;
}

int pg_engine_me_fired(PgEngine *e, double t, const double *x, int *index)
{
    *index = -1;
    if (e->has_pending && e->t == t) { /* a cascade, or an event at the start or of an input change */
        *index = e->pending_index;
        return PG_OK;
    }
    e->zero_hit = 0, e->zero_in_place = 0;
    for (int k = 0; k < e->n_active; ++k) { /* (active[] is in the model's order: priority) */
        int i = e->active[k];
        double g;
        TRY(guard_at(e, i, t, x, &g));
        double G = sgn_of(e, i) * g, band = e->zband[i];
        if (!(e->zarm[i] ? G > band : armed_at(e, i, t) && G >= 0.0)) continue;
        if (e->zarm[i] && e->me_prov[i]) { /* a guessed rebound that went on to its after side: the crossing
                                             * of its event went on (an input's step onto the level of a
                                             * counter of x - u, u rising on: counted twice, 5.6e-14 s apart,
                                             * until 2026-12-07) */
            e->zarm[i] = 0, e->armed[i] = 0, e->me_prov[i] = 0;
            continue;
        }
        if (e->me_input_crossed[i]) { /* an input change carried it past zero: it fires whatever the flow does
                                       * there, as in co-simulation (not a crossing the importer located) */
            *index = i;
            e->me_decl_n = 0;
            e->zero_hit = 0;
            return PG_OK;
        }
        /* a crossing or a touch, unless the flow carries the guard back to its before side: the
         * importer's interpolant, whose error is its tolerance, met the threshold where the motion
         * leaves it (a mass leaving a wall at 1e-7 m/s seen 1e-13 m inside it) */
        double f[PG_MAX_X], dg, d;
        TRY(MODEL(e)->flow(t, x, e->q, u_at(e, t), e->p, f, &e->msg));
        TRY(guard_change(e, i, t, x, f, &dg, &d));
        if (dg < 0.0) {
            TRY(me_decline_storm(e, i, t));
            if (G <= 4 * band) {
                /* at zero to rounding: armed at zero here, its band widened to this rounding, so that
                 * its indicator is back on its before side for the importer's restart */
                e->zarm[i] = 1, e->armed[i] = 1, e->me_seen[i] = 0;
                e->zband[i] = pmax(e->zband[i], 2 * fabs(G));
            } /* (else its indicator changes sign on the way back, and again where it crosses) */
            continue;
        }
        *index = i;
        e->me_decl_n = 0;
        e->zero_hit = e->zarm[i]; /* from zero, its guard never having left its band to its before side */
        /* found far past its zero (the importer located no root: an input's motion across it between
         * two of its points that its root finding let pass, found at the step's end): it fires beyond
         * its zero, as one an input change carried past, its value there not taken for its zero (a
         * counter fired 0.1 s late with its guard 0.02 past zero had its band widened to 0.02, and fired
         * again from that "zero" until a false storm; a user's audit, 2026-12-07) */
        if (!e->zarm[i] && G > 4 * band + fabs(dg) / (2 * d) * ME_ROOT_TIME * pmax(fabs(t), 1.0))
            e->me_input_crossed[i] = 1;
        return PG_OK;
    }
    return PG_OK;
}

/* model exchange: the inputs' rate from the importer's samples (e->me_du), each sample (t, u) it sets,
 * changed or not. A change at the time of the sample before is a discrete change (Event Mode, an
 * input's step): no rate until a sample at another time. Else the secant from the anchor sample, once
 * this one is a rate step away from it (closer, the secant is the rounding's; the rate found before
 * is kept). The rate holds at the latest sample's time only (inputs_on_line): an importer that stops
 * setting the inputs holds them. Returns 1 for a discrete change */
static int me_input_rate(PgEngine *e, double t, const double *u, int change)
{
    size_t nu = sizeof(double) * (size_t)e->nu;
    int discrete = change && e->me_has_ua && t == e->me_t_last;
    e->me_t_last = t;
    if (!e->me_has_ua || discrete) {
        e->me_has_du = 0;
    } else if (fabs(t - e->me_ta) >= RATE_STEP * pmax(fabs(t), 1.0)) {
        for (int i = 0; i < e->nu; ++i) e->me_du[i] = (u[i] - e->me_ua[i]) / (t - e->me_ta);
        e->me_has_du = 1;
    } else {
        return discrete;
    }
    memcpy(e->me_ua, u, nu), e->me_ta = t, e->me_has_ua = 1;
    return discrete;
}

int pg_engine_restart_at(PgEngine *e, double t, const double *x, const double *u)
{
    /* model exchange: the importer sets the inputs at every point it tries, beyond a crossing too;
     * the arming of a model with states is the observed trajectory's and is kept (an armed guard that
     * the new inputs put on its after side fires: pg_engine_me_fired), and so is an event pending at
     * this instant; a model without states is re-armed by the change, as in co-simulation */
    int pending = e->has_pending && e->t == t;
    e->t = e->t_out = t;
    memcpy(e->x, x, sizeof(double) * (size_t)NX(e));
    memcpy(e->x_out, x, sizeof(double) * (size_t)NX(e));
    e->has_seg = 0, e->has_pending = 0, e->flow_reached = 0;
    if (e->stateless) return pg_engine_set_input(e, u); /* (an input change is the only motion: as in co-simulation) */
    int change = 0;
    for (int i = 0; i < e->nu; ++i) change |= !(u[i] == e->u[i]);
    e->has_pending = pending;
    if (!change) {
        me_input_rate(e, t, u, 0);
        return PG_OK;
    }
    /* the new inputs bound, and nothing else of a co-simulation restart (pg_engine_set_inputs): the
     * importer integrates, so no step size is chosen, and the flow is tried at no point it did not ask for */
    TRY(check_inputs(e, u));
    /* a discrete change (at the time of the sample before) can carry an armed guard past zero at this
     * point; a change at a new time is the inputs' motion along the importer's trajectory, whose
     * crossings the importer locates (their direction counting that motion: me_input_rate). Until
     * 2026-12-07 such a change fired a rebound the states' rounding put a hair past its band (the
     * states at the new point, the inputs old and new): a ball bouncing on a platform rising at
     * 0.05 m/s fired again 2.3e-12 s after a bounce, moving away, and was sent through the platform */
    int step = me_input_rate(e, t, u, 1);
    double g_old[PG_MAX_EVENTS]; /* each armed guard at this point under the inputs before the change */
    for (int k = 0; k < e->n_active; ++k)
        if (armed_at(e, e->active[k], t)) TRY(at_time(e, guard_at(e, e->active[k], t, x, &g_old[k]), "the input change at t = ", t, " s"));
    memcpy(e->u, u, sizeof(double) * (size_t)e->nu);
    memset(e->du, 0, sizeof(double) * (size_t)e->nu);
    e->has_du = 0, e->t_u = t;
    TRY(at_time(e, bind(e), "the input change at t = ", t, " s")); /* (e->g: each active guard under the new inputs) */
    for (int k = 0; k < e->n_active; ++k) { /* an armed guard the change carried past zero (past its band, armed at zero) */
        int i = e->active[k];
        if (!armed_at(e, i, t)) continue;
        double sgn = sgn_of(e, i), at = e->zarm[i] ? e->zband[i] : 0.0;
        int crossed = step && sgn * g_old[k] <= at && sgn * e->g[k] > at;
        if (crossed && e->zarm[i] == 1 && sgn * g_old[k] >= -at) {
            /* a rebound at zero that the change put on its after side: crossed unless the flow under the
             * new inputs still carries it to its before side (zero_moved, as in co-simulation) */
            double dg, d, z;
            TRY(at_time(e, guard_motion(e, i, t, x, e->f, e->g[k], &dg, &d, &z), "the input change at t = ", t, " s"));
            if (dg < -2 * z) {
                zero_moved(e, i, sgn * e->g[k], z);
                crossed = 0, e->me_input_crossed[i] = 0;
            }
        }
        if (crossed) e->me_input_crossed[i] = 1;
        else if (sgn * e->g[k] <= at) e->me_input_crossed[i] = 0; /* (back: the importer tried a point before the change) */
    }
    return PG_OK;
}

const double *pg_engine_inputs_at(PgEngine *e, double t) { return u_at(e, t); }

int pg_engine_domain_problem(PgEngine *e, double t, const double *x)
{
    int rc = MODEL(e)->domain(t, x, e->q, u_at(e, t), e->p, e->s, &e->msg);
    return rc == PG_RAISE;
}

int pg_engine_flow(PgEngine *e, double t, const double *x, double *dx)
{
    /* (model exchange: the rates handed to the importer, each finite, or the flow named) */
    int rc = MODEL(e)->flow(t, x, e->q, u_at(e, t), e->p, dx, &e->msg);
    return model_call(e, &e->msg, rc, "the flow", -1, t, x, dx, NX(e), "d%s/dt", MODEL(e)->state_names);
}

#ifndef PG_STATE_OUTPUTS_EXACT
/* an output of a state's name that does not carry the state's value (a NaN state: told elsewhere) */
static PG_NOINLINE int state_output_differs(PgEngine *e, int k, double t, const double *x, const double *y)
{
    int o = e->xy_y[k], i = e->xy_x[k];
    PgMsg *m = &e->msg;
    pg_msg_clear(m);
    function_failed_at(e, m, "the outputs", -1, t, x);
    pg_msg_printf(m, "it returned %s = ", MODEL(e)->output_names[o]);
    pg_msg_value(m, y[o], 'f', "r");
    pg_msg_printf(m, ", which violates the rule: an output that shares a state's name carries that state's value "
                     "(%s = ", MODEL(e)->state_names[i]);
    pg_msg_value(m, x[i], 'f', "r");
    pg_msg_str(m, ")");
    return PG_RAISE;
}
#endif

int pg_engine_guard(PgEngine *e, int k, const double *x, double *g) { return guard_at(e, k, e->t_out, x, g); }

int pg_engine_outputs(PgEngine *e, double t, const double *x, const double *q, double *y)
{
    int rc = MODEL(e)->outputs(t, x, q, u_at(e, t), e->p, y, &e->msg);
    rc = model_call(e, &e->msg, rc, "the outputs", -1, t, x, y, NY(e), "%s", MODEL(e)->output_names);
#ifndef PG_STATE_OUTPUTS_EXACT
    for (int k = 0; !rc && k < e->n_xy; ++k)
        if (!(y[e->xy_y[k]] == x[e->xy_x[k]]) && isfinite(x[e->xy_x[k]])) return state_output_differs(e, k, t, x, y);
#endif
    return rc;
}

size_t pg_engine_sizeof(void) { return sizeof(PgEngine); }
const char *pg_engine_message(const PgEngine *e) { return e->msg.text; }

void pg_engine_served(const PgEngine *e, double *t_out, double *x_out, double *q_out, long *n_events)
{
    *t_out = e->t_out;
    memcpy(x_out, e->x_out, sizeof(double) * (size_t)NX(e));
    memcpy(q_out, e->q_out, sizeof(double) * (size_t)e->nq);
    *n_events = e->n_events;
}

void pg_engine_stats(const PgEngine *e, long *n_steps, long *n_rejected, long *n_jacobians, long *n_switches,
                     int *method_in_use)
{
    *n_steps = e->n_steps, *n_rejected = e->n_rejected, *n_jacobians = e->n_jacobians;
    *n_switches = e->n_switches, *method_in_use = e->cur;
}

int pg_engine_last_event(const PgEngine *e, double *time, int *index)
{
    if (!e->has_last) return 0;
    *time = e->last.time, *index = e->last.index;
    return 1;
}

static const char *method_name(int method) { return method == 1 ? "Rodas5P" : method == 8 ? "DOP853" : "DOPRI5"; }

void pg_engine_switch_message(PgMsg *m, double t, int from, int to, double h_rho)
{
    pg_msg_clear(m);
    pg_msg_printf(m, "method switch at t = ");
    pg_msg_value(m, t, 'f', "r");
    pg_msg_printf(m, " s: %s -> %s (%s: h*rho = ", method_name(from), method_name(to),
                  to == 1 ? "stiff" : "no longer stiff");
    pg_msg_value(m, h_rho, 'f', ".3g");
    pg_msg_str(m, to == 1 ? " > 3 in 15 steps, DOPRI5's stiffness test)" : " < 3 in 15 steps, rho from the Jacobian)");
}
