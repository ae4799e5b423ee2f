/* pogofmu native engine: messages formatted as Python formats them, and the arithmetic of Python
 * floats where it differs from C's (an operation that raises in Python fails here the same way). */
#ifndef PG_SUPPORT_H
#define PG_SUPPORT_H

#include "pg_crt_math.h" /* (<math.h>; the Windows build: the UCRT's math functions) */
#include "pg_model.h"
#include "pg_repr.h"

void pg_msg_clear(PgMsg *m);
void pg_msg_str(PgMsg *m, const char *s);
/* a value as Python formats it: spec "r" is repr() (kind 'f' float, 'i' int, 'b' bool), else a
 * format spec of the form [.N](g|e|f) as in f"{v:.6g}" */
void pg_msg_value(PgMsg *m, double v, char kind, const char *spec);
void pg_msg_printf(PgMsg *m, const char *fmt, ...);
/* Python's repr() of a float into buf: pg_repr.h (pg_repr_double) */
void pg_format(double v, const char *spec, char *buf, size_t size);

int pg_arith(PgMsg *m, int kind); /* sets m->arith and Python's detail text; returns PG_ARITH */
int pg_pow(double a, double b, double *out, PgMsg *m);
int pg_sqrt(double a, double *out, PgMsg *m);
int pg_exp(double a, double *out, PgMsg *m);
int pg_log(double a, double *out, PgMsg *m);
int pg_cos(double a, double *out, PgMsg *m);
int pg_sin(double a, double *out, PgMsg *m);
int pg_atan2(double a, double b, double *out, PgMsg *m);
int pg_hypot(double a, double b, double *out, PgMsg *m);
int pg_copysign(double a, double b, double *out, PgMsg *m);
int pg_tan(double a, double *out, PgMsg *m);
int pg_asin(double a, double *out, PgMsg *m);
int pg_acos(double a, double *out, PgMsg *m);
int pg_atan(double a, double *out, PgMsg *m);
int pg_sinh(double a, double *out, PgMsg *m);
int pg_cosh(double a, double *out, PgMsg *m);
int pg_tanh(double a, double *out, PgMsg *m);
int pg_log10(double a, double *out, PgMsg *m);
int pg_trunc(double a, double *out, PgMsg *m);

#endif
