/* pogofmu engine: the hybrid integrator of every FMU (native ones link it with their generated
 * model; the Python-hosted ones' launcher carries it, runtime/solver/cengine.py binds it), written
 * once in C for any model.
 *
 * Its rules (docs/solver.md): DOPRI5 / DOP853 / Rodas5P with
 * error control, the step running ahead of the communication points and serving them from the
 * dense output, event location on the continuous extension (Illinois) then on exact steps
 * (secant), hidden crossings, guards at zero after a jump or at the start, the restart caps, the
 * work budget, the event storm bound, the domain conditions — and the same messages.
 *
 * A PgEngine holds no pointer to memory of its own: copying the struct copies the whole state
 * (fmi2GetFMUstate is a memcpy). Functions return PG_OK, or PG_RAISE with the message in e->msg
 * (the text of the exception the Python binding raises). */
#ifndef PG_ENGINE_H
#define PG_ENGINE_H

#include "pg_model.h"
#include "pg_pairs.h"
#include "pg_rodas.h"

/* The largest model the engine takes. A native FMU's own pg_sizes.h (pg_pairs.h includes it) sets
 * each size to its model's count, so that its instance and every FMU state (a copy of the instance,
 * fmi2GetFMUstate) hold what the model uses and no more: a segmented-mirror actuator's state is a
 * few kB instead of ~80 kB. */
#ifndef PG_MAX_Q
#define PG_MAX_Q 16
#endif
#ifndef PG_MAX_U
#define PG_MAX_U 1024 /* a reconstructor of a 12-ring segmented mirror takes 469 */
#endif
#ifndef PG_MAX_Y
#define PG_MAX_Y 1024 /* the model's outputs */
#endif
#ifndef PG_MAX_P
#define PG_MAX_P 64
#endif
#define PG_NS 8 /* solver settings: method rel_tol abs_tol max_step initial_step log_events max_steps_per_second
                  max_steps_per_call (the order of SOLVER_PARAMETERS in engine/settings.py) */
#ifndef PG_MAX_EVENTS
#define PG_MAX_EVENTS 16
#endif
#ifndef PG_MAX_TIME_EVENTS
#define PG_MAX_TIME_EVENTS 16
#endif
#define PG_RECENT 200 /* max(zeno_max_events, STORM_EVENTS) */

enum { PG_S_METHOD, PG_S_REL_TOL, PG_S_ABS_TOL, PG_S_MAX_STEP, PG_S_INITIAL_STEP, PG_S_LOG_EVENTS,
       PG_S_MAX_STEPS_PER_SECOND, PG_S_MAX_STEPS_PER_CALL };

typedef struct PgSeg {
    double t0, t1;
    double y0[PG_MAX_X], y1[PG_MAX_X], f0[PG_MAX_X];
    double K[PG_MAX_STAGES * PG_MAX_X];
    int dense_built;
    int method; /* the method that made the step (5, 8 or 1): its continuous extension */
    double Q[PG_MAX_DENSE * PG_MAX_X];
} PgSeg;

typedef struct PgEvent {
    double time;
    int index;
    double x_before[PG_MAX_X], x_after[PG_MAX_X];
} PgEvent;

typedef struct PgEngine PgEngine;
/* called at each event when the parameter log_events is 1 (number: 1 for the first event) */
typedef void (*PgEventHook)(void *ctx, const PgEngine *e, const PgEvent *ev, long number);
/* called with a warning text (the work budget) */
typedef void (*PgWarnHook)(void *ctx, const char *text);
/* method = 0 (automatic): called at each switch, at time t, from one method to the other (5 DOPRI5,
 * 1 Rodas5P), with the stiffness estimate h*rho that decided it (rho: the largest eigenvalue's
 * modulus of the flow's Jacobian as estimated, h the step) */
typedef void (*PgSwitchHook)(void *ctx, const PgEngine *e, double t, int from, int to, double h_rho);

