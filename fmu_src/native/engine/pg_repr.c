/* Python's repr(float) in C, once for every part of the project: the engine's messages
 * (pg_support.c, pg_repr_double) and the SSP master's CSV rows (master/pg_csv.c, pg_repr_put).
 *
 * repr(float) is the shortest decimal that reads back as the same double (the one closest to the
 * double when several are as short), laid out in fixed notation when the decimal exponent is
 * -4 .. 15 and in exponent notation (at least two exponent digits, always signed) otherwise;
 * "0.0" / "-0.0", "inf" / "-inf", "nan". The digits here: glibc's printf is exact (a correctly
 * rounded P-digit decimal), strtod reads exactly; for a normal double a decimal of 15 digits or
 * fewer that reads back is the correctly rounded 15-digit one (half an ulp is below half a unit of
 * the 15th digit), so P = 15, 16, 17 are tried in turn (17 always reads back); at a power of two
 * the interval of the decimals reading back is narrower below than above, so a 16-digit
 * neighbour of the correctly rounded one may read back where that one does not. A subnormal has
 * fewer significant bits: every P from 1 is tried. tests/test_csv_format.py compares with Python
 * on millions of doubles.
 *
 * Standard C (printf, strtod) with unsigned __int128 where the compiler has it (gcc, clang, zig);
 * without it, the printf path alone. */
#include "pg_repr.h"

#include <float.h>
#include "pg_crt_math.h" /* (<math.h>; the Windows build: the UCRT's log10) */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    char d[20]; /* significant digits, d[0] != '0' */
    int n;      /* how many */
    int e;      /* decimal exponent of d[0] */
} digits;

/* The correctly rounded P-digit decimal of x > 0 (printf), as digits. */
static void printf_digits(double x, int p, digits *out)
{
    char buf[48];
    int k = 0;
    const char *s = buf;
    snprintf(buf, sizeof buf, "%.*e", p - 1, x);
    while (*s && *s != 'e' && *s != 'E') {
        if (*s >= '0' && *s <= '9')
            out->d[k++] = *s;
        s++;
    }
    out->n = k;
    out->e = (int)strtol(s + 1, NULL, 10);
}

/* strtod of the digits: the double they read back as. */
static double read_back(const digits *g)
{
    char buf[48];
    memcpy(buf, g->d, (size_t)g->n);
    snprintf(buf + g->n, sizeof buf - (size_t)g->n, "e%d", g->e - (g->n - 1));
    return strtod(buf, NULL);
}

/* One unit of the last digit added to x (a carry past the first digit makes 10...0 one exponent up). */
static void add_unit(digits *x)
{
    int k;
    for (k = x->n - 1; k >= 0 && x->d[k] == '9'; k--)
        x->d[k] = '0';
    if (k >= 0)
        x->d[k]++;
    else {
        x->d[0] = '1';
        x->e++;
    }
}

/* g rounded to p < g->n digits, when the digits dropped tell which way (not exactly half of the
 * last digit kept: then the double itself decides, and 0 is returned). */
static int round_digits(const digits *g, int p, digits *out)
{
    int tail = 0, half = 5, i;
    for (i = p; i < g->n; i++) {
        tail = tail * 10 + (g->d[i] - '0');
        if (i > p)
            half *= 10;
    }
    if (tail == half)
        return 0;
    memcpy(out->d, g->d, (size_t)p);
    out->n = p;
    out->e = g->e;
    if (tail > half)
        add_unit(out);
    return 1;
}

/* The P-digit decimal one unit of the last digit above (up > 0) or below g. */
static void step_digits(const digits *g, int up, digits *out)
{
    int k, p = g->n;
    *out = *g;
    if (up) {
        add_unit(out);
    } else {
        for (k = p - 1; k >= 0 && out->d[k] == '0'; k--)
            out->d[k] = '9';
        out->d[k]--; /* k >= 0: d[0] != '0' */
        if (out->d[0] == '0') { /* 1000..0 -> 0999..9: the P nines of the decade below */
            memmove(out->d, out->d + 1, (size_t)(p - 1));
            out->d[p - 1] = '9';
            out->e--;
        }
    }
}

/* The same digits without printf and strtod for 1e-15 <= x < 1e17 (a run's usual numbers): x =
 * f 2^k exactly, x 10^s (s = 16 - e <= 31) = f 5^s 2^(k+s) and the bounds of the interval of the
 * decimals reading back as x, (4f -/+ 2) 5^s 2^(k+s-2) (4f - 1 below a power of two), all
 * integers times powers of two below 2^127; rounding is to nearest, ties to even (printf's), and a
 * bound belongs to the interval when f is even (strtod's ties to even). Returns 0 outside. */
#if defined(__SIZEOF_INT128__)
typedef unsigned __int128 u128;

