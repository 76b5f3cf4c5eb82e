/*
 * mpp_msg.h - the envelopes of the mpmd protocol seen from C: Request,
 * Reply and StreamMsg as plain structs, with encoders (plain struct ->
 * packed bytes) and decoders (packed bytes -> plain struct), and any
 * schema message as JSON <-> bytes.
 *
 *  - mpp_request.c: the Request decoder (mpmd) and encoder (clients);
 *  - mpp_reply.c:   the Reply encoders (mpmd) and decoder (clients);
 *  - mpp_stream.c:  the StreamMsg encoders (mpmd's workers) and decoder
 *                   (clients).
 *
 * Decoders use protobuf-c's own unpack and keep the unpacked message alive
 * inside the decoded struct: strings and a snapshot's arrays point into
 * it, so a snapshot of tens of MB is copied once (by the unpack) and never
 * again.  Release a decoded struct with its _clear() function in every
 * case (also after an error); it is then all-zero again.
 *
 * Every function returns 0 or a negative MPM_E* code; decoders fill an
 * mpm_error (field paths in the schema's spelling; render them with
 * mpm_error_field(..., MPM_FIELD_JSON, ...)).  Packed buffers and strings
 * returned are malloc'd: free() them.  No generated header is needed: a
 * client keeps a case as an opaque Mpmd__Case or as packed bytes.
 */
#ifndef MPP_MSG_H
#define MPP_MSG_H

#include <stddef.h>
#include <stdint.h>

#include "mpm.h"
#include "mpp.h"
#include "mpp_case.h"

/* ---- any schema message as JSON <-> bytes ------------------------------ */

typedef enum {
    MPP_MSG_CASE = 0,    /* mpmd.Case */
    MPP_MSG_REQUEST = 1, /* mpmd.Request */
    MPP_MSG_REPLY = 2,   /* mpmd.Reply */
    MPP_MSG_STREAM = 3   /* mpmd.StreamMsg */
} mpp_msg_kind;

/* JSON text of a message of that kind -> packed bytes (malloc'd). */
int mpp_msg_json_to_bytes(mpp_msg_kind kind, const char *json, size_t len, uint8_t **buf, size_t *n,
                          mpm_error *err);

/* Packed bytes of a message of that kind -> JSON text (malloc'd); max is
 * the largest n accepted (0: MPP_MSG_MAX); flags 0 or MPP_JSON_PRETTY. */
int mpp_msg_bytes_to_json(mpp_msg_kind kind, const void *buf, size_t n, size_t max, unsigned flags,
                          char **json, mpm_error *err);

/* ---- requests (mpp_request.c) ------------------------------------------ */

typedef enum {
    MPP_REQ_SUBMIT = 1,
    MPP_REQ_CANCEL,
    MPP_REQ_STATUS,
    MPP_REQ_LIST_RUNS,
    MPP_REQ_GET_RUN,
    MPP_REQ_GET_ENERGY,
    MPP_REQ_GET_SNAPSHOT,
    MPP_REQ_PING,
    MPP_REQ_VERSION,
    MPP_REQ_RESUME /* Resume: id = run_id */
} mpp_req_kind;

/* A Request. */
typedef struct {
    mpp_req_kind kind;
    uint32_t schema_version;
    uint64_t id;        /* Cancel, Status: job_id; GetRun, GetEnergy, GetSnapshot, Resume:
                           run_id */
    int status;         /* ListRuns: mpp_status filter, 0 = all */
    uint32_t limit;     /* ListRuns, GetEnergy: 0 = server default */
    uint64_t before_id; /* ListRuns: only runs with a smaller id; 0 = from the newest */
    int with_case;      /* GetRun */
    uint64_t from_seq;  /* GetEnergy */
    int has_step;       /* GetSnapshot: 0 = the latest */
    int64_t step;
    Mpmd__Case *case_pb;    /* Submit: the case (owned by a decoded request;
                               convert with mpp_case_from_pb) */
    const void *case_bytes; /* Submit, mpp_request_encode() only: a packed Case sent */
    size_t case_len;        /* as it is when case_pb is NULL (never set by decode) */
} mpp_request;

