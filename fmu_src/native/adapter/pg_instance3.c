/* pogofmu FMUs (both kinds): the FMI 3.0 extension of the adapter, the semantics written down in
 * fmu_src/pogofmu/runtime/fmi3.py's docstring: model exchange (the importer integrates the states
 * and locates the indicators' sign changes; the engine arms the guards and says which event fires:
 * pg_engine_me_indicators, pg_engine_me_fired), and co-simulation with event mode and early
 * return. (The names of the Python adapter's methods these functions once followed are kept in
 * their comments.) */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "pg_instance.h"
#include "pg_support.h"

static const PgModel *model_of(const PgInstance *in) { return in->fmu->model; }

/* _indicators: each event's guard where it is active in mode q, 1 (it cannot cross zero) elsewhere */
static int indicators(const PgModel *md, double t, const double *x, const double *q, const double *u,
                      const double *p, double *z, PgMsg *m)
{
    for (int k = 0; k < md->ne; ++k) {
        int on = 0;
        int rc = md->active(k, q, &on, m);
        if (!rc && on) rc = md->guard(k, t, x, q, u, p, &z[k], m);
        else if (!rc) z[k] = 1.0;
        if (rc) return rc;
    }
    return PG_OK;
}

void pg3_attach(PgInstance *in, char mode, int event_mode_used, int early_return_allowed)
{
    in->mode = mode;
    in->event_mode_used = event_mode_used != 0, in->early_return_allowed = early_return_allowed != 0;
}

/* _reset_state (what is not in PgState, which pg_inst_reset clears) */
void pg3_reset(PgInstance *in)
{
    in->me_stale = 0, in->cs_stale = 0, in->event_mode = 0, in->has_stop = 0;
}

void pg3_set_event_mode(PgInstance *in, int on) { in->event_mode = on; }

static void stale(PgInstance *in) { in->me_stale = 1; }

/* _require_mode */
static PG_NOINLINE int wrong_mode(PgInstance *in, char mode, const char *what);

static int require_mode(PgInstance *in, char mode, const char *what)
{
    return in->mode == mode ? PG_ST_OK : wrong_mode(in, mode, what);
}

/* (out of line: its message buffer stays off the calling step's stack) */
static PG_NOINLINE int wrong_mode(PgInstance *in, char mode, const char *what)
{
    PgMsg m;
    pg_msg_clear(&m);
    pg_msg_printf(&m, "%s is a %s function: this instance is a %s instance", what,
                  mode == 'm' ? "model-exchange" : "co-simulation", mode == 'm' ? "co-simulation" : "model-exchange");
    return pg_inst_refuse(in, &m);
}

/* _me_inputs */
static int me_inputs(PgInstance *in)
{
    PgMsg m;
    pg_msg_clear(&m);
    if (pg_inst_input_problem(in, in->st.me_t, &m)) return pg_inst_refuse(in, &m);
    PgEngine *e = &in->st.sim;
    if (pg_engine_restart_at(e, in->st.me_t, in->st.me_x, in->st.u) != PG_OK) return pg_inst_model_failed(in);
    in->st.inputs_changed = 0;
    stale(in);
    return PG_ST_OK;
}

/* _me_instance */
static int me_instance(PgInstance *in, const char *what)
{
    int rc = require_mode(in, 'm', what);
    if (rc) return rc;
    PgMsg m;
    pg_msg_clear(&m);
    if (in->st.failed) {
        pg_inst_stopped_text(in, what, in->st.t_ok, &m);
        return pg_inst_refuse(in, &m);
    }
    if (!in->st.has_sim) {
        pg_msg_printf(&m, "%s called before fmi3ExitInitializationMode", what);
        return pg_inst_refuse(in, &m);
    }
    if (in->st.inputs_changed) return me_inputs(in);
    return PG_ST_OK;
}

/* _me_refresh */
static int me_refresh(PgInstance *in)
{
    in->me_stale = 0;
    if (!in->st.has_sim) return PG_ST_OK;
    if (in->st.inputs_changed) {
        int rc = me_inputs(in);
        if (rc) return rc;
        in->me_stale = 0;
    }
    /* (an output that is not finite, or a state's output that is not the state: the run ends here, as a
     * co-simulation step that served it would) */
    if (pg_inst_update_outputs_at(in, in->st.me_t, in->st.me_x, in->st.sim.q)) return pg_inst_model_failed(in);
    return PG_ST_OK;
}

