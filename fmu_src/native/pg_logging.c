/* See pg_logging.h. */
#include "pg_logging.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int pg_log_wanted(const PgLogFilter *f, int status, const char *category)
{
    if (status >= PG_ST_WARNING) return 1;
    if (!f->on) return 0;
    if (!f->categories) return 1;
    for (size_t i = 0; i < f->n; ++i)
        if (strcmp(f->categories[i], category) == 0) return 1;
    return 0;
}

void pg_log_free(PgLogFilter *f)
{
    for (size_t i = 0; i < f->n; ++i) free(f->categories[i]);
    free(f->categories);
    f->categories = NULL;
    f->n = 0;
}

int pg_log_set(PgLogFilter *f, const char *const *known, size_t n_known, int on, size_t n,
               const char *const categories[], const char *function, char *text, size_t size)
{
    for (size_t i = 0; i < n && n_known; ++i) {
        int found = 0;
        for (size_t k = 0; k < n_known && !found; ++k) found = categories[i] && strcmp(categories[i], known[k]) == 0;
        if (!found) {
            size_t used = (size_t)snprintf(text, size, "%s refused: %s%s%s is not a log category of this FMU (the "
                                           "categories are", function, categories[i] ? "'" : "",
                                           categories[i] ? categories[i] : "NULL", categories[i] ? "'" : "");
            for (size_t k = 0; k < n_known && used < size; ++k)
                used += (size_t)snprintf(text + used, size - used, "%s%s", k ? ", " : " ", known[k]);
            if (used < size) snprintf(text + used, size - used, ")");
            return 1;
        }
    }
    pg_log_free(f);
    f->on = on;
    if (n > 0) {
        f->categories = calloc(n, sizeof(char *));
        if (!f->categories) return -1;
        for (size_t i = 0; i < n; ++i) {
            const char *name = categories[i] ? categories[i] : "";
            f->categories[i] = malloc(strlen(name) + 1);
            if (f->categories[i]) strcpy(f->categories[i], name);
            f->n = i + 1;
        }
    }
    return 0;
}
