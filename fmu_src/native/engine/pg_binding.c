/* pogofmu engine: the functions the Python binding calls (pogofmu.runtime.solver.cengine, through
 * ctypes), the only exported symbols of the engine wherever it is linked: the host's engine
 * library, and the launcher of the Python-hosted FMUs (whose model functions are Python callbacks).
 *
 * The engine itself (pg_engine.c) stays hidden; these wrappers add what a caller outside C needs:
 * the event-storm bound and the history switch set at start, every served value in one call (each
 * ctypes call costs about a microsecond), and an engine copied as bytes (an FMU state) made live
 * again with this process's model and hooks. */
#include <stdio.h>
#include <string.h>

#include "pg_engine.h"

#if defined(_WIN32)
#define PGB_API __declspec(dllexport)
#else
#define PGB_API __attribute__((visibility("default")))
#endif

PGB_API size_t pgb_sizeof(void) { return sizeof(PgEngine); }

/* the fixed sizes the binding's mirrors of PgEvent and PgScale are laid out with */
PGB_API void pgb_limits(int *out) { out[0] = PG_MAX_X, out[1] = PG_MAX_SCALES, out[2] = PG_MAX_SCALE_NAMES; }

PGB_API const char *pgb_message(const PgEngine *e) { return e->msg.text; }

/* ---- the model's hot functions called in C (flow, guards, activity, outputs, domain) ---------
 *
 * A ctypes callback costs about 1.5 µs a call; these trampolines call the model's Python function
 * directly with the Python C API: the arguments built in C (t a float, x a list of floats: what
 * the model got through ctypes, the same doubles), the result converted in C the way ctypes did
 * (a sequence of the state's size, each item through PyFloat_AsDouble; an output through float()).
 * The discrete state q and the inputs u are compared as bytes with the ones the model's dict and
 * tuple were made from: only a change calls the binding's `sync` (Simulator._tsync) for new ones.
 * Any Python exception goes to the binding's `fail` (Simulator._fail), the one place that turns it
 * into the engine's result (a model error kept to be raised again, an arithmetic error as the
 * engine's refusal).
 *
 * No Python header and no libpython: the C API functions used are given by the binding as
 * addresses (ctypes.pythonapi), so this file compiles the same for the host's engine library, the
 * launchers of the Python-hosted FMUs (which find the interpreter at run time) and Windows. The
 * functions run with the GIL held (the library is loaded with ctypes.PyDLL). */
typedef struct _object PyObject;
typedef long long PgbSsize; /* Py_ssize_t on the 64-bit platforms the FMUs are built for */

typedef struct PgbPyApi {
    PyObject *(*Float_FromDouble)(double);
    double (*Float_AsDouble)(PyObject *);
    PyObject *(*List_New)(PgbSsize);
    int (*List_SetItem)(PyObject *, PgbSsize, PyObject *);
    PyObject *(*List_GetItem)(PyObject *, PgbSsize);
    PyObject *(*Tuple_New)(PgbSsize);
    int (*Tuple_SetItem)(PyObject *, PgbSsize, PyObject *);
    PyObject *(*Tuple_GetItem)(PyObject *, PgbSsize);
    PyObject *(*Object_CallObject)(PyObject *, PyObject *);
    PgbSsize (*Sequence_Size)(PyObject *);
    PyObject *(*Sequence_GetItem)(PyObject *, PgbSsize);
    PyObject *(*Object_GetItem)(PyObject *, PyObject *);
    PyObject *(*Number_Float)(PyObject *);
    int (*Object_IsTrue)(PyObject *);
    PyObject *(*Err_Occurred)(void);
    void (*Err_Fetch)(PyObject **, PyObject **, PyObject **);
    void (*Err_NormalizeException)(PyObject **, PyObject **, PyObject **);
    int (*Exception_SetTraceback)(PyObject *, PyObject *);
    void (*Err_SetString)(PyObject *, const char *);
    PyObject *(*Long_FromVoidPtr)(void *);
    long (*Long_AsLong)(PyObject *);
    void (*IncRef)(PyObject *);
    void (*DecRef)(PyObject *);
    PyObject *none;
    PyObject *value_error;
} PgbPyApi;

static PgbPyApi api;
static int api_ready;

PGB_API void pgb_py_api(const PgbPyApi *a)
{
    api = *a;
    api_ready = 1;
}

/* one run's Python side (a Simulator): what the Python binding fills in (borrowed references, the
 * Simulator keeps them alive) and the cache the trampolines keep (owned references) */
