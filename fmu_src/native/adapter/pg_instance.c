/* See pg_instance.h. Each function names the method of the former Python adapter (runtime/fmi2.py
 * HybridSlave, before the one adapter) whose rules and messages it keeps. */
#include "pg_instance.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pg_sha256.h"
#include "pg_support.h"

#define STATE_FORMAT "pogofmu-native-state-4" /* 3: the input derivatives; 4: a pending input */

/* ---- messages ------------------------------------------------------------------------------ */
static void say(PgInstance *in, int status, const char *category, const char *text)
{
    if (in->log) in->log(in->log_env, status, category, text);
}

static int refuse(PgInstance *in, const PgMsg *m)
{
    say(in, PG_ST_ERROR, "logStatusError", m->text);
    return PG_ST_ERROR;
}

int pg_inst_refuse(PgInstance *in, const PgMsg *m) { return refuse(in, m); }

int pg_inst_refuse_text(PgInstance *in, const char *text)
{
    say(in, PG_ST_ERROR, "logStatusError", text);
    return PG_ST_ERROR;
}

static const char *fn_prefix(const PgInstance *in) { return in->fmu->fmi == 3 ? "fmi3" : "fmi2"; }

/* the FMI 2.0 function name as this FMU's FMI version spells it (fmi2.py _fn) */
static void fn_name(const PgInstance *in, const char *name2, char *out, size_t size)
{
    if (in->fmu->fmi == 2) {
        snprintf(out, size, "fmi2%s", name2);
        return;
    }
    if (strcmp(name2, "SetFMUstate") == 0) snprintf(out, size, "fmi3SetFMUState");
    else if (strcmp(name2, "GetFMUstate") == 0) snprintf(out, size, "fmi3GetFMUState");
    else if (strcmp(name2, "SerializeFMUstate") == 0) snprintf(out, size, "fmi3SerializeFMUState");
    else if (strcmp(name2, "DeSerializeFMUstate") == 0) snprintf(out, size, "fmi3DeserializeFMUState");
    else snprintf(out, size, "fmi3%s", name2);
}

/* ---- the parameters and the settings ------------------------------------------------------ */
static const char *model_name(const PgInstance *in) { return in->fmu->model->name; }

void pg_inst_reset(PgInstance *in)
{
    const PgFmu *f = in->fmu;
    PgState *st = &in->st;
    memset(st, 0, sizeof *st);
    for (int k = 0; k < f->n_vars; ++k) {
        const PgVar *v = &f->vars[k];
        if (v->role == 'm') st->par[v->index] = v->start;
        else if (v->role == 's') st->set[v->index] = v->start;
        else if (v->role == 'u') st->u[v->index] = v->start;
    }
    st->t_start = 0.0, st->t_stop = INFINITY, st->t_ok = 0.0;
    st->inputs_changed = 1;
    in->h_fast = -1.0;
    in->rel_tol_set = 0;
    if (f->fmi == 3) pg3_reset(in);
}

void pg_inst_init(PgInstance *in, const PgFmu *fmu, PgLogFn log, void *log_env)
{
    memset(in, 0, sizeof *in);
    in->fmu = fmu, in->log = log, in->log_env = log_env;
    in->mode = 'c';
    pg_inst_reset(in);
}

/* the variable of value reference vr where the table keeps it, at index vr (every variable of the
 * project's FMUs), else NULL */
static inline const PgVar *indexed_variable(const PgFmu *fmu, unsigned vr)
{
    return vr < (unsigned)fmu->n_vars && fmu->vars[vr].vr == vr ? &fmu->vars[vr] : NULL;
}

const PgVar *pg_inst_variable(const PgFmu *fmu, unsigned vr)
{
    const PgVar *v = indexed_variable(fmu, vr);
    if (v) return v;
    for (int k = 0; k < fmu->n_vars; ++k)
        if (fmu->vars[k].vr == vr) return &fmu->vars[k];
    return NULL;
}

/* the type's name in the instance's FMI version (fmi2.py _type_name): FMI 3.0 says Float64 and Int32 */
static const char *type_name(const PgInstance *in, char t)
{
    if (in->fmu->fmi == 3) return t == 'R' ? "Float64" : t == 'I' ? "Int32" : t == 'B' ? "Boolean" : "String";
    return t == 'R' ? "Real" : t == 'I' ? "Integer" : t == 'B' ? "Boolean" : "String";
}

static PG_NOINLINE const PgVar *no_variable(PgInstance *in, unsigned vr, char type, const PgVar *v);

