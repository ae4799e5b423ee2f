/* pogofmu extension of the native FMI 2.0 FMUs (not part of FMI; linked into their binaries only).
 *
 * fmpy's co-simulation loop (fmpy.simulation.simulateCS, FMI 2.0, no inputs) in C, over this FMU's
 * own fmi2DoStep, fmi2GetReal and fmi2GetInteger (fmi2/pg_fmi2.c) — so the call-state checks and
 * every status are the standard entry points' — for hosts that run many short simulations
 * (`pogofmu sweep`): on an initialized instance, from `start` to `stop` at the grid start + k h (the
 * last step shortened to stop), recording after each step a row of the time, the reals `rvr` and
 * the integers `ivr` (as doubles) into `out` (at most `max_rows` rows). The same time arithmetic as
 * fmpy's Python loop, hence the same rows to the bit. Returns the status of the last call; `*rows`
 * the rows recorded. */
#include <math.h>
#include <stdlib.h>

#include "fmi2Functions.h"

static int close_to(double a, double b) /* Python's math.isclose(a, b) with its defaults */
{
    if (a == b) return 1;
    if (isinf(a) || isinf(b)) return 0;
    double d = fabs(a - b), m = fabs(a) > fabs(b) ? fabs(a) : fabs(b);
    return d <= 1e-9 * m;
}

static fmi2Status record_row(fmi2Component c, double t, const fmi2ValueReference *rvr, size_t nr,
                             const fmi2ValueReference *ivr, size_t ni, double *row, int *ints)
{
    row[0] = t;
    fmi2Status st = nr ? fmi2GetReal(c, rvr, nr, row + 1) : fmi2OK;
    if (st > fmi2Warning) return st;
    fmi2Status st2 = ni ? fmi2GetInteger(c, ivr, ni, ints) : fmi2OK;
    for (size_t i = 0; i < ni; ++i) row[1 + nr + i] = (double)ints[i];
    return st2 > st ? st2 : st;
}

FMI2_Export int pogofmu_fmi2_run_grid(fmi2Component c, double start, double stop, double h,
                                      const fmi2ValueReference *rvr, size_t nr, const fmi2ValueReference *ivr,
                                      size_t ni, double *out, size_t max_rows, size_t *rows)
{
    *rows = 0;
    if (!c || !out || max_rows == 0 || !(h > 0) || (ni && !ivr) || (nr && !rvr)) return fmi2Error;
    int *ints = ni ? malloc(ni * sizeof *ints) : NULL;
    if (ni && !ints) return fmi2Error;
    size_t width = 1 + nr + ni;
    double t = start;
    long n_steps = 0;
    fmi2Status st = record_row(c, t, rvr, nr, ivr, ni, out, ints);
    if (st <= fmi2Warning) *rows = 1;
    while (st <= fmi2Warning && !(t > stop || close_to(t, stop))) {
        if (*rows >= max_rows) {
            st = fmi2Error;
            break;
        }
        double next_regular = start + (double)(n_steps + 1) * h;
        double next = next_regular;
        if (next > stop && !close_to(next, stop)) next = stop;
        fmi2Status s = fmi2DoStep(c, t, next - t, fmi2True);
        if (s > fmi2Warning) {
            st = s;
            break;
        }
        t = next;
        s = record_row(c, t, rvr, nr, ivr, ni, out + *rows * width, ints);
        if (s > fmi2Warning) {
            st = s;
            break;
        }
        *rows += 1;
        if (close_to(t, next_regular)) n_steps += 1;
    }
    free(ints);
    return st;
}
