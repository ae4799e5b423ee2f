/* The SSP master's C level stepping (fmu_src/native/master/pg_level.c) on its own, driven with
 * stand-in components (plain C functions with the FMI 2.0 signatures), built with
 * -fsanitize=thread by tests/test_level_pool.py.
 *
 * Two levels: A components step x' = u (u set from a constant slot), B components step y' = u
 * with u the line of an A output over the step (its value at the macro step's start and the slope
 * to its value now, as pogofmu.ssp.algorithms.Exchange.feed sets it). Each step also spins a
 * little arithmetic so that the threads overlap. Every macro step is run through pgm_run_levels;
 * the value array after STEPS macro steps is compared to the bit with a run without a pool (one
 * thread), for 2, 3 and 4 threads. Then a component fails at a chosen step: the call stops after
 * that level, the failure's code is (3 << 8) | 3, and no later component of its level is run
 * after the failure is seen.
 *
 * Meanwhile a writer thread has the pool's workers format blocks of CSV rows between their batches
 * (pgm_pool_csv_rows, as the master's CSV writer does), in pieces of a buffer smaller than the
 * block and whole: every text is compared with pgm_csv_rows's in the writer's own thread. A last
 * block is asked for while no batch runs (the workers asleep).
 *
 * Prints "ok" and exits 0; anything else is a failure (ThreadSanitizer exits 66 on a race). */
#include "pg_level.c"
#include "pg_csv.c"
#include "pg_repr.c" /* (engine/: the one repr(float) in C) */

#include <math.h>
#include <stdio.h>

#define NA 37
#define NB 29
#define STEPS 200

typedef struct {
    double x, u, du;
    int steps, fail_at;
    double work;
} Comp;

static int set_real(void *c, const unsigned *vr, size_t n, const double *v)
{
    (void)vr;
    if (n) ((Comp *)c)->u = v[0], ((Comp *)c)->du = 0.0;
    return 0;
}
static int set_deriv(void *c, const unsigned *vr, size_t n, const int *order, const double *v)
{
    (void)vr, (void)order;
    if (n) ((Comp *)c)->du = v[0];
    return 0;
}
static int get_real(void *c, const unsigned *vr, size_t n, double *out)
{
    (void)vr;
    if (n) out[0] = ((Comp *)c)->x;
    return 0;
}
static int set_int(void *c, const unsigned *vr, size_t n, const int *v) { (void)c, (void)vr, (void)n, (void)v; return 0; }
static int get_int(void *c, const unsigned *vr, size_t n, int *out) { (void)c, (void)vr, (void)n, (void)out; return 0; }
static int get_state(void *c, void **state) { *state = c; return 0; }
static int do_step(void *cv, double t, double h, int flag)
{
    Comp *c = cv;
    (void)t, (void)flag;
    if (++c->steps == c->fail_at)
        return 3;
    double w = c->work;
    for (int k = 0; k < 300; k++) /* some work */
        w = sin(w + 1e-3 * k);
    c->work = w;
    c->x += h * c->u + 0.5 * h * h * c->du;
    return 0;
}

typedef struct {
    Comp comp[NA + NB];
    pgm_comp pc[NA + NB];
    pgm_comp *ptr[NA + NB];
    unsigned char ops[NA + NB];
    double before[NA + NB];
    int result[NA + NB];
    int span[NA + NB];
    unsigned vr[1];
    int src[NA + NB], held[NA + NB], start[NA + NB], spn[NA + NB];
    double inbuf[NA + NB], outbuf[NA + NB], linebuf[NA + NB];
    unsigned linevr[NA + NB];
    int order1[NA + NB], outslot[NA + NB];
    void *state[NA + NB];
    /* slots: [0] the constant, A outputs, B outputs, held inputs, A starts, spans */
    double values[1 + 4 * (NA + NB) + NA];
    unsigned char known[1 + 4 * (NA + NB) + NA];
} System;

enum { OUT = 1, HELD = 1 + NA + NB, START = 1 + 2 * (NA + NB), SPAN = 1 + 2 * (NA + NB) + NA };

static void setup(System *s, int fail_comp, int fail_at)
{
    memset(s, 0, sizeof *s);
    s->values[0] = 0.25;
    for (int i = 0; i < NA + NB; i++) {
        Comp *c = &s->comp[i];
        c->work = i;
        c->fail_at = i == fail_comp ? fail_at : -1;
        pgm_comp *p = &s->pc[i];
        p->instance = c;
        p->do_step = (void *)do_step, p->set_real = (void *)set_real, p->get_real = (void *)get_real;
        p->set_int = (void *)set_int, p->get_int = (void *)get_int, p->get_state = (void *)get_state;
        p->set_deriv = (void *)set_deriv;
        p->state = &s->state[i];
        p->n_in_real = 1, p->n_out_real = 1;
        p->in_real_vr = s->vr, p->out_real_vr = s->vr;
        p->in_real_held = &s->held[i], s->held[i] = HELD + i;
        p->in_real_buf = &s->inbuf[i], p->out_real_buf = &s->outbuf[i];
        p->out_real_slot = &s->outslot[i], s->outslot[i] = OUT + i;
        p->event_slot = -1;
        if (i < NA) {
            s->src[i] = 0;
        } else { /* B: the line of A output (i - NA) % NA */
            int a = (i - NA) % NA;
            s->src[i] = OUT + a;
            s->start[i] = START + a, s->spn[i] = SPAN + a;
            p->in_real_start = &s->start[i], p->in_real_span = &s->spn[i];
            p->line_vr = &s->linevr[i], p->line_order = &s->order1[i], p->line_buf = &s->linebuf[i];
        }
        p->in_real_src = &s->src[i];
        s->ptr[i] = p;
        s->ops[i] = OP_FEED | OP_SAVE | OP_STEP | OP_READ;
        s->span[i] = i < NA ? SPAN + i : -1;
    }
}

