/*
 * srv_codec.h - the mpmd wire schema (proto/mpmd.proto) seen from C.
 *
 * srv_codec.c is the only file that includes the generated mpmd.pb-c.h; the
 * rest of the daemon uses this header:
 *  - cases: JSON text or protobuf bytes -> Mpmd__Case (opaque here) ->
 *    srv_case, a checked, self-contained mpm_case ready for mpm_sim_new(),
 *    with the run control and output requests beside it;
 *  - any schema message as JSON <-> bytes (for mpmctl and exports);
 *  - the control envelopes: a Request decoded into a plain struct, and
 *    Reply / StreamMsg encoders that take plain structs and return packed
 *    bytes;
 *  - for clients (mpmctl, the benches): the Request encoder, and Reply /
 *    StreamMsg decoders into plain structs (srv_reply_peek,
 *    srv_stream_peek, srv_reply_energy_decode) that read a snapshot's
 *    header without copying its arrays.  A client keeps a case as JSON or
 *    as packed bytes (srv_request.case_bytes) and needs no generated
 *    header.
 * Every function returns 0 or a negative SRV_CODEC_* code and, where it has
 * an err buffer, writes a message there; case errors start with the JSON
 * path of the field (lowerCamelCase, also for the solver's own checks), e.g.
 * "bodies[0].sphere.radius: must be > 0".  Packed buffers and strings returned are malloc'd: free() them.
 */
#ifndef SRV_CODEC_H
#define SRV_CODEC_H

#include <stddef.h>
#include <stdint.h>

#include "mpm.h"

/* The generated case message; opaque outside srv_codec.c. */
typedef struct Mpmd__Case Mpmd__Case;

/* Return codes (negative). */
enum {
    SRV_CODEC_OK = 0,
    SRV_CODEC_ESYNTAX = -1,  /* not JSON / not a protobuf message of the type */
    SRV_CODEC_EINVAL = -2,   /* a field is missing or invalid (text names it) */
    SRV_CODEC_ENOMEM = -3,   /* allocation failed */
    SRV_CODEC_ETOOBIG = -4,  /* above a size limit below */
    SRV_CODEC_ECFL = -5,     /* the case's dt is above the CFL limit */
    SRV_CODEC_EVERSION = -6  /* a request of another schema version */
};

/* SCHEMA_VERSION of proto/mpmd.proto (checked against it at compile time). */
#define SRV_SCHEMA_VERSION 1

/* Limits applied while converting a case (a case above them is rejected
 * with SRV_CODEC_ETOOBIG before anything big is allocated). */
#define SRV_CASE_MAX_PARTICLES 10000000u  /* explicit + estimated generated */
#define SRV_CASE_MAX_NODES 20000000u      /* grid nodes */
#define SRV_CASE_MAX_ITEMS 100000u        /* materials, bodies, tractions each */
#define SRV_CASE_MAX_NODE_FIXES 10000000u /* boundary.nodes */
#define SRV_CASE_MAX_STEPS 1000000000000LL
/* Default largest message accepted by the unpack functions (max = 0). */
#define SRV_MSG_MAX ((size_t)512 << 20)

/* Snapshot field bits (srv_case.snapshot_fields). */
enum {
    SRV_SNAP_X = 1,
    SRV_SNAP_V = 2,
    SRV_SNAP_STRESS = 4,
    SRV_SNAP_PRESSURE = 8,
    SRV_SNAP_VOLUME = 16,
    SRV_SNAP_ALL = 31
};

/* A converted case.  `c` points only into this struct's own arrays, so it
 * stays valid until srv_case_destroy() whatever happens to the message it
 * came from. */
typedef struct srv_case {
    mpm_case c;                 /* the solver case (passed mpm_case_check) */
    mpm_case_info info;         /* what mpm_case_check found (particles, ...) */
    char *name;                 /* Case.name, "" when absent */
    int has_end_time;           /* 1: run until end_time; 0: run `steps` steps */
    double end_time;
    long long steps;
    unsigned energy_every;      /* Output.energy_every (0: only the final sample) */
    unsigned snapshot_every;    /* Output.snapshot_every (0: none) */
    unsigned snapshot_fields;   /* SRV_SNAP_* bits; SRV_SNAP_ALL when none listed */
    int record_snapshots;       /* Output.record_snapshots */
    size_t explicit_points;     /* particles given as explicit points */
    size_t est_particles;       /* explicit + estimated generated particles */

    /* Storage behind c (owned). */
    mpm_material_desc *materials;
    mpm_body_desc *bodies;
    double **point_blocks;      /* per body: its explicit arrays, or NULL */
    mpm_traction_desc *tractions;
    int *node_ijk;
    unsigned *node_mask;
} srv_case;

