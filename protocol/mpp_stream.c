/*
 * mpp_stream.c - the StreamMsg envelope: the encoders mpmd's workers
 * publish with (one into a reusable buffer, for snapshots), and the
 * decoder for clients (packed bytes -> mpp_stream, with protobuf-c's own
 * unpack; a snapshot's arrays point into the unpacked message; see
 * mpp_msg.h).
 */
#include "mpp_internal.h"

#include <stdlib.h>
#include <string.h>

/* ---- encoders ------------------------------------------------------------------- */

static int pack_stream(Mpmd__StreamMsg *m, uint64_t job_id, uint64_t seq, uint8_t **buf,
                       size_t *len)
{
    m->has_job_id = m->has_seq = 1;
    m->job_id = job_id;
    m->seq = seq;
    return mpp_pack(&m->base, buf, len);
}

int mpp_stream_progress(uint64_t job_id, uint64_t seq, const mpp_progress *p, uint8_t **buf,
                        size_t *len)
{
    Mpmd__StreamMsg m = MPMD__STREAM_MSG__INIT;
    Mpmd__Progress pp = MPMD__PROGRESS__INIT;
    pp.has_step = pp.has_t = pp.has_dt = pp.has_steps_total = pp.has_wall_s = 1;
    pp.step = p->step;
    pp.t = p->t;
    pp.dt = p->dt;
    pp.steps_total = p->steps_total;
    pp.wall_s = p->wall_s;
    m.body_case = MPMD__STREAM_MSG__BODY_PROGRESS;
    m.progress = &pp;
    return pack_stream(&m, job_id, seq, buf, len);
}

int mpp_stream_energy(uint64_t job_id, uint64_t seq, const mpm_energy_sample *s, uint8_t **buf,
                      size_t *len)
{
    Mpmd__StreamMsg m = MPMD__STREAM_MSG__INIT;
    Mpmd__EnergySample es;
    mpp_fill_energy(&es, s);
    m.body_case = MPMD__STREAM_MSG__BODY_ENERGY;
    m.energy = &es;
    return pack_stream(&m, job_id, seq, buf, len);
}

int mpp_stream_snapshot(uint64_t job_id, uint64_t seq, const mpp_snapshot *s, uint8_t **buf,
                        size_t *len)
{
    Mpmd__StreamMsg m = MPMD__STREAM_MSG__INIT;
    Mpmd__Snapshot ps;
    mpp_fill_snapshot(&ps, s);
    m.body_case = MPMD__STREAM_MSG__BODY_SNAPSHOT;
    m.snapshot = &ps;
    return pack_stream(&m, job_id, seq, buf, len);
}

int mpp_stream_finished(uint64_t job_id, uint64_t seq, const mpp_finished *f, uint8_t **buf,
                        size_t *len)
{
    Mpmd__StreamMsg m = MPMD__STREAM_MSG__INIT;
    Mpmd__Finished pf = MPMD__FINISHED__INIT;
    Mpmd__EnergySample es;
    pf.has_status = pf.has_steps = pf.has_t = pf.has_wall_s = 1;
    pf.status = (Mpmd__RunStatus)f->status;
    pf.error = (char *)f->error;
    pf.steps = f->steps;
    pf.t = f->t;
    pf.wall_s = f->wall_s;
    if (f->energy) {
        mpp_fill_energy(&es, f->energy);
        pf.energy = &es;
    }
    pf.has_balance_error = f->has_balance != 0;
    pf.balance_error = f->balance_error;
    pf.warning = (char *)f->warning;
    m.body_case = MPMD__STREAM_MSG__BODY_FINISHED;
    m.finished = &pf;
    return pack_stream(&m, job_id, seq, buf, len);
}

int mpp_stream_snapshot_into(uint64_t job_id, uint64_t seq, const mpp_snapshot *s, uint8_t *buf,
                             size_t cap, size_t *len)
{
    Mpmd__StreamMsg m = MPMD__STREAM_MSG__INIT;
    Mpmd__Snapshot ps;
    mpp_fill_snapshot(&ps, s);
    m.body_case = MPMD__STREAM_MSG__BODY_SNAPSHOT;
    m.snapshot = &ps;
    m.has_job_id = m.has_seq = 1;
    m.job_id = job_id;
    m.seq = seq;
    *len = protobuf_c_message_get_packed_size(&m.base);
    if (!buf || cap < *len) return MPM_ETOOBIG;
    if (protobuf_c_message_pack(&m.base, buf) != *len) return MPM_ENOMEM;
    return 0;
}

/* ---- the decoder ------------------------------------------------------------------ */

int mpp_stream_decode(const void *buf, size_t len, size_t max, mpp_stream *out, mpm_error *err)
{
    ProtobufCMessage *m;
    memset(out, 0, sizeof *out);
    int rc = mpp_unpack(&mpmd__stream_msg__descriptor, buf, len, max, &m, err);
    if (rc) return rc;
    const Mpmd__StreamMsg *sm = (const Mpmd__StreamMsg *)m;
    out->msg_ = m;
    out->has_job_id = sm->has_job_id;
    out->job_id = sm->job_id;
    out->has_seq = sm->has_seq;
    out->seq = sm->seq;
    out->kind = (mpp_stream_kind)sm->body_case;
    switch (sm->body_case) {
    case MPMD__STREAM_MSG__BODY_PROGRESS:
        out->progress.step = sm->progress->step;
        out->progress.t = sm->progress->t;
        out->progress.dt = sm->progress->dt;
        out->progress.steps_total = sm->progress->steps_total;
        out->progress.wall_s = sm->progress->wall_s;
        break;
    case MPMD__STREAM_MSG__BODY_ENERGY: mpp_take_energy(&out->energy, sm->energy); break;
    case MPMD__STREAM_MSG__BODY_SNAPSHOT:
        if ((rc = mpp_take_snapshot(&out->snapshot, sm->snapshot, err))) {
            mpp_stream_clear(out);
            return rc;
        }
        break;
    case MPMD__STREAM_MSG__BODY_FINISHED: {
        const Mpmd__Finished *f = sm->finished;
        out->finished.status = f->has_status ? (int)f->status : 0;
        out->finished.error = f->error ? f->error : "";
        out->finished.steps = f->steps;
        out->finished.t = f->t;
        out->finished.wall_s = f->wall_s;
        out->finished.has_balance = f->has_balance_error;
        out->finished.balance_error = f->balance_error;
        out->finished.warning = f->warning ? f->warning : "";
        out->has_energy = f->energy != NULL;
        mpp_take_energy(&out->energy, f->energy);
        break;
    }
    default: break;
    }
    return 0;
}

void mpp_stream_clear(mpp_stream *s)
{
    if (!s) return;
    if (s->msg_) protobuf_c_message_free_unpacked(s->msg_, NULL);
    memset(s, 0, sizeof *s);
}