/* _variable: the variable of value reference vr, of the type asked (the message only when not) */
static inline const PgVar *variable(PgInstance *in, unsigned vr, char type)
{
    const PgVar *v = indexed_variable(in->fmu, vr);
    if (!v) v = pg_inst_variable(in->fmu, vr);
    return v && v->type == type ? v : no_variable(in, vr, type, v);
}

static PG_NOINLINE const PgVar *no_variable(PgInstance *in, unsigned vr, char type, const PgVar *v)
{
    PgMsg m;
    pg_msg_clear(&m);
    if (!v) {
        pg_msg_printf(&m, "value reference %u is not a variable of %s", vr, model_name(in));
        refuse(in, &m);
        return NULL;
    }
    if (v->type != type) {
        pg_msg_printf(&m, "variable %s (value reference %u) is of type %s, not %s: use the %s getter/setter", v->name,
                      vr, type_name(in, v->type), type_name(in, type), type_name(in, v->type));
        refuse(in, &m);
        return NULL;
    }
    return v;
}

int pg_inst_no_such_type(PgInstance *in, const unsigned vr[], size_t n, const char *type)
{
    char t = strcmp(type, "Boolean") == 0 ? 'B' : 'S';
    for (size_t i = 0; i < n; ++i)
        if (!variable(in, vr[i], t)) return PG_ST_ERROR;
    return PG_ST_OK;
}

/* ---- outputs ------------------------------------------------------------------------------- */
static int n_model_outputs(const PgInstance *in) { return in->fmu->model->ny; }

/* _initial_outputs: from the start values (zeros if they break a rule) */
static void initial_outputs(PgInstance *in)
{
    const PgModel *md = in->fmu->model;
    PgState *st = &in->st;
    double x[PG_MAX_X] = {0}, q[PG_MAX_Q] = {0};
    PgMsg m;
    int ny = n_model_outputs(in);
    int ok = md->initial(st->par, x, q, &m) == PG_OK && md->outputs(st->t_start, x, q, st->u, st->par, st->out, &m) == PG_OK;
    if (!ok)
        for (int i = 0; i < ny; ++i) st->out[i] = 0.0;
    st->out[ny] = 0.0, st->out[ny + 1] = st->t_start, st->out[ny + 2] = 0.0;
    if (in->fmu->fmi == 3) { /* _complete_outputs: the states and the time (zeros where a rule is broken) */
        for (int i = 0; i < md->nx; ++i) st->out[ny + 3 + i] = ok ? x[i] : 0.0;
        st->out[ny + 3 + md->nx] = ok ? st->t_start : 0.0;
    }
    st->has_out = 1;
}

/* _update_outputs: the outputs at the point served last, or at (t, x, q) (FMI 3.0 model exchange:
 * the importer's time and states) */
int pg_inst_update_outputs_at(PgInstance *in, double t, const double *x, const double *q)
{
    PgState *st = &in->st;
    PgEngine *e = &st->sim;
    int ny = n_model_outputs(in);
    int rc = pg_engine_outputs(e, t, x, q, st->out);
    if (in->fmu->fmi == 3) { /* (PG_N: a native FMU's count of states, a constant) */
        int nx = PG_N(e->nx);
        memcpy(st->out + ny + 3, x, sizeof(double) * (size_t)nx);
        st->out[ny + 3 + nx] = t;
    }
    st->out[ny] = (double)e->n_events;
    st->out[ny + 1] = e->has_last ? e->last.time : st->t_start;
    st->out[ny + 2] = e->has_last ? e->last.index + 1 : 0;
    st->has_out = 1;
    return rc;
}

static int update_outputs(PgInstance *in)
{
    PgEngine *e = &in->st.sim;
    return pg_inst_update_outputs_at(in, e->t_out, e->x_out, e->q_out);
}

int pg_inst_update_outputs(PgInstance *in) { return update_outputs(in); }

static double value_of(PgInstance *in, const PgVar *v)
{
    PgState *st = &in->st;
    switch (v->role) {
    case 'm': return st->par[v->index];
    case 's': return st->set[v->index];
    case 'u': return st->u[v->index];
    case 'y': case 'e': case 'x': case 't':
        if (!st->has_out) initial_outputs(in);
        switch (v->role) {
        case 'y': return st->out[v->index];
        case 'e': return st->out[n_model_outputs(in) + v->index];
        case 'x': return st->out[n_model_outputs(in) + 3 + v->index];
        default: return st->out[n_model_outputs(in) + 3 + in->fmu->model->nx];
        }
    case 'd': case 'g': return pg3_derived(in, v);
    default: return 0.0;
    }
}

