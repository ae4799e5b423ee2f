/* SHA-256 (FIPS 180-4), for the seal of serialized FMU states. */
#ifndef PG_SHA256_H
#define PG_SHA256_H

#include <stddef.h>

/* the digest of data[0..n) as 64 lowercase hex digits and a NUL into hex[65] */
void pg_sha256_hex(const unsigned char *data, size_t n, char hex[65]);

#endif
