/*
 * mpp_request.c - the Request envelope: decoded into an mpp_request by
 * mpmd, encoded from one by the clients (see mpp_msg.h).  A Submit can
 * carry a case packed beforehand, copied into the request as it is.
 */
#include "mpp_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Request body: the id field of a body, which must be present. */
#define NEED_ID(body, field, path)                             \
    do {                                                       \
        if (!r->body->has_##field) {                           \
            rc = mpm_fail(err, MPM_EREQUEST, path, "missing"); \
            goto out;                                          \
        }                                                      \
        rq->id = r->body->field;                               \
    } while (0)

int mpp_request_decode(const void *buf, size_t len, size_t max, mpp_request *rq, mpm_error *err)
{
    ProtobufCMessage *m;
    Mpmd__Request *r;
    int rc;
    memset(rq, 0, sizeof *rq);
    rc = mpp_unpack(&mpmd__request__descriptor, buf, len, max, &m, err);
    if (rc) return rc;
    r = (Mpmd__Request *)m;
    rq->schema_version = r->has_schema_version ? r->schema_version : 0;
    if (rq->schema_version != MPP_SCHEMA_VERSION) {
        rc = mpm_fail(err, MPM_EVERSION, "schema_version", "%s%u; this server speaks %d",
                      r->has_schema_version ? "" : "missing, taken as ", rq->schema_version,
                      MPP_SCHEMA_VERSION);
        goto out;
    }
    switch (r->body_case) {
    case MPMD__REQUEST__BODY_SUBMIT:
        rq->kind = MPP_REQ_SUBMIT;
        if (!r->submit->case_) {
            rc = mpm_fail(err, MPM_EREQUEST, "submit.case", "missing");
            goto out;
        }
        rq->case_pb = r->submit->case_;
        r->submit->case_ = NULL;
        break;
    case MPMD__REQUEST__BODY_CANCEL:
        rq->kind = MPP_REQ_CANCEL;
        NEED_ID(cancel, job_id, "cancel.job_id");
        break;
    case MPMD__REQUEST__BODY_STATUS:
        rq->kind = MPP_REQ_STATUS;
        NEED_ID(status, job_id, "status.job_id");
        break;
    case MPMD__REQUEST__BODY_LIST_RUNS:
        rq->kind = MPP_REQ_LIST_RUNS;
        if (r->list_runs->has_status) {
            if (!mpp_status_name(r->list_runs->status)) {
                rc = mpm_fail(err, MPM_EREQUEST, "list_runs.status", "unknown value %d",
                              (int)r->list_runs->status);
                goto out;
            }
            rq->status = r->list_runs->status;
        }
        rq->limit = r->list_runs->has_limit ? r->list_runs->limit : 0;
        rq->before_id = r->list_runs->has_before_run_id ? r->list_runs->before_run_id : 0;
        break;
    case MPMD__REQUEST__BODY_GET_RUN:
        rq->kind = MPP_REQ_GET_RUN;
        NEED_ID(get_run, run_id, "get_run.run_id");
        rq->with_case = r->get_run->has_with_case && r->get_run->with_case;
        break;
    case MPMD__REQUEST__BODY_GET_ENERGY:
        rq->kind = MPP_REQ_GET_ENERGY;
        NEED_ID(get_energy, run_id, "get_energy.run_id");
        rq->from_seq = r->get_energy->has_from_seq ? r->get_energy->from_seq : 0;
        rq->limit = r->get_energy->has_limit ? r->get_energy->limit : 0;
        break;
    case MPMD__REQUEST__BODY_GET_SNAPSHOT:
        rq->kind = MPP_REQ_GET_SNAPSHOT;
        NEED_ID(get_snapshot, run_id, "get_snapshot.run_id");
        rq->has_step = r->get_snapshot->has_step;
        rq->step = r->get_snapshot->has_step ? r->get_snapshot->step : 0;
        break;
    case MPMD__REQUEST__BODY_PING: rq->kind = MPP_REQ_PING; break;
    case MPMD__REQUEST__BODY_VERSION: rq->kind = MPP_REQ_VERSION; break;
    case MPMD__REQUEST__BODY_RESUME:
        rq->kind = MPP_REQ_RESUME;
        NEED_ID(resume, run_id, "resume.run_id");
        break;
    default:
        rc = mpm_fail(err, MPM_EREQUEST, NULL,
                      "request: no body (one of submit, cancel, status, listRuns, getRun, "
                      "getEnergy, getSnapshot, ping, version, resume)");
        break;
    }
out:
    protobuf_c_message_free_unpacked(m, NULL);
    return rc;
}
#undef NEED_ID

void mpp_request_clear(mpp_request *rq)
{
    if (!rq) return;
    mpp_case_pb_free(&rq->case_pb);
    memset(rq, 0, sizeof *rq);
}

/* Appends a varint; returns the bytes written (at most 10). */
/* Wire types of the protobuf encoding used by the Submit writer below. */
enum { WT_VARINT = 0, WT_LEN = 2 };

static size_t put_varint(uint8_t *p, uint64_t v)
{
    size_t k = 0;
    do {
        p[k++] = (uint8_t)((v & 0x7f) | (v > 0x7f ? 0x80 : 0));
        v >>= 7;
    } while (v);
    return k;
}

/* A Submit request around case bytes packed beforehand: Request {
 * schema_version, submit = Submit { case = <the bytes> } }, written
 * directly (the bytes are copied, not decoded). */