struct PgEngine {
    const PgModel *model;
    int nx, nq, nu, np;
    double p[PG_MAX_P], s[PG_NS];
    int method;
    double rtol, atol, max_step, t_stop, zeno_window;
    int zeno_max_events;
    double u[PG_MAX_U];
    /* linear inputs (FMI 2.0 fmi2SetRealInputDerivatives): u(t) = u + du (t - t_u) from the
     * communication point t_u on; has_du = 0 (every slope zero) is held inputs, u itself */
    int has_du;
    double t_u, du[PG_MAX_U];
    double t, t_out;
    double x[PG_MAX_X], q[PG_MAX_Q];
    double x_out[PG_MAX_X], q_out[PG_MAX_Q];
    long n_events;
    int has_last;
    PgEvent last;
    int keep_history;
    double recent_t[PG_RECENT];
    int recent_i[PG_RECENT];
    int recent_n, recent_head; /* ring buffer of the latest events' (time, index) */
    int has_seg;
    PgSeg segs[2]; /* the last step's segment, segs[seg_i]; the other: the next step's, built in place */
    int seg_i;
    int has_pending, pending_index;
    double pending_x[PG_MAX_X];
    long n_steps, n_rejected;
    double budget, win_t0, warn_n;
    long win_n;
    int warned;
    signed char through_warned[PG_MAX_EVENTS]; /* the warning of a crossing that goes on through its jump, said */
    int stateless;
    int n_active, active[PG_MAX_EVENTS];
    /* the arming of each event's guard (docs/solver.md, "Event semantics"): armed[i] = 1 while it may
     * fire (seen on its before side, or at zero after a restart); zarm[i] = 1 while it sits at zero
     * within its rounding band zband[i] after a jump, a start or an input change: it fires when the
     * flow carries it past +zband[i] to its after side */
    signed char armed[PG_MAX_EVENTS], zarm[PG_MAX_EVENTS];
    double zband[PG_MAX_EVENTS];
    /* the pending event fires from zero without its guard having left its band (zero_hit), and how
     * many of the latest events in a row of event zrun_event did (a storm at ZERO_REFIRES) */
    int zero_hit, zrun, zrun_event;
    int own_same; /* (during a re-arming) the jump just applied left x and q as they were */
    /* (e->t, e->x) is where a step of the flow ended, no jump since having changed x (0 after the start, a
     * jump that changed x, an input change, a point the importer set); and, during a re-arming, the jump
     * just applied at such a point changed q only (a counter): its guard's departure from zero goes on */
    int flow_reached, own_kept;
    /* the instant of the last re-arming after a jump (armed_at_ok: valid); during a re-arming, own_carry:
     * the jump left x as it was at that same instant, so each guard keeps the band it was armed with there
     * (a crossing located beyond rounding stays at its zero through the instant's other jumps) */
    double armed_at_t;
    int armed_at_ok, own_carry;
    /* (e->t, e->x) is still the point where an event's crossing was located at this instant (its jump
     * and those after it left x as it was; zero_at_ok), its guard's value there zero_at_g: an event that
     * fires there by a cascade with the same guard value has its zero there too (two events on one guard) */
    double zero_at_g;
    int zero_at_ok;
    /* kept[i]: guard i, disarmed so (its counter's crossing going on at a tangency), is still within its
     * band zband[i]: its dither there is that crossing's rounding, not a new one (armed_after_step, step) */
    signed char kept[PG_MAX_EVENTS];
    /* the pending event fires where its step started, armed at zero with no first-order direction
     * (zarm 2): at the restart point itself; if its jump changes nothing, it stays armed at zero and
     * fires again past its band (apply_pending_event) */
    int zero_in_place;
    PgMsg note; /* a trial stage's non-finite rate since the last accepted step (the flow named): the cause, if the step collapses */
    int has_note;
    int probe; /* (during probe_step) the flow's values are checked */
    int pending_located; /* the pending event's guard was located at its crossing (a step's root, the importer's):
                          * its value there is its zero; an event an input change or a jump fired is beyond it */
    /* time events: each one's next instant (INFINITY: no more), first instant, period and count */
    double te_next[PG_MAX_TIME_EVENTS], te_at[PG_MAX_TIME_EVENTS], te_every[PG_MAX_TIME_EVENTS];
    long te_count[PG_MAX_TIME_EVENTS];
    /* model exchange: guard me_decl_event located at its threshold with the flow carrying it back (no
     * event) me_decl_n times in a row since me_decl_t0 (pg_engine_me_fired; a storm at the bound) */
    int me_decl_n, me_decl_event;
    double me_decl_t0, me_decl_t;
    /* model exchange: the armed guards an input change carried past their zero (pg_engine_restart_at), until
     * an event fires or the guard is seen on its before side again: such a guard fires whatever the flow
     * does there (pg_engine_me_fired), beyond its zero, not at a located crossing (pg_engine_apply_event);
     * so does one pg_engine_me_fired finds far past its zero (a crossing the importer did not locate) */
    signed char me_input_crossed[PG_MAX_EVENTS];
    /* model exchange: guard i was armed by an observation (pg_engine_me_indicators) and not since by a
     * restart (me_seen[i]), at the earliest time me_seen_t[i] it was seen on its before side. The importer
     * observes out of time order (its root search tries points beyond a root, then comes back): such a
     * guard is armed only at a time after me_seen_t[i] (armed_at) */
    signed char me_seen[PG_MAX_EVENTS];
    double me_seen_t[PG_MAX_EVENTS];
    /* model exchange: the inputs' rate me_du (me_has_du: known), the secant from the anchor sample (me_ta,
     * me_ua; me_has_ua) to the importer's latest sample (at me_t_last) a rate step away (me_input_rate): the
     * importer moves its inputs between its points, and a guard's direction at zero (guard_change)
     * counts that motion as a co-simulation's input derivatives do. Only the direction rules read it:
     * the flow and the guards' values read the inputs as set */
    double me_ua[PG_MAX_U], me_du[PG_MAX_U], me_ta, me_t_last;
    int me_has_ua, me_has_du;
    /* model exchange: me_prov[i], guard i armed at zero as a rebound (zarm 1) by a restart where the
     * rebound is a guess about the inputs: the importer had just set them with no rate known (a discrete
     * change, at that instant), or their secant alone makes it, the guard still along the flow with them
     * held (the importer may turn them back; inputs never set are held, their rate 0, known). Seen
     * beyond its band on its after side before its before side, its crossing went on, and it is disarmed
     * (pg_engine_me_fired); seen beyond its band on its before side, it is an ordinary armed guard */
    signed char me_prov[PG_MAX_EVENTS];
    /* the outputs that share a state's name (docs/writing-models.md section 6: they carry that state's
     * value; in FMI 3.0 they are the state's own variable): output xy_y[k] is state xy_x[k] */
    int n_xy, xy_y[PG_MAX_X], xy_x[PG_MAX_X];
    double f[PG_MAX_X], g[PG_MAX_EVENTS], g_prev[PG_MAX_EVENTS];
    int has_g_prev;
    double h;
    /* the method in use (e->method unless it is 0: then 5 or 1, switched by the stiffness tests) */
    int cur;
    int switch_to; /* a switch decided after the latest step, made before the next */
    int stiff_n, calm_n; /* consecutive-ish steps found stiff / not stiff (method = 0) */
    double h_rho;        /* the latest stiffness estimate */
    long n_switches, n_jacobians;
    /* the flow's Jacobian at (jac_t, jac_y) in the current mode and inputs, and d flow / dt there:
     * kept while it serves (a rejected step, the steps redone up to an event); jac_ok = 0 after a
     * jump or an input change */
    int jac_ok;
    double jac_t, jac_y[PG_MAX_X], jac_rho;
    /* the model's flow_jvp answered PG_NO_JVP: the Jacobian by differences from then on */
    int jvp_off;
    double J[PG_MAX_X * PG_MAX_X], dT[PG_MAX_X];
    /* not state: the hooks of the adapter, and scratch */
    PgEventHook on_event;
    PgWarnHook on_warning;
    PgSwitchHook on_switch;
    void *hook_ctx;
    PgMsg msg; /* the message of the latest PG_RAISE */
    PgMsg scratch;
    double u_t[PG_MAX_U]; /* the inputs at the time of a model call (has_du) */
};