/* STEPS macro steps; the level that stopped a step (2: none) of the last one run */
static int run(System *s, pgm_pool *p, int *steps_run)
{
    int n[2] = {NA, NB};
    pgm_comp *const *comps[2] = {s->ptr, s->ptr + NA};
    const unsigned char *ops[2] = {s->ops, s->ops + NA};
    double *before[2] = {s->before, s->before + NA};
    int *result[2] = {s->result, s->result + NA};
    const int *span[2] = {s->span, s->span + NA};
    double h = 1e-3;
    int stop = 2;
    for (int k = 0; k < STEPS; k++) {
        double t = k * h;
        for (int a = 0; a < NA; a++) /* the macro step's start: the A outputs' start slots */
            s->values[START + a] = s->values[OUT + a];
        stop = pgm_run_levels(p, 1, 2, n, comps, ops, t, h, t, s->values, s->known, before, result, span);
        *steps_run = k + 1;
        if (stop != 2)
            break;
    }
    return stop;
}

/* the CSV writer: blocks of rows formatted by the pool, compared with the calling thread's */
#define ROWS 40
#define COLS 57
typedef struct {
    pgm_pool *p;
    int blocks, bad;
    volatile int stop; /* (set by the main thread once the runs are over: read under no lock) */
    double data[ROWS * COLS];
    unsigned char is_int[COLS];
    char mine[1 << 16], theirs[1 << 16];
} Writer;

static int one_block(Writer *w, long cap)
{
    long r = 0, done_mine, done_theirs;
    while (r < ROWS) {
        long n_theirs = pgm_pool_csv_rows(w->p, w->data + r * COLS, ROWS - r, COLS, w->is_int, w->theirs, cap,
                                          &done_theirs);
        long n_mine = pgm_csv_rows(w->data + r * COLS, ROWS - r, COLS, w->is_int, w->mine, cap, &done_mine);
        if (done_theirs <= 0 || n_theirs != n_mine || done_theirs != done_mine ||
            memcmp(w->mine, w->theirs, (size_t)n_mine) != 0)
            return 1;
        r += done_mine;
    }
    return 0;
}

static void *writer(void *arg)
{
    Writer *w = arg;
    while (!__atomic_load_n(&w->stop, __ATOMIC_ACQUIRE)) {
        /* the whole block in one text, then in pieces of a few rows */
        w->bad |= one_block(w, (long)sizeof w->mine) | one_block(w, 5 * pgm_csv_row_max(COLS, w->is_int));
        w->blocks++;
    }
    return NULL;
}

static void fill(Writer *w, pgm_pool *p)
{
    memset(w, 0, sizeof *w);
    w->p = p;
    for (int j = 0; j < COLS; j++)
        w->is_int[j] = j % 7 == 1;
    for (int k = 0; k < ROWS * COLS; k++)
        w->data[k] = w->is_int[k % COLS] ? (double)(k % 13 - 6) : sin(0.37 * k) * pow(10.0, k % 11 - 5);
}

int main(void)
{
    static System ref, sys;
    static Writer w;
    int steps;
    setup(&ref, -1, -1);
    if (run(&ref, NULL, &steps) != 2 || steps != STEPS) {
        printf("the run without a pool stopped at step %d\n", steps);
        return 1;
    }
    for (int threads = 2; threads <= 4; threads++) {
        pgm_pool *p = pgm_pool_new(threads);
        if (!p) {
            printf("no pool of %d threads\n", threads);
            return 1;
        }
        pthread_t wt;
        fill(&w, p);
        if (pthread_create(&wt, NULL, writer, &w) != 0) {
            printf("no writer thread\n");
            return 1;
        }
        for (int rep = 0; rep < 3; rep++) {
            setup(&sys, -1, -1);
            if (run(&sys, p, &steps) != 2 || memcmp(sys.values, ref.values, sizeof ref.values) != 0 ||
                memcmp(sys.known, ref.known, sizeof ref.known) != 0) {
                printf("%d threads: the values differ from one thread's\n", threads);
                return 1;
            }
        }
        /* a B component fails at its 150th step: the call stops after level B with its code */
        setup(&sys, NA + 11, 150);
        int stop = run(&sys, p, &steps);
        if (stop != 1 || steps != 150 || sys.result[NA + 11] != (CALL_STEP << 8 | 3)) {
            printf("%d threads: a failure gave stop %d at step %d, code %d\n", threads, stop, steps,
                   sys.result[NA + 11]);
            return 1;
        }
        for (int i = 0; i < NA; i++)
            if (sys.result[i] != 0) {
                printf("%d threads: level A has result %d at %d\n", threads, sys.result[i], i);
                return 1;
            }
        for (int i = NA; i < NA + NB; i++)
            if (sys.result[i] != 0 && sys.result[i] != -1 && i != NA + 11) {
                printf("%d threads: component %d has result %d\n", threads, i, sys.result[i]);
                return 1;
            }
        __atomic_store_n(&w.stop, 1, __ATOMIC_RELEASE);
        pthread_join(wt, NULL);
        struct timespec nap = {0, 5000000}; /* the workers asleep (past their polling) */
        nanosleep(&nap, NULL);
        w.bad |= one_block(&w, (long)sizeof w.mine);
        if (w.bad || w.blocks < 1) {
            printf("%d threads: the pool's CSV rows differ from the caller's (%d blocks)\n", threads, w.blocks);
            return 1;
        }
        pgm_pool_free(p);
    }
    printf("ok\n");
    return 0;
}