static PG_NOINLINE int get_real(PgInstance *in, const unsigned vr[], size_t n, double out[])
{
    if (in->fmu->fmi == 3) {
        int rc = pg3_refresh(in);
        if (rc) return rc;
    }
    for (size_t i = 0; i < n; ++i) {
        const PgVar *v = variable(in, vr[i], 'R');
        if (!v) return PG_ST_ERROR;
        out[i] = value_of(in, v);
    }
    return PG_ST_OK;
}

int pg_inst_get_real(PgInstance *in, const unsigned vr[], size_t n, double out[])
{
    /* what an importer reads after every step of FMI 2.0, the model's outputs once served: straight
     * from them, a loop that calls nothing; anything else (another role, FMI 3.0, a value reference
     * that is not a Real) by get_real, from the start (reading is idempotent) */
    const PgFmu *fmu = in->fmu;
    if (fmu->fmi == 2 && in->st.has_out) {
        size_t i = 0;
        for (; i < n; ++i) {
            const PgVar *v = indexed_variable(fmu, vr[i]);
            if (!v || v->type != 'R' || v->role != 'y') break;
            out[i] = in->st.out[v->index];
        }
        if (i == n) return PG_ST_OK;
    }
    return get_real(in, vr, n, out);
}

int pg_inst_get_integer(PgInstance *in, const unsigned vr[], size_t n, int out[])
{
    if (in->fmu->fmi == 3) {
        int rc = pg3_refresh(in);
        if (rc) return rc;
    }
    for (size_t i = 0; i < n; ++i) {
        const PgVar *v = variable(in, vr[i], 'I');
        if (!v) return PG_ST_ERROR;
        double d = value_of(in, v);
        out[i] = isfinite(d) ? (int)d : 0;
    }
    return PG_ST_OK;
}

/* _set */
static int set_value(PgInstance *in, const PgVar *v, double value, char kind)
{
    PgState *st = &in->st;
    PgMsg m;
    pg_msg_clear(&m);
    if (v->role == 'm' || v->role == 's') {
        if (st->has_sim) {
            pg_msg_printf(&m, "parameter %s is fixed: it cannot be changed after initialization (tried ", v->name);
            pg_msg_value(&m, value, kind, "r");
            pg_msg_str(&m, ")");
            return refuse(in, &m);
        }
        if (v->role == 'm') st->par[v->index] = value;
        else st->set[v->index] = value;
        if (v->role == 's' && v->index == PG_S_REL_TOL) in->rel_tol_set = 1;
        st->has_out = 0;
        return PG_ST_OK;
    }
    if (v->role == 'u') {
        st->u[v->index] = value;
        st->du[v->index] = 0.0; /* a value set without a derivative is held */
        st->inputs_changed = 1;
        if (!st->has_sim) st->has_out = 0;
        return PG_ST_OK;
    }
    pg_msg_printf(&m, "variable %s is an output: it cannot be set", v->name);
    return refuse(in, &m);
}

int pg_inst_set_real(PgInstance *in, const unsigned vr[], size_t n, const double values[])
{
    for (size_t i = 0; i < n; ++i) {
        const PgVar *v = variable(in, vr[i], 'R');
        if (!v) return PG_ST_ERROR;
        int rc = set_value(in, v, values[i], 'f');
        if (rc) return rc;
    }
    if (in->fmu->fmi == 3) pg3_after_set(in);
    return PG_ST_OK;
}

int pg_inst_set_integer(PgInstance *in, const unsigned vr[], size_t n, const int values[])
{
    for (size_t i = 0; i < n; ++i) {
        const PgVar *v = variable(in, vr[i], 'I');
        if (!v) return PG_ST_ERROR;
        int rc = set_value(in, v, (double)values[i], 'i');
        if (rc) return rc;
    }
    if (in->fmu->fmi == 3) pg3_after_set(in);
    return PG_ST_OK;
}

/* ---- what the engine noted: warnings, then events (_drain_engine) ------------------------ */
typedef struct {
    int status;
    char category[24];
    char *text;
} Noted;

typedef struct PgNotes {
    PgInstance *in;
    Noted *items;
    size_t n, cap;
    size_t n_warnings;
} Notes;