/* _cs_event_inputs */
static int cs_event_inputs(PgInstance *in)
{
    in->cs_stale = 0;
    PgMsg m;
    pg_msg_clear(&m);
    if (pg_inst_input_problem(in, in->st.sim.t_out, &m)) return pg_inst_refuse(in, &m);
    PgNotes *nt = pg_inst_notes_begin(in);
    int rc = pg_engine_set_input(&in->st.sim, in->st.u);
    pg_inst_notes_end(in, nt);
    if (rc) return pg_inst_model_failed(in);
    in->st.inputs_changed = 0;
    pg_inst_update_outputs(in);
    return PG_ST_OK;
}

int pg3_refresh(PgInstance *in)
{
    if (in->me_stale) return me_refresh(in);
    if (in->cs_stale) return cs_event_inputs(in);
    return PG_ST_OK;
}

/* _set, after the FMI 2.0 part */
void pg3_after_set(PgInstance *in)
{
    if (!(in->st.inputs_changed && in->st.has_sim)) return;
    if (in->mode == 'm') stale(in);
    else if (in->event_mode) in->cs_stale = 1;
}

/* _derived: a state's derivative or an event indicator at the point the outputs describe */
double pg3_derived(PgInstance *in, const PgVar *v)
{
    const PgModel *md = model_of(in);
    PgState *st = &in->st;
    PgEngine *e = &st->sim;
    double x0[PG_MAX_X] = {0}, q0[PG_MAX_Q] = {0}, out[PG_MAX_X > PG_MAX_EVENTS ? PG_MAX_X : PG_MAX_EVENTS];
    const double *x, *q, *u, *p;
    double t;
    PgMsg m;
    pg_msg_clear(&m);
    if (!st->has_sim) {
        if (md->initial(st->par, x0, q0, &m) != PG_OK) return 0.0;
        t = st->t_start, x = x0, q = q0, u = st->u, p = st->par;
    } else if (in->mode == 'm') {
        t = st->me_t, x = st->me_x, q = e->q, u = e->u, p = e->p;
    } else {
        t = e->t_out, x = e->x_out, q = e->q_out, u = e->u, p = e->p;
    }
    if (v->role == 'd') {
        if (md->flow(t, x, q, u, p, out, &m) != PG_OK) return 0.0;
    } else if (indicators(md, t, x, q, u, p, out, &m) != PG_OK) {
        return 0.0;
    }
    return out[v->index];
}

/* exit_initialization_mode, after the FMI 2.0 part */
void pg3_after_exit_initialization(PgInstance *in)
{
    in->event_mode = in->mode == 'm' || in->event_mode_used;
    PgEngine *e = &in->st.sim;
    in->st.me_t = e->t_out;
    memcpy(in->st.me_x, e->x_out, sizeof in->st.me_x);
    in->st.has_me_x = 1; /* (the engine armed the guards) */
}

/* _set_fmu_state, after the FMI 2.0 part */
void pg3_after_restore(PgInstance *in)
{
    in->has_stop = 0;
    if (in->mode == 'm' && in->st.has_sim) stale(in);
}

/* ---- model exchange ------------------------------------------------------------------------ */
int pg3_set_time(PgInstance *in, double t)
{
    int rc = require_mode(in, 'm', "fmi3SetTime");
    if (rc) return rc;
    if (!isfinite(t)) {
        PgMsg m;
        pg_msg_clear(&m);
        pg_msg_str(&m, "time = ");
        pg_msg_value(&m, t, 'f', "r");
        pg_msg_str(&m, " violates the rule: a finite number");
        return pg_inst_refuse(in, &m);
    }
    in->st.me_t = t;
    stale(in);
    return PG_ST_OK;
}

int pg3_set_continuous_states(PgInstance *in, const double *x, size_t n)
{
    int rc = require_mode(in, 'm', "fmi3SetContinuousStates");
    if (rc) return rc;
    const PgModel *md = model_of(in);
    PgMsg m;
    pg_msg_clear(&m);
    if (n != (size_t)md->nx) {
        pg_msg_printf(&m, "%zu continuous states given, %s has %d", n, md->name, md->nx);
        return pg_inst_refuse(in, &m);
    }
    if (!in->st.has_sim) return pg_inst_refuse_text(in, "fmi3SetContinuousStates called before fmi3ExitInitializationMode");
    memcpy(in->st.me_x, x, sizeof(double) * n);
    in->st.has_me_x = 1;
    stale(in);
    return PG_ST_OK;
}

int pg3_get_continuous_states(PgInstance *in, double *x)
{
    const PgModel *md = model_of(in);
    if (!in->st.has_sim) {
        double q[PG_MAX_Q];
        PgMsg m, out;
        pg_msg_clear(&m);
        if (md->initial(in->st.par, x, q, &m) != PG_OK) {
            pg_msg_clear(&out);
            pg_msg_printf(&out, "%s: no initial state: %s", md->name, m.text);
            return pg_inst_refuse(in, &out);
        }
        return PG_ST_OK;
    }
    memcpy(x, in->st.me_x, sizeof(double) * (size_t)md->nx);
    return PG_ST_OK;
}