/* Decodes a packed Request (max as in mpp_msg_bytes_to_json()).  Fails
 * with MPM_ESYNTAX (undecodable), MPM_EVERSION (schema_version not
 * MPP_SCHEMA_VERSION; rq->schema_version holds it), MPM_EREQUEST (no body,
 * or the body lacks its id or case, or holds an unknown status; the field
 * names it, e.g. cancel.job_id) or MPM_ETOOBIG.  Release with
 * mpp_request_clear() in every case. */
int mpp_request_decode(const void *buf, size_t len, size_t max, mpp_request *rq, mpm_error *err);
void mpp_request_clear(mpp_request *rq);

/* The reverse, for clients: packs a Request from the fields of rq that its
 * kind uses (schema_version 0 means MPP_SCHEMA_VERSION; GetEnergy.fromSeq,
 * the limits and ListRuns.status are sent only when non-zero, GetSnapshot
 * .step only with has_step; Submit sends rq->case_pb, which stays the
 * caller's, or when that is NULL the packed Case rq->case_bytes (case_len
 * bytes, from mpp_case_pack() or mpp_msg_json_to_bytes(MPP_MSG_CASE)),
 * copied in without being decoded: a client can keep a case as bytes and
 * submit it again and again; the daemon checks it as any other).  Returns
 * 0, MPM_EINVAL (unknown kind, Submit without a case) or MPM_ENOMEM. */
int mpp_request_encode(const mpp_request *rq, uint8_t **buf, size_t *len);

/* ---- the plain structs of replies and stream messages ------------------- */

/* Particle fields at one step (Snapshot); NULL arrays are left out.  A
 * decoder checks that every array present holds its n*width values. */
typedef struct {
    int64_t step;
    double t;
    size_t n;
    int dim;
    /* n*dim, n*dim, n*6, n, n; mean_stress: (sxx + syy + szz)/3, negative
     * in compression (Snapshot.mean_stress) */
    const double *x, *v, *stress, *mean_stress, *volume;
    /* only from runs whose particles carry them: n, n*dim*dim (F,
     * row-major), n (0/1; the int of protobuf-c's bool) */
    const double *plastic_strain, *deformation_gradient;
    const int *yielded;
    /* n: the pressure -mean_stress, positive in compression
     * (Snapshot.pressure; mpp_snapshot_pressure() makes it).  Encoders
     * send each of the two that is non-NULL; decoders give both whenever
     * either came (the other derived: a daemon before schema 1.1 sent only
     * the mean stress). */
    const double *pressure;
} mpp_snapshot;

/* The pressure of n mean stresses, p[i] = 0.0 - mean[i]: positive in
 * compression, exactly the negated value (+0 for a stress-free point, never
 * -0).  The one place of the sign convention; also the reverse (mean from
 * p).  p and mean may not overlap. */
void mpp_snapshot_pressure(const double *mean, size_t n, double *p);

/* A run record (RunInfo).  NULL strings/pointers and times <= 0 are left
 * out; other numbers are always sent. */
typedef struct {
    uint64_t run_id, job_id;
    const char *name;
    int status; /* mpp_status (0: absent, decoded only) */
    const char *error;
    double submitted_at, started_at, finished_at; /* Unix time, s */
    int64_t steps, steps_total;
    double t, wall_s;
    uint64_t particles, nodes;
    int dim;
    const mpm_energy_sample *last_energy;
    uint64_t energy_samples;
    size_t n_snapshot_steps;
    const int64_t *snapshot_steps;
    mpm_method method;     /* always sent (RunInfo.method) */
    mpm_update update;     /* always sent (RunInfo.update) */
    mpm_transfer transfer; /* always sent (RunInfo.transfer; decoded
                              absent: FLIP) */
    const char *warning;   /* RunInfo.warning: NULL (decoded: "") when none */
    const char *owner;     /* RunInfo.owner: NULL (decoded: "") when not recorded */
    int has_balance;       /* balance_error recorded (RunInfo.balance_error) */
    double balance_error;  /* the balance error at the run's end */
    int has_checkpoint;    /* RunInfo.checkpoint_step / _t sent (decoded: present) */
    int64_t checkpoint_step;
    double checkpoint_t;
    uint32_t resumes;       /* RunInfo.resumes: sent when > 0 */
    const char *plan;       /* RunInfo.plan: NULL (decoded: "") when none */
    const void *case_bytes; /* packed Case to include, or NULL; its
                               method, update and transfer are sent as
                               the three fields above say (encode only:
                               a decoded run has NULL here) */
    size_t case_len;
} mpp_run_info;