static void note(Notes *nt, int status, const char *category, const char *text, int first)
{
    if (nt->n == nt->cap) {
        size_t cap = nt->cap ? 2 * nt->cap : 8;
        Noted *more = realloc(nt->items, cap * sizeof *more);
        if (!more) return;
        nt->items = more, nt->cap = cap;
    }
    char *copy = malloc(strlen(text) + 1);
    if (!copy) return;
    strcpy(copy, text);
    size_t at = first ? nt->n_warnings++ : nt->n;
    memmove(nt->items + at + 1, nt->items + at, (nt->n - at) * sizeof *nt->items);
    nt->items[at].status = status;
    snprintf(nt->items[at].category, sizeof nt->items[at].category, "%s", category);
    nt->items[at].text = copy;
    nt->n += 1;
}

static void on_warning(void *ctx, const char *text)
{
    Notes *nt = ctx;
    PgMsg m;
    pg_msg_clear(&m);
    pg_msg_printf(&m, "%s: %s", model_name(nt->in), text);
    note(nt, PG_ST_WARNING, "logStatusWarning", m.text, 1);
}

/* the event record of runtime/eventlog.py (event_message), byte for byte: the host reads both */
static void on_event(void *ctx, const PgEngine *e, const PgEvent *ev, long number)
{
    Notes *nt = ctx;
    const PgModel *md = nt->in->fmu->model;
    PgMsg m;
    pg_msg_clear(&m);
    pg_msg_printf(&m, "event %ld %s at t = ", number,
                  ev->index < md->ne ? md->event_names[ev->index] : md->time_event_names[ev->index - md->ne]);
    pg_msg_value(&m, ev->time, 'f', "r");
    pg_msg_str(&m, " s; state before jump: ");
    for (int i = 0; i < e->nx; ++i) {
        if (i) pg_msg_str(&m, ", ");
        pg_msg_printf(&m, "%s=", md->state_names[i]);
        pg_msg_value(&m, ev->x_before[i], 'f', "r");
    }
    note(nt, PG_ST_OK, "logEvents", m.text, 0);
}

/* method = 0: each switch between the explicit and the implicit method, with its time and estimate */
static void on_switch(void *ctx, const PgEngine *e, double t, int from, int to, double h_rho)
{
    Notes *nt = ctx;
    PgMsg m;
    (void)e;
    pg_engine_switch_message(&m, t, from, to, h_rho);
    note(nt, PG_ST_OK, "logSolver", m.text, 0);
}

static void notes_begin(PgInstance *in, Notes *nt)
{
    memset(nt, 0, sizeof *nt);
    nt->in = in;
    PgEngine *e = &in->st.sim;
    e->on_event = on_event, e->on_warning = on_warning, e->on_switch = on_switch, e->hook_ctx = nt;
}

static void notes_end(PgInstance *in, Notes *nt)
{
    PgEngine *e = &in->st.sim;
    e->on_event = NULL, e->on_warning = NULL, e->on_switch = NULL, e->hook_ctx = NULL;
    if (!nt->items) return; /* (nothing noted: most calls) */
    for (size_t i = 0; i < nt->n; ++i) {
        say(in, nt->items[i].status, nt->items[i].category, nt->items[i].text);
        free(nt->items[i].text);
    }
    free(nt->items);
}

PgNotes *pg_inst_notes_begin(PgInstance *in)
{
    Notes *nt = malloc(sizeof *nt);
    if (nt) notes_begin(in, nt);
    return nt;
}

void pg_inst_notes_end(PgInstance *in, PgNotes *nt)
{
    if (!nt) return;
    notes_end(in, nt);
    free(nt);
}

/* ---- initialization ------------------------------------------------------------------------ */
/* the rule of rel_tol: REL_TOL_MIN, REL_TOL_MAX of runtime/solver/settings.py (tests/test_tolerance.py
 * holds the two to the same numbers) */
#define REL_TOL_MIN 1e-14
#define REL_TOL_MAX 1e-3

