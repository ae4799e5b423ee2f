/* pogofmu: what the FMI entry files ask of a backend.
 *
 * Every FMI function exists once, in the entry file of its FMI version (fmi2/pg_fmi2.c,
 * fmi3/pg_fmi3.c): it checks the instance's call state against the one table of call_states.h,
 * checks its arguments, filters the log (pg_logging.h), maps the statuses — and hands the work to
 * the backend the binary was linked with, through the functions below:
 *
 *   - the one adapter (adapter/pg_backend.c, over adapter/pg_instance.c, pg_instance3.c,
 *     pg_handles.c, pg_derivatives.c), the FMI rules written once; its model comes from a model
 *     source (adapter/pg_source.h): the generated C of one model (the native FMUs, no Python) or,
 *     compiled with PG_PYTHON_SOURCE, the FMU's Python code (python/pg_source_py.c over
 *     python/python_embed.c: the Python-hosted FMUs).
 *
 * Statuses are PG_ST_* (the numbers of fmi2Status and fmi3Status alike); flags are ints; nothing
 * here depends on the FMI headers. A backend logs through the `log` function it was given (the
 * entry file's, which drops what the log filter does not want; warnings and errors always pass). */
#ifndef PG_BACKEND_H
#define PG_BACKEND_H

#include <stddef.h>

#include "pg_model.h" /* PG_NOINLINE */

enum { PG_ST_OK = 0, PG_ST_WARNING = 1, PG_ST_DISCARD = 2, PG_ST_ERROR = 3, PG_ST_FATAL = 4 };

typedef void (*PgLogFn)(void *env, int status, const char *category, const char *message);

typedef struct PgBackend PgBackend;

typedef struct PgSetup {
    const char *instance_name;
    const char *token;     /* the instantiation token the importer read from the modelDescription */
    const char *resources; /* FMI 2.0: fmuResourceLocation (a URI); FMI 3.0: resourcePath */
    int visible;
    int fmi;        /* 2 or 3 */
    char interface; /* 'c' co-simulation, 'm' model exchange */
    int event_mode_used, early_return_allowed; /* FMI 3.0 co-simulation */
    PgLogFn log;
    void *log_env;
} PgSetup;

/* a new instance, or NULL with the reason logged */
PgBackend *pgb_new(const PgSetup *setup);
void pgb_free(PgBackend *b);
/* the FMU's log categories (those of its modelDescription) */
const char *const *pgb_log_categories(PgBackend *b, size_t *n);
/* FMI 3.0: the numbers of continuous states and event indicators */
void pgb_counts(PgBackend *b, size_t *nx, size_t *nz);
/* FMI 3.0: the array variables, as (value reference, number of elements) pairs, flat (*n pairs;
 * the table lives as long as the backend). An array's value reference is its first element's; its
 * elements have the consecutive ones after it, and every function below takes those (scalars only):
 * the entry file expands an array's value reference, and refuses an element's. */
const unsigned *pgb_arrays(PgBackend *b, size_t *n);

int pgb_setup_experiment(PgBackend *b, int tolerance_defined, double tolerance, double start, int stop_defined,
                         double stop);
int pgb_enter_initialization(PgBackend *b);
int pgb_exit_initialization(PgBackend *b);
int pgb_terminate(PgBackend *b);
int pgb_reset(PgBackend *b);

int pgb_get_real(PgBackend *b, const unsigned vr[], size_t n, double out[]);
int pgb_get_integer(PgBackend *b, const unsigned vr[], size_t n, int out[]);
int pgb_set_real(PgBackend *b, const unsigned vr[], size_t n, const double values[]);
int pgb_set_integer(PgBackend *b, const unsigned vr[], size_t n, const int values[]);
/* FMI 2.0 fmi2SetRealInputDerivatives (order 1, Real inputs; the refusals name variable, order, rule) */
int pgb_set_input_derivatives(PgBackend *b, const unsigned vr[], size_t n, const int order[], const double values[]);
/* Boolean and String: the FMUs have none; an Error naming the first value reference ("Boolean",
 * "String") unless n == 0 */
int pgb_no_such_type(PgBackend *b, const unsigned vr[], size_t n, const char *type);

/* FMU states: *slot a new handle (or the one there overwritten); `mode` the instance's call state
 * (the entry file's number, its flags included), kept with the state, serialized and sealed with
 * it, deserialized with it and given back by set and by pgb_state_mode (which the entry file
 * checks before a set) */
int pgb_state_get(PgBackend *b, unsigned mode, void **slot);
int pgb_state_set(PgBackend *b, void *state, unsigned *mode);
int pgb_state_mode(PgBackend *b, void *state, unsigned *mode);
int pgb_state_free(PgBackend *b, void **slot);
int pgb_state_size(PgBackend *b, void *state, size_t *size);
int pgb_state_serialize(PgBackend *b, void *state, unsigned char *bytes, size_t size);
int pgb_state_deserialize(PgBackend *b, const unsigned char *bytes, size_t size, void **slot);

/* sensitivity = J seed at the point the outputs describe; `fn` names the FMI function */
int pgb_directional(PgBackend *b, const unsigned *unknowns, size_t n_unknowns, const unsigned *knowns, size_t n_knowns,
                    const double *seed, double *sensitivity, const char *fn);

/* FMI 2.0 co-simulation */
int pgb_do_step(PgBackend *b, double t, double h);
int pgb_last_successful_time(PgBackend *b, double *t);
int pgb_terminated(PgBackend *b, int *terminated);

/* FMI 3.0, both interfaces */
typedef struct PgEventFlags {
    int discrete_states_need_update, terminate_simulation, nominals_changed, values_changed,
        next_event_time_defined;
    double next_event_time;
} PgEventFlags;
int pgb_enter_event_mode(PgBackend *b);
int pgb_update_discrete_states(PgBackend *b, PgEventFlags *flags);
/* FMI 3.0 model exchange */
int pgb_enter_continuous_time_mode(PgBackend *b);
int pgb_completed_integrator_step(PgBackend *b, int *enter_event_mode, int *terminate_simulation);
int pgb_set_time(PgBackend *b, double t);
int pgb_set_continuous_states(PgBackend *b, const double *x, size_t n);
int pgb_get_continuous_states(PgBackend *b, double *x, size_t n);
int pgb_get_derivatives(PgBackend *b, double *dx, size_t n);
int pgb_get_event_indicators(PgBackend *b, double *z, size_t n);
int pgb_get_nominals(PgBackend *b, double *nominals, size_t n);
/* FMI 3.0 co-simulation */
int pgb_enter_step_mode(PgBackend *b);
int pgb_do_step3(PgBackend *b, double t, double h, int *event_handling_needed, int *terminate_simulation,
                 int *early_return, double *last_successful_time);

#endif