static int submit_bytes(uint32_t version, const void *cb, size_t cn, uint8_t **buf, size_t *len)
{
    const ProtobufCFieldDescriptor *fv = protobuf_c_message_descriptor_get_field_by_name(
        &mpmd__request__descriptor, "schema_version");
    const ProtobufCFieldDescriptor *fs =
        protobuf_c_message_descriptor_get_field_by_name(&mpmd__request__descriptor, "submit");
    const ProtobufCFieldDescriptor *fc =
        protobuf_c_message_descriptor_get_field_by_name(&mpmd__request__submit__descriptor, "case");
    uint8_t head[64], tmp[10];
    size_t h = 0, inner;
    if (!fv || !fs || !fc) return MPM_EINVAL;
    h += put_varint(head + h, (uint64_t)fv->id << 3 | WT_VARINT);
    h += put_varint(head + h, version);
    inner = put_varint(tmp, (uint64_t)fc->id << 3 | WT_LEN) + put_varint(tmp, cn) + cn;
    h += put_varint(head + h, (uint64_t)fs->id << 3 | WT_LEN);
    h += put_varint(head + h, inner);
    h += put_varint(head + h, (uint64_t)fc->id << 3 | WT_LEN);
    h += put_varint(head + h, cn);
    if (cn > SIZE_MAX - h) return MPM_ENOMEM;
    uint8_t *b = malloc(h + cn);
    if (!b) return MPM_ENOMEM;
    memcpy(b, head, h);
    if (cn) memcpy(b + h, cb, cn);
    *buf = b;
    *len = h + cn;
    return 0;
}

int mpp_request_encode(const mpp_request *rq, uint8_t **buf, size_t *len)
{
    Mpmd__Request r = MPMD__REQUEST__INIT;
    Mpmd__Request__Submit sub = MPMD__REQUEST__SUBMIT__INIT;
    Mpmd__Request__Cancel can = MPMD__REQUEST__CANCEL__INIT;
    Mpmd__Request__Status sta = MPMD__REQUEST__STATUS__INIT;
    Mpmd__Request__ListRuns lr = MPMD__REQUEST__LIST_RUNS__INIT;
    Mpmd__Request__GetRun gr = MPMD__REQUEST__GET_RUN__INIT;
    Mpmd__Request__GetEnergy ge = MPMD__REQUEST__GET_ENERGY__INIT;
    Mpmd__Request__GetSnapshot gs = MPMD__REQUEST__GET_SNAPSHOT__INIT;
    Mpmd__Request__Ping pi = MPMD__REQUEST__PING__INIT;
    Mpmd__Request__Version ve = MPMD__REQUEST__VERSION__INIT;
    Mpmd__Request__Resume res = MPMD__REQUEST__RESUME__INIT;
    *buf = NULL;
    *len = 0;
    r.has_schema_version = 1;
    r.schema_version = rq->schema_version ? rq->schema_version : MPP_SCHEMA_VERSION;
    switch (rq->kind) {
    case MPP_REQ_SUBMIT:
        if (!rq->case_pb && rq->case_bytes)
            return submit_bytes(r.schema_version, rq->case_bytes, rq->case_len, buf, len);
        if (!rq->case_pb) return MPM_EINVAL;
        sub.case_ = rq->case_pb;
        r.body_case = MPMD__REQUEST__BODY_SUBMIT;
        r.submit = &sub;
        break;
    case MPP_REQ_CANCEL:
        can.has_job_id = 1;
        can.job_id = rq->id;
        r.body_case = MPMD__REQUEST__BODY_CANCEL;
        r.cancel = &can;
        break;
    case MPP_REQ_STATUS:
        sta.has_job_id = 1;
        sta.job_id = rq->id;
        r.body_case = MPMD__REQUEST__BODY_STATUS;
        r.status = &sta;
        break;
    case MPP_REQ_LIST_RUNS:
        if (rq->status) {
            lr.has_status = 1;
            lr.status = (Mpmd__RunStatus)rq->status;
        }
        if (rq->limit) {
            lr.has_limit = 1;
            lr.limit = rq->limit;
        }
        if (rq->before_id) {
            lr.has_before_run_id = 1;
            lr.before_run_id = rq->before_id;
        }
        r.body_case = MPMD__REQUEST__BODY_LIST_RUNS;
        r.list_runs = &lr;
        break;
    case MPP_REQ_GET_RUN:
        gr.has_run_id = 1;
        gr.run_id = rq->id;
        if (rq->with_case) gr.has_with_case = gr.with_case = 1;
        r.body_case = MPMD__REQUEST__BODY_GET_RUN;
        r.get_run = &gr;
        break;
    case MPP_REQ_GET_ENERGY:
        ge.has_run_id = 1;
        ge.run_id = rq->id;
        if (rq->from_seq) {
            ge.has_from_seq = 1;
            ge.from_seq = rq->from_seq;
        }
        if (rq->limit) {
            ge.has_limit = 1;
            ge.limit = rq->limit;
        }
        r.body_case = MPMD__REQUEST__BODY_GET_ENERGY;
        r.get_energy = &ge;
        break;
    case MPP_REQ_GET_SNAPSHOT:
        gs.has_run_id = 1;
        gs.run_id = rq->id;
        if (rq->has_step) {
            gs.has_step = 1;
            gs.step = rq->step;
        }
        r.body_case = MPMD__REQUEST__BODY_GET_SNAPSHOT;
        r.get_snapshot = &gs;
        break;
    case MPP_REQ_PING:
        r.body_case = MPMD__REQUEST__BODY_PING;
        r.ping = &pi;
        break;
    case MPP_REQ_VERSION:
        r.body_case = MPMD__REQUEST__BODY_VERSION;
        r.version = &ve;
        break;
    case MPP_REQ_RESUME:
        res.has_run_id = 1;
        res.run_id = rq->id;
        r.body_case = MPMD__REQUEST__BODY_RESUME;
        r.resume = &res;
        break;
    default: return MPM_EINVAL;
    }
    return mpp_pack(&r.base, buf, len);
}