int pg_inst_setup_experiment(PgInstance *in, int tolerance_defined, double tolerance, double start, int stop_defined,
                             double stop)
{
    PgMsg m;
    pg_msg_clear(&m);
    if (!isfinite(start)) {
        pg_msg_str(&m, "startTime = ");
        pg_msg_value(&m, start, 'f', "r");
        pg_msg_str(&m, " violates the rule: a finite number");
        return refuse(in, &m);
    }
    if (stop_defined && !(stop >= start)) {
        pg_msg_str(&m, "stopTime = ");
        pg_msg_value(&m, stop, 'f', "r");
        pg_msg_str(&m, " violates the rule: stopTime >= startTime = ");
        pg_msg_value(&m, start, 'f', "r");
        return refuse(in, &m);
    }
    in->st.t_start = in->st.t_ok = start;
    in->st.t_stop = stop_defined ? stop : INFINITY;
    /* the importer's tolerance is the solver's relative tolerance, unless the user set rel_tol
     * (before or after this call); a hint outside rel_tol's rule is brought into it, with a warning */
    if (tolerance_defined && !in->rel_tol_set) {
        double rel_tol = tolerance < REL_TOL_MIN ? REL_TOL_MIN : tolerance > REL_TOL_MAX ? REL_TOL_MAX : tolerance;
        in->st.set[PG_S_REL_TOL] = rel_tol;
        if (rel_tol != tolerance) { /* a warning logged and returned, as by the Python backend */
            pg_msg_printf(&m, "%s: the importer's tolerance = ", model_name(in));
            pg_msg_value(&m, tolerance, 'f', "r");
            pg_msg_str(&m, " lies outside the rule of rel_tol, 1e-14 <= rel_tol <= 0.001: the solver takes rel_tol = ");
            pg_msg_value(&m, rel_tol, 'f', "r");
            say(in, PG_ST_WARNING, "logStatusWarning", m.text);
            return PG_ST_WARNING;
        }
    }
    return PG_ST_OK;
}

/* _fast_step_limit */
static double fast_step_limit(const PgInstance *in)
{
    if (in->fmu->model->nx) {
        double limit = in->st.sim.s[PG_S_MAX_STEPS_PER_CALL] * in->st.sim.max_step;
        return limit < INFINITY ? limit : -1.0;
    }
    return 1e300;
}

/* the derivatives of the inputs set so far: any not zero */
static int any_slope(const PgInstance *in)
{
    for (int i = 0; i < in->fmu->model->nu; ++i)
        if (in->st.du[i] != 0.0) return 1;
    return 0;
}

/* exit_initialization_mode */
int pg_inst_exit_initialization(PgInstance *in)
{
    PgState *st = &in->st;
    Notes nt;
    PgEngine *e = &st->sim;
    memset(e, 0, sizeof *e);
    notes_begin(in, &nt);
    int rc = pg_engine_init(e, in->fmu->model, st->par, st->set, st->u, st->t_start, st->t_stop);
    if (!rc) rc = pg_engine_advance(e, st->t_start);
    if (rc) {
        PgMsg m;
        pg_msg_clear(&m);
        pg_msg_printf(&m, "%s: initialization failed: %s", model_name(in), e->msg.text);
        st->has_sim = 0;
        notes_end(in, &nt);
        return refuse(in, &m);
    }
    st->has_sim = 1;
    st->inputs_changed = any_slope(in); /* derivatives set before: the first step takes them */
    in->h_fast = fast_step_limit(in);
    notes_end(in, &nt);
    if (update_outputs(in)) return pg_inst_model_failed(in); /* an output that is not finite */
    if (in->fmu->fmi == 3) pg3_after_exit_initialization(in);
    return PG_ST_OK;
}

/* fmi2.py set_real_input_derivatives */
int pg_inst_set_input_derivatives(PgInstance *in, const unsigned vr[], size_t n, const int order[],
                                  const double values[])
{
    const char *fn = "fmi2SetRealInputDerivatives";
    PgMsg m;
    pg_msg_clear(&m);
    for (size_t i = 0; i < n; ++i) {
        const PgVar *v = variable(in, vr[i], 'R');
        if (!v) return PG_ST_ERROR;
        if (v->role != 'u') {
            pg_msg_printf(&m, "%s refused: variable %s is %s, not an input: only a continuous Real input has a "
                          "derivative to set", fn, v->name, v->causality == 'p' ? "a parameter" : v->causality == 'o' ?
                          "an output" : "not an input");
            return refuse(in, &m);
        }
        if (order[i] != 1) {
            pg_msg_printf(&m, "%s refused: order = %d for input %s violates the rule: order = 1 (this FMU "
                          "interpolates its inputs linearly, u(t) = u + du (t - t_c) over a step; it takes no "
                          "derivative of order 0 or 2 and higher)", fn, order[i], v->name);
            return refuse(in, &m);
        }
        if (!isfinite(values[i])) {
            pg_msg_printf(&m, "%s refused: the derivative of input %s = ", fn, v->name);
            pg_msg_value(&m, values[i], 'f', "r");
            pg_msg_printf(&m, " violates the rule: it must be a finite number");
            return refuse(in, &m);
        }
    }
    for (size_t i = 0; i < n; ++i) {
        const PgVar *v = pg_inst_variable(in->fmu, vr[i]);
        in->st.du[v->index] = values[i];
    }
    if (n) in->st.inputs_changed = 1;
    return PG_ST_OK;
}