/* ---- cases ---------------------------------------------------------- */

/* JSON text -> case message (schema checks only: names, types, enums).
 * *out is NULL on error; free it with srv_case_pb_free(). */
int srv_case_from_json(const char *json, size_t len, Mpmd__Case **out,
                       char *err, size_t errlen);

/* Packed bytes -> case message; max is the largest len accepted (0:
 * SRV_MSG_MAX).  Garbage or truncated bytes give SRV_CODEC_ESYNTAX. */
int srv_case_unpack(const void *buf, size_t len, size_t max, Mpmd__Case **out,
                    char *err, size_t errlen);

/* Case message -> packed bytes in a malloc'd *buf of *len bytes (*buf is
 * never NULL on success, even for 0 bytes).  Returns 0 or
 * SRV_CODEC_ENOMEM. */
int srv_case_pack(const Mpmd__Case *pb, uint8_t **buf, size_t *len);

/* Case message -> JSON text (flags: 0 or SRV_JSON_PRETTY from srv_json.h)
 * in a malloc'd string. */
int srv_case_to_json(const Mpmd__Case *pb, unsigned flags, char **json,
                     char *err, size_t errlen);

/* Frees a case message and nulls the pointer (NULL is fine). */
void srv_case_pb_free(Mpmd__Case **pb);

/* Marks Case.method and Case.update present (with their current values,
 * the schema's defaults when they were absent), so the packed case says
 * which method and update it means to any peer, whatever its defaults. */
void srv_case_pin_defaults(Mpmd__Case *pb);

/* Case message -> srv_case: validates what the schema cannot express
 * (dimensions, array lengths, indices, enum values, ranges, limits), then
 * runs mpm_case_check().  Returns 0, SRV_CODEC_EINVAL, SRV_CODEC_ETOOBIG,
 * SRV_CODEC_ECFL or SRV_CODEC_ENOMEM; *out is NULL on error. */
int srv_case_from_pb(const Mpmd__Case *pb, srv_case **out, char *err,
                     size_t errlen);

/* JSON text -> srv_case in one call (srv_case_from_json + _from_pb). */
int srv_case_load(const char *json, size_t len, srv_case **out, char *err,
                  size_t errlen);

/* Frees a srv_case and nulls the pointer (NULL is fine). */
void srv_case_destroy(srv_case **sc);

/* The protobuf-c runtime version, e.g. "1.4.1". */
const char *srv_codec_protobuf_c_version(void);

/* ---- any schema message as JSON <-> bytes --------------------------- */

typedef enum {
    SRV_MSG_CASE = 0,     /* mpmd.Case */
    SRV_MSG_REQUEST = 1,  /* mpmd.Request */
    SRV_MSG_REPLY = 2,    /* mpmd.Reply */
    SRV_MSG_STREAM = 3    /* mpmd.StreamMsg */
} srv_msg_kind;

/* JSON text of a message of that kind -> packed bytes (malloc'd). */
int srv_msg_json_to_bytes(srv_msg_kind kind, const char *json, size_t len,
                          uint8_t **buf, size_t *n, char *err, size_t errlen);

/* Packed bytes of a message of that kind -> JSON text (malloc'd); max as in
 * srv_case_unpack(); flags as in srv_case_to_json(). */
int srv_msg_bytes_to_json(srv_msg_kind kind, const void *buf, size_t n,
                          size_t max, unsigned flags, char **json, char *err,
                          size_t errlen);

/* ---- envelopes ------------------------------------------------------ */

/* Run status; values as mpmd.RunStatus. */
typedef enum {
    SRV_STATUS_QUEUED = 1,
    SRV_STATUS_RUNNING = 2,
    SRV_STATUS_FINISHED = 3,
    SRV_STATUS_FAILED = 4,
    SRV_STATUS_CANCELLED = 5,
    SRV_STATUS_INTERRUPTED = 6
} srv_status;

