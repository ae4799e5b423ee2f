/* The native backend of the FMI entry files (pg_backend.h): an instance of the adapter
 * (pg_instance.c, pg_instance3.c) over the generated C of one model (`PG_FMU`), its FMU states
 * (pg_handles.c) and its directional derivatives (pg_derivatives.c). No Python, no resources. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pg_backend.h"
#include "pg_handles.h"
#include "pg_instance.h"

extern const PgFmu PG_FMU;

struct PgBackend {
    PgInstance inst;
};

PgBackend *pgb_new(const PgSetup *s)
{
    if (!s->token || strcmp(s->token, PG_FMU.token) != 0) {
        char text[600];
        snprintf(text, sizeof text, "instantiation token %s does not match this FMU's (%s): the model description "
                 "read by the importer belongs to another FMU or build", s->token ? s->token : "(null)", PG_FMU.token);
        if (s->log) s->log(s->log_env, PG_ST_ERROR, "logStatusError", text);
        return NULL;
    }
    PgBackend *b = calloc(1, sizeof *b);
    if (!b) return NULL;
    pg_inst_init(&b->inst, &PG_FMU, s->log, s->log_env);
    if (s->fmi == 3) pg3_attach(&b->inst, s->interface, s->event_mode_used, s->early_return_allowed);
    return b;
}

void pgb_free(PgBackend *b) { free(b); }

const char *const *pgb_log_categories(PgBackend *b, size_t *n)
{
    (void)b;
    *n = (size_t)PG_FMU.n_log_categories;
    return PG_FMU.log_categories;
}

void pgb_counts(PgBackend *b, size_t *nx, size_t *nz)
{
    (void)b;
    *nx = (size_t)PG_FMU.model->nx;
    *nz = (size_t)PG_FMU.model->ne;
}

const unsigned *pgb_arrays(PgBackend *b, size_t *n)
{
    (void)b;
    *n = (size_t)PG_FMU.n_arrays;
    return PG_FMU.arrays;
}

int pgb_setup_experiment(PgBackend *b, int tolerance_defined, double tolerance, double start, int stop_defined,
                         double stop)
{
    return pg_inst_setup_experiment(&b->inst, tolerance_defined, tolerance, start, stop_defined, stop);
}

int pgb_enter_initialization(PgBackend *b)
{
    (void)b;
    return PG_ST_OK;
}

int pgb_exit_initialization(PgBackend *b) { return pg_inst_exit_initialization(&b->inst); }

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
    return pg_inst_get_real(&b->inst, vr, n, out);
}

int pgb_get_integer(PgBackend *b, const unsigned vr[], size_t n, int out[])
{
    return pg_inst_get_integer(&b->inst, vr, n, out);
}

int pgb_set_real(PgBackend *b, const unsigned vr[], size_t n, const double values[])
{
    return pg_inst_set_real(&b->inst, vr, n, values);
}

int pgb_set_input_derivatives(PgBackend *b, const unsigned vr[], size_t n, const int order[], const double values[])
{
    return pg_inst_set_input_derivatives(&b->inst, vr, n, order, values);
}

int pgb_set_integer(PgBackend *b, const unsigned vr[], size_t n, const int values[])
{
    return pg_inst_set_integer(&b->inst, vr, n, values);
}

int pgb_no_such_type(PgBackend *b, const unsigned vr[], size_t n, const char *type)
{
    return pg_inst_no_such_type(&b->inst, vr, n, type);
}

int pgb_state_get(PgBackend *b, unsigned mode, void **slot) { return pg_handle_get(&b->inst, mode, slot); }

int pgb_state_set(PgBackend *b, void *state, unsigned *mode) { return pg_handle_set(&b->inst, state, mode); }

int pgb_state_free(PgBackend *b, void **slot) { return pg_handle_free(&b->inst, slot); }

int pgb_state_size(PgBackend *b, void *state, size_t *size) { return pg_handle_size(&b->inst, state, size); }

int pgb_state_serialize(PgBackend *b, void *state, unsigned char *bytes, size_t size)
{
    return pg_handle_serialize(&b->inst, state, bytes, size);
}

int pgb_state_mode(PgBackend *b, void *state, unsigned *mode) { return pg_handle_mode(&b->inst, state, mode); }

int pgb_state_deserialize(PgBackend *b, const unsigned char *bytes, size_t size, void **slot)
{
    return pg_handle_deserialize(&b->inst, bytes, size, slot);
}

int pgb_directional(PgBackend *b, const unsigned *unknowns, size_t n_unknowns, const unsigned *knowns, size_t n_knowns,
                    const double *seed, double *sensitivity, const char *fn)
{
    return pg_inst_directional(&b->inst, unknowns, n_unknowns, knowns, n_knowns, seed, sensitivity, fn);
}

int pgb_do_step(PgBackend *b, double t, double h) { return pg_inst_do_step(&b->inst, t, h); }

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

int pgb_update_discrete_states(PgBackend *b, PgEventFlags *f)
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

int pgb_enter_continuous_time_mode(PgBackend *b)
{
    pg3_set_event_mode(&b->inst, 0);
    return PG_ST_OK;
}

int pgb_completed_integrator_step(PgBackend *b, int *enter_event_mode, int *terminate_simulation)
{
    *terminate_simulation = 0;
    return pg3_completed_integrator_step(&b->inst, enter_event_mode);
}

int pgb_set_time(PgBackend *b, double t) { return pg3_set_time(&b->inst, t); }

int pgb_set_continuous_states(PgBackend *b, const double *x, size_t n)
{
    return pg3_set_continuous_states(&b->inst, x, n);
}

int pgb_get_continuous_states(PgBackend *b, double *x, size_t n)
{
    (void)n; /* checked against nx by the entry file */
    return pg3_get_continuous_states(&b->inst, x);
}

int pgb_get_derivatives(PgBackend *b, double *dx, size_t n)
{
    (void)n;
    return pg3_get_derivatives(&b->inst, dx);
}

int pgb_get_event_indicators(PgBackend *b, double *z, size_t n)
{
    (void)n;
    return pg3_get_event_indicators(&b->inst, z);
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
    return pg3_do_step(&b->inst, t, h, event_handling_needed, early_return, last_successful_time);
}