/* ---- a communication step -------------------------------------------------------------------- */
void pg_inst_stopped_text(PgInstance *in, const char *call, double t, PgMsg *m)
{
    char fn[40];
    fn_name(in, "SetFMUstate", fn, sizeof fn);
    pg_msg_printf(m, "%s refused: the instance stopped at t = ", call);
    pg_msg_value(m, t, 'f', "r");
    pg_msg_printf(m, " s (%s); restore a saved state (%s) or reset the instance", in->st.failed_text, fn);
}

/* _input_problem */
int pg_inst_input_problem(PgInstance *in, double t, PgMsg *m)
{
    const PgModel *md = in->fmu->model;
    for (int i = 0; i < md->nu; ++i) {
        double v = in->st.u[i];
        if (!isfinite(v)) {
            pg_msg_printf(m, "%s: input %s = ", md->name, md->input_names[i]);
            pg_msg_value(m, v, 'f', "r");
            pg_msg_str(m, " at t = ");
            pg_msg_value(m, t, 'f', "r");
            pg_msg_printf(m, " s violates the rule: %s must be a finite number", md->input_names[i]);
            return 1;
        }
    }
    return 0;
}

/* _step_problem */
static int step_problem(PgInstance *in, double t, double h, PgMsg *m)
{
    PgState *st = &in->st;
    PgEngine *e = &st->sim;
    const char *api = fn_prefix(in);
    char call[40];
    pg_msg_clear(m);
    if (st->failed) {
        snprintf(call, sizeof call, "%sDoStep", api);
        pg_inst_stopped_text(in, call, st->t_ok, m);
        return 1;
    }
    if (!st->has_sim) {
        pg_msg_printf(m, "%sDoStep called before %sExitInitializationMode", api, api);
        return 1;
    }
    if (!isfinite(t)) {
        pg_msg_str(m, "currentCommunicationPoint = ");
        pg_msg_value(m, t, 'f', "r");
        pg_msg_str(m, " violates the rule: a finite number equal to the end of the previous step (");
        pg_msg_value(m, e->t_out, 'f', "r");
        pg_msg_str(m, ")");
        return 1;
    }
    if (!(isfinite(h) && h >= 0)) {
        pg_msg_str(m, "communication step size step_size = ");
        pg_msg_value(m, h, 'f', "r");
        pg_msg_str(m, " violates the rule: 0 <= step_size < inf");
        return 1;
    }
    double big = fabs(t) > 1.0 ? fabs(t) : 1.0;
    if (fabs(t - e->t_out) > 1e-9 * big) {
        pg_msg_str(m, "currentCommunicationPoint = ");
        pg_msg_value(m, t, 'f', "r");
        pg_msg_str(m, " violates the rule: it must equal the end of the previous step (");
        pg_msg_value(m, e->t_out, 'f', "r");
        pg_msg_str(m, ")");
        return 1;
    }
    double end = t + h;
    if (!isfinite(end)) {
        pg_msg_str(m, "communication step size step_size = ");
        pg_msg_value(m, h, 'f', "r");
        pg_msg_str(m, " violates the rule: the end of the step, currentCommunicationPoint + step_size, must be finite");
        return 1;
    }
    double min_steps = in->fmu->model->nx ? h / e->max_step : 0.0;
    double budget = e->s[PG_S_MAX_STEPS_PER_CALL];
    if (min_steps > budget) {
        pg_msg_str(m, "communication step size step_size = ");
        pg_msg_value(m, h, 'f', "r");
        pg_msg_str(m, " violates the rule: one step may take at most max_steps_per_call = ");
        pg_msg_value(m, budget, 'f', "g");
        pg_msg_str(m, " internal steps, and this one needs at least step_size/max_step = ");
        pg_msg_value(m, min_steps, 'f', ".3g");
        pg_msg_str(m, " (max_step = ");
        pg_msg_value(m, e->max_step, 'f', "r");
        pg_msg_str(m, " s); use shorter communication steps, or raise the parameter max_steps_per_call");
        return 1;
    }
    if (end > st->t_stop * (1 + 1e-12) + 1e-12) {
        pg_msg_str(m, "communication step size step_size = ");
        pg_msg_value(m, h, 'f', "r");
        pg_msg_str(m, " violates the rule: the step must end at or before stopTime = ");
        pg_msg_value(m, st->t_stop, 'f', "r");
        pg_msg_str(m, " (it ends at ");
        pg_msg_value(m, end, 'f', "r");
        pg_msg_str(m, ")");
        return 1;
    }
    if (in->st.inputs_changed) return pg_inst_input_problem(in, t, m);
    return 0;
}

