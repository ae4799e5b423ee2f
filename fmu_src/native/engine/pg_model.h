/* pogofmu native engine: what a generated model provides.
 *
 * A model's C file (generated at build time from its Python HybridModel by pogofmu.codegen) defines
 * one `const PgModel PG_MODEL`: counts, names, event directions, and one function per pure
 * function of the model — the settings' and the parameters' rules, the initial state, the flow,
 * each event's guard, activity and jump, the outputs, the domain conditions, the scales. Every function does the floating-point operations of the Python code in the same
 * order (the same bits) and reports what Python raises:
 *
 *   PG_OK     done;
 *   PG_RAISE  a model error: `m->text` holds the message Python's exception carries;
 *   PG_ARITH  an arithmetic failure (a division by zero, a math domain or range error):
 *             `m->text` holds Python's detail ("float division by zero", ...), `m->arith` its kind;
 *   PG_NO_JVP (flow_jvp only) the model's derivative cannot be taken this way (the Python binding:
 *             the model's flow does not run on dual numbers): the engine takes the Jacobian by
 *             differences for the rest of the run. Generated C never returns it.
 *
 * Arrays: t time, x continuous states, q discrete state (every slot a double, integers exactly),
 * u inputs, p the model's parameters, s the solver's settings (in SOLVER_PARAMETERS order). */
#ifndef PG_MODEL_H
#define PG_MODEL_H

#include <stddef.h>

/* a function of the rare path (a refusal's message, a checked call), kept out of the callers' hot code */
#if defined(__GNUC__) || defined(__clang__)
#define PG_NOINLINE __attribute__((noinline))
#elif defined(_MSC_VER)
#define PG_NOINLINE __declspec(noinline)
#else
#define PG_NOINLINE
#endif

/* C99's restrict (MSVC, which may compile the C sources an FMU carries, spells it __restrict) */
#if defined(_MSC_VER) && !defined(__clang__)
#define PG_RESTRICT __restrict
#else
#define PG_RESTRICT restrict
#endif

#define PG_MSG_MAX 2048

enum { PG_OK = 0, PG_RAISE = 1, PG_ARITH = 2, PG_NO_JVP = 3 };
enum { PG_ZERO_DIVISION = 1, PG_OVERFLOW = 2, PG_DOMAIN = 3 };
enum { PG_FALLING = -1, PG_RISING = 1 };

typedef struct PgMsg {
    char text[PG_MSG_MAX];
    size_t len;
    int arith; /* PG_ZERO_DIVISION, PG_OVERFLOW, PG_DOMAIN when PG_ARITH */
} PgMsg;

#define PG_MAX_SCALES 16
#define PG_MAX_SCALE_NAMES 6
typedef struct PgScale {
    const char *label;
    const char *names[PG_MAX_SCALE_NAMES];
    int n_names;
    double value;
} PgScale;

typedef struct PgModel {
    const char *name;
    int nx, nq, nu, np, ns, ny, ne;
    const char *const *state_names;
    const char *const *q_names;
    const char *q_kinds;             /* 'i' or 'f' per slot */
    const char *const *input_names;
    const char *const *parameter_names;
    const char *parameter_kinds;     /* 'i' or 'f' per parameter */
    const char *const *output_names; /* the model's outputs (the engine's come after them) */
    const char *const *event_names;
    const signed char *event_direction;
    int has_time_scales, has_error_scales;
    /* the checks of a run's start, called by the engine in this order: */
    int (*check_settings)(const double *s, PgMsg *m); /* the solver settings' rules */
    int (*check)(const double *p, PgMsg *m);           /* the parameter rules */
    int (*initial)(const double *p, double *x, double *q, PgMsg *m);
    int (*flow)(double t, const double *x, const double *q, const double *u, const double *p, double *dx, PgMsg *m);
    /* event k's guard and jump at time t (a model's guard or jump may read the time) */
    int (*guard)(int k, double t, const double *x, const double *q, const double *u, const double *p, double *g,
                 PgMsg *m);
    int (*active)(int k, const double *q, int *on, PgMsg *m);
    int (*jump)(int k, double t, const double *x, const double *q, const double *u, const double *p, double *x_new,
                double *q_new, PgMsg *m);
    int (*outputs)(double t, const double *x, const double *q, const double *u, const double *p, double *y, PgMsg *m);
    /* PG_RAISE with the condition's text when (t, x) leaves the domain, PG_OK inside it */
    int (*domain)(double t, const double *x, const double *q, const double *u, const double *p, const double *s,
                  PgMsg *m);
    int (*time_scales)(const double *p, PgScale *out, int *n, PgMsg *m);
    int (*error_scales)(const double *p, PgScale *out, int *n, PgMsg *m);
    /* directional derivatives (the flow's and the outputs' on dual numbers, pogofmu.runtime.dual):
     * df = (d flow / dx) sx + (d flow / du) su, dy likewise, at (t, x) in mode q */
    int (*flow_jvp)(double t, const double *x, const double *q, const double *u, const double *p, const double *sx,
                    const double *su, double *df, PgMsg *m);
    int (*outputs_jvp)(double t, const double *x, const double *q, const double *u, const double *p, const double *sx,
                       const double *su, double *dy, PgMsg *m);
    /* time events (after the ne state events in the engine's numbering: event ne + k): k's first
     * instant *at and period *every (0: once), from the parameters; its jump at time t */
    int nte;
    const char *const *time_event_names;
    int (*time_event)(int k, const double *p, double *at, double *every, PgMsg *m);
    int (*time_jump)(int k, double t, const double *x, const double *q, const double *u, const double *p,
                     double *x_new, double *q_new, PgMsg *m);
} PgModel;

#endif
