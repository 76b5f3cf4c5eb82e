/*
 * mpp.h - the vocabulary of the mpmd protocol, shared by the daemon, the
 * store, mpmctl and the benches: the release version, the schema version,
 * the run status and the wire error codes, with the values of
 * proto/mpmd.proto (the codec checks them against the generated enums at
 * compile time).  Method and update are the solver's mpm_method and
 * mpm_update, whose values are the schema's Case.Method and Case.Update.
 *
 * Plain C, no generated code: any layer may include it.  The few functions
 * declared here are in protocol/mpp.c (link libmpp).
 */
#ifndef MPP_H
#define MPP_H

#include "mpm.h"

/* The release of mpmd (daemon and mpmctl). */
#define MPP_VERSION "0.4.0"
/* SCHEMA_VERSION of proto/mpmd.proto. */
#define MPP_SCHEMA_VERSION 1
/* SCHEMA_MINOR of proto/mpmd.proto: additions within the schema version
 * (1: Snapshot.pressure positive in compression beside .mean_stress). */
#define MPP_SCHEMA_MINOR 1

/* The particle limit of a case when the caller gives none (mpmd's
 * --max-particles default, mpmctl's local check).  One limit: the codec's
 * early refusal and the count of the case check use the same value. */
#define MPP_DEFAULT_MAX_PARTICLES ((size_t)10000000)

/* Run status; values as mpmd.RunStatus. */
typedef enum {
    MPP_STATUS_QUEUED = 1,
    MPP_STATUS_RUNNING = 2,
    MPP_STATUS_FINISHED = 3,
    MPP_STATUS_FAILED = 4,
    MPP_STATUS_CANCELLED = 5,
    MPP_STATUS_INTERRUPTED = 6
} mpp_status;
#define MPP_STATUS_MIN MPP_STATUS_QUEUED
#define MPP_STATUS_MAX MPP_STATUS_INTERRUPTED

/* 1 for the statuses a run never leaves (FINISHED and after). */
#define MPP_STATUS_ENDED(s) ((s) >= MPP_STATUS_FINISHED && (s) <= MPP_STATUS_MAX)

/* Wire error codes of a Reply.error; values as mpmd.Error.Code. */
typedef enum {
    MPP_ERR_INTERNAL = 1,
    MPP_ERR_BAD_REQUEST = 2,
    MPP_ERR_BAD_SCHEMA = 3,
    MPP_ERR_INVALID_CASE = 4,
    MPP_ERR_NOT_FOUND = 5,
    MPP_ERR_QUEUE_FULL = 6,
    MPP_ERR_TOO_LARGE = 7,
    MPP_ERR_CONFLICT = 8,
    MPP_ERR_UNAVAILABLE = 9,
    MPP_ERR_FORBIDDEN = 10
} mpp_err_code;

/* "QUEUED", ... as in the schema; NULL for a value that is not a status. */
const char *mpp_status_name(int status);
/* The status named (schema spelling), or 0 if none. */
int mpp_status_from_name(const char *name);

/* "INVALID_CASE", ... as in the schema; NULL for an unknown value. */
const char *mpp_err_code_name(int code);

/* The wire Error.Code for an MPM_E* code (the one mapping): EINVAL and
 * ECFL -> INVALID_CASE, EREQUEST and ESYNTAX -> BAD_REQUEST, EVERSION ->
 * BAD_SCHEMA, ENOTFOUND -> NOT_FOUND, EFULL -> QUEUE_FULL, ETOOBIG ->
 * TOO_LARGE, ECONFLICT -> CONFLICT, EUNAVAIL -> UNAVAILABLE, anything
 * else -> INTERNAL. */
mpp_err_code mpp_error_wire_code(int mpm_code);

/* The protobuf-c runtime version, e.g. "1.4.1". */
const char *mpp_protobuf_c_version(void);

#endif