/* _model_failed: remember why, so that later steps are refused */
PG_NOINLINE int pg_inst_model_failed(PgInstance *in)
{
    PgState *st = &in->st;
    st->failed = 1;
    if (in->mode == 'm') st->t_ok = st->me_t; /* (model exchange: the failing call's time, where the run stopped) */
    snprintf(st->failed_text, sizeof st->failed_text, "%s: %s", model_name(in), st->sim.msg.text);
    PgMsg m;
    pg_msg_clear(&m);
    pg_msg_str(&m, st->failed_text);
    return refuse(in, &m);
}

/* the checks of a step off the fast path (pg_inst_do_step), out of line: its message buffer stays off
 * the fast path's stack; 1 when the step is refused (said) */
static PG_NOINLINE int step_refused(PgInstance *in, double t, double h)
{
    PgMsg m;
    if (!step_problem(in, t, h, &m)) return 0;
    refuse(in, &m);
    return 1;
}

int pg_inst_do_step(PgInstance *in, double t, double h)
{
    PgState *st = &in->st;
    PgEngine *e = &st->sim;
    double end = t + h;
    if (!(!st->failed && st->has_sim && !st->inputs_changed && t == e->t_out && 0.0 <= h && h <= in->h_fast &&
          end <= st->t_stop)) {
        if (step_refused(in, t, h)) return PG_ST_ERROR;
        if (end < e->t_out) end = e->t_out;
    }
    Notes nt;
    notes_begin(in, &nt);
    int rc = PG_OK;
    if (st->inputs_changed) {
        rc = pg_engine_set_inputs(e, st->u, st->du);
        st->inputs_changed = 0;
    }
    if (!rc) rc = in->fmu->fmi == 3 ? pg3_advance_engine(in, end) : pg_engine_advance(e, end);
    notes_end(in, &nt);
    if (rc || update_outputs(in)) return pg_inst_model_failed(in); /* (an output that is not finite) */
    st->t_ok = e->t_out;
    return PG_ST_OK;
}

double pg_inst_last_successful_time(const PgInstance *in) { return in->st.t_ok; }

/* ---- FMU states ---------------------------------------------------------------------------- */
void pg_inst_owner_text(const char *model, const char *build, int fmi, PgMsg *m)
{
    pg_msg_printf(m, "model '%s', build '%s', FMI %s", model, build, fmi == 3 ? "3.0" : "2.0");
}

/* the sealed header: format, owner, the call state the state was taken in (the entry file's number,
 * checked there on restore), the size of the record */
static size_t header(const PgInstance *in, unsigned call_state, char *out, size_t size)
{
    return (size_t)snprintf(out, size,
                            "{\"format\":\"%s\",\"owner\":[\"%s\",\"%s\",\"fmi%d\"],\"call_state\":%u,\"bytes\":%zu}\n",
                            STATE_FORMAT, model_name(in), in->fmu->build, in->fmu->fmi, call_state, sizeof(PgState));
}

size_t pg_inst_serialized_size(const PgInstance *in, unsigned call_state)
{
    char head[512];
    return header(in, call_state, head, sizeof head) + sizeof(PgState) + 1 + 64;
}

int pg_inst_serialize(PgInstance *in, const PgState *state, unsigned call_state, unsigned char *bytes, size_t size)
{
    char head[512];
    size_t nh = header(in, call_state, head, sizeof head);
    size_t need = nh + sizeof(PgState) + 1 + 64;
    if (size < need) {
        PgMsg m;
        pg_msg_clear(&m);
        char fn[40];
        fn_name(in, "SerializeFMUstate", fn, sizeof fn);
        pg_msg_printf(&m, "%s: the buffer of %zu bytes is too small for the state's %zu bytes (%sSerializedFMUState%s"
                      "Size)", fn, size, need, fn_prefix(in), in->fmu->fmi == 3 ? "" : "");
        return refuse(in, &m);
    }
    PgState copy = *state;
    copy.sim.on_event = NULL, copy.sim.on_warning = NULL, copy.sim.on_switch = NULL, copy.sim.hook_ctx = NULL;
    copy.sim.model = NULL;
    memcpy(bytes, head, nh);
    memcpy(bytes + nh, &copy, sizeof copy);
    bytes[nh + sizeof copy] = '\n';
    char hex[65];
    pg_sha256_hex(bytes, nh + sizeof copy, hex);
    memcpy(bytes + nh + sizeof copy + 1, hex, 64);
    return PG_ST_OK;
}

