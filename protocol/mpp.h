/*
 * mpp.h - the vocabulary of the mpmd protocol, shared by the daemon, the
 * store, mpmctl and the benches: the release version, the schema version,
 * the run status and the wire error codes, with the values of
 * proto/mpmd.proto (the codec checks them against the generated enums at
 * compile time).  Method and update are the solver's mpm_method and
 * mpm_update, whose values are the schema's Case.Method and Case.Update.
 *
 * Plain C, no generated code: any layer may include it.
 */
#ifndef MPP_H
#define MPP_H

#include "mpm.h"

/* The release of mpmd (daemon and mpmctl). */
#define MPP_VERSION "0.3.0"
/* SCHEMA_VERSION of proto/mpmd.proto. */
#define MPP_SCHEMA_VERSION 1

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
    MPP_ERR_UNAVAILABLE = 9
} mpp_err_code;

#endif