/* _initial_point */
static int initial_point(PgInstance *in, const char *what, double *x, double *q)
{
    PgMsg m, out;
    pg_msg_clear(&m);
    if (model_of(in)->initial(in->st.par, x, q, &m) != PG_OK) {
        pg_msg_clear(&out);
        pg_msg_printf(&out, "%s refused: no initial state with these parameters: %s", what, m.text);
        return pg_inst_refuse(in, &out);
    }
    return PG_ST_OK;
}

/* Initialization Mode: a function of the model that failed at the start, or returned a value that is not
 * finite (rc PG_OK, values v[0..n)), is refused with the message fmi3ExitInitializationMode gives, found by
 * setting the engine up for the start as the exit does (and does again): the function named with the time
 * and the state, never a NaN handed to the importer with status OK */
static PG_NOINLINE int start_refused(PgInstance *in, const char *what)
{
    PgEngine *e = &in->st.sim; /* (unused before the exit, which sets it up afresh) */
    PgMsg m;
    pg_msg_clear(&m);
    memset(e, 0, sizeof *e);
    if (pg_engine_init(e, model_of(in), in->st.par, in->st.set, in->st.u, in->st.t_start, in->st.t_stop) != PG_OK)
        pg_msg_printf(&m, "%s: %s refused: initialization failed: %s", model_of(in)->name, what, e->msg.text);
    else /* (the engine's own start passed: a function that fails at random) */
        pg_msg_printf(&m, "%s: %s refused: the model's functions at the start returned a value that is not finite",
                      model_of(in)->name, what);
    memset(e, 0, sizeof *e);
    return pg_inst_refuse(in, &m);
}

static int start_values(PgInstance *in, const char *what, int rc, const double *v, int n)
{
    for (int i = 0; !rc && i < n; ++i)
        if (!isfinite(v[i])) rc = PG_RAISE;
    return rc ? start_refused(in, what) : PG_ST_OK;
}

int pg3_get_derivatives(PgInstance *in, double *dx)
{
    const PgModel *md = model_of(in);
    PgMsg m;
    pg_msg_clear(&m);
    if (!in->st.has_sim && in->mode == 'm') {
        double x[PG_MAX_X], q[PG_MAX_Q];
        int rc = initial_point(in, "fmi3GetContinuousStateDerivatives", x, q);
        if (rc) return rc;
        if (md->nx) rc = md->flow(in->st.t_start, x, q, in->st.u, in->st.par, dx, &m);
        return start_values(in, "fmi3GetContinuousStateDerivatives", rc, dx, md->nx);
    }
    int rc = me_instance(in, "fmi3GetContinuousStateDerivatives");
    if (rc) return rc;
    if (md->nx && pg_engine_flow(&in->st.sim, in->st.me_t, in->st.me_x, dx) != PG_OK) return pg_inst_model_failed(in);
    return PG_ST_OK;
}

int pg3_get_event_indicators(PgInstance *in, double *z)
{
    const PgModel *md = model_of(in);
    PgMsg m;
    pg_msg_clear(&m);
    if (!in->st.has_sim && in->mode == 'm') {
        double x[PG_MAX_X], q[PG_MAX_Q];
        int rc = initial_point(in, "fmi3GetEventIndicators", x, q);
        if (rc) return rc;
        rc = indicators(md, in->st.t_start, x, q, in->st.u, in->st.par, z, &m);
        return start_values(in, "fmi3GetEventIndicators", rc, z, md->ne);
    }
    int rc = me_instance(in, "fmi3GetEventIndicators");
    if (rc) return rc;
    PgEngine *e = &in->st.sim; /* the engine's arming, updated from this observation */
    if (pg_engine_me_indicators(e, in->st.me_t, in->st.me_x, z) != PG_OK) return pg_inst_model_failed(in);
    return PG_ST_OK;
}

int pg3_completed_integrator_step(PgInstance *in, int *enter_event_mode)
{
    *enter_event_mode = 0;
    int rc = me_instance(in, "fmi3CompletedIntegratorStep");
    if (rc) return rc;
    const PgModel *md = model_of(in);
    PgEngine *e = &in->st.sim;
    double z[PG_MAX_EVENTS];
    rc = pg3_get_event_indicators(in, z); /* (an observation of the trajectory: the arming updated) */
    if (rc) return rc;
    int fired = -1;
    if (pg_engine_me_fired(e, in->st.me_t, in->st.me_x, &fired) != PG_OK) return pg_inst_model_failed(in);
    if (fired >= 0) {
        *enter_event_mode = 1;
        return PG_ST_OK;
    }
    int outside = pg_engine_domain_problem(e, in->st.me_t, in->st.me_x);
    int finite = 1;
    for (int i = 0; i < md->nx; ++i) finite &= isfinite(in->st.me_x[i]) != 0;
    if (outside || !finite) {
        PgMsg m;
        pg_msg_clear(&m);
        pg_msg_printf(&m, "%s: the trajectory left the model's domain at t = ", md->name);
        pg_msg_value(&m, in->st.me_t, 'f', ".10g");
        pg_msg_printf(&m, " s: %s", outside ? e->msg.text : "the state became non-finite");
        in->st.failed = 1, in->st.t_ok = in->st.me_t;
        snprintf(in->st.failed_text, sizeof in->st.failed_text, "%s", m.text);
        return pg_inst_refuse(in, &m);
    }
    return PG_ST_OK;
}

