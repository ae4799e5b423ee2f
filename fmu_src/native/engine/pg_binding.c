/* pogofmu engine: the functions the Python binding calls (pogofmu.runtime.engine.cengine, through
 * ctypes), the only exported symbols of the engine wherever it is linked: the host's engine
 * library, and the launcher of the Python-hosted FMUs (whose model functions are Python callbacks).
 *
 * The engine itself (pg_engine.c) stays hidden; these wrappers add what a caller outside C needs:
 * the event-storm bound and the history switch set at start, every served value in one call (each
 * ctypes call costs about a microsecond), and an engine copied as bytes (an FMU state) made live
 * again with this process's model and hooks. */
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

/* a method switch (method = 0) handed on as its text, as the native FMUs log it */
typedef void (*PgbSwitchText)(const char *text);
static void on_switch(void *ctx, const PgEngine *e, double t, int from, int to, double h_rho)
{
    (void)ctx;
    PgMsg m;
    pg_engine_switch_message(&m, t, from, to, h_rho);
    PgbSwitchText to_caller = (PgbSwitchText)e->hook_ctx;
    if (to_caller) to_caller(m.text);
}

/* pg_engine_init with the hooks set first (init keeps them), then the storm bound and the history:
 * keep_history < 0 keeps the engine's choice (the setting log_events) */
PGB_API int pgb_init(PgEngine *e, const PgModel *model, const double *p, const double *s, const double *u, double t0,
                     double t_stop, int zeno_max_events, double zeno_window, int keep_history, PgEventHook on_event,
                     PgWarnHook on_warning, PgbSwitchText on_switch_text)
{
    memset(e, 0, sizeof *e);
    e->on_event = on_event, e->on_warning = on_warning, e->on_switch = on_switch;
    e->hook_ctx = (void *)on_switch_text;
    int rc = pg_engine_init(e, model, p, s, u, t0, t_stop);
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
                        PgbSwitchText on_switch_text)
{
    e->model = model;
    e->on_event = on_event, e->on_warning = on_warning, e->on_switch = on_switch;
    e->hook_ctx = (void *)on_switch_text;
}

PGB_API void pgb_read(const PgEngine *e, double *out);

/* pg_engine_advance, and what pgb_read gives, in one call (the common call of a communication step) */
PGB_API int pgb_advance(PgEngine *e, double t_target, double *out)
{
    int rc = pg_engine_advance(e, t_target);
    if (!rc) pgb_read(e, out);
    return rc;
}

PGB_API int pgb_advance_to_event(PgEngine *e, double t_target, int *stopped, double *out)
{
    int rc = pg_engine_advance_to_event(e, t_target, stopped);
    if (!rc) pgb_read(e, out);
    return rc;
}

PGB_API int pgb_set_input(PgEngine *e, const double *u) { return pg_engine_set_input(e, u); }

PGB_API int pgb_apply_event(PgEngine *e, int index, double t, const double *x)
{
    return pg_engine_apply_event(e, index, t, x);
}

PGB_API int pgb_restart_at(PgEngine *e, double t, const double *x, const double *u)
{
    return pg_engine_restart_at(e, t, x, u);
}

PGB_API int pgb_event_due(const PgEngine *e) { return pg_engine_event_due(e); }

/* Everything a caller reads after a call, into out[]:
 *   [0] t_out  [1] t (the integrator, may be ahead)  [2] h (the next step)  [3] max_step
 *   [4] n_events  [5] n_steps  [6] n_rejected  [7] has_last  [8] last time  [9] last index
 *   [10] event due  then x_out (nx), q_out (nq), x (nx), q (nq), u (nu) */
PGB_API void pgb_read(const PgEngine *e, double *out)
{
    out[0] = e->t_out, out[1] = e->t, out[2] = e->h, out[3] = e->max_step;
    out[4] = (double)e->n_events, out[5] = (double)e->n_steps, out[6] = (double)e->n_rejected;
    out[7] = e->has_last, out[8] = e->last.time, out[9] = e->last.index;
    out[10] = pg_engine_event_due(e);
    double *o = out + 11;
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
