/* See pg_support.h. */
#include "pg_support.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void pg_msg_clear(PgMsg *m)
{
    m->text[0] = '\0';
    m->len = 0;
    m->arith = 0;
}

void pg_msg_str(PgMsg *m, const char *s)
{
    size_t n = strlen(s);
    if (m->len + n >= PG_MSG_MAX) n = PG_MSG_MAX - 1 - m->len;
    memcpy(m->text + m->len, s, n);
    m->len += n;
    m->text[m->len] = '\0';
}

void pg_msg_printf(PgMsg *m, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(m->text + m->len, PG_MSG_MAX - m->len, fmt, ap);
    va_end(ap);
    if (n > 0) m->len += (size_t)n < PG_MSG_MAX - m->len ? (size_t)n : PG_MSG_MAX - 1 - m->len;
}

/* pg_repr_double (Python's repr): pg_repr.c, the one repr(float) in C. */

void pg_format(double v, const char *spec, char *buf, size_t size)
{
    if (isnan(v)) {
        snprintf(buf, size, "nan");
        return;
    }
    if (isinf(v)) {
        snprintf(buf, size, v > 0 ? "inf" : "-inf");
        return;
    }
    int prec = 6;
    char type = 'g';
    const char *c = spec;
    if (*c == '.') {
        prec = atoi(c + 1);
        ++c;
        while (*c >= '0' && *c <= '9') ++c;
    }
    if (*c) type = *c;
    if (type == 'g' && prec == 0) prec = 1;
    char fmt[16];
    snprintf(fmt, sizeof fmt, "%%.%d%c", prec, type);
    snprintf(buf, size, fmt, v);
}

void pg_msg_value(PgMsg *m, double v, char kind, const char *spec)
{
    char buf[64];
    if (strcmp(spec, "r") == 0) {
        if (kind == 'b') {
            snprintf(buf, sizeof buf, "%s", v != 0.0 ? "True" : "False");
        } else if (kind == 'i' && isfinite(v)) {
            snprintf(buf, sizeof buf, "%.0f", v);
        } else {
            pg_repr_double(v, buf, sizeof buf);
        }
    } else {
        pg_format(v, spec, buf, sizeof buf);
    }
    pg_msg_str(m, buf);
}

int pg_arith(PgMsg *m, int kind)
{
    pg_msg_clear(m);
    m->arith = kind;
    pg_msg_str(m, kind == PG_ZERO_DIVISION ? "float division by zero"
                  : kind == PG_OVERFLOW    ? "Numerical result out of range"
                                           : "math domain error");
    return PG_ARITH;
}

static int arith_text(PgMsg *m, int kind, const char *text)
{
    pg_msg_clear(m);
    m->arith = kind;
    pg_msg_str(m, text);
    return PG_ARITH;
}