/* "QUEUED", ... as in the schema; NULL for an unknown value. */
const char *srv_status_name(int status);
/* The status named (schema spelling), or 0 if none. */
int srv_status_from_name(const char *name);

/* Error codes of a Reply.error; values as mpmd.Error.Code. */
typedef enum {
    SRV_ERR_INTERNAL = 1,
    SRV_ERR_BAD_REQUEST = 2,
    SRV_ERR_BAD_SCHEMA = 3,
    SRV_ERR_INVALID_CASE = 4,
    SRV_ERR_NOT_FOUND = 5,
    SRV_ERR_QUEUE_FULL = 6,
    SRV_ERR_TOO_LARGE = 7,
    SRV_ERR_CONFLICT = 8,
    SRV_ERR_UNAVAILABLE = 9
} srv_err_code;

typedef enum {
    SRV_REQ_SUBMIT = 1,
    SRV_REQ_CANCEL,
    SRV_REQ_STATUS,
    SRV_REQ_LIST_RUNS,
    SRV_REQ_GET_RUN,
    SRV_REQ_GET_ENERGY,
    SRV_REQ_GET_SNAPSHOT,
    SRV_REQ_PING,
    SRV_REQ_VERSION
} srv_req_kind;

/* A decoded Request. */
typedef struct {
    srv_req_kind kind;
    uint32_t schema_version;
    uint64_t id;          /* Cancel, Status: job_id; GetRun, GetEnergy, GetSnapshot: run_id */
    int status;           /* ListRuns: srv_status filter, 0 = all */
    uint32_t limit;       /* ListRuns, GetEnergy: 0 = server default */
    int with_case;        /* GetRun */
    uint64_t from_seq;    /* GetEnergy */
    int has_step;         /* GetSnapshot: 0 = the latest */
    int64_t step;
    Mpmd__Case *case_pb;  /* Submit: the case (owned; convert with srv_case_from_pb) */
    const void *case_bytes; /* Submit, srv_request_encode() only: a packed Case sent */
    size_t case_len;        /* as it is when case_pb is NULL (never set by decode) */
} srv_request;

/* Decodes a packed Request (max as in srv_case_unpack()).  Fails with
 * SRV_CODEC_ESYNTAX (undecodable), SRV_CODEC_EVERSION (schema_version not
 * SRV_SCHEMA_VERSION; rq->schema_version holds it), SRV_CODEC_EINVAL (no
 * body, or the body lacks its id or case) or SRV_CODEC_ETOOBIG.  Release
 * with srv_request_clear() in every case. */
int srv_request_decode(const void *buf, size_t len, size_t max,
                       srv_request *rq, char *err, size_t errlen);
void srv_request_clear(srv_request *rq);

/* The reverse, for clients: packs a Request from the fields of rq that its
 * kind uses (schema_version 0 means SRV_SCHEMA_VERSION; GetEnergy.fromSeq,
 * the limits and ListRuns.status are sent only when non-zero, GetSnapshot
 * .step only with has_step; Submit sends rq->case_pb, which stays the
 * caller's, or when that is NULL the packed Case rq->case_bytes (case_len
 * bytes, from srv_case_pack() or srv_msg_json_to_bytes(SRV_MSG_CASE)),
 * copied in without being decoded: a client can keep a case as bytes and
 * submit it again and again; the daemon checks it as any other).  Returns
 * 0, SRV_CODEC_EINVAL (unknown kind, Submit without a case) or
 * SRV_CODEC_ENOMEM. */
int srv_request_encode(const srv_request *rq, uint8_t **buf, size_t *len);

/* Energies at one step (EnergySample). */
typedef struct {
    int64_t step;
    double t;
    int dim;              /* momentum has dim entries */
    mpm_energy e;
    uint64_t seq;         /* index of the sample in its run: 0, 1, 2, ... (always sent) */
} srv_energy_sample;

/* Particle fields at one step (Snapshot); NULL arrays are left out. */
typedef struct {
    int64_t step;
    double t;
    size_t n;
    int dim;
    const double *x, *v, *stress, *pressure, *volume; /* n*dim, n*dim, n*6, n, n */
} srv_snapshot;

/* A run record (RunInfo).  NULL strings/pointers and times <= 0 are left
 * out; other numbers are always sent. */
