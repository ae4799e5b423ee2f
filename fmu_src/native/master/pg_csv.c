/* The SSP master's CSV rows in C: a block of rows (a C-contiguous array of doubles, with a flag
 * per column "integer") formatted as the text Python's csv.writer writes for the same rows, byte
 * for byte: a float as repr(float), an integer column as int(value), ',' between the fields and
 * "\r\n" after each row. Called from Python through ctypes.CDLL (the GIL released), so the
 * formatting of the rows overlaps the stepping (pogofmu.ssp.record.CSVStream).
 *
 * A float is written by pg_repr_put (engine/pg_repr.c: the one repr(float) in C, shared with the
 * engine's messages).
 *
 * Host-side only (pogofmu.ssp.record loads it with pg_level.c's library); never part of an FMU. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <float.h>
#include <stdint.h>

#include "pg_repr.h"

#ifdef _WIN32
#define PGM_EXPORT __declspec(dllexport)
#else
#define PGM_EXPORT __attribute__((visibility("default")))
#endif

#define PGM_CSV_FLOAT_MAX PG_REPR_MAX
#define PGM_CSV_INT_MAX 330   /* int(-1.8e308): 309 digits and the sign */

/* str(int(x)) of an integral double (an integer column; anything else written as a float) */
static char *put_int(char *s, double x)
{
    if (!isfinite(x) || x != trunc(x))
        return pg_repr_put(s, x);
    if (x == 0) {
        *s++ = '0';
        return s;
    }
    if (x < 0) {
        *s++ = '-';
        x = -x;
    }
    if (x < 9.2e18)
        return pg_put_uint(s, (unsigned long long)x);
    return s + sprintf(s, "%.0f", x); /* exact in glibc */
}

/* The longest text of one row. */
PGM_EXPORT long pgm_csv_row_max(int n_cols, const unsigned char *is_int)
{
    long n = 2;
    int j;
    for (j = 0; j < n_cols; j++)
        n += (is_int[j] ? PGM_CSV_INT_MAX : PGM_CSV_FLOAT_MAX) + 1;
    return n;
}

/* Rows ``data[0 .. n_rows)`` (``n_cols`` doubles each) formatted into ``out`` (``cap`` bytes) a
 * piece at a time, from the cursor ``*row``, ``*col`` and ``len`` (the bytes so far) on: at most
 * ``budget`` values (a row that is begun is ended by later pieces; a row is begun only when it
 * surely fits: ``row_max``, pgm_csv_row_max). Returns the bytes so far and moves the cursor; the
 * rows are all done when ``*row == n_rows`` or ``*col == 0`` and the next row does not fit. The
 * pool's workers format a block this way between batches (pg_level.c). */
long pgm_csv_piece(const double *data, long n_rows, int n_cols, const unsigned char *is_int, char *out, long cap,
                   long row_max, long *row, int *col, long len, long budget)
{
    char *s = out + len;
    long r = *row;
    int j = *col;
    while (r < n_rows && budget > 0) {
        if (j == 0 && (long)(s - out) + row_max > cap)
            break;
        const double *v = data + (size_t)r * (size_t)n_cols;
        for (; j < n_cols && budget > 0; j++, budget--) {
            if (j)
                *s++ = ',';
            s = is_int[j] ? put_int(s, v[j]) : pg_repr_put(s, v[j]);
        }
        if (j == n_cols) {
            *s++ = '\r';
            *s++ = '\n';
            j = 0;
            r++;
        }
    }
    *row = r;
    *col = j;
    return (long)(s - out);
}

/* Rows ``data[0 .. n_rows)`` (``n_cols`` doubles each) formatted into ``out`` as csv.writer
 * writes them, as many whole rows as surely fit in ``cap`` bytes (see pgm_csv_row_max); returns
 * the bytes written and sets ``*done`` to the rows. */
PGM_EXPORT long pgm_csv_rows(const double *data, long n_rows, int n_cols, const unsigned char *is_int, char *out,
                             long cap, long *done)
{
    int col = 0;
    *done = 0;
    return pgm_csv_piece(data, n_rows, n_cols, is_int, out, cap, pgm_csv_row_max(n_cols, is_int), done, &col, 0,
                         n_rows * (long)n_cols + 1);
}
