/* The SSP master's hot path in C: one level of the update order stepped with the GIL released.
 *
 * For each component of a batch (FMI 2.0 co-simulation, called through the FMU's own functions,
 * whose addresses the Python side takes from fmpy): set its inputs from slots of a flat value
 * array, save its FMU state (fmi2GetFMUstate, the state object reused), fmi2DoStep, read its
 * outputs into their slots — each part when the Python side asks for it (the ``ops`` bits). An
 * input the component takes as a line over the step (Gauss-Seidel, ``--inputs interpolate``) is set
 * to its source's value at the macro step's start, with the slope to its source's value now
 * (fmi2SetRealInputDerivatives), as pogofmu.ssp.algorithms.Exchange.feed does. The
 * components of a batch are independent (none feeds another within the call), so they are
 * taken by the pool's threads in runs of neighbours; each does exactly the calls it would do
 * alone, so the results do not depend on the thread count. pgm_run_levels runs the levels of a
 * Gauss-Seidel macro step one after the other in one call. Every decision about events stays in
 * Python: this code only reports, per component, that its event counter changed over the step.
 *
 * A worker with no batch to run formats the recording's rows instead (pgm_pool_csv_rows, asked by
 * the CSV writer thread, pogofmu.ssp.record): a few values at a time, looking for a batch between
 * them, so that the writer is not a third thread on two cores beside the caller and a worker
 * waiting for it, and the worker's time between batches is not spent polling.
 *
 * Host-side only (pogofmu.ssp.native_level loads it); never part of an FMU. POSIX threads and the
 * GCC/Clang atomic builtins. */
#include <pthread.h>
#include <sched.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#ifdef _WIN32
#define PGM_EXPORT __declspec(dllexport)
#else
#define PGM_EXPORT __attribute__((visibility("default")))
#endif

typedef int (*set_real_f)(void *, const unsigned *, size_t, const double *);
typedef int (*get_real_f)(void *, const unsigned *, size_t, double *);
typedef int (*set_int_f)(void *, const unsigned *, size_t, const int *);
typedef int (*get_int_f)(void *, const unsigned *, size_t, int *);
typedef int (*do_step_f)(void *, double, double, int);
typedef int (*get_state_f)(void *, void **);
typedef int (*set_deriv_f)(void *, const unsigned *, size_t, const int *, const double *);

/* one component (filled by the Python side, pogofmu/ssp/native_level.py: keep the two in step) */
typedef struct {
    void *instance;
    void *do_step, *set_real, *get_real, *set_int, *get_int, *get_state, *set_deriv;
    void **state; /* the fmi2FMUstate variable the Python side keeps (not NULL when SAVE is asked) */
    int n_in_real, n_in_int, n_out_real, n_out_int;
    int int_first; /* the integer inputs are set before the reals (the Python path's order) */
    const unsigned *in_real_vr;  const int *in_real_src; const int *in_real_held; double *in_real_buf;
    const unsigned *in_int_vr;   const int *in_int_src;  const int *in_int_held;  int *in_int_buf;
    const unsigned *out_real_vr; const int *out_real_slot; double *out_real_buf;
    const unsigned *out_int_vr;  const int *out_int_slot;  int *out_int_buf;
    int event_slot; /* the slot of its event counter (n_events), or -1 */
    /* input lines (NULL: none): per real input, the slot of its source's value at the macro step's
     * start (-1: held) and the slot of the time its source has stepped since that start (a line
     * only when > 0: the source has stepped); the buffers of one fmi2SetRealInputDerivatives */
    const int *in_real_start; const int *in_real_span;
    unsigned *line_vr; int *line_order; double *line_buf;
} pgm_comp;

enum { OP_FEED = 1, OP_SAVE = 2, OP_STEP = 4, OP_READ = 8 };
/* result codes: 0 done, 1 done and the event counter changed, -1 not run (another failed);
 * (call << 8) | status for an error status > 1 of a call (pogofmu/ssp/native_level.py CALLS) */
enum { CALL_SET_REAL = 1, CALL_SAVE = 2, CALL_STEP = 3, CALL_GET_REAL = 4, CALL_SET_INT = 5, CALL_GET_INT = 6,
       CALL_SET_DERIV = 7 };

typedef struct {
    pgm_comp *const *comps;
    const unsigned char *ops;
    int n;
    double t, h;
    double t_mark; /* the macro step's start: inputs are lines for a step from it (else NaN) */
    double *values;
    unsigned char *known;
    double *before;
    int *result;
    int next;     /* the next component to take (atomic) */
    int failed;   /* a component failed: run no more (atomic) */
    int threads;  /* the threads that may take components */
} job_t;