static const unsigned long long POW5[28] = {
    1ULL, 5ULL, 25ULL, 125ULL, 625ULL, 3125ULL, 15625ULL, 78125ULL, 390625ULL, 1953125ULL, 9765625ULL,
    48828125ULL, 244140625ULL, 1220703125ULL, 6103515625ULL, 30517578125ULL, 152587890625ULL,
    762939453125ULL, 3814697265625ULL, 19073486328125ULL, 95367431640625ULL, 476837158203125ULL,
    2384185791015625ULL, 11920928955078125ULL, 59604644775390625ULL, 298023223876953125ULL,
    1490116119384765625ULL, 7450580596923828125ULL};
static const unsigned long long POW10[19] = {
    1ULL, 10ULL, 100ULL, 1000ULL, 10000ULL, 100000ULL, 1000000ULL, 10000000ULL, 100000000ULL,
    1000000000ULL, 10000000000ULL, 100000000000ULL, 1000000000000ULL, 10000000000000ULL,
    100000000000000ULL, 1000000000000000ULL, 10000000000000000ULL, 100000000000000000ULL,
    1000000000000000000ULL};

static u128 pow5(int n)
{
    return n <= 27 ? (u128)POW5[n] : (u128)POW5[27] * POW5[n - 27];
}

/* v / d and v % d for a quotient below 2^64 and a small d, in 64-bit divisions: a 128-bit division
 * would call the compiler's runtime (__udivti3), and zig's runtime, once linked, also brings its
 * own exp, log, sin, ... which then replace the C library's in the whole binary: other last bits
 * (a native FMU's outputs must be the Python-hosted FMU's, which use the C library's). */
static unsigned long long div_small(u128 v, unsigned d, unsigned long long *rem)
{
    unsigned long long hi = (unsigned long long)(v >> 64), lo = (unsigned long long)v;
    unsigned long long r = hi % d; /* (hi / d is 0: the quotient is below 2^64) */
    unsigned long long mid = (r << 32) | (lo >> 32);
    unsigned long long q1 = mid / d;
    unsigned long long low = ((mid % d) << 32) | (lo & 0xffffffffULL);
    *rem = low % d;
    return (q1 << 32) + low / d;
}

/* A 2^t / d rounded to nearest, ties to even (d = 1, 10, 100; the result below 2^63). */
static unsigned long long round_scaled(u128 a, int t, unsigned d)
{
    unsigned long long q, b;
    if (t >= 0) {
        u128 v = a << t;
        q = div_small(v, d, &b);
        return q + (2 * b > d || (2 * b == d && (q & 1)));
    } else {
        int sh = -t;
        u128 rem = a & (((u128)1 << sh) - 1), half = (u128)1 << (sh - 1);
        unsigned long long q0 = (unsigned long long)(a >> sh);
        q = q0 / d;
        b = q0 % d;
        if (d == 1)
            return q + (rem > half || (rem == half && (q & 1)));
        return q + (b > d / 2 || (b == d / 2 && (rem > 0 || (q & 1))));
    }
}

/* The sign of D - a 2^t. */
static int cmp_scaled(unsigned long long D, u128 a, int t)
{
    if (t >= 0) {
        u128 v = a << t;
        return D < v ? -1 : D > v;
    } else {
        int sh = -t;
        u128 q = a >> sh, rem = a & (((u128)1 << sh) - 1);
        if (D != q)
            return D < q ? -1 : 1;
        return rem ? -1 : 0;
    }
}

/* D (the digits of x 10^s, below 10^20) as digits: pg_put_uint's, without a NUL (d holds 20). */
static void int_digits(unsigned long long D, int s, digits *out)
{
    out->n = (int)(pg_put_uint(out->d, D) - out->d);
    out->e = out->n - 1 - s;
}

static int shortest_exact(double x, digits *out)
{
    unsigned long long bits, frac, f, N, D;
    int E, k, e, s, t, pass, p, even, pow2;
    memcpy(&bits, &x, sizeof bits);
    E = (int)((bits >> 52) & 0x7ff);
    frac = bits & ((1ULL << 52) - 1);
    if (E == 0 || E == 0x7ff)
        return 0;
    f = frac | (1ULL << 52);
    k = E - 1075;
    even = !(f & 1);
    pow2 = frac == 0 && E > 1;
    e = (int)floor(log10(x));
    for (pass = 0;; pass++) {
        s = 16 - e;
        if (s < 0 || s > 31 || pass > 2)
            return 0;
        t = k + s - 2; /* the scale of 4f 5^s */
        if (t < -120 || t > 8)
            return 0;
        N = round_scaled((u128)f * pow5(s), k + s, 1);
        if (N < POW10[16])
            e--;
        else if (N >= POW10[17])
            e++;
        else
            break;
    }
    u128 mid = (u128)(4 * f) * pow5(s), lo = (u128)(4 * f - (pow2 ? 1 : 2)) * pow5(s), hi = (u128)(4 * f + 2) * pow5(s);
    for (p = 15; p <= 16; p++) {
        unsigned d = p == 15 ? 100 : 10;
        D = round_scaled(mid, t, d) * d;
        int c_lo = cmp_scaled(D, lo, t), c_hi = cmp_scaled(D, hi, t);
        if ((c_lo > 0 || (c_lo == 0 && even)) && (c_hi < 0 || (c_hi == 0 && even))) {
            int_digits(D, s, out);
            return 1;
        }
        if (p == 16 && pow2) { /* the 16-digit neighbour on the other side of x */
            unsigned long long h = cmp_scaled(D, mid, t) < 0 ? D + 10 : D == POW10[16] ? D - 1 : D - 10;
            c_lo = cmp_scaled(h, lo, t);
            c_hi = cmp_scaled(h, hi, t);
            if ((c_lo > 0 || (c_lo == 0 && even)) && (c_hi < 0 || (c_hi == 0 && even))) {
                int_digits(h, s, out);
                return 1;
            }
        }
    }
    int_digits(N, s, out);
    return 1;
}
#else
static int shortest_exact(double x, digits *out)
{
    (void)x;
    (void)out;
    return 0;
}
#endif