typedef struct PgbPy {
    void (*switch_text)(const char *text); /* a method switch (method = 0), its text */
    PyObject *sync, *fail, *fun_for, *domain_text; /* the Simulator's methods */
    PyObject *guards, *guard_times, *actives;      /* lists: each event's guard, whether it reads t, activity */
    PyObject *output_fn, *output_names, *domain, *p, *slack;
    int nx, nq, nu, ny;
    int q_ok, u_ok;
    PyObject *qdict, *uc, *bound; /* owned: the model's q dict, u tuple, bound flow (or NULL) */
    double qkey[PG_MAX_Q], ukey[PG_MAX_U]; /* last: the binding lays out only what comes before */
} PgbPy;

PGB_API size_t pgb_py_sizeof(void) { return sizeof(PgbPy); }

static void set_ref(PyObject **slot, PyObject *value) /* value: a new reference or NULL */
{
    PyObject *old = *slot;
    *slot = value;
    if (old) api.DecRef(old);
}

/* drop the cache (the binding changed what the model's dict, tuple or bound flow are made of) */
PGB_API void pgb_py_forget(PgbPy *c)
{
    c->q_ok = c->u_ok = 0;
    set_ref(&c->qdict, NULL), set_ref(&c->uc, NULL), set_ref(&c->bound, NULL);
}

#if defined(_MSC_VER)
static __declspec(thread) PgbPy *current;
#else
static _Thread_local PgbPy *current; /* the run whose engine call is under way on this thread */
#endif

/* the C adapter hosting a Python model (python/pg_source_py.c): the run of its instance made the
 * current one of this thread for the length of an FMI call (GIL held); the previous one returned */
PGB_API void *pgb_py_enter(void *c)
{
    PgbPy *old = current;
    current = (PgbPy *)c;
    return old;
}

/* the pending Python exception handed to the binding's fail: its result code */
static int py_failed(PgbPy *c, PgMsg *m)
{
    PyObject *type, *value, *tb;
    api.Err_Fetch(&type, &value, &tb);
    api.Err_NormalizeException(&type, &value, &tb);
    if (tb && value) api.Exception_SetTraceback(value, tb);
    PyObject *addr = api.Long_FromVoidPtr(m);
    PyObject *args = api.Tuple_New(2);
    int rc = PG_RAISE;
    if (args && addr && value) {
        api.Tuple_SetItem(args, 0, value), value = NULL;
        api.Tuple_SetItem(args, 1, addr), addr = NULL;
        PyObject *r = api.Object_CallObject(c->fail, args);
        if (r) {
            rc = (int)api.Long_AsLong(r);
            api.DecRef(r);
        }
    }
    if (api.Err_Occurred()) { /* (fail itself failed: nothing better than a plain refusal) */
        PyObject *t2, *v2, *tb2;
        api.Err_Fetch(&t2, &v2, &tb2);
        if (t2) api.DecRef(t2);
        if (v2) api.DecRef(v2);
        if (tb2) api.DecRef(tb2);
        snprintf(m->text, PG_MSG_MAX, "%s", "a model callback failed");
        m->len = strlen(m->text);
        rc = PG_RAISE;
    }
    if (args) api.DecRef(args);
    if (addr) api.DecRef(addr);
    if (value) api.DecRef(value);
    if (type) api.DecRef(type);
    if (tb) api.DecRef(tb);
    return rc;
}

/* the model's dict of q and tuple of u up to date (u NULL: q only, as the activity needs) */
static int py_sync(PgbPy *c, const double *q, const double *u)
{
    size_t qb = sizeof(double) * (size_t)c->nq, ub = sizeof(double) * (size_t)c->nu;
    int q_new = !c->q_ok || (qb && memcmp(q, c->qkey, qb) != 0);
    int u_new = u && (!c->u_ok || (ub && memcmp(u, c->ukey, ub) != 0));
    if (!q_new && !u_new) return 0;
    PyObject *args = api.Tuple_New(2);
    if (!args) return -1;
    api.Tuple_SetItem(args, 0, api.Long_FromVoidPtr((void *)q));
    if (u) {
        api.Tuple_SetItem(args, 1, api.Long_FromVoidPtr((void *)u));
    } else {
        api.IncRef(api.none);
        api.Tuple_SetItem(args, 1, api.none);
    }
    PyObject *r = api.Object_CallObject(c->sync, args);
    api.DecRef(args);
    if (!r) return -1;
    PyObject *qd = api.Tuple_GetItem(r, 0), *uc = api.Tuple_GetItem(r, 1);
    if (!qd || !uc) {
        api.DecRef(r);
        return -1;
    }
    api.IncRef(qd), api.IncRef(uc);
    set_ref(&c->qdict, qd), set_ref(&c->uc, uc), set_ref(&c->bound, NULL);
    api.DecRef(r);
    memcpy(c->qkey, q, qb), c->q_ok = 1;
    if (u) memcpy(c->ukey, u, ub), c->u_ok = 1;
    return 0;
}