typedef struct pgm_pool pgm_pool;
PGM_EXPORT void pgm_pool_free(pgm_pool *p);

/* pg_csv.c */
long pgm_csv_piece(const double *data, long n_rows, int n_cols, const unsigned char *is_int, char *out, long cap,
                   long row_max, long *row, int *col, long len, long budget);
PGM_EXPORT long pgm_csv_row_max(int n_cols, const unsigned char *is_int);
PGM_EXPORT long pgm_csv_rows(const double *data, long n_rows, int n_cols, const unsigned char *is_int, char *out,
                             long cap, long *done);

/* the side job: a block of CSV rows to format (pgm_pool_csv_rows), with its cursor */
typedef struct {
    const double *data;
    long n_rows;
    int n_cols;
    const unsigned char *is_int;
    char *out;
    long cap, row_max;
    long row; /* the cursor: rows done, the column within the next, the bytes so far */
    int col;
    long len;
} side_t;

enum { SIDE_NONE, SIDE_POSTED, SIDE_DONE };
#define SIDE_PIECE 64 /* values per piece (a few microseconds): a worker looks for a batch between pieces */

/* The pool. The caller of a batch takes its components too; once every one is taken it closes the
 * batch and waits only for the workers inside it (running a component): a worker that was not on
 * a CPU while the batch ran is not waited for (it finds the batch closed). A waiting thread — a
 * worker for the next batch, the caller for the workers inside — first polls for up to SPIN_NS,
 * yielding the CPU every few polls, then sleeps on a condition variable: a level of small
 * components takes ~0.1 ms, and the master's Python between two macro steps about as long, so a
 * sleep and a wake-up through the kernel at every level (tens of microseconds on a virtual
 * machine) would cost as much as the second thread gives. */
#define SPIN_NS 200000L

struct pgm_pool {
    int threads; /* workers besides the calling thread */
    pthread_t *tid;
    pthread_mutex_t mu;
    pthread_cond_t go, done;
    unsigned long generation; /* a batch was posted: changed under mu, read atomically */
    int open;                 /* workers may enter the batch (atomic) */
    int inside;               /* workers entered (atomic) */
    int quit;                 /* (set under mu, read atomically) */
    job_t job;
    side_t side;
    int side_state; /* SIDE_*: set under mu (POSTED by the asker, DONE by the worker that ends it) */
    int side_claim; /* a worker is formatting a piece (atomic) */
    pthread_cond_t side_cv; /* the side job changed state */
};

static int one(job_t *j, int i)
{
    pgm_comp *c = j->comps[i];
    unsigned char ops = j->ops[i];
    double *v = j->values;
    int k, st, lines = 0;
    if (ops & OP_FEED) {
        int lined = c->in_real_start != NULL && j->t == j->t_mark;
        for (k = 0; k < c->n_in_real; k++) {
            double x = v[c->in_real_src[k]];
            if (lined && c->in_real_start[k] >= 0) {
                double span = v[c->in_real_span[k]];
                if (span > 0) { /* the source has stepped: the line from its value at the start */
                    double x0 = v[c->in_real_start[k]];
                    c->line_vr[lines] = c->in_real_vr[k];
                    c->line_order[lines] = 1;
                    c->line_buf[lines++] = (x - x0) / span;
                    x = x0;
                }
            }
            c->in_real_buf[k] = x;
            v[c->in_real_held[k]] = x;
            j->known[c->in_real_held[k]] = 1;
        }
        for (k = 0; k < c->n_in_int; k++) {
            double x = v[c->in_int_src[k]];
            c->in_int_buf[k] = (int)x;
            v[c->in_int_held[k]] = x;
            j->known[c->in_int_held[k]] = 1;
        }
        for (int pass = 0; pass < 2; pass++) {
            if (pass == c->int_first) {
                if (c->n_in_real && (st = ((set_real_f)c->set_real)(c->instance, c->in_real_vr,
                                                                      (size_t)c->n_in_real, c->in_real_buf)) > 1)
                    return CALL_SET_REAL << 8 | st;
            } else if (c->n_in_int && (st = ((set_int_f)c->set_int)(c->instance, c->in_int_vr, (size_t)c->n_in_int,
                                                                      c->in_int_buf)) > 1) {
                return CALL_SET_INT << 8 | st;
            }
        }
        /* after the values: an fmi2SetReal of an input sets its derivative back to 0 */
        if (lines && (st = ((set_deriv_f)c->set_deriv)(c->instance, c->line_vr, (size_t)lines, c->line_order,
                                                       c->line_buf)) > 1)
            return CALL_SET_DERIV << 8 | st;
    }
    if ((ops & OP_SAVE) && (st = ((get_state_f)c->get_state)(c->instance, c->state)) > 1)
        return CALL_SAVE << 8 | st;
    if ((ops & OP_STEP) && (st = ((do_step_f)c->do_step)(c->instance, j->t, j->h, 1)) > 1)
        return CALL_STEP << 8 | st;
    if (!(ops & OP_READ))
        return 0;
    if (c->n_out_real && (st = ((get_real_f)c->get_real)(c->instance, c->out_real_vr, (size_t)c->n_out_real,
                                                           c->out_real_buf)) > 1)
        return CALL_GET_REAL << 8 | st;
    if (c->n_out_int && (st = ((get_int_f)c->get_int)(c->instance, c->out_int_vr, (size_t)c->n_out_int,
                                                        c->out_int_buf)) > 1)
        return CALL_GET_INT << 8 | st;
    double n0 = c->event_slot >= 0 ? v[c->event_slot] : 0.0;
    for (k = 0; k < c->n_out_real; k++) {
        v[c->out_real_slot[k]] = c->out_real_buf[k];
        j->known[c->out_real_slot[k]] = 1;
    }
    for (k = 0; k < c->n_out_int; k++) {
        v[c->out_int_slot[k]] = (double)c->out_int_buf[k];
        j->known[c->out_int_slot[k]] = 1;
    }
    j->before[i] = n0;
    return c->event_slot >= 0 && v[c->event_slot] != n0;
}