/* Progress of a running job (Progress). */
typedef struct {
    int64_t step, steps_total;
    double t, dt, wall_s;
} mpp_progress;

/* End of a job (Finished). */
typedef struct {
    int status;        /* mpp_status (0: absent, decoded only) */
    const char *error; /* NULL: none (decoded: "" when none) */
    int64_t steps;
    double t, wall_s;
    const mpm_energy_sample *energy; /* NULL: none */
    int has_balance;                 /* balance_error sent (Finished.balance_error) */
    double balance_error;            /* the balance error at the run's end */
    const char *warning;             /* Finished.warning: NULL (decoded: "") when none */
} mpp_finished;

/* ---- replies (mpp_reply.c) ---------------------------------------------- */

/* Encoders: each packs a Reply (schema_version set) into a malloc'd *buf
 * of *len bytes.  Return 0, MPM_ENOMEM, or MPM_ESYNTAX when
 * mpp_reply_run() gets case bytes that are not a Case. */

/* An Error reply with a wire code (mpp_err_code), a message and a field
 * (JSON spelling; NULL or "": none), as given. */
int mpp_reply_error(int wire_code, const char *message, const char *field, uint8_t **buf,
                    size_t *len);
/* The Error reply for an mpm_error: code mpp_error_wire_code(e->code),
 * field the path in lowerCamelCase, message "field: message" (the text a
 * user reads, as mpm_error_text(MPM_FIELD_JSON) renders it). */
int mpp_reply_error_from(const mpm_error *e, uint8_t **buf, size_t *len);
int mpp_reply_submit_ok(uint64_t job_id, uint64_t run_id, uint8_t **buf, size_t *len);
int mpp_reply_run(const mpp_run_info *ri, uint8_t **buf, size_t *len);
int mpp_reply_runs(const mpp_run_info *ri, size_t n, uint8_t **buf, size_t *len);
/* The same with the paging cursor RunList.next_before_run_id (0: absent,
 * the listing is complete). */
int mpp_reply_runs_page(const mpp_run_info *ri, size_t n, uint64_t next_before, uint8_t **buf,
                        size_t *len);
int mpp_reply_energy(uint64_t run_id, const mpm_energy_sample *s, size_t n, int more, uint8_t **buf,
                     size_t *len);
int mpp_reply_snapshot(const mpp_snapshot *s, uint8_t **buf, size_t *len);
int mpp_reply_pong(const char *server_version, const char *stream_endpoint, uint8_t **buf,
                   size_t *len);
/* names[i] / versions[i]: the n linked components */
int mpp_reply_version(const char *server_version, const char *const *names,
                      const char *const *versions, size_t n, uint8_t **buf, size_t *len);

/* The body of a Reply (values as the oneof's field numbers). */
typedef enum {
    MPP_REPLY_NONE = 0,
    MPP_REPLY_ERROR = 2,
    MPP_REPLY_SUBMIT_OK = 3,
    MPP_REPLY_RUN = 4,
    MPP_REPLY_RUNS = 5,
    MPP_REPLY_ENERGY = 6,
    MPP_REPLY_SNAPSHOT = 7,
    MPP_REPLY_PONG = 8,
    MPP_REPLY_VERSION = 9
} mpp_reply_kind;

/* The JSON name of a Reply body ("error", "submitOk", "run", ...), as the
 * Reply's JSON form keys it; "nothing" for MPP_REPLY_NONE. */
const char *mpp_reply_kind_name(mpp_reply_kind kind);

/* A decoded Reply.  Absent numbers read 0, absent strings "" (never NULL
 * for the body that came). */
typedef struct {
    mpp_reply_kind kind;
    uint32_t schema_version; /* Reply.schema_version, 0 when absent */
    /* ERROR */
    int err_code; /* mpp_err_code (INTERNAL when absent) */
    const char *err_message, *err_field;
    /* SUBMIT_OK: the new job and run; ENERGY: run_id */
    int has_job_id, has_run_id;
    uint64_t job_id, run_id;
    /* RUN: runs[0] (n_runs 1); RUNS: every run (strings, steps and the last
     * energy point into this struct) */
    size_t n_runs;
    mpp_run_info *runs;
    /* ENERGY: the samples of this page and whether more follow */
    size_t n_samples;
    mpm_energy_sample *samples;
    int more;
    /* SNAPSHOT (arrays point into the message) */
    mpp_snapshot snapshot;
    /* PONG, VERSION (server_schema: their schema_version; server_minor:
     * their schema_minor, 0 from a daemon older than schema 1.1) */
    const char *server_version, *stream_endpoint;
    uint32_t server_schema, server_minor;
    size_t n_components; /* VERSION */

    /* owned: the unpacked message and the arrays above */
    void *msg_;
    mpm_energy_sample *energies_;
} mpp_reply;