typedef struct {
    uint64_t run_id, job_id;
    const char *name;
    int status;                   /* srv_status */
    const char *error;
    double submitted_at, started_at, finished_at;  /* Unix time, s */
    int64_t steps, steps_total;
    double t, wall_s;
    uint64_t particles, nodes;
    int dim;
    const srv_energy_sample *last_energy;
    uint64_t energy_samples;
    size_t n_snapshot_steps;
    const int64_t *snapshot_steps;
    mpm_method method;            /* always sent (RunInfo.method) */
    mpm_update update;            /* always sent (RunInfo.update) */
    const void *case_bytes;       /* packed Case to include, or NULL; its
                                     method and update are sent as the two
                                     fields above say */
    size_t case_len;
} srv_run_info;

/* Progress of a running job (Progress). */
typedef struct {
    int64_t step, steps_total;
    double t, dt, wall_s;
} srv_progress;

/* End of a job (Finished). */
typedef struct {
    int status;                   /* srv_status */
    const char *error;            /* NULL: none */
    int64_t steps;
    double t, wall_s;
    const srv_energy_sample *energy;  /* NULL: none */
} srv_finished;

/* Reply encoders: each packs a Reply (schema_version set) into a malloc'd
 * *buf of *len bytes.  Return 0, SRV_CODEC_ENOMEM, or SRV_CODEC_ESYNTAX
 * when srv_reply_run() gets case bytes that are not a Case. */
int srv_reply_error(int code, const char *message, const char *field,
                    uint8_t **buf, size_t *len);
int srv_reply_submit_ok(uint64_t job_id, uint64_t run_id, uint8_t **buf,
                        size_t *len);
int srv_reply_run(const srv_run_info *ri, uint8_t **buf, size_t *len);
int srv_reply_runs(const srv_run_info *ri, size_t n, uint8_t **buf,
                   size_t *len);
int srv_reply_energy(uint64_t run_id, const srv_energy_sample *s, size_t n,
                     int more, uint8_t **buf, size_t *len);
int srv_reply_snapshot(const srv_snapshot *s, uint8_t **buf, size_t *len);
int srv_reply_pong(const char *server_version, const char *stream_endpoint, uint8_t **buf,
                   size_t *len);
/* names[i] / versions[i]: the n linked components */
int srv_reply_version(const char *server_version, const char *const *names,
                      const char *const *versions, size_t n, uint8_t **buf,
                      size_t *len);

/* StreamMsg encoders, same conventions. */
int srv_stream_progress(uint64_t job_id, uint64_t seq, const srv_progress *p,
                        uint8_t **buf, size_t *len);
int srv_stream_energy(uint64_t job_id, uint64_t seq,
                      const srv_energy_sample *s, uint8_t **buf, size_t *len);
int srv_stream_snapshot(uint64_t job_id, uint64_t seq, const srv_snapshot *s,
                        uint8_t **buf, size_t *len);
int srv_stream_finished(uint64_t job_id, uint64_t seq, const srv_finished *f,
                        uint8_t **buf, size_t *len);

/* ---- decoding replies and stream messages (clients) ------------------ */

/* What the daemon answers or streams, decoded into plain structs, so that
 * a client needs neither the generated header nor the JSON bridge.  The
 * *_peek() functions never copy or allocate for the particle arrays of a
 * Snapshot (one of tens of MB): they only count its values, walking the
 * protobuf wire format; every other body is decoded in full.  Strings are
 * copied into the struct's own buffers (cut to fit, always NUL-terminated),
 * so a struct owns nothing and needs no release.  Absent fields read 0 (or
 * ""); the has_* members say which of the ids were present.  Undecodable
 * bytes (garbage, truncation, a wrong wire type for a known field) give
 * SRV_CODEC_ESYNTAX with a message in err; a message without a body is not
 * an error: its kind is the *_NONE value. */

/* A snapshot's header: the values (doubles) each array holds, not the
 * values themselves. */
typedef struct {
    int64_t step;
    double t;
    uint64_t n;           /* particles */
    uint32_t dim;
    size_t n_x, n_v, n_stress, n_pressure, n_volume;
} srv_snapshot_info;