/* The shortest digits of x > 0 (finite) reading back as x, the closest to x of those. */
static void shortest(double x, digits *out)
{
    digits g17, g;
    int p, ex;
    if (shortest_exact(x, out))
        return;
    if (x < DBL_MIN) { /* subnormal: few significant bits, the shortest may have any length */
        for (p = 1; p < 17; p++) {
            printf_digits(x, p, out);
            if (read_back(out) == x)
                return;
        }
        printf_digits(x, 17, out);
        return;
    }
    printf_digits(x, 17, &g17);
    /* A P-digit decimal reading back as x is within half an ulp of x (at most 1.1103 units of the
     * 17th digit per unit of the leading digit d0 + 1), and g17 within half a unit: the last
     * 17 - P digits of g17 then lie that close to a multiple of 10^(17 - P) units. When they do
     * not, no P-digit decimal reads back (most doubles: no strtod for P = 15). */
    double near = 1.1103 * (g17.d[0] - '0' + 1) + 0.5;
    int t15 = (g17.d[15] - '0') * 10 + (g17.d[16] - '0'), t16 = g17.d[16] - '0';
    int dev[2] = {t15 < 100 - t15 ? t15 : 100 - t15, t16 < 10 - t16 ? t16 : 10 - t16};
    for (p = 15; p <= 16; p++) {
        if (dev[p - 15] > near && frexp(x, &ex) != 0.5)
            continue;
        if (!round_digits(&g17, p, &g))
            printf_digits(x, p, &g);
        double y = read_back(&g);
        if (y == x) {
            *out = g;
            return;
        }
        if (p == 16) {
            if (frexp(x, &ex) == 0.5) { /* a power of two: the interval is asymmetric */
                digits h;
                step_digits(&g, y < x, &h);
                if (read_back(&h) == x) {
                    *out = h;
                    return;
                }
            }
        }
    }
    *out = g17;
}

/* str(v) at s (no terminating NUL); returns the end. */
char *pg_put_uint(char *s, unsigned long long v)
{
    char tmp[24];
    int k = 0;
    do {
        tmp[k++] = (char)('0' + v % 10);
        v /= 10;
    } while (v);
    while (k)
        *s++ = tmp[--k];
    return s;
}

/* repr(x) at s (no terminating NUL); returns the end. */
char *pg_repr_put(char *s, double x)
{
    digits g;
    int n, decpt, i;
    if (isnan(x)) {
        memcpy(s, "nan", 3);
        return s + 3;
    }
    if (signbit(x)) {
        *s++ = '-';
        x = -x;
    }
    if (isinf(x)) {
        memcpy(s, "inf", 3);
        return s + 3;
    }
    if (x == 0) {
        memcpy(s, "0.0", 3);
        return s + 3;
    }
    shortest(x, &g);
    n = g.n;
    while (n > 1 && g.d[n - 1] == '0')
        n--;
    decpt = g.e + 1; /* x = 0.d1d2... 10^decpt */
    if (g.e < -4 || g.e > 15) {
        *s++ = g.d[0];
        if (n > 1) {
            *s++ = '.';
            memcpy(s, g.d + 1, (size_t)(n - 1));
            s += n - 1;
        }
        *s++ = 'e';
        *s++ = g.e < 0 ? '-' : '+';
        i = g.e < 0 ? -g.e : g.e;
        if (i < 10)
            *s++ = '0';
        return pg_put_uint(s, (unsigned long long)i);
    }
    if (decpt <= 0) {
        *s++ = '0';
        *s++ = '.';
        for (i = 0; i < -decpt; i++)
            *s++ = '0';
        memcpy(s, g.d, (size_t)n);
        return s + n;
    }
    if (decpt < n) {
        memcpy(s, g.d, (size_t)decpt);
        s += decpt;
        *s++ = '.';
        memcpy(s, g.d + decpt, (size_t)(n - decpt));
        return s + (n - decpt);
    }
    memcpy(s, g.d, (size_t)n);
    s += n;
    for (i = n; i < decpt; i++)
        *s++ = '0';
    *s++ = '.';
    *s++ = '0';
    return s;
}

void pg_repr_double(double v, char *buf, size_t size)
{
    char text[PG_REPR_MAX + 1];
    char *end = pg_repr_put(text, v);
    *end = '\0';
    if (size)
        snprintf(buf, size, "%s", text);
}