static long now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long)ts.tv_sec * 1000000000L + ts.tv_nsec;
}

static void relax(void)
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ __volatile__("yield");
#endif
}

static int batch_posted(pgm_pool *p, unsigned long seen)
{
    return __atomic_load_n(&p->generation, __ATOMIC_ACQUIRE) != seen || __atomic_load_n(&p->quit, __ATOMIC_ACQUIRE);
}

static int side_posted(pgm_pool *p)
{
    return __atomic_load_n(&p->side_state, __ATOMIC_ACQUIRE) == SIDE_POSTED;
}

static int batch_or_side(pgm_pool *p, unsigned long seen)
{
    return batch_posted(p, seen) || side_posted(p);
}

/* One piece of the side job, by the worker that claims it (none if another does: returns 0); the
 * piece that ends the job says so to its asker. */
static int side_piece(pgm_pool *p)
{
    int idle = 0;
    if (!__atomic_compare_exchange_n(&p->side_claim, &idle, 1, 0, __ATOMIC_ACQUIRE, __ATOMIC_RELAXED))
        return 0;
    if (side_posted(p)) {
        side_t *d = &p->side;
        d->len = pgm_csv_piece(d->data, d->n_rows, d->n_cols, d->is_int, d->out, d->cap, d->row_max, &d->row,
                               &d->col, d->len, SIDE_PIECE);
        if (d->row == d->n_rows || (d->col == 0 && d->len + d->row_max > d->cap)) {
            pthread_mutex_lock(&p->mu);
            __atomic_store_n(&p->side_state, SIDE_DONE, __ATOMIC_RELEASE);
            pthread_cond_broadcast(&p->side_cv);
            pthread_mutex_unlock(&p->mu);
        }
    }
    __atomic_store_n(&p->side_claim, 0, __ATOMIC_RELEASE);
    return 1;
}

static int workers_out(pgm_pool *p, unsigned long unused)
{
    (void)unused;
    return __atomic_load_n(&p->inside, __ATOMIC_SEQ_CST) == 0;
}

/* until ready(p, arg): polls (SPIN_NS), then sleeps on ``cond`` (whoever makes it true signals
 * ``cond`` under mu) */
static void wait_for(pgm_pool *p, int (*ready)(pgm_pool *, unsigned long), unsigned long arg, pthread_cond_t *cond)
{
    long until = now_ns() + SPIN_NS;
    for (int k = 1; !ready(p, arg); k++) {
        if ((k & 63) == 0) {
            if (now_ns() > until) {
                pthread_mutex_lock(&p->mu);
                while (!ready(p, arg))
                    pthread_cond_wait(cond, &p->mu);
                pthread_mutex_unlock(&p->mu);
                return;
            }
            sched_yield();
        } else {
            relax();
        }
    }
}

static void signal_caller(pgm_pool *p)
{
    pthread_mutex_lock(&p->mu);
    pthread_cond_signal(&p->done);
    pthread_mutex_unlock(&p->mu);
}

