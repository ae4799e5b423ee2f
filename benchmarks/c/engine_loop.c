/* The compiled limit of benchmark (g), benchmarks/bench_native.py: the native engine and a
 * generated model (the very C files of a native FMU, no FMI layer) driven over the communication
 * grid by a plain loop, every output recorded in memory as the C host records it (the model's
 * outputs, the states, the event count, the time).
 *
 *   engine_loop STOP STEP NP P... NS S...
 *
 * Prints one line: the points recorded, the last time, the event count and the CPU time of the
 * loop alone (as the C host prints it). Exit status 1 if the
 * engine refused or failed (its message on stderr). */
#define _POSIX_C_SOURCE 199309L /* clock_gettime under -std=c99 */
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "pg_engine.h"

extern const PgModel PG_MODEL;

int main(int argc, char **argv)
{
    if (argc < 4) { fprintf(stderr, "usage: see the source\n"); return 2; }
    double stop = atof(argv[1]), h = atof(argv[2]);
    int a = 3, np = atoi(argv[a++]);
    double p[PG_MAX_P], s[PG_NS], u[PG_MAX_U] = {0};
    for (int i = 0; i < np && a < argc; ++i) p[i] = atof(argv[a++]);
    int ns = a < argc ? atoi(argv[a++]) : 0;
    for (int i = 0; i < ns && a < argc; ++i) s[i] = atof(argv[a++]);
    if (np != PG_MODEL.np || ns != PG_NS) { fprintf(stderr, "expected %d parameters and %d settings\n", PG_MODEL.np, PG_NS); return 2; }
    PgEngine *e = malloc(pg_engine_sizeof());
    if (!e || pg_engine_init(e, &PG_MODEL, p, s, u, 0.0, stop) != PG_OK) {
        fprintf(stderr, "%s\n", e ? pg_engine_message(e) : "out of memory");
        return 1;
    }
    long steps = (long)(stop / h + 0.5), k;
    int ny = PG_MODEL.ny, nx = PG_MODEL.nx, w = ny + nx + 2;
    double *rec = malloc(sizeof(double) * (size_t)(steps + 1) * (size_t)w);
    if (!rec) return 2;
    double t_out, x[PG_MAX_X], q[PG_MAX_Q];
    long n_events = 0;
    struct timespec c0, c1;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c0);
    for (k = 0; k <= steps; ++k) {
        double t = k * h;
        if (k > 0 && pg_engine_advance(e, t) != PG_OK) { fprintf(stderr, "%s\n", pg_engine_message(e)); return 1; }
        pg_engine_served(e, &t_out, x, q, &n_events);
        double *row = rec + k * w;
        if (pg_engine_outputs(e, t_out, x, q, row) != PG_OK) { fprintf(stderr, "%s\n", pg_engine_message(e)); return 1; }
        for (int i = 0; i < nx; ++i) row[ny + i] = x[i];
        row[w - 2] = (double)n_events;
        row[w - 1] = t_out;
    }
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c1);
    printf("recorded %ld points, last t = %.17g, %ld events, loop cpu %.9f s\n", k, rec[(k - 1) * w + w - 1], n_events,
           (double)(c1.tv_sec - c0.tv_sec) + 1e-9 * (double)(c1.tv_nsec - c0.tv_nsec));
    free(rec);
    free(e);
    return 0;
}
