/* pogofmu extension of the native FMI 2.0 FMUs (not part of FMI; linked into their binaries only):
 * the sweep's stepping loop (pg_run_grid.h) over this FMU's own fmi2DoStep, fmi2GetReal and
 * fmi2GetInteger (fmi2/pg_fmi2.c). */
#include "fmi2Functions.h"
#include "pg_run_grid.h"

static int step2(void *c, double t, double h, int *early, double *last_t, int *terminate)
{
    (void)early, (void)last_t, (void)terminate; /* FMI 2.0: a step is done or refused */
    return (int)fmi2DoStep(c, t, h, fmi2True);
}

static int reals2(void *c, const uint32_t *vr, size_t n, double *values)
{
    return (int)fmi2GetReal(c, vr, n, values);
}

static int ints2(void *c, const uint32_t *vr, size_t n, int32_t *values)
{
    return (int)fmi2GetInteger(c, vr, n, values);
}

static const PgGridCalls CALLS2 = {step2, reals2, ints2};

FMI2_Export int pogofmu_fmi2_run_grid(fmi2Component c, double start, double stop, double h,
                                      const fmi2ValueReference *rvr, size_t nr, const fmi2ValueReference *ivr,
                                      size_t ni, double *out, size_t max_rows, size_t *rows)
{
    return pg_run_grid(&CALLS2, c, start, stop, h, rvr, nr, ivr, ni, out, max_rows, rows);
}
