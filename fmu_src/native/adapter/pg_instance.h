/* pogofmu native FMUs: one adapter from any generated model to FMI — the C twin of the Python
 * adapter fmu_src/pogofmu/runtime/fmi2.py (HybridSlave): the variable table, parameters fixed at
 * initialization and checked there, inputs held over a step and checked at the step, outputs
 * refreshed once per step, the step's rules, the event log, FMU states with their owner and seal.
 * The same rules in the same order with the same messages as the Python adapter.
 *
 * The FMI entry files (fmu_src/native/fmi2/) check the call states and map the statuses; this file
 * knows nothing of the FMI headers. */
#ifndef PG_INSTANCE_H
#define PG_INSTANCE_H

#include <stddef.h>

#include "pg_engine.h"

enum { PG_ST_OK = 0, PG_ST_WARNING = 1, PG_ST_DISCARD = 2, PG_ST_ERROR = 3, PG_ST_FATAL = 4 };

/* one FMU variable: what build_fmu.py writes into the modelDescription (same value reference) */
typedef struct PgVar {
    const char *name;
    unsigned vr;
    char type;      /* 'R' Real (Float64), 'I' Integer (Int32) */
    char causality; /* 'p' parameter, 'i' input, 'o' output, 'l' local, 't' independent (time) */
    char role;      /* 'm' model parameter, 's' solver setting, 'u' input, 'y' model output, 'e' engine
                       output, 'x' a state, 'd' a state's derivative, 'g' an event indicator, 't' time */
    int index;      /* in the array of its role */
    double start;
} PgVar;

/* one built FMU: its model, its variables, who it is (for FMU states) */
typedef struct PgFmu {
    const PgModel *model;
    const PgVar *vars;
    int n_vars;
    const char *token; /* the instantiation token (guid) of its modelDescription */
    const char *build; /* the build's name: a state is restored only into the same build */
    int fmi;           /* 2 or 3 */
    const char *const *log_categories; /* the modelDescription's LogCategories */
    int n_log_categories;
} PgFmu;

#define PG_MAX_OUT (64 + 3)

typedef void (*PgLogFn)(void *env, int status, const char *category, const char *message);

/* what an FMU state holds (copied as a whole by fmi2GetFMUstate) */
typedef struct PgState {
    double par[PG_MAX_P], set[PG_NS], u[PG_MAX_U];
    int has_sim;
    PgEngine sim;
    int has_out;
    double out[PG_MAX_OUT]; /* the model's outputs, then n_events, t_last_event, last_event */
    double t_start, t_stop, t_ok;
    int failed;
    char failed_text[PG_MSG_MAX];
} PgState;

typedef struct PgInstance {
    const PgFmu *fmu;
    PgLogFn log;
    void *log_env;
    PgState st;
    int inputs_changed;
    double h_fast;
} PgInstance;

void pg_inst_init(PgInstance *in, const PgFmu *fmu, PgLogFn log, void *log_env);
void pg_inst_reset(PgInstance *in);
const PgVar *pg_inst_variable(const PgFmu *fmu, unsigned vr);

int pg_inst_get_real(PgInstance *in, const unsigned vr[], size_t n, double out[]);
int pg_inst_get_integer(PgInstance *in, const unsigned vr[], size_t n, int out[]);
int pg_inst_set_real(PgInstance *in, const unsigned vr[], size_t n, const double values[]);
int pg_inst_set_integer(PgInstance *in, const unsigned vr[], size_t n, const int values[]);
/* no Boolean or String variables: names the problem */
int pg_inst_no_such_type(PgInstance *in, const unsigned vr[], size_t n, const char *type);

int pg_inst_setup_experiment(PgInstance *in, double start, int stop_defined, double stop);
int pg_inst_exit_initialization(PgInstance *in);
int pg_inst_do_step(PgInstance *in, double t, double h);
double pg_inst_last_successful_time(const PgInstance *in);

/* FMU states: a copy of st; serialized with the owner (model, build, FMI version) and a SHA-256 seal */
size_t pg_inst_serialized_size(const PgInstance *in);
int pg_inst_serialize(PgInstance *in, const PgState *state, unsigned char *bytes, size_t size);
int pg_inst_deserialize(PgInstance *in, const unsigned char *bytes, size_t size, PgState *state);
void pg_inst_restore(PgInstance *in, const PgState *state);

#endif