/* a run of the model from t0 to t_stop with the parameters p, the settings s and the inputs u:
 * every rule checked (settings, parameters, initial state, domain) in a fixed order; PG_RAISE names
 * the rule broken */
int pg_engine_init(PgEngine *e, const PgModel *model, const double *p, const double *s, const double *u,
                   double t0, double t_stop);
int pg_engine_set_input(PgEngine *e, const double *u);
/* the inputs from the time served last (t_out) on: u(t) = u + du (t - t_out), du NULL for held
 * inputs (pg_engine_set_input); a change restarts the integrator there, as for held inputs */
int pg_engine_set_inputs(PgEngine *e, const double *u, const double *du);
/* the inputs the model sees at time t (e->u itself for held inputs) */
const double *pg_engine_inputs_at(PgEngine *e, double t);
int pg_engine_advance(PgEngine *e, double t_target);
/* stops before the jump of the first event in (t_out, t_target]: *stopped = 1 and t_out is its time */
int pg_engine_advance_to_event(PgEngine *e, double t_target, int *stopped);
int pg_engine_event_due(const PgEngine *e);
/* FMI 3.0 model exchange: the importer's solver located the event / moved the states. The jump
 * re-arms every guard; a cascade leaves the next event pending at t (pg_engine_event_due) */