int pg_inst_deserialize(PgInstance *in, const unsigned char *bytes, size_t size, PgState *state,
                        unsigned *call_state)
{
    char fn[40];
    fn_name(in, "DeSerializeFMUstate", fn, sizeof fn);
    PgMsg m;
    pg_msg_clear(&m);
    const char *prefix = "{\"format\":\"pogofmu-";
    if (!bytes || size < strlen(prefix) || memcmp(bytes, prefix, strlen(prefix)) != 0) {
        pg_msg_printf(&m, "%s refused: the %zu bytes are not a serialized pogofmu FMU state", fn, size);
        return refuse(in, &m);
    }
    char hex[65];
    if (size >= 66) pg_sha256_hex(bytes, size - 65, hex);
    if (size < 66 || bytes[size - 65] != '\n' || memcmp(hex, bytes + size - 64, 64) != 0) {
        pg_msg_printf(&m, "%s refused: the serialized state is damaged (its SHA-256 seal does not match its %zu bytes)",
                      fn, size >= 65 ? size - 65 : size);
        return refuse(in, &m);
    }
    const unsigned char *nl = memchr(bytes, '\n', size - 65);
    if (!nl) {
        pg_msg_printf(&m, "%s refused: the sealed state cannot be read (no header)", fn);
        return refuse(in, &m);
    }
    size_t nh = (size_t)(nl - bytes) + 1;
    char head[512], mine[512];
    if (nh >= sizeof head) {
        pg_msg_printf(&m, "%s refused: the sealed state cannot be read (a header of %zu bytes)", fn, nh);
        return refuse(in, &m);
    }
    memcpy(head, bytes, nh);
    head[nh] = '\0';
    unsigned saved_call_state = 0;
    const char *cs = strstr(head, "\"call_state\":");
    if (cs) sscanf(cs + 13, "%u", &saved_call_state);
    header(in, saved_call_state, mine, sizeof mine);
    if (strcmp(head, mine) != 0) {
        /* the owner from the header: ["model","build","fmiN"] */
        char model[128] = "?", build[128] = "?";
        int fmi = 0;
        const char *o = strstr(head, "\"owner\":[\"");
        if (o) sscanf(o + 10, "%127[^\"]\",\"%127[^\"]\",\"fmi%d", model, build, &fmi);
        if (!strstr(head, "\"format\":\"" STATE_FORMAT "\"")) {
            pg_msg_printf(&m, "%s refused: a pogofmu FMU state of another format (%.200s); this FMU reads '%s'", fn, head,
                          STATE_FORMAT);
            return refuse(in, &m);
        }
        pg_msg_printf(&m, "%s refused: the state belongs to ", fn);
        pg_inst_owner_text(model, build, fmi, &m);
        pg_msg_str(&m, "; this instance is ");
        pg_inst_owner_text(model_name(in), in->fmu->build, in->fmu->fmi, &m);
        return refuse(in, &m);
    }
    if (size - 65 - nh != sizeof(PgState)) {
        pg_msg_printf(&m, "%s refused: the state record is incomplete (%zu bytes, not %zu)", fn, size - 65 - nh,
                      sizeof(PgState));
        return refuse(in, &m);
    }
    memcpy(state, bytes + nh, sizeof *state);
    state->sim.model = in->fmu->model;
    *call_state = saved_call_state;
    return PG_ST_OK;
}

/* _set_fmu_state */
void pg_inst_restore(PgInstance *in, const PgState *state)
{
    if (state != &in->st) in->st = *state;
    in->st.sim.model = in->fmu->model;
    in->st.sim.on_event = NULL, in->st.sim.on_warning = NULL, in->st.sim.on_switch = NULL, in->st.sim.hook_ctx = NULL;
    /* (whether an input is pending comes with the state: forcing it here re-anchored an FMI 2.0 input
     * line at the restored point, u(t) = u + du (t - t_restore), a user's audit, 2026-12-07) */
    if (in->st.has_sim) {
        in->h_fast = fast_step_limit(in);
        if (in->st.has_out) update_outputs(in);
    }
    if (in->fmu->fmi == 3) pg3_after_restore(in);
}
