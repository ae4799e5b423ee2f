/* pogofmu native engine: the sizes of the engine's arrays for one model (PG_MAX_X, PG_MAX_Q, PG_MAX_U,
 * PG_MAX_Y, PG_MAX_P, PG_MAX_EVENTS). This default leaves every size at the engine's maximum
 * (pg_pairs.h, pg_engine.h): the host's engine library, which runs any model, is built with it. A
 * native FMU's sources carry their own, generated from the model (pogofmu.codegen.cmodel.sizes_header). */
#ifndef PG_SIZES_H
#define PG_SIZES_H
#endif