static PyObject *py_list(const double *x, int n)
{
    PyObject *l = api.List_New(n);
    if (!l) return NULL;
    for (int i = 0; i < n; i++) {
        PyObject *v = api.Float_FromDouble(x[i]);
        if (!v) {
            api.DecRef(l);
            return NULL;
        }
        api.List_SetItem(l, i, v);
    }
    return l;
}

/* a call with n arguments, each a new reference (NULL: a failure already pending) */
static PyObject *py_call(PyObject *fn, int n, PyObject **argv)
{
    PyObject *args = api.Tuple_New(n);
    int ok = args != NULL;
    for (int i = 0; i < n; i++) {
        if (!argv[i]) ok = 0;
        if (args && argv[i]) api.Tuple_SetItem(args, i, argv[i]);
        else if (argv[i]) api.DecRef(argv[i]);
    }
    PyObject *r = ok ? api.Object_CallObject(fn, args) : NULL;
    if (args) api.DecRef(args);
    return r;
}

static PyObject *ref(PyObject *o)
{
    api.IncRef(o);
    return o;
}

/* a returned sequence into out[n], as ctypes' slice assignment did */
static int py_doubles(PyObject *seq, double *out, int n)
{
    PgbSsize len = api.Sequence_Size(seq);
    if (len < 0) return -1;
    if (len != n) {
        api.Err_SetString(api.value_error, "Can only assign sequence of same size");
        return -1;
    }
    for (int i = 0; i < n; i++) {
        PyObject *v = api.Sequence_GetItem(seq, i);
        if (!v) return -1;
        double d = api.Float_AsDouble(v);
        api.DecRef(v);
        if (d == -1.0 && api.Err_Occurred()) return -1;
        out[i] = d;
    }
    return 0;
}

/* a trampoline called outside an entry of this file (no run on this thread): refused, not a crash */
static int no_run(PgMsg *m)
{
    snprintf(m->text, PG_MSG_MAX, "%s", "a model function was called outside a run of the Python binding");
    m->len = strlen(m->text);
    return PG_RAISE;
}

static int tr_flow(double t, const double *x, const double *q, const double *u, const double *p, double *dx, PgMsg *m)
{
    PgbPy *c = current;
    if (!c) return no_run(m);
    if (py_sync(c, q, u)) return py_failed(c, m);
    if (!c->bound) {
        PyObject *a[1] = {ref(c->qdict)};
        PyObject *b = py_call(c->fun_for, 1, a);
        if (!b) return py_failed(c, m);
        set_ref(&c->bound, b);
    }
    PyObject *a[2] = {api.Float_FromDouble(t), py_list(x, c->nx)};
    PyObject *r = py_call(c->bound, 2, a);
    if (!r) return py_failed(c, m);
    int bad = c->nx ? py_doubles(r, dx, c->nx) : 0;
    api.DecRef(r);
    return bad ? py_failed(c, m) : PG_OK;
}

static int tr_guard(int k, double t, const double *x, const double *q, const double *u, const double *p, double *g,
                    PgMsg *m)
{
    PgbPy *c = current;
    if (!c) return no_run(m);
    if (py_sync(c, q, u)) return py_failed(c, m);
    /* guard(x, q, u, p), or guard(t, x, q, u, p) for one that reads the time */
    int timed = api.Object_IsTrue(api.List_GetItem(c->guard_times, k)) == 1;
    PyObject *a[5];
    int n = 0;
    if (timed) a[n++] = api.Float_FromDouble(t);
    a[n++] = py_list(x, c->nx), a[n++] = ref(c->qdict), a[n++] = ref(c->uc), a[n++] = ref(c->p);
    PyObject *r = py_call(api.List_GetItem(c->guards, k), n, a);
    if (!r) return py_failed(c, m);
    double v = api.Float_AsDouble(r);
    api.DecRef(r);
    if (v == -1.0 && api.Err_Occurred()) return py_failed(c, m);
    *g = v;
    return PG_OK;
}

static int tr_active(int k, const double *q, int *on, PgMsg *m)
{
    PgbPy *c = current;
    if (!c) return no_run(m);
    if (py_sync(c, q, NULL)) return py_failed(c, m);
    PyObject *a[1] = {ref(c->qdict)};
    PyObject *r = py_call(api.List_GetItem(c->actives, k), 1, a);
    if (!r) return py_failed(c, m);
    int v = api.Object_IsTrue(r);
    api.DecRef(r);
    if (v < 0) return py_failed(c, m);
    *on = v ? 1 : 0;
    return PG_OK;
}