/* _me_update: the jump of the event that fires here (the engine's pg_engine_me_fired), which
 * re-arms every guard; another update is needed while it leaves an event pending at this instant */
static int me_update(PgInstance *in, int *need, int *changed)
{
    *need = 0, *changed = 0;
    int rc = me_instance(in, "fmi3UpdateDiscreteStates");
    if (rc) return rc;
    const PgModel *md = model_of(in);
    PgEngine *e = &in->st.sim;
    int fired = -1;
    if (pg_engine_me_fired(e, in->st.me_t, in->st.me_x, &fired) != PG_OK) return pg_inst_model_failed(in);
    if (fired < 0) fired = pg_engine_time_event_due(e, in->st.me_t); /* a time event reached: its jump */
    if (fired >= 0) {
        double x[PG_MAX_X];
        memcpy(x, in->st.me_x, sizeof x);
        PgNotes *nt = pg_inst_notes_begin(in);
        rc = pg_engine_apply_event(e, fired, in->st.me_t, x);
        pg_inst_notes_end(in, nt);
        if (rc) return pg_inst_model_failed(in);
        for (int i = 0; i < md->nx; ++i) *changed |= !(e->x[i] == x[i]);
        memcpy(in->st.me_x, e->x, sizeof(double) * (size_t)md->nx);
        stale(in);
        /* another event at this instant: a cascade, or a time event due within its 16 ulps (its
         * nextEventTime would be a hair ahead, which an importer cannot step to) */
        *need = pg_engine_event_due(e) || pg_engine_time_event_due(e, in->st.me_t) >= 0;
    }
    return PG_ST_OK;
}

/* ---- co-simulation ------------------------------------------------------------------------- */
/* _advance_engine */
int pg3_advance_engine(PgInstance *in, double end)
{
    PgEngine *e = &in->st.sim;
    if (pg_engine_event_due(e)) {
        int rc = pg_engine_advance(e, e->t); /* an event the importer left unhandled: its jump first */
        if (rc) return rc;
    }
    in->has_stop = 0;
    if (!in->early_return_allowed) return pg_engine_advance(e, end);
    int stopped = 0;
    int rc = pg_engine_advance_to_event(e, end, &stopped);
    if (rc || !stopped) return rc;
    in->has_stop = 1, in->stop = e->t_out;
    if (!in->event_mode_used) return pg_engine_advance(e, e->t_out); /* handled here: return right after its jump */
    return PG_OK;
}

/* do_step3 */
int pg3_do_step(PgInstance *in, double t, double h, int *event_handling_needed, int *early_return, double *last)
{
    int rc = require_mode(in, 'c', "fmi3DoStep");
    if (rc) return rc;
    in->has_stop = 0;
    rc = pg_inst_do_step(in, t, h);
    if (rc > PG_ST_WARNING) return rc;
    double end = t + h;
    *event_handling_needed = in->has_stop && in->event_mode_used;
    *early_return = in->has_stop && in->stop < end;
    *last = pg_inst_last_successful_time(in);
    return rc;
}

/* _cs_update */
static int cs_update(PgInstance *in)
{
    if (!in->st.has_sim) return pg_inst_refuse_text(in, "fmi3UpdateDiscreteStates called before fmi3ExitInitializationMode");
    if (in->cs_stale) {
        int rc = cs_event_inputs(in);
        if (rc) return rc;
    }
    PgEngine *e = &in->st.sim;
    if (pg_engine_event_due(e)) {
        PgNotes *nt = pg_inst_notes_begin(in);
        int rc = pg_engine_advance(e, e->t);
        pg_inst_notes_end(in, nt);
        if (rc) return pg_inst_model_failed(in);
        pg_inst_update_outputs(in);
    }
    return PG_ST_OK;
}

int pg3_update_discrete_states(PgInstance *in, int *need, int *changed)
{
    *need = 0, *changed = 0;
    return in->mode == 'm' ? me_update(in, need, changed) : cs_update(in);
}