/* Decodes a packed Reply into *out (cleared first); max as in
 * mpp_msg_bytes_to_json().  Returns 0, MPM_ESYNTAX (also for a Snapshot
 * whose arrays do not hold n times their width, or dim not 1..3 with
 * arrays), MPM_ETOOBIG or MPM_ENOMEM.  A Reply without a body is not an error: its kind is
 * MPP_REPLY_NONE.  Release with mpp_reply_clear(). */
int mpp_reply_decode(const void *buf, size_t len, size_t max, mpp_reply *out, mpm_error *err);
void mpp_reply_clear(mpp_reply *r);

/* One energy sample as the JSON mapping writes an EnergySample (every
 * field present), in a malloc'd string; for a client's --json output. */
int mpp_energy_to_json(const mpm_energy_sample *s, char **json, mpm_error *err);
/* A snapshot as the JSON mapping writes a Snapshot, likewise. */
int mpp_snapshot_to_json(const mpp_snapshot *s, char **json, mpm_error *err);

/* ---- stream messages (mpp_stream.c) -------------------------------------- */

/* Encoders, same conventions as the Reply encoders. */
int mpp_stream_progress(uint64_t job_id, uint64_t seq, const mpp_progress *p, uint8_t **buf,
                        size_t *len);
int mpp_stream_energy(uint64_t job_id, uint64_t seq, const mpm_energy_sample *s, uint8_t **buf,
                      size_t *len);
int mpp_stream_snapshot(uint64_t job_id, uint64_t seq, const mpp_snapshot *s, uint8_t **buf,
                        size_t *len);
int mpp_stream_finished(uint64_t job_id, uint64_t seq, const mpp_finished *f, uint8_t **buf,
                        size_t *len);

/* mpp_stream_snapshot() into the caller's buffer: packs the StreamMsg into
 * buf when it fits in cap bytes.  *len is always set to the packed size;
 * returns 0, or MPM_ETOOBIG (nothing written) when cap is smaller.  Lets a
 * publisher reuse one buffer for every snapshot of a job. */
int mpp_stream_snapshot_into(uint64_t job_id, uint64_t seq, const mpp_snapshot *s, uint8_t *buf,
                             size_t cap, size_t *len);

/* The body of a StreamMsg (values as the oneof's field numbers). */
typedef enum {
    MPP_STREAM_NONE = 0,
    MPP_STREAM_PROGRESS = 3,
    MPP_STREAM_ENERGY = 4,
    MPP_STREAM_SNAPSHOT = 5,
    MPP_STREAM_FINISHED = 6
} mpp_stream_kind;

/* A decoded StreamMsg. */
typedef struct {
    mpp_stream_kind kind;
    int has_job_id, has_seq;
    uint64_t job_id;
    uint64_t seq;             /* StreamMsg.seq */
    mpp_progress progress;    /* PROGRESS */
    mpm_energy_sample energy; /* ENERGY; FINISHED: its final sample, if has_energy */
    mpp_snapshot snapshot;    /* SNAPSHOT (arrays point into the message) */
    mpp_finished finished;    /* FINISHED (error points into the message,
                                 "" when none; energy is NULL: see below) */
    int has_energy;           /* FINISHED: `energy` holds the final sample */

    void *msg_; /* owned: the unpacked message */
} mpp_stream;

/* Decodes a packed StreamMsg into *out (cleared first); max as in
 * mpp_msg_bytes_to_json().  Returns 0, MPM_ESYNTAX (as for a Reply's
 * Snapshot) or MPM_ETOOBIG; a
 * message without a body is not an error (kind MPP_STREAM_NONE).  Release
 * with mpp_stream_clear(). */
int mpp_stream_decode(const void *buf, size_t len, size_t max, mpp_stream *out, mpm_error *err);
void mpp_stream_clear(mpp_stream *s);

#endif
