/* pogofmu native FMUs: FMU state handles, shared by the FMI 2.0 and FMI 3.0 entry files — a copy
 * of the instance's PgState with a magic number, its owner (this FMU: this copy of this build)
 * and the call state it was taken in. */
#ifndef PG_HANDLES_H
#define PG_HANDLES_H

#include "pg_instance.h"

#define PG_HANDLE_MAGIC 0x706f6e61u /* 'pona': a state handle of a pogofmu FMU (either backend) */

typedef struct PgHandle {
    unsigned magic;
    /* this FMU's build (its PgFmu's build string, by address: one per loaded copy of a build, for
     * the process's life; a Python-hosted FMU's PgFmu is its instance's, the string its build's) */
    const char *owner;
    char owner_model[128], owner_build[128]; /* who it is, for the message of a refusal */
    int owner_fmi;
    unsigned mode; /* the instance's call state when the state was taken (0: none) */
    PgState state;
} PgHandle;

/* Get: into *slot (a new handle, or the one there overwritten); the status */
int pg_handle_get(PgInstance *in, unsigned mode, void **slot);
/* the handle behind a state pointer, or NULL with an Error logged ("<what> refused: ...") */
PgHandle *pg_handle_check(PgInstance *in, void *state, const char *what);
/* Set: the state restored; *mode the call state it was taken in (0: none) */
int pg_handle_set(PgInstance *in, void *state, unsigned *mode);
/* the call state a state was taken in (serialized with it) */
int pg_handle_mode(PgInstance *in, void *state, unsigned *mode);
int pg_handle_free(PgInstance *in, void **slot);
int pg_handle_size(PgInstance *in, void *state, size_t *size);
int pg_handle_serialize(PgInstance *in, void *state, unsigned char *bytes, size_t size);
/* Deserialize into *slot, with the call state it was serialized with */
int pg_handle_deserialize(PgInstance *in, const unsigned char *bytes, size_t size, void **slot);

#endif