static int tr_outputs(double t, const double *x, const double *q, const double *u, const double *p, double *y, PgMsg *m)
{
    PgbPy *c = current;
    if (!c) return no_run(m);
    if (py_sync(c, q, u)) return py_failed(c, m);
    PyObject *a[5] = {api.Float_FromDouble(t), py_list(x, c->nx), ref(c->qdict), ref(c->uc), ref(c->p)};
    PyObject *out = py_call(c->output_fn, 5, a);
    if (!out) return py_failed(c, m);
    for (int i = 0; i < c->ny; i++) {
        PyObject *v = api.Object_GetItem(out, api.Tuple_GetItem(c->output_names, i));
        PyObject *f = v ? api.Number_Float(v) : NULL;
        if (v) api.DecRef(v);
        if (!f) {
            api.DecRef(out);
            return py_failed(c, m);
        }
        y[i] = api.Float_AsDouble(f);
        api.DecRef(f);
    }
    api.DecRef(out);
    return PG_OK;
}

static int tr_domain(double t, const double *x, const double *q, const double *u, const double *p, const double *s,
                     PgMsg *m)
{
    PgbPy *c = current;
    if (!c) return no_run(m);
    if (py_sync(c, q, u)) return py_failed(c, m);
    PyObject *a[6] = {api.Float_FromDouble(t), py_list(x, c->nx), ref(c->qdict), ref(c->uc), ref(c->p),
                      ref(c->slack)};
    PyObject *r = py_call(c->domain, 6, a);
    if (!r) return py_failed(c, m);
    if (r == api.none) {
        api.DecRef(r);
        return PG_OK;
    }
    PyObject *b[2] = {r, api.Long_FromVoidPtr(m)}; /* the condition's text into m: PG_RAISE */
    PyObject *rc = py_call(c->domain_text, 2, b);
    if (!rc) return py_failed(c, m);
    int v = (int)api.Long_AsLong(rc);
    api.DecRef(rc);
    return v;
}

/* the trampolines' addresses, for the binding's PgModel: flow, guard, active, outputs, domain */
PGB_API void pgb_py_functions(void **out)
{
    out[0] = (void *)tr_flow, out[1] = (void *)tr_guard, out[2] = (void *)tr_active, out[3] = (void *)tr_outputs;
    out[4] = (void *)tr_domain;
}

/* a method switch (method = 0) handed on as its text, as the native FMUs log it */
static void on_switch(void *ctx, const PgEngine *e, double t, int from, int to, double h_rho)
{
    (void)ctx;
    PgMsg m;
    pg_engine_switch_message(&m, t, from, to, h_rho);
    PgbPy *c = (PgbPy *)e->hook_ctx;
    if (c && c->switch_text) c->switch_text(m.text);
}

/* every entry that may call the model: its run is the current one of this thread while it lasts */
#define ENTER(e) PgbPy *outer = current; current = (PgbPy *)(e)->hook_ctx
#define LEAVE() current = outer

/* pg_engine_init with the hooks set first (init keeps them), then the storm bound and the history:
 * keep_history < 0 keeps the engine's choice (the setting log_events) */
PGB_API int pgb_init(PgEngine *e, const PgModel *model, const double *p, const double *s, const double *u, double t0,
                     double t_stop, int zeno_max_events, double zeno_window, int keep_history, PgEventHook on_event,
                     PgWarnHook on_warning, PgbPy *py)
{
    memset(e, 0, sizeof *e);
    e->on_event = on_event, e->on_warning = on_warning, e->on_switch = on_switch;
    e->hook_ctx = (void *)py;
    ENTER(e);
    int rc = pg_engine_init(e, model, p, s, u, t0, t_stop);
    LEAVE();
    if (rc) return rc;
    if (zeno_max_events > 0) {
        e->zeno_max_events = zeno_max_events > PG_RECENT ? PG_RECENT : zeno_max_events;
        e->zeno_window = zeno_window;
    }
    if (keep_history >= 0) e->keep_history = keep_history != 0;
    return PG_OK;
}

/* an engine restored from bytes: this process's model and hooks */
PGB_API void pgb_rebind(PgEngine *e, const PgModel *model, PgEventHook on_event, PgWarnHook on_warning,
                        PgbPy *py)
{
    e->model = model;
    e->on_event = on_event, e->on_warning = on_warning, e->on_switch = on_switch;
    e->hook_ctx = (void *)py;
}

PGB_API void pgb_read(const PgEngine *e, double *out);

