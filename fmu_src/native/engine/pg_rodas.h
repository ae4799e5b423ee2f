/* pogofmu native engine: Rodas5P, the stiff method (method = 1).
 *
 * A Rosenbrock method of order 5 (embedded order 4), 8 stages, L-stable and stiffly accurate
 * (Steinebach 2023, "Construction of Rosenbrock-Wanner method Rodas5P and numerical benchmarks
 * within the Julia Differential Equations package"; coefficients as in OrdinaryDiffEq.jl), with
 * a continuous extension of order 4. Each stage is one evaluation of the flow and one solve with
 * W = I/(h gamma) - J, J the flow's Jacobian at the start of the step (exact for a native model,
 * from flow_jvp), dT = d flow / dt there. Linear solves only: no Newton iteration, nothing to
 * converge. The dense systems are tiny (<= PG_MAX_X states): W is factored here directly, by
 * Gaussian elimination with partial pivoting.
 *
 * Stage vectors (the increments k_i, not derivatives) are rows of PG_MAX_X doubles in K. */
#ifndef PG_RODAS_H
#define PG_RODAS_H

#include "pg_pairs.h"

#define PG_RODAS_STAGES 8
#define PG_RODAS_GAMMA 0.21193756319429014

/* J: row-major with row stride PG_MAX_X (J[i*PG_MAX_X + j] = d f_i / d y_j); dT: d f / d t.
 * *singular = 1 when W could not be factored (y_new is then left non-finite: the caller rejects
 * the step and retries with a smaller h, which moves 1/(h gamma) off J's eigenvalue). */
int pg_rodas_step(PgFun fun, void *ctx, double t, const double *y, const double *f, double h, int n,
                  const double *J, const double *dT, double *y_new, double *f_new, double *K, int *singular,
                  PgMsg *m);
/* the error estimate (the last increment k8, the difference of the order 5 and 4 solutions),
 * in the norm of the explicit pairs */
double pg_rodas_error_norm(const double *K, const double *y, const double *y_new, double atol, double rtol,
                           int n);
/* the three coefficient vectors of the continuous extension */
void pg_rodas_dense(const double *K, int n, double *Q);
void pg_rodas_eval(const double *Q, double t0, double h, const double *y0, const double *y1, double t, int n,
                   double *out);

/* LU with partial pivoting of the n x n matrix A (row stride PG_MAX_X), in place; 0 if singular */
int pg_lu_factor(double *A, int *piv, int n);
void pg_lu_solve(const double *LU, const int *piv, int n, double *b);

#endif
