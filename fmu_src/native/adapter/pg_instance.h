/* pogofmu FMUs: the one adapter from any model to FMI, of both kinds of FMU (the model generated C,
 * or Python code: pg_source.h): the variable table, parameters fixed at
 * initialization and checked there, inputs held over a step and checked at the step, outputs
 * refreshed once per step, the step's rules, the event log, FMU states with their owner and seal.
 * (Comments name the methods of the Python adapter, runtime/fmi2.py, that these functions replaced
 * and whose messages they keep.)
 *
 * The FMI entry files (fmu_src/native/fmi2/) check the call states and map the statuses; this file
 * knows nothing of the FMI headers. */
#ifndef PG_INSTANCE_H
#define PG_INSTANCE_H

#include <stddef.h>

#include "pg_backend.h" /* the statuses PG_ST_*, PgLogFn */
#include "pg_engine.h"

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
    const unsigned *arrays; /* FMI 3.0: the array variables, (value reference, elements) pairs (pgb_arrays) */
    int n_arrays;
} PgFmu;

/* the served outputs: the model's, the engine's (n_events, t_last_event, last_event), then for
 * FMI 3.0 the states and the time */
#define PG_MAX_OUT (PG_MAX_Y + 3 + PG_MAX_X + 1)

/* what an FMU state holds (copied as a whole by fmi2GetFMUstate) */
typedef struct PgState {
    double par[PG_MAX_P], set[PG_NS], u[PG_MAX_U];
    /* FMI 2.0: the inputs' first derivatives (fmi2SetRealInputDerivatives), from the communication
     * point the step starts at; an fmi2SetReal of the input sets its derivative back to 0 */
    double du[PG_MAX_U];
    /* an input (or its derivative) set since the engine last took them: the next step or model-exchange
     * call hands them over. Part of the state: a state taken between an fmi2SetReal and the step keeps
     * that input pending, and one taken with none pending goes on along the engine's own line */
    int inputs_changed;
    int has_sim;
    PgEngine sim;
    int has_out;
    double out[PG_MAX_OUT]; /* the model's outputs, then n_events, t_last_event, last_event */
    double t_start, t_stop, t_ok;
    int failed;
    char failed_text[PG_MSG_MAX];
    /* FMI 3.0 (fmi3.py, Fmi3Slave._get_fmu_state "fmi3"): model exchange's time and states (the
     * arming of the guards is the engine's, in sim) */
    double me_t;
    int has_me_x;
    double me_x[PG_MAX_X];
} PgState;

typedef struct PgInstance {
    const PgFmu *fmu;
    PgLogFn log;
    void *log_env;
    PgState st;
    double h_fast;
    int rel_tol_set; /* the user set rel_tol: the importer's tolerance no longer applies */
    /* FMI 3.0: the interface and its flags (fixed at instantiation), and what is not state */
    char mode; /* 'c' co-simulation, 'm' model exchange */
    int event_mode_used, early_return_allowed;
    int me_stale, cs_stale, event_mode, has_stop;
    double stop;
} PgInstance;

void pg_inst_init(PgInstance *in, const PgFmu *fmu, PgLogFn log, void *log_env);
void pg_inst_reset(PgInstance *in);
const PgVar *pg_inst_variable(const PgFmu *fmu, unsigned vr);

int pg_inst_get_real(PgInstance *in, const unsigned vr[], size_t n, double out[]);
int pg_inst_get_integer(PgInstance *in, const unsigned vr[], size_t n, int out[]);
int pg_inst_set_real(PgInstance *in, const unsigned vr[], size_t n, const double values[]);
int pg_inst_set_integer(PgInstance *in, const unsigned vr[], size_t n, const int values[]);
/* fmi2SetRealInputDerivatives: order 1 of Real inputs only, finite; all checked before any is set */
int pg_inst_set_input_derivatives(PgInstance *in, const unsigned vr[], size_t n, const int order[],
                                  const double values[]);
/* no Boolean or String variables: names the problem */
int pg_inst_no_such_type(PgInstance *in, const unsigned vr[], size_t n, const char *type);