/* pg_engine_advance, and what pgb_read gives, in one call (the common call of a communication step) */
PGB_API int pgb_advance(PgEngine *e, double t_target, double *out)
{
    ENTER(e);
    int rc = pg_engine_advance(e, t_target);
    LEAVE();
    if (!rc) pgb_read(e, out);
    return rc;
}

PGB_API int pgb_advance_to_event(PgEngine *e, double t_target, int *stopped, double *out)
{
    ENTER(e);
    int rc = pg_engine_advance_to_event(e, t_target, stopped);
    LEAVE();
    if (!rc) pgb_read(e, out);
    return rc;
}

PGB_API int pgb_set_input(PgEngine *e, const double *u)
{
    ENTER(e);
    int rc = pg_engine_set_input(e, u);
    LEAVE();
    return rc;
}

/* pg_engine_set_inputs: inputs on a line from the time served last (du NULL: held) */
PGB_API int pgb_set_inputs(PgEngine *e, const double *u, const double *du)
{
    ENTER(e);
    int rc = pg_engine_set_inputs(e, u, du);
    LEAVE();
    return rc;
}

/* the inputs the model sees at t into out[nu]; 1 if they lie on a line (a slope set), 0 if held */
PGB_API int pgb_inputs_at(PgEngine *e, double t, double *out)
{
    memcpy(out, pg_engine_inputs_at(e, t), sizeof(double) * (size_t)e->nu);
    return e->has_du;
}

PGB_API int pgb_apply_event(PgEngine *e, int index, double t, const double *x)
{
    ENTER(e);
    int rc = pg_engine_apply_event(e, index, t, x);
    LEAVE();
    return rc;
}

/* the next time event's instant (INFINITY: none); the first time event due at t (-1: none) */
PGB_API double pgb_next_time_event(const PgEngine *e) { return pg_engine_next_time_event(e); }
PGB_API int pgb_time_event_due(const PgEngine *e, double t) { return pg_engine_time_event_due(e, t); }

PGB_API int pgb_restart_at(PgEngine *e, double t, const double *x, const double *u)
{
    ENTER(e);
    int rc = pg_engine_restart_at(e, t, x, u);
    LEAVE();
    return rc;
}

/* model exchange: the indicators at (t, x) into z[ne] (the arming updated), the event that fires there */
PGB_API int pgb_me_indicators(PgEngine *e, double t, const double *x, double *z)
{
    ENTER(e);
    int rc = pg_engine_me_indicators(e, t, x, z);
    LEAVE();
    return rc;
}

PGB_API int pgb_me_fired(PgEngine *e, double t, const double *x, int *index)
{
    ENTER(e);
    int rc = pg_engine_me_fired(e, t, x, index);
    LEAVE();
    return rc;
}

PGB_API int pgb_event_due(const PgEngine *e) { return pg_engine_event_due(e); }

/* Everything a caller reads after a call, into out[]:
 *   [0] t_out  [1] t (the integrator, may be ahead)  [2] h (the next step)  [3] max_step
 *   [4] n_events  [5] n_steps  [6] n_rejected  [7] has_last  [8] last time  [9] last index
 *   [10] event due  [11] the Jacobian by differences (the model's flow_jvp answered PG_NO_JVP)
 *   then x_out (nx), q_out (nq), x (nx), q (nq), u (nu) */
PGB_API void pgb_read(const PgEngine *e, double *out)
{
    out[0] = e->t_out, out[1] = e->t, out[2] = e->h, out[3] = e->max_step;
    out[4] = (double)e->n_events, out[5] = (double)e->n_steps, out[6] = (double)e->n_rejected;
    out[7] = e->has_last, out[8] = e->last.time, out[9] = e->last.index;
    out[10] = pg_engine_event_due(e), out[11] = e->jvp_off;
    double *o = out + 12;
    memcpy(o, e->x_out, sizeof(double) * (size_t)e->nx), o += e->nx;
    memcpy(o, e->q_out, sizeof(double) * (size_t)e->nq), o += e->nq;
    memcpy(o, e->x, sizeof(double) * (size_t)e->nx), o += e->nx;
    memcpy(o, e->q, sizeof(double) * (size_t)e->nq), o += e->nq;
    memcpy(o, e->u, sizeof(double) * (size_t)e->nu);
}

/* the latest event's states before and after its jump */
PGB_API void pgb_last_event(const PgEngine *e, double *x_before, double *x_after)
{
    memcpy(x_before, e->last.x_before, sizeof(double) * (size_t)e->nx);
    memcpy(x_after, e->last.x_after, sizeof(double) * (size_t)e->nx);
}