/* float ** float as CPython's float_pow computes it, with its errors */
int pg_pow(double iv, double iw, double *out, PgMsg *m)
{
    if (iw == 0.0) { *out = 1.0; return PG_OK; }
    if (isnan(iv)) { *out = iv == 1.0 ? 1.0 : iv; return PG_OK; }
    if (isnan(iw)) { *out = iv == 1.0 ? 1.0 : iw; return PG_OK; }
    if (isinf(iw)) {
        double a = fabs(iv);
        *out = a == 1.0 ? 1.0 : ((iw > 0) == (a > 1.0)) ? INFINITY : 0.0;
        return PG_OK;
    }
    if (isinf(iv)) {
        int odd = fmod(fabs(iw), 2.0) == 1.0;
        if (iw > 0) *out = odd ? iv : fabs(iv);
        else *out = odd ? copysign(0.0, iv) : 0.0;
        return PG_OK;
    }
    if (iv == 0.0) {
        int odd = fmod(fabs(iw), 2.0) == 1.0;
        if (iw < 0.0) return arith_text(m, PG_ZERO_DIVISION, "0.0 cannot be raised to a negative power");
        *out = odd ? iv : 0.0;
        return PG_OK;
    }
    int negate = 0;
    if (iv < 0.0) {
        if (iw != floor(iw)) /* Python returns a complex number here: no real result */
            return arith_text(m, PG_DOMAIN, "math domain error");
        iv = -iv;
        negate = fmod(fabs(iw), 2.0) == 1.0;
    }
    if (iv == 1.0) { *out = negate ? -1.0 : 1.0; return PG_OK; }
    errno = 0;
    /* the exponent through memory: a compiler that sees a constant 2.0 (a model's x ** 2 inlined by the
     * link-time optimization) makes pow(x, 2.0) x * x, which differs from the C library's pow, the one
     * CPython calls, in about one case in a thousand: the Python-hosted and native FMUs of a stiff Van
     * der Pol written with x ** 3 (its exact Jacobian's 3 x ** 2) parted by 5e-11 (a user's audit,
     * 2026-12-07) */
    volatile double w = iw;
    double ix = pow(iv, w);
    if (isinf(ix)) return arith_text(m, PG_OVERFLOW, "Numerical result out of range");
    *out = negate ? -ix : ix;
    return PG_OK;
}

/* The functions of CPython's math module with its errors, one line each: ValueError (math domain
 * error) where the argument is outside the domain; OverflowError (math range error) for a finite
 * argument with an infinite result; none for the functions defined everywhere. */
#define PG_MATH_TOTAL(fn)                                                                                       \
    int pg_##fn(double a, double *out, PgMsg *m) { (void)m; *out = fn(a); return PG_OK; }
#define PG_MATH_TOTAL2(fn)                                                                                      \
    int pg_##fn(double a, double b, double *out, PgMsg *m) { (void)m; *out = fn(a, b); return PG_OK; }
#define PG_MATH_DOMAIN(fn, outside)                                                                             \
    int pg_##fn(double a, double *out, PgMsg *m)                                                                \
    {                                                                                                           \
        if (outside) return arith_text(m, PG_DOMAIN, "math domain error");                                      \
        *out = fn(a);                                                                                           \
        return PG_OK;                                                                                           \
    }
#define PG_MATH_RANGE(fn)                                                                                       \
    int pg_##fn(double a, double *out, PgMsg *m)                                                                \
    {                                                                                                           \
        double r = fn(a);                                                                                       \
        if (isinf(r) && isfinite(a)) return arith_text(m, PG_OVERFLOW, "math range error");                     \
        *out = r;                                                                                               \
        return PG_OK;                                                                                           \
    }

PG_MATH_DOMAIN(sqrt, a < 0.0)
PG_MATH_DOMAIN(log, !(a > 0.0) && !isnan(a))
PG_MATH_DOMAIN(log10, !(a > 0.0) && !isnan(a))
PG_MATH_DOMAIN(cos, isinf(a))
PG_MATH_DOMAIN(sin, isinf(a))
PG_MATH_DOMAIN(tan, isinf(a))
PG_MATH_DOMAIN(asin, a < -1.0 || a > 1.0)
PG_MATH_DOMAIN(acos, a < -1.0 || a > 1.0)
PG_MATH_RANGE(exp)
PG_MATH_RANGE(sinh)
PG_MATH_RANGE(cosh)
PG_MATH_TOTAL(atan)
PG_MATH_TOTAL(tanh)
PG_MATH_TOTAL2(atan2)
PG_MATH_TOTAL2(hypot)
PG_MATH_TOTAL2(copysign)

/* math.trunc of a float: an int in Python; NaN and infinities raise */
int pg_trunc(double a, double *out, PgMsg *m)
{
    if (isnan(a)) return arith_text(m, PG_DOMAIN, "cannot convert float NaN to integer");
    if (isinf(a)) return arith_text(m, PG_OVERFLOW, "cannot convert float infinity to integer");
    *out = trunc(a);
    return PG_OK;
}