int pg_engine_apply_event(PgEngine *e, int index, double t, const double *x);
/* model exchange, the arming of co-simulation (docs/solver.md, "Event semantics"): the event
 * indicators the importer sees at (t, x) into z[ne], each guard's arming updated from this
 * observation (seen on its before side: armed; a guard armed at zero that leaves its band to its
 * before side: an ordinary armed guard). Reported: the guard; for one armed at zero, the guard
 * shifted by its band, sgn (G - zband), so the sign changes where it leaves the band to its after
 * side; an unarmed guard exactly 0 as 1e-300 on its before side; 1 for an inactive event */
int pg_engine_me_indicators(PgEngine *e, double t, const double *x, double *z);
/* the event that fires at (t, x), -1 for none: an event pending at t (a cascade of the latest jump,
 * one at the start or of an input change), else the first in priority order whose armed guard is on
 * its after side (beyond its band for one armed at zero: then the event fires from zero, and
 * pg_engine_apply_event of it counts toward the storm, "event storm: ... happens again within the
 * rounding of its own location") and not carried back to its before side by the flow there (the
 * importer's interpolant, whose error is its tolerance, met the guard where the motion leaves it:
 * no event; one within rounding of its threshold is armed at zero there, its band widened to it;
 * zeno_max_events of these within zeno_window, none firing, end in the storm error naming the event) */
int pg_engine_me_fired(PgEngine *e, double t, const double *x, int *index);
int pg_engine_restart_at(PgEngine *e, double t, const double *x, const double *u);
/* the domain condition at (t, x) in the current mode: 1 with its text in e->msg, 0 inside */
int pg_engine_domain_problem(PgEngine *e, double t, const double *x);
/* the next time event's instant (INFINITY: none), for FMI nextEventTime */
double pg_engine_next_time_event(const PgEngine *e);
/* the engine index (ne + k) of the first time event due at t (its instant <= t), -1 for none */
int pg_engine_time_event_due(const PgEngine *e, double t);
/* the flow and the active guards at (t, x) in the current mode (for model exchange) */
int pg_engine_flow(PgEngine *e, double t, const double *x, double *dx);
int pg_engine_guard(PgEngine *e, int k, const double *x, double *g); /* (at t_out) */
int pg_engine_outputs(PgEngine *e, double t, const double *x, const double *q, double *y);

size_t pg_engine_sizeof(void);
const char *pg_engine_message(const PgEngine *e);
/* the time, state and discrete state served last, and the event count */
void pg_engine_served(const PgEngine *e, double *t_out, double *x_out, double *q_out, long *n_events);
int pg_engine_last_event(const PgEngine *e, double *time, int *index);
/* the text of a method switch (method = 0), logged under logSolver by both backends */
void pg_engine_switch_message(PgMsg *m, double t, int from, int to, double h_rho);
/* the work done: accepted and rejected steps, Jacobians evaluated, method switches, the method in use */
void pg_engine_stats(const PgEngine *e, long *n_steps, long *n_rejected, long *n_jacobians, long *n_switches,
                     int *method_in_use);

#endif
