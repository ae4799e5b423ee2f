/* pogofmu: where the C adapter's model comes from (its "model source").
 *
 * The adapter (pg_backend.c over pg_instance.c, pg_instance3.c, pg_handles.c, pg_derivatives.c)
 * is the same for every FMU; only its PgFmu (the variable table and the PgModel, pg_instance.h)
 * comes from elsewhere:
 *
 *   - native FMUs: the generated C of one model (`PG_FMU`, pogofmu.codegen.cfmu), after the
 *     instantiation token's check (in pg_backend.c itself: no code of this file);
 *   - Python-hosted FMUs (compiled with PG_PYTHON_SOURCE): python/pg_source_py.c boots CPython,
 *     loads the FMU's resources and builds the PgFmu at run time (pogofmu.runtime.hosted), whose
 *     PgModel's functions are the Python binding's trampolines and callbacks
 *     (engine/pg_binding.c, pogofmu.runtime.solver.cengine.Binding). Every backend call that may
 *     reach the model runs between pg_source_enter and pg_source_leave: the GIL held, the
 *     instance's binding the current one of the thread, its parameters those of the instance. */
#ifndef PG_SOURCE_H
#define PG_SOURCE_H

#include "pg_instance.h"

typedef struct PgSource PgSource;

/* the PgFmu of a new instance, or NULL with the reason logged (through setup->log); *src the
 * source's own part of the instance (freed by pg_source_close) */
const PgFmu *pg_source_open(const PgSetup *setup, PgSource **src);
void pg_source_close(PgSource *src);

typedef struct PgSourceGuard {
    PgInstance *in;
    int gil;
    void *outer;
    int jvp_off; /* the engine took the Jacobian by differences before the call */
} PgSourceGuard;

/* PG_ST_OK, or PG_ST_ERROR with the reason logged when the instance's parameters cannot be handed
 * to the model's functions (the call must then not run: they would read other values); in either
 * case pg_source_leave follows */
int pg_source_enter(PgSource *src, PgInstance *in, PgSourceGuard *g);
/* the call done: what the Python side noted during it logged (the Jacobian gone to differences:
 * the binding's text, logSolver), the thread and the GIL as they were */
void pg_source_leave(PgSource *src, PgSourceGuard *g);

#endif
