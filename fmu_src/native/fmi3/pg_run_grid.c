/* pogofmu extension of the native FMI 3.0 FMUs (not part of FMI; linked into their binaries only):
 * the sweep's stepping loop (pg_run_grid.h) over this FMU's own fmi3DoStep, fmi3GetFloat64 and
 * fmi3GetInt32 (fmi3/pg_fmi3.c), on a co-simulation instance in Step Mode. */
#include "fmi3Functions.h"
#include "pg_run_grid.h"

static int step3(void *c, double t, double h, int *early, double *last_t, int *terminate)
{
    fmi3Boolean event = fmi3False, term = fmi3False, ret = fmi3False;
    fmi3Float64 last = t + h;
    int st = (int)fmi3DoStep(c, t, h, fmi3True, &event, &term, &ret, &last);
    *early = ret ? 1 : 0;
    *last_t = last;
    *terminate = term ? 1 : 0;
    return st;
}

static int reals3(void *c, const uint32_t *vr, size_t n, double *values)
{
    return (int)fmi3GetFloat64(c, vr, n, values, n);
}

static int ints3(void *c, const uint32_t *vr, size_t n, int32_t *values)
{
    return (int)fmi3GetInt32(c, vr, n, values, n);
}

static const PgGridCalls CALLS3 = {step3, reals3, ints3};

FMI3_Export int pogofmu_fmi3_run_grid(fmi3Instance c, double start, double stop, double h,
                                      const fmi3ValueReference *rvr, size_t nr, const fmi3ValueReference *ivr,
                                      size_t ni, double *out, size_t max_rows, size_t *rows)
{
    return pg_run_grid(&CALLS3, c, start, stop, h, rvr, nr, ivr, ni, out, max_rows, rows);
}