/* take components until none is left, a run of consecutive ones at a time (a share of what is left,
 * at least one: guided, so that the threads end together and seldom write neighbouring slots of
 * the value array); after a failure the rest are not run (result -1) */
static void work(job_t *j)
{
    for (;;) {
        int i = __atomic_load_n(&j->next, __ATOMIC_RELAXED), size;
        do {
            if (i >= j->n)
                return;
            size = (j->n - i) / (2 * j->threads);
            if (size < 1)
                size = 1;
        } while (!__atomic_compare_exchange_n(&j->next, &i, i + size, 1, __ATOMIC_ACQ_REL, __ATOMIC_RELAXED));
        for (int k = i; k < i + size; k++) {
            if (__atomic_load_n(&j->failed, __ATOMIC_ACQUIRE))
                continue;
            int r = one(j, k);
            j->result[k] = r;
            if (r > 1)
                __atomic_store_n(&j->failed, 1, __ATOMIC_RELEASE);
        }
    }
}

static void *worker(void *arg)
{
    pgm_pool *p = arg;
    unsigned long seen = 0;
    for (;;) {
        wait_for(p, batch_or_side, seen, &p->go);
        if (__atomic_load_n(&p->quit, __ATOMIC_ACQUIRE)) {
            while (side_posted(p)) /* (its asker waits for it) */
                if (!side_piece(p))
                    relax();
            break;
        }
        if (!batch_posted(p, seen)) { /* no batch: a piece of the side job (another worker's: wait) */
            if (!side_piece(p))
                relax();
            continue;
        }
        seen = __atomic_load_n(&p->generation, __ATOMIC_ACQUIRE);
        /* enter, then look whether the batch is still open (the caller closes it, then waits
         * until no worker is inside: one of the two sees the other) */
        __atomic_add_fetch(&p->inside, 1, __ATOMIC_SEQ_CST);
        if (__atomic_load_n(&p->open, __ATOMIC_SEQ_CST))
            work(&p->job);
        if (__atomic_sub_fetch(&p->inside, 1, __ATOMIC_SEQ_CST) == 0)
            signal_caller(p);
    }
    return NULL;
}

/* A pool of ``threads`` threads in all (the caller is one of them); NULL if a thread cannot be
 * started. */
PGM_EXPORT pgm_pool *pgm_pool_new(int threads)
{
    pgm_pool *p = calloc(1, sizeof *p);
    if (!p)
        return NULL;
    p->threads = threads > 1 ? threads - 1 : 0;
    pthread_mutex_init(&p->mu, NULL);
    pthread_cond_init(&p->go, NULL);
    pthread_cond_init(&p->done, NULL);
    pthread_cond_init(&p->side_cv, NULL);
    p->tid = calloc((size_t)(p->threads ? p->threads : 1), sizeof *p->tid);
    if (!p->tid) {
        free(p);
        return NULL;
    }
    for (int k = 0; k < p->threads; k++) {
        if (pthread_create(&p->tid[k], NULL, worker, p) != 0) {
            p->threads = k;
            pgm_pool_free(p);
            return NULL;
        }
    }
    return p;
}

PGM_EXPORT void pgm_pool_free(pgm_pool *p)
{
    if (!p)
        return;
    pthread_mutex_lock(&p->mu);
    __atomic_store_n(&p->quit, 1, __ATOMIC_RELEASE);
    pthread_cond_broadcast(&p->go);
    pthread_mutex_unlock(&p->mu);
    for (int k = 0; k < p->threads; k++)
        pthread_join(p->tid[k], NULL);
    pthread_cond_destroy(&p->go);
    pthread_cond_destroy(&p->done);
    pthread_cond_destroy(&p->side_cv);
    pthread_mutex_destroy(&p->mu);
    free(p->tid);
    free(p);
}

/* Run the batch: ``ops[i]`` on ``comps[i]`` (steps from ``t`` of length ``h``), on the pool's
 * threads when ``parallel`` and there are several components. ``result[i]`` as above;
 * ``before[i]``: the event counter before the step (read components). Returns the number of
 * components whose result is not 0; every call has ended when it returns. */
