/* The backend of the FMI entry files (pg_backend.h) over the C adapter: an instance of the adapter
 * (pg_instance.c, pg_instance3.c) over one model's PgFmu, its FMU states (pg_handles.c) and its
 * directional derivatives (pg_derivatives.c). Where the PgFmu comes from is the model source
 * (pg_source.h): the generated C of one model (`PG_FMU`: the native FMUs, no Python, no resources),
 * or, compiled with PG_PYTHON_SOURCE, the Python-hosted FMU's model through python/pg_source_py.c. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pg_backend.h"
#include "pg_handles.h"
#include "pg_instance.h"
#include "pg_source.h"

struct PgBackend {
    PgInstance inst;
    PgSource *src;
};

#ifdef PG_PYTHON_SOURCE
/* every call that may reach the model: between pg_source_enter and pg_source_leave */
#define GUARDED(b, expr)                                                                                   \
    do {                                                                                                   \
        PgSourceGuard g_;                                                                                  \
        int rc_ = pg_source_enter((b)->src, &(b)->inst, &g_);                                              \
        if (rc_ == PG_ST_OK) rc_ = (expr);                                                                 \
        pg_source_leave((b)->src, &g_);                                                                    \
        return rc_;                                                                                        \
    } while (0)
#else
#define GUARDED(b, expr) return (expr)

extern const PgFmu PG_FMU;

/* the native model source: the generated model, after the token's check */
const PgFmu *pg_source_open(const PgSetup *s, PgSource **src)
{
    *src = NULL;
    if (!s->token || strcmp(s->token, PG_FMU.token) != 0) {
        char text[600];
        snprintf(text, sizeof text, "instantiation token %s does not match this FMU's (%s): the model description "
                 "read by the importer belongs to another FMU or build", s->token ? s->token : "(null)", PG_FMU.token);
        if (s->log) s->log(s->log_env, PG_ST_ERROR, "logStatusError", text);
        return NULL;
    }
    return &PG_FMU;
}

void pg_source_close(PgSource *src) { (void)src; }
#endif

PgBackend *pgb_new(const PgSetup *s)
{
    PgSource *src = NULL;
    const PgFmu *fmu = pg_source_open(s, &src);
    if (!fmu) return NULL;
    PgBackend *b = calloc(1, sizeof *b);
    if (!b) {
        pg_source_close(src);
        return NULL;
    }
    b->src = src;
    pg_inst_init(&b->inst, fmu, s->log, s->log_env);
    if (s->fmi == 3) pg3_attach(&b->inst, s->interface, s->event_mode_used, s->early_return_allowed);
    return b;
}

void pgb_free(PgBackend *b)
{
    if (!b) return;
    pg_source_close(b->src);
    free(b);
}

const char *const *pgb_log_categories(PgBackend *b, size_t *n)
{
    *n = (size_t)b->inst.fmu->n_log_categories;
    return b->inst.fmu->log_categories;
}

void pgb_counts(PgBackend *b, size_t *nx, size_t *nz)
{
    *nx = (size_t)b->inst.fmu->model->nx;
    *nz = (size_t)b->inst.fmu->model->ne;
}

const unsigned *pgb_arrays(PgBackend *b, size_t *n)
{
    *n = (size_t)b->inst.fmu->n_arrays;
    return b->inst.fmu->arrays;
}

int pgb_setup_experiment(PgBackend *b, int tolerance_defined, double tolerance, double start, int stop_defined,
                         double stop)
{
    GUARDED(b, pg_inst_setup_experiment(&b->inst, tolerance_defined, tolerance, start, stop_defined, stop));
}

int pgb_enter_initialization(PgBackend *b)
{
    (void)b;
    return PG_ST_OK;
}

int pgb_exit_initialization(PgBackend *b) { GUARDED(b, pg_inst_exit_initialization(&b->inst)); }

int pgb_terminate(PgBackend *b)
{
    (void)b;
    return PG_ST_OK;
}

int pgb_reset(PgBackend *b)
{
    pg_inst_reset(&b->inst);
    return PG_ST_OK;
}

int pgb_get_real(PgBackend *b, const unsigned vr[], size_t n, double out[])
{
    GUARDED(b, pg_inst_get_real(&b->inst, vr, n, out));
}

int pgb_get_integer(PgBackend *b, const unsigned vr[], size_t n, int out[])
{
    GUARDED(b, pg_inst_get_integer(&b->inst, vr, n, out));
}

int pgb_set_real(PgBackend *b, const unsigned vr[], size_t n, const double values[])
{
    GUARDED(b, pg_inst_set_real(&b->inst, vr, n, values));
}

int pgb_set_input_derivatives(PgBackend *b, const unsigned vr[], size_t n, const int order[], const double values[])
{
    GUARDED(b, pg_inst_set_input_derivatives(&b->inst, vr, n, order, values));
}

int pgb_set_integer(PgBackend *b, const unsigned vr[], size_t n, const int values[])
{
    GUARDED(b, pg_inst_set_integer(&b->inst, vr, n, values));
}

int pgb_no_such_type(PgBackend *b, const unsigned vr[], size_t n, const char *type)
{
    GUARDED(b, pg_inst_no_such_type(&b->inst, vr, n, type));
}

int pgb_state_get(PgBackend *b, unsigned mode, void **slot) { GUARDED(b, pg_handle_get(&b->inst, mode, slot)); }

