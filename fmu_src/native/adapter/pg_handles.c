/* See pg_handles.h. */
#include "pg_handles.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pg_support.h"

static void own(PgHandle *h, const PgInstance *in)
{
    h->owner = in->fmu->build;
    snprintf(h->owner_model, sizeof h->owner_model, "%s", in->fmu->model->name);
    snprintf(h->owner_build, sizeof h->owner_build, "%s", in->fmu->build);
    h->owner_fmi = in->fmu->fmi;
}

int pg_handle_get(PgInstance *in, unsigned mode, void **slot)
{
    PgHandle *h = *slot;
    if (h && h->magic != PG_HANDLE_MAGIC)
        return pg_inst_refuse_text(in, "get FMU state refused: the state to overwrite is not one of this FMU");
    if (!h) h = malloc(sizeof *h);
    if (!h) return PG_ST_ERROR;
    h->magic = PG_HANDLE_MAGIC;
    own(h, in);
    h->mode = mode;
    h->state = in->st;
    *slot = h;
    return PG_ST_OK;
}

PgHandle *pg_handle_check(PgInstance *in, void *state, const char *what)
{
    PgHandle *h = state;
    if (!h || h->magic != PG_HANDLE_MAGIC) {
        PgMsg m;
        pg_msg_clear(&m);
        pg_msg_printf(&m, "%s refused: %s", what,
                      !h ? "no FMU state given (NULL)"
                         : "not an FMU state of a pogofmu FMU (or one already freed)");
        pg_inst_refuse(in, &m);
        return NULL;
    }
    if (h->owner != in->fmu->build) { /* both named, as a serialized state's refusal names them */
        PgMsg m;
        pg_msg_clear(&m);
        pg_msg_printf(&m, "%s refused: the state belongs to ", what);
        pg_inst_owner_text(h->owner_model, h->owner_build, h->owner_fmi, &m);
        pg_msg_str(&m, "; this instance is ");
        pg_inst_owner_text(in->fmu->model->name, in->fmu->build, in->fmu->fmi, &m);
        if (strcmp(h->owner_build, in->fmu->build) == 0)
            pg_msg_str(&m, " (another loaded copy of it: restore the state into an instance of the copy that saved it)");
        pg_inst_refuse(in, &m);
        return NULL;
    }
    return h;
}

int pg_handle_set(PgInstance *in, void *state, unsigned *mode)
{
    PgHandle *h = pg_handle_check(in, state, "set FMU state");
    if (!h) return PG_ST_ERROR;
    pg_inst_restore(in, &h->state);
    *mode = h->mode;
    return PG_ST_OK;
}

int pg_handle_free(PgInstance *in, void **slot)
{
    PgHandle *h = slot ? *slot : NULL;
    if (!h) return PG_ST_OK;
    if (h->magic != PG_HANDLE_MAGIC)
        return pg_inst_refuse_text(in, "free FMU state refused: not an FMU state of a pogofmu FMU");
    h->magic = 0;
    free(h);
    *slot = NULL;
    return PG_ST_OK;
}

int pg_handle_mode(PgInstance *in, void *state, unsigned *mode)
{
    PgHandle *h = pg_handle_check(in, state, "set FMU state");
    if (!h) return PG_ST_ERROR;
    *mode = h->mode;
    return PG_ST_OK;
}

int pg_handle_size(PgInstance *in, void *state, size_t *size)
{
    PgHandle *h = pg_handle_check(in, state, "serialized FMU state size");
    if (!h) return PG_ST_ERROR;
    *size = pg_inst_serialized_size(in, h->mode);
    return PG_ST_OK;
}

int pg_handle_serialize(PgInstance *in, void *state, unsigned char *bytes, size_t size)
{
    PgHandle *h = pg_handle_check(in, state, "serialize FMU state");
    if (!h) return PG_ST_ERROR;
    return pg_inst_serialize(in, &h->state, h->mode, bytes, size);
}

int pg_handle_deserialize(PgInstance *in, const unsigned char *bytes, size_t size, void **slot)
{
    PgHandle *h = malloc(sizeof *h);
    if (!h) return PG_ST_ERROR;
    unsigned mode = 0;
    int st = pg_inst_deserialize(in, bytes, size, &h->state, &mode);
    if (st) {
        free(h);
        return st;
    }
    h->magic = PG_HANDLE_MAGIC;
    own(h, in);
    h->mode = mode; /* the call state it was taken in, as serialized */
    if (*slot && ((PgHandle *)*slot)->magic == PG_HANDLE_MAGIC) {
        *(PgHandle *)*slot = *h;
        free(h);
    } else {
        *slot = h;
    }
    return PG_ST_OK;
}