/* the importer's tolerance (if defined) becomes rel_tol unless the user set rel_tol (fmi2.py) */
int pg_inst_setup_experiment(PgInstance *in, int tolerance_defined, double tolerance, double start, int stop_defined,
                             double stop);
int pg_inst_exit_initialization(PgInstance *in);
int pg_inst_do_step(PgInstance *in, double t, double h);
double pg_inst_last_successful_time(const PgInstance *in);

/* FMU states: a copy of st; serialized with the owner (model, build, FMI version), the call state
 * it was taken in (a number of the entry file, given back by deserialize) and a SHA-256 seal */
size_t pg_inst_serialized_size(const PgInstance *in, unsigned call_state);
int pg_inst_serialize(PgInstance *in, const PgState *state, unsigned call_state, unsigned char *bytes, size_t size);
int pg_inst_deserialize(PgInstance *in, const unsigned char *bytes, size_t size, PgState *state,
                        unsigned *call_state);
void pg_inst_restore(PgInstance *in, const PgState *state);
/* a state's owner as every refusal names it: "model 'M', build 'B', FMI 2.0" */
void pg_inst_owner_text(const char *model, const char *build, int fmi, PgMsg *m);

/* directional derivatives (pg_derivatives.c): sensitivity = J seed, J the Jacobian of the unknowns
 * with respect to the knowns at the point the outputs describe; `fn` names the FMI function */
int pg_inst_directional(PgInstance *in, const unsigned *unknowns, size_t n_unknowns, const unsigned *knowns,
                        size_t n_knowns, const double *seed, double *sensitivity, const char *fn);

/* ---- FMI 3.0 (fmu_src/native/adapter/pg_instance3.c, the twin of runtime/fmi3.py) ---------- */
void pg3_attach(PgInstance *in, char mode, int event_mode_used, int early_return_allowed);
/* before any get: refresh what inputs set in Event Mode or model exchange made stale */
int pg3_refresh(PgInstance *in);
/* after a successful set: mark what the inputs make stale */
void pg3_after_set(PgInstance *in);
double pg3_derived(PgInstance *in, const PgVar *v);
void pg3_after_exit_initialization(PgInstance *in);
void pg3_after_restore(PgInstance *in);
void pg3_reset(PgInstance *in);
int pg3_set_time(PgInstance *in, double t);
int pg3_set_continuous_states(PgInstance *in, const double *x, size_t n);
int pg3_get_continuous_states(PgInstance *in, double *x);
int pg3_get_derivatives(PgInstance *in, double *dx);
int pg3_get_event_indicators(PgInstance *in, double *z);
int pg3_completed_integrator_step(PgInstance *in, int *enter_event_mode);
/* valuesOfContinuousStatesChanged in *changed */
int pg3_update_discrete_states(PgInstance *in, int *need, int *changed);
int pg3_do_step(PgInstance *in, double t, double h, int *event_handling_needed, int *early_return, double *last);
void pg3_set_event_mode(PgInstance *in, int on);

/* the adapter's pieces the FMI 3.0 extension uses */
int pg_inst_refuse(PgInstance *in, const PgMsg *m);
int pg_inst_refuse_text(PgInstance *in, const char *text);
int pg_inst_update_outputs_at(PgInstance *in, double t, const double *x, const double *q);
int pg_inst_update_outputs(PgInstance *in);
int pg_inst_model_failed(PgInstance *in);
int pg_inst_input_problem(PgInstance *in, double t, PgMsg *m); /* (t: the time the inputs apply from) */
void pg_inst_stopped_text(PgInstance *in, const char *call, double t, PgMsg *m);
typedef struct PgNotes PgNotes;
PgNotes *pg_inst_notes_begin(PgInstance *in);
void pg_inst_notes_end(PgInstance *in, PgNotes *nt);
/* the communication step's engine run (fmi2.py _advance_engine; FMI 3.0: stop at events) */
int pg3_advance_engine(PgInstance *in, double end);

#endif