int pgb_state_set(PgBackend *b, void *state, unsigned *mode) { GUARDED(b, pg_handle_set(&b->inst, state, mode)); }

int pgb_state_free(PgBackend *b, void **slot) { GUARDED(b, pg_handle_free(&b->inst, slot)); }

int pgb_state_size(PgBackend *b, void *state, size_t *size) { GUARDED(b, pg_handle_size(&b->inst, state, size)); }

int pgb_state_serialize(PgBackend *b, void *state, unsigned char *bytes, size_t size)
{
    GUARDED(b, pg_handle_serialize(&b->inst, state, bytes, size));
}

int pgb_state_mode(PgBackend *b, void *state, unsigned *mode) { GUARDED(b, pg_handle_mode(&b->inst, state, mode)); }

int pgb_state_deserialize(PgBackend *b, const unsigned char *bytes, size_t size, void **slot)
{
    GUARDED(b, pg_handle_deserialize(&b->inst, bytes, size, slot));
}

int pgb_directional(PgBackend *b, const unsigned *unknowns, size_t n_unknowns, const unsigned *knowns, size_t n_knowns,
                    const double *seed, double *sensitivity, const char *fn)
{
#ifdef PG_PYTHON_SOURCE
    /* the Python-hosted FMUs declare no directional derivatives (providesDirectionalDerivative =
     * false: the binding's PgModel has no outputs_jvp) */
    (void)unknowns, (void)n_unknowns, (void)knowns, (void)n_knowns, (void)seed, (void)sensitivity;
    char text[200];
    snprintf(text, sizeof text, "%s (providesDirectionalDerivative = false) is not supported by this FMU", fn);
    return pg_inst_refuse_text(&b->inst, text);
#else
    GUARDED(b, pg_inst_directional(&b->inst, unknowns, n_unknowns, knowns, n_knowns, seed, sensitivity, fn));
#endif
}

int pgb_do_step(PgBackend *b, double t, double h) { GUARDED(b, pg_inst_do_step(&b->inst, t, h)); }

int pgb_last_successful_time(PgBackend *b, double *t)
{
    *t = pg_inst_last_successful_time(&b->inst);
    return PG_ST_OK;
}

int pgb_terminated(PgBackend *b, int *terminated)
{
    (void)b;
    *terminated = 0; /* the FMU never asks to end the simulation */
    return PG_ST_OK;
}

int pgb_enter_event_mode(PgBackend *b)
{
    pg3_set_event_mode(&b->inst, 1);
    return PG_ST_OK;
}

static int update_discrete_states(PgBackend *b, PgEventFlags *f)
{
    int need = 0, changed = 0;
    int st = pg3_update_discrete_states(&b->inst, &need, &changed);
    memset(f, 0, sizeof *f);
    f->discrete_states_need_update = need;
    f->values_changed = changed;
    if (st == PG_ST_OK && b->inst.mode == 'm' && b->inst.st.has_sim) { /* model exchange: the next time event */
        double next = pg_engine_next_time_event(&b->inst.st.sim);
        f->next_event_time_defined = isfinite(next) != 0;
        f->next_event_time = f->next_event_time_defined ? next : 0.0;
        /* another time event due at this instant: an update more (event iteration) */
        f->discrete_states_need_update |= f->next_event_time_defined && next <= b->inst.st.me_t;
    }
    return st;
}

int pgb_update_discrete_states(PgBackend *b, PgEventFlags *f) { GUARDED(b, update_discrete_states(b, f)); }

int pgb_enter_continuous_time_mode(PgBackend *b)
{
    pg3_set_event_mode(&b->inst, 0);
    return PG_ST_OK;
}

int pgb_completed_integrator_step(PgBackend *b, int *enter_event_mode, int *terminate_simulation)
{
    *terminate_simulation = 0;
    GUARDED(b, pg3_completed_integrator_step(&b->inst, enter_event_mode));
}

int pgb_set_time(PgBackend *b, double t) { GUARDED(b, pg3_set_time(&b->inst, t)); }

int pgb_set_continuous_states(PgBackend *b, const double *x, size_t n)
{
    GUARDED(b, pg3_set_continuous_states(&b->inst, x, n));
}

int pgb_get_continuous_states(PgBackend *b, double *x, size_t n)
{
    (void)n; /* checked against nx by the entry file */
    GUARDED(b, pg3_get_continuous_states(&b->inst, x));
}

int pgb_get_derivatives(PgBackend *b, double *dx, size_t n)
{
    (void)n;
    GUARDED(b, pg3_get_derivatives(&b->inst, dx));
}

int pgb_get_event_indicators(PgBackend *b, double *z, size_t n)
{
    (void)n;
    GUARDED(b, pg3_get_event_indicators(&b->inst, z));
}

int pgb_get_nominals(PgBackend *b, double *nominals, size_t n)
{
    (void)b;
    for (size_t i = 0; i < n; ++i) nominals[i] = 1.0;
    return PG_ST_OK;
}

int pgb_enter_step_mode(PgBackend *b)
{
    pg3_set_event_mode(&b->inst, 0);
    return PG_ST_OK;
}

int pgb_do_step3(PgBackend *b, double t, double h, int *event_handling_needed, int *terminate_simulation,
                 int *early_return, double *last_successful_time)
{
    *terminate_simulation = 0;
    GUARDED(b, pg3_do_step(&b->inst, t, h, event_handling_needed, early_return, last_successful_time));
}