/* The body of a StreamMsg (values as the oneof's field numbers). */
typedef enum {
    SRV_STREAM_NONE = 0,
    SRV_STREAM_PROGRESS = 3,
    SRV_STREAM_ENERGY = 4,
    SRV_STREAM_SNAPSHOT = 5,
    SRV_STREAM_FINISHED = 6
} srv_stream_kind;

typedef struct {
    srv_stream_kind kind;
    int has_job_id, has_seq;
    uint64_t job_id;
    uint64_t seq;                 /* StreamMsg.seq */
    srv_progress progress;        /* PROGRESS */
    srv_energy_sample energy;     /* ENERGY; FINISHED: its final sample, if has_energy */
    srv_snapshot_info snapshot;   /* SNAPSHOT */
    /* FINISHED */
    int status;                   /* srv_status; 0 when absent */
    int64_t steps;
    double t, wall_s;
    int has_energy;
    char error[512];              /* Finished.error, "" when none */
} srv_stream_info;

/* Decodes a packed StreamMsg into *out (cleared first).  Returns 0 or
 * SRV_CODEC_ESYNTAX. */
int srv_stream_peek(const void *buf, size_t len, srv_stream_info *out, char *err,
                    size_t errlen);

/* The body of a Reply (values as the oneof's field numbers). */
typedef enum {
    SRV_REPLY_NONE = 0,
    SRV_REPLY_ERROR = 2,
    SRV_REPLY_SUBMIT_OK = 3,
    SRV_REPLY_RUN = 4,
    SRV_REPLY_RUNS = 5,
    SRV_REPLY_ENERGY = 6,
    SRV_REPLY_SNAPSHOT = 7,
    SRV_REPLY_PONG = 8,
    SRV_REPLY_VERSION = 9
} srv_reply_kind;

typedef struct {
    srv_reply_kind kind;
    uint32_t schema_version;      /* Reply.schema_version, 0 when absent */
    /* ERROR */
    int err_code;                 /* srv_err_code (INTERNAL when absent) */
    char err_message[512], err_field[256];
    /* SUBMIT_OK: the new job and run; RUN: the run's; ENERGY: run_id */
    int has_job_id, has_run_id;
    uint64_t job_id, run_id;
    /* RUN */
    char name[256], run_error[512];
    int status;                   /* srv_status; 0 when absent */
    int64_t steps, steps_total;
    double t, wall_s;
    uint64_t particles, nodes, energy_samples;
    int dim;
    /* RUNS: how many; ENERGY: samples in this page and whether more follow */
    size_t n_runs, n_samples;
    int more;
    /* SNAPSHOT */
    srv_snapshot_info snapshot;
    /* PONG, VERSION (server_schema: their schema_version) */
    char server_version[128], stream_endpoint[256];
    uint32_t server_schema;
    size_t n_components;          /* VERSION */
} srv_reply_info;

/* Decodes a packed Reply into *out (cleared first).  Returns 0,
 * SRV_CODEC_ESYNTAX, or SRV_CODEC_ETOOBIG for a body other than a Snapshot
 * in a message above SRV_MSG_MAX. */
int srv_reply_peek(const void *buf, size_t len, srv_reply_info *out, char *err,
                   size_t errlen);

/* The samples of an EnergySeries reply (GetEnergy) as a malloc'd array of
 * *n entries (*samples NULL when there are none; free() it), with the
 * series' run_id and `more`.  max as in srv_case_unpack().  A reply that is
 * not an EnergySeries gives SRV_CODEC_EINVAL (srv_reply_peek() tells what
 * it is); otherwise 0, SRV_CODEC_ESYNTAX, SRV_CODEC_ETOOBIG or
 * SRV_CODEC_ENOMEM. */
int srv_reply_energy_decode(const void *buf, size_t len, size_t max, uint64_t *run_id,
                            srv_energy_sample **samples, size_t *n, int *more, char *err,
                            size_t errlen);

/* srv_stream_snapshot() into the caller's buffer: packs the StreamMsg into
 * buf when it fits in cap bytes.  *len is always set to the packed size;
 * returns 0, or SRV_CODEC_ETOOBIG (nothing written) when cap is smaller.
 * Lets a publisher reuse one buffer for every snapshot of a job. */
int srv_stream_snapshot_into(uint64_t job_id, uint64_t seq, const srv_snapshot *s,
                             uint8_t *buf, size_t cap, size_t *len);

#endif
