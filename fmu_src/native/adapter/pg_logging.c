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

int pg_log_set(PgLogFilter *f, const PgFmu *fmu, int on, size_t n, const char *const categories[],
               const char *function, char *text, size_t size)
{
    for (size_t i = 0; i < n; ++i) {
        int known = 0;
        for (int k = 0; k < fmu->n_log_categories && !known; ++k)
            known = categories[i] && strcmp(categories[i], fmu->log_categories[k]) == 0;
        if (!known) {
            size_t used = (size_t)snprintf(text, size, "%s refused: %s%s%s is not a log category of this FMU (the "
                                           "categories are", function, categories[i] ? "'" : "",
                                           categories[i] ? categories[i] : "NULL", categories[i] ? "'" : "");
            for (int k = 0; k < fmu->n_log_categories && used < size; ++k)
                used += (size_t)snprintf(text + used, size - used, "%s%s", k ? ", " : " ", fmu->log_categories[k]);
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
            f->categories[i] = malloc(strlen(categories[i]) + 1);
            if (f->categories[i]) strcpy(f->categories[i], categories[i]);
            f->n = i + 1;
        }
    }
    return 0;
}
