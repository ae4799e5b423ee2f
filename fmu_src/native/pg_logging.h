/* pogofmu: which log messages an instance passes on (fmi2/fmi3SetDebugLogging), shared by the
 * FMI 2.0 and FMI 3.0 entry files of both backends. Warnings and errors always go out; OK messages
 * only with logging on and, when categories were given, only theirs. */
#ifndef PG_LOGGING_H
#define PG_LOGGING_H

#include <stddef.h>

#include "pg_backend.h"

typedef struct PgLogFilter {
    int on;
    char **categories; /* the enabled categories (NULL: all) */
    size_t n;
} PgLogFilter;

int pg_log_wanted(const PgLogFilter *f, int status, const char *category);
/* SetDebugLogging: every category must be one of the FMU's `known` ones (any, if it names none).
 * 0: set; 1: refused, the message (naming `function` and the FMU's categories) in `text`; -1: out
 * of memory */
int pg_log_set(PgLogFilter *f, const char *const *known, size_t n_known, int on, size_t n,
               const char *const categories[], const char *function, char *text, size_t size);
void pg_log_free(PgLogFilter *f);

#endif
