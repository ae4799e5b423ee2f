/* Python's repr(float) in C, once (pg_repr.c). */
#ifndef PG_REPR_H
#define PG_REPR_H

#include <stddef.h>

#define PG_REPR_MAX 24 /* the longest repr of a double: "-1.2345678901234567e-308" */

/* repr(x) written at s, without a terminating NUL (at most PG_REPR_MAX characters); returns the end. */
char *pg_repr_put(char *s, double x);
/* str(v) of an unsigned integer at s, without a terminating NUL; returns the end. */
char *pg_put_uint(char *s, unsigned long long v);
/* repr(v) into buf (NUL-terminated, cut to size - 1 characters). */
void pg_repr_double(double v, char *buf, size_t size);

#endif
