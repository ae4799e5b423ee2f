/* pogofmu native engine: the Runge-Kutta pairs (pg_pairs.c is generated from the
 * tableaux, runtime/solver/tableaux.py, by pogofmu.codegen.cpairs). Stage vectors are rows of PG_MAX_X doubles. */
#ifndef PG_PAIRS_H
#define PG_PAIRS_H

#include "pg_model.h"
#include "pg_sizes.h"

#ifndef PG_MAX_X
#define PG_MAX_X 32
#endif
/* the number of states n of a loop: a native FMU's pg_sizes.h gives its model's as the constant
 * PG_NX (the compiler then unrolls and vectorizes the loops: the same operations on each state, the
 * same bits); the host's engine library, which runs any model, takes n as it comes */
#ifdef PG_NX
#define PG_N(n) PG_NX
#else
#define PG_N(n) ((n) + 0) /* (+ 0: `n = PG_N(n);` is no self-assignment clang warns of) */
#endif
#define PG_MAX_STAGES 13 /* DOP853's 12 stages and f(t + h) */
#define PG_MAX_DENSE 7   /* coefficient vectors of the continuous extension */

/* the right-hand side for the current (q, u, p): PG_OK, or PG_ARITH/PG_RAISE with m set */
typedef int (*PgFun)(void *ctx, double t, const double *y, double *dy, PgMsg *m);

int pg_dopri5_step(PgFun fun, void *ctx, double t, const double *y, const double *f, double h, int n,
                   double *y_new, double *f_new, double *K, PgMsg *m);
double pg_dopri5_error_norm(const double *K, double h, const double *y, const double *y_new, double atol,
                            double rtol, int n);
void pg_dopri5_dense(const double *PG_RESTRICT K, int n, double *PG_RESTRICT Q);
void pg_dopri5_eval(const double *PG_RESTRICT Q, double t0, double h, const double *PG_RESTRICT y0, double t, int n,
                    double *PG_RESTRICT out);

int pg_dop853_step(PgFun fun, void *ctx, double t, const double *y, const double *f, double h, int n,
                   double *y_new, double *f_new, double *K, PgMsg *m);
double pg_dop853_error_norm(const double *K, double h, const double *y, const double *y_new, double atol,
                            double rtol, int n);
int pg_dop853_dense(PgFun fun, void *ctx, double t0, const double *y0, const double *y1, double h,
                    const double *K, int n, double *Q, PgMsg *m);
void pg_dop853_eval(const double *PG_RESTRICT Q, double t0, double h, const double *PG_RESTRICT y0, double t, int n,
                    double *PG_RESTRICT out);

#endif
