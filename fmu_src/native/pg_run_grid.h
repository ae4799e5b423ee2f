/* pogofmu extension of the native FMUs (not part of FMI; linked into their binaries only): the
 * sweep's stepping loop, once for both FMI versions (fmi2/pg_run_grid.c, fmi3/pg_run_grid.c give
 * it their doStep and getters).
 *
 * fmpy's co-simulation loop (fmpy.simulation.simulateCS, no inputs, no event mode) in C, over the
 * FMU's own entry points — so the call-state checks and every status are the standard's — for
 * hosts that run many short simulations (`pogofmu sweep`): on an initialized instance, from
 * `start` to `stop` at the grid start + k h (the last step shortened to stop), recording after
 * each step a row of the time, the reals `rvr` and the integers `ivr` (as doubles) into `out` (at
 * most `max_rows` rows). The same time arithmetic as fmpy's Python loop, hence the same rows to
 * the bit. A step that returns early moves the time to its last successful time; a step that asks
 * to terminate ends the loop after its row (fmpy's FMI 3.0 loop). Statuses are the standards'
 * numbers (OK 0, Warning 1, Discard 2, Error 3, Fatal 4, the same in both). Returns the status of
 * the last call; `*rows` the rows recorded. */
#ifndef PG_RUN_GRID_H
#define PG_RUN_GRID_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

typedef struct {
    /* one step from t of length h; *early set (with *last_t) when it returned early, *terminate when
     * the FMU asks to end the run */
    int (*step)(void *c, double t, double h, int *early, double *last_t, int *terminate);
    int (*get_reals)(void *c, const uint32_t *vr, size_t n, double *values);
    int (*get_ints)(void *c, const uint32_t *vr, size_t n, int32_t *values);
} PgGridCalls;

enum { PG_GRID_WARNING = 1, PG_GRID_ERROR = 3 };

static int pg_grid_close_to(double a, double b) /* Python's math.isclose(a, b) with its defaults */
{
    if (a == b) return 1;
    if (isinf(a) || isinf(b)) return 0;
    double d = fabs(a - b), m = fabs(a) > fabs(b) ? fabs(a) : fabs(b);
    return d <= 1e-9 * m;
}

static int pg_grid_row(const PgGridCalls *f, void *c, double t, const uint32_t *rvr, size_t nr, const uint32_t *ivr,
                       size_t ni, double *row, int32_t *ints)
{
    row[0] = t;
    int st = nr ? f->get_reals(c, rvr, nr, row + 1) : 0;
    if (st > PG_GRID_WARNING) return st;
    int st2 = ni ? f->get_ints(c, ivr, ni, ints) : 0;
    for (size_t i = 0; i < ni; ++i) row[1 + nr + i] = (double)ints[i];
    return st2 > st ? st2 : st;
}

static int pg_run_grid(const PgGridCalls *f, void *c, double start, double stop, double h, const uint32_t *rvr,
                       size_t nr, const uint32_t *ivr, size_t ni, double *out, size_t max_rows, size_t *rows)
{
    *rows = 0;
    if (!c || !out || max_rows == 0 || !(h > 0) || (ni && !ivr) || (nr && !rvr)) return PG_GRID_ERROR;
    int32_t *ints = ni ? malloc(ni * sizeof *ints) : NULL;
    if (ni && !ints) return PG_GRID_ERROR;
    size_t width = 1 + nr + ni;
    double t = start;
    long n_steps = 0;
    int st = pg_grid_row(f, c, t, rvr, nr, ivr, ni, out, ints);
    if (st <= PG_GRID_WARNING) *rows = 1;
    while (st <= PG_GRID_WARNING && !(t > stop || pg_grid_close_to(t, stop))) {
        if (*rows >= max_rows) {
            st = PG_GRID_ERROR;
            break;
        }
        double next_regular = start + (double)(n_steps + 1) * h;
        double next = next_regular;
        if (next > stop && !pg_grid_close_to(next, stop)) next = stop;
        int early = 0, terminate = 0;
        double last_t = next;
        int s = f->step(c, t, next - t, &early, &last_t, &terminate);
        if (s > PG_GRID_WARNING) {
            st = s;
            break;
        }
        t = early && last_t < next ? last_t : next;
        s = pg_grid_row(f, c, t, rvr, nr, ivr, ni, out + *rows * width, ints);
        if (s > PG_GRID_WARNING) {
            st = s;
            break;
        }
        *rows += 1;
        if (terminate) break;
        if (pg_grid_close_to(t, next_regular)) n_steps += 1;
    }
    free(ints);
    return st;
}

#endif