PGM_EXPORT int pgm_run(pgm_pool *p, int parallel, int n, pgm_comp *const *comps, const unsigned char *ops,
                       double t, double h, double t_mark, double *values, unsigned char *known, double *before,
                       int *result)
{
    job_t local, *j = p ? &p->job : &local; /* (no worker reads the pool's job while it is closed) */
    int k, helpers = (p && parallel && n > 1 && p->threads > 0);
    *j = (job_t){comps, ops, n, t, h, t_mark, values, known, before, result, 0, 0, helpers ? p->threads + 1 : 1};
    for (k = 0; k < n; k++)
        result[k] = -1;
    if (helpers) {
        __atomic_store_n(&p->open, 1, __ATOMIC_SEQ_CST);
        pthread_mutex_lock(&p->mu); /* (a worker going to sleep checks the generation under mu) */
        __atomic_add_fetch(&p->generation, 1, __ATOMIC_RELEASE);
        pthread_cond_broadcast(&p->go);
        pthread_mutex_unlock(&p->mu);
    }
    work(j);
    if (helpers) {
        /* every component is taken: close the batch, and wait for the workers inside (those
         * running a component) to leave */
        __atomic_store_n(&p->open, 0, __ATOMIC_SEQ_CST);
        wait_for(p, workers_out, 0, &p->done);
    }
    int count = 0;
    for (k = 0; k < n; k++)
        count += result[k] != 0;
    return count;
}

/* A Gauss-Seidel macro step of ``n_levels`` levels, each a batch as pgm_run's (level L: ``n[L]``
 * components ``comps[L]``, ``ops[L]``, ``before[L]``, ``result[L]``), every component at the macro
 * step's start ``t`` = ``t_mark`` and stepped by ``h``: level after level, each fed from the
 * outputs of those before. ``span[L][i]`` is the slot of the time component i has stepped since
 * t_mark (-1: none), which the input lines of later levels read: ``t - t_mark`` before its step,
 * ``(t + h) - t_mark`` after (the doubles pogofmu.ssp.native_level.Batch.go writes). Stops after
 * the first level with a result that is not 0 (an event counted, a failure); returns its index, or
 * n_levels when every level ended with all results 0. */
PGM_EXPORT int pgm_run_levels(pgm_pool *p, int parallel, int n_levels, const int *n, pgm_comp *const *const *comps,
                              const unsigned char *const *ops, double t, double h, double t_mark, double *values,
                              unsigned char *known, double *const *before, int *const *result,
                              const int *const *span)
{
    int L, i;
    double before_step = t - t_mark, after_step = (t + h) - t_mark;
    for (L = 0; L < n_levels; L++)
        for (i = 0; i < n[L]; i++)
            if (span[L][i] >= 0)
                values[span[L][i]] = before_step;
    for (L = 0; L < n_levels; L++) {
        if (pgm_run(p, parallel, n[L], comps[L], ops[L], t, h, t_mark, values, known, before[L], result[L]))
            return L;
        for (i = 0; i < n[L]; i++)
            if (span[L][i] >= 0)
                values[span[L][i]] = after_step;
    }
    return n_levels;
}

/* ``pgm_csv_rows`` (pg_csv.c) done by the pool's workers between their batches, for a thread
 * other than the pool's caller (the CSV writer): it waits, asleep, until they have formatted the
 * rows. One block at a time (a second asker waits for the first). Without workers the asking
 * thread formats them itself. Not to be called during or after pgm_pool_free (the pool's memory
 * goes): pogofmu.ssp.native_level.NativeLevels holds a lock around both. */
PGM_EXPORT long pgm_pool_csv_rows(pgm_pool *p, const double *data, long n_rows, int n_cols,
                                  const unsigned char *is_int, char *out, long cap, long *done)
{
    if (!p || p->threads == 0)
        return pgm_csv_rows(data, n_rows, n_cols, is_int, out, cap, done);
    pthread_mutex_lock(&p->mu);
    while (__atomic_load_n(&p->side_state, __ATOMIC_ACQUIRE) != SIDE_NONE)
        pthread_cond_wait(&p->side_cv, &p->mu);
    p->side = (side_t){data, n_rows, n_cols, is_int, out, cap, pgm_csv_row_max(n_cols, is_int), 0, 0, 0};
    __atomic_store_n(&p->side_state, SIDE_POSTED, __ATOMIC_RELEASE);
    pthread_cond_broadcast(&p->go); /* (a sleeping worker waits for a batch or a side job) */
    while (__atomic_load_n(&p->side_state, __ATOMIC_ACQUIRE) != SIDE_DONE)
        pthread_cond_wait(&p->side_cv, &p->mu);
    long len = p->side.len;
    *done = p->side.row;
    __atomic_store_n(&p->side_state, SIDE_NONE, __ATOMIC_RELEASE);
    pthread_cond_broadcast(&p->side_cv);
    pthread_mutex_unlock(&p->mu);
    return len;
}
