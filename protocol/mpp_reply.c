/*
 * mpp_reply.c - the Reply envelope: the encoders mpmd answers with (plain
 * structs -> packed bytes, the Error reply also from an mpm_error), and
 * the decoder for clients (packed bytes -> mpp_reply, with protobuf-c's
 * own unpack; see mpp_msg.h).
 */
#include "mpp_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- encoders ------------------------------------------------------------------- */

/* Fills ri into pi (es: storage for its last energy).  Unpacks the case
 * bytes into pi->case_ (free with protobuf_c_message_free_unpacked). */
static int fill_run(Mpmd__RunInfo *pi, Mpmd__EnergySample *es, const mpp_run_info *ri)
{
    mpmd__run_info__init(pi);
    pi->has_run_id = pi->has_job_id = pi->has_status = 1;
    pi->has_steps = pi->has_steps_total = pi->has_t = pi->has_wall_s = 1;
    pi->has_particles = pi->has_nodes = pi->has_dim = pi->has_energy_samples = 1;
    pi->run_id = ri->run_id;
    pi->job_id = ri->job_id;
    pi->name = (char *)ri->name;
    pi->status = (Mpmd__RunStatus)ri->status;
    pi->error = (char *)ri->error;
    pi->has_submitted_at = ri->submitted_at > 0;
    pi->submitted_at = ri->submitted_at;
    pi->has_started_at = ri->started_at > 0;
    pi->started_at = ri->started_at;
    pi->has_finished_at = ri->finished_at > 0;
    pi->finished_at = ri->finished_at;
    pi->steps = ri->steps;
    pi->steps_total = ri->steps_total;
    pi->t = ri->t;
    pi->wall_s = ri->wall_s;
    pi->particles = ri->particles;
    pi->nodes = ri->nodes;
    pi->dim = (uint32_t)(ri->dim > 0 ? ri->dim : 0);
    if (ri->last_energy) {
        mpp_fill_energy(es, ri->last_energy);
        pi->last_energy = es;
    }
    pi->energy_samples = ri->energy_samples;
    pi->n_snapshot_steps = ri->snapshot_steps ? ri->n_snapshot_steps : 0;
    pi->snapshot_steps = (int64_t *)ri->snapshot_steps;
    pi->has_method = pi->has_update = 1;
    pi->method = (Mpmd__Case__Method)ri->method;
    pi->update = (Mpmd__Case__Update)ri->update;
    pi->has_transfer = 1;
    pi->transfer = (Mpmd__Case__Transfer)ri->transfer;
    pi->warning = (char *)ri->warning;
    pi->owner = (char *)ri->owner;
    pi->plan = (char *)ri->plan;
    pi->has_balance_error = ri->has_balance != 0;
    pi->balance_error = ri->balance_error;
    pi->has_checkpoint_step = pi->has_checkpoint_t = ri->has_checkpoint != 0;
    pi->checkpoint_step = ri->checkpoint_step;
    pi->checkpoint_t = ri->checkpoint_t;
    pi->has_resumes = ri->resumes > 0;
    pi->resumes = ri->resumes;
    if (ri->case_bytes) {
        ProtobufCMessage *cm;
        if (mpp_unpack(&mpmd__case__descriptor, ri->case_bytes, ri->case_len, (size_t)-1, &cm,
                       NULL))
            return MPM_ESYNTAX;
        pi->case_ = (Mpmd__Case *)cm;
        /* what the run used, also for a case stored without the fields
         * under other defaults */
        pi->case_->has_method = pi->case_->has_update = 1;
        pi->case_->method = pi->method;
        pi->case_->update = pi->update;
        pi->case_->has_transfer = 1;
        pi->case_->transfer = pi->transfer;
    }
    return 0;
}

static int pack_reply(Mpmd__Reply *r, uint8_t **buf, size_t *len)
{
    r->has_schema_version = 1;
    r->schema_version = MPP_SCHEMA_VERSION;
    return mpp_pack(&r->base, buf, len);
}

int mpp_reply_error(int code, const char *message, const char *field, uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__Error e = MPMD__ERROR__INIT;
    e.has_code = 1;
    e.code = (Mpmd__Error__Code)code;
    e.message = (char *)message;
    e.field = (char *)field;
    r.body_case = MPMD__REPLY__BODY_ERROR;
    r.error = &e;
    return pack_reply(&r, buf, len);
}

int mpp_reply_error_from(const mpm_error *e, uint8_t **buf, size_t *len)
{
    char field[256], text[MPM_ERROR_MSG_MAX + 256];
    mpm_error_field(e, MPM_FIELD_JSON, field, sizeof field);
    mpm_error_text(e, MPM_FIELD_JSON, text, sizeof text);
    return mpp_reply_error(mpp_error_wire_code(e ? e->code : MPM_EINTERNAL), text, field, buf, len);
}

int mpp_reply_submit_ok(uint64_t job_id, uint64_t run_id, uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__SubmitOk s = MPMD__SUBMIT_OK__INIT;
    s.has_job_id = s.has_run_id = 1;
    s.job_id = job_id;
    s.run_id = run_id;
    r.body_case = MPMD__REPLY__BODY_SUBMIT_OK;
    r.submit_ok = &s;
    return pack_reply(&r, buf, len);
}

int mpp_reply_run(const mpp_run_info *ri, uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__RunInfo pi;
    Mpmd__EnergySample es;
    int rc = fill_run(&pi, &es, ri);
    *buf = NULL;
    *len = 0;
    if (!rc) {
        r.body_case = MPMD__REPLY__BODY_RUN;
        r.run = &pi;
        rc = pack_reply(&r, buf, len);
    }
    if (pi.case_) protobuf_c_message_free_unpacked(&pi.case_->base, NULL);
    return rc;
}

int mpp_reply_runs(const mpp_run_info *ri, size_t n, uint8_t **buf, size_t *len)
{
    return mpp_reply_runs_page(ri, n, 0, buf, len);
}

int mpp_reply_runs_page(const mpp_run_info *ri, size_t n, uint64_t next_before, uint8_t **buf,
                        size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__RunList rl = MPMD__RUN_LIST__INIT;
    Mpmd__RunInfo *pis = calloc(n ? n : 1, sizeof *pis);
    Mpmd__RunInfo **ptrs = calloc(n ? n : 1, sizeof *ptrs);
    Mpmd__EnergySample *ess = calloc(n ? n : 1, sizeof *ess);
    size_t filled = 0;
    int rc = 0;
    *buf = NULL;
    *len = 0;
    if (!pis || !ptrs || !ess) rc = MPM_ENOMEM;
    for (; !rc && filled < n; filled++) {
        rc = fill_run(&pis[filled], &ess[filled], &ri[filled]);
        ptrs[filled] = &pis[filled];
    }
    if (!rc) {
        rl.n_runs = n;
        rl.runs = ptrs;
        rl.has_next_before_run_id = next_before != 0;
        rl.next_before_run_id = next_before;
        r.body_case = MPMD__REPLY__BODY_RUNS;
        r.runs = &rl;
        rc = pack_reply(&r, buf, len);
    }
    for (size_t i = 0; pis && i < filled; i++)
        if (pis[i].case_) protobuf_c_message_free_unpacked(&pis[i].case_->base, NULL);
    free(pis);
    free(ptrs);
    free(ess);
    return rc;
}

int mpp_reply_energy(uint64_t run_id, const mpm_energy_sample *s, size_t n, int more, uint8_t **buf,
                     size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__EnergySeries es = MPMD__ENERGY_SERIES__INIT;
    Mpmd__EnergySample *smp = calloc(n ? n : 1, sizeof *smp);
    Mpmd__EnergySample **ptrs = calloc(n ? n : 1, sizeof *ptrs);
    int rc;
    *buf = NULL;
    *len = 0;
    if (!smp || !ptrs) {
        free(smp);
        free(ptrs);
        return MPM_ENOMEM;
    }
    for (size_t i = 0; i < n; i++) {
        mpp_fill_energy(&smp[i], &s[i]);
        ptrs[i] = &smp[i];
    }
    es.has_run_id = es.has_more = 1;
    es.run_id = run_id;
    es.more = more != 0;
    es.n_samples = n;
    es.samples = ptrs;
    r.body_case = MPMD__REPLY__BODY_ENERGY;
    r.energy = &es;
    rc = pack_reply(&r, buf, len);
    free(smp);
    free(ptrs);
    return rc;
}

int mpp_reply_snapshot(const mpp_snapshot *s, uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__Snapshot ps;
    mpp_fill_snapshot(&ps, s);
    r.body_case = MPMD__REPLY__BODY_SNAPSHOT;
    r.snapshot = &ps;
    return pack_reply(&r, buf, len);
}

int mpp_reply_pong(const char *server_version, const char *stream_endpoint, uint8_t **buf,
                   size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__Pong p = MPMD__PONG__INIT;
    p.server_version = (char *)server_version;
    p.stream_endpoint = (char *)stream_endpoint;
    p.has_schema_version = 1;
    p.schema_version = MPP_SCHEMA_VERSION;
    p.has_schema_minor = 1;
    p.schema_minor = MPP_SCHEMA_MINOR;
    r.body_case = MPMD__REPLY__BODY_PONG;
    r.pong = &p;
    return pack_reply(&r, buf, len);
}

int mpp_reply_version(const char *server_version, const char *const *names,
                      const char *const *versions, size_t n, uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__VersionInfo vi = MPMD__VERSION_INFO__INIT;
    Mpmd__VersionInfo__Component *cs = calloc(n ? n : 1, sizeof *cs);
    Mpmd__VersionInfo__Component **ptrs = calloc(n ? n : 1, sizeof *ptrs);
    int rc;
    *buf = NULL;
    *len = 0;
    if (!cs || !ptrs) {
        free(cs);
        free(ptrs);
        return MPM_ENOMEM;
    }
    for (size_t i = 0; i < n; i++) {
        mpmd__version_info__component__init(&cs[i]);
        cs[i].name = (char *)names[i];
        cs[i].version = (char *)versions[i];
        ptrs[i] = &cs[i];
    }
    vi.server_version = (char *)server_version;
    vi.has_schema_version = 1;
    vi.schema_version = MPP_SCHEMA_VERSION;
    vi.has_schema_minor = 1;
    vi.schema_minor = MPP_SCHEMA_MINOR;
    vi.n_components = n;
    vi.components = ptrs;
    r.body_case = MPMD__REPLY__BODY_VERSION;
    r.version = &vi;
    rc = pack_reply(&r, buf, len);
    free(cs);
    free(ptrs);
    return rc;
}

/* ---- JSON of single bodies (clients' --json output) ------------------------------ */

int mpp_energy_to_json(const mpm_energy_sample *s, char **json, mpm_error *err)
{
    Mpmd__EnergySample es;
    mpp_fill_energy(&es, s);
    return mpp_json_from_pb(&es.base, 0, json, err);
}

int mpp_snapshot_to_json(const mpp_snapshot *s, char **json, mpm_error *err)
{
    Mpmd__Snapshot ps;
    mpp_fill_snapshot(&ps, s);
    return mpp_json_from_pb(&ps.base, 0, json, err);
}

/* ---- the decoder ------------------------------------------------------------------ */

const char *mpp_reply_kind_name(mpp_reply_kind kind)
{
    /* the JSON names of the Reply.body members, by field number */
    static const char *const names[] = {"nothing", "schemaVersion", "error",  "submitOk",
                                        "run",     "runs",          "energy", "snapshot",
                                        "pong",    "version"};
    return kind >= MPP_REPLY_NONE && kind <= MPP_REPLY_VERSION && kind != 1 ? names[kind]
                                                                            : "unknown";
}

static const char *str(const char *s)
{
    return s ? s : "";
}

/* A RunInfo message into ri (strings and steps point into it; e: storage
 * for its last energy). */
static void take_run(mpp_run_info *ri, mpm_energy_sample *e, const Mpmd__RunInfo *pi)
{
    memset(ri, 0, sizeof *ri);
    ri->run_id = pi->run_id;
    ri->job_id = pi->job_id;
    ri->name = str(pi->name);
    ri->status = pi->has_status ? (int)pi->status : 0;
    ri->error = str(pi->error);
    ri->submitted_at = pi->has_submitted_at ? pi->submitted_at : 0;
    ri->started_at = pi->has_started_at ? pi->started_at : 0;
    ri->finished_at = pi->has_finished_at ? pi->finished_at : 0;
    ri->steps = pi->steps;
    ri->steps_total = pi->steps_total;
    ri->t = pi->t;
    ri->wall_s = pi->wall_s;
    ri->particles = pi->particles;
    ri->nodes = pi->nodes;
    ri->dim = (int)pi->dim;
    if (pi->last_energy) {
        mpp_take_energy(e, pi->last_energy);
        ri->last_energy = e;
    }
    ri->energy_samples = pi->energy_samples;
    ri->n_snapshot_steps = pi->n_snapshot_steps;
    ri->snapshot_steps = pi->snapshot_steps;
    ri->method = (mpm_method)pi->method;
    ri->update = (mpm_update)pi->update;
    ri->transfer = (mpm_transfer)pi->transfer;
    ri->warning = str(pi->warning);
    ri->owner = str(pi->owner);
    ri->plan = str(pi->plan);
    ri->has_balance = pi->has_balance_error;
    ri->balance_error = pi->balance_error;
    ri->has_checkpoint = pi->has_checkpoint_step;
    ri->checkpoint_step = pi->checkpoint_step;
    ri->checkpoint_t = pi->checkpoint_t;
    ri->resumes = pi->has_resumes ? pi->resumes : 0;
}

int mpp_reply_decode(const void *buf, size_t len, size_t max, mpp_reply *out, mpm_error *err)
{
    ProtobufCMessage *m;
    memset(out, 0, sizeof *out);
    int rc = mpp_unpack(&mpmd__reply__descriptor, buf, len, max, &m, err);
    if (rc) return rc;
    const Mpmd__Reply *r = (const Mpmd__Reply *)m;
    out->msg_ = m;
    out->schema_version = r->has_schema_version ? r->schema_version : 0;
    out->kind = (mpp_reply_kind)r->body_case;
    switch (r->body_case) {
    case MPMD__REPLY__BODY_ERROR:
        out->err_code = (int)r->error->code; /* the schema's default when absent */
        out->err_message = str(r->error->message);
        out->err_field = str(r->error->field);
        break;
    case MPMD__REPLY__BODY_SUBMIT_OK:
        out->has_job_id = r->submit_ok->has_job_id;
        out->job_id = r->submit_ok->job_id;
        out->has_run_id = r->submit_ok->has_run_id;
        out->run_id = r->submit_ok->run_id;
        break;
    case MPMD__REPLY__BODY_RUN:
    case MPMD__REPLY__BODY_RUNS: {
        size_t n = r->body_case == MPMD__REPLY__BODY_RUN ? 1 : r->runs->n_runs;
        Mpmd__RunInfo *const *pis = r->body_case == MPMD__REPLY__BODY_RUN ? &r->run : r->runs->runs;
        out->runs = calloc(n ? n : 1, sizeof *out->runs);
        out->energies_ = calloc(n ? n : 1, sizeof *out->energies_);
        if (!out->runs || !out->energies_) {
            mpp_reply_clear(out);
            return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
        }
        for (size_t i = 0; i < n; i++) take_run(&out->runs[i], &out->energies_[i], pis[i]);
        out->n_runs = n;
        if (r->body_case == MPMD__REPLY__BODY_RUN) {
            out->has_job_id = r->run->has_job_id;
            out->job_id = r->run->job_id;
            out->has_run_id = r->run->has_run_id;
            out->run_id = r->run->run_id;
        }
        break;
    }
    case MPMD__REPLY__BODY_ENERGY: {
        const Mpmd__EnergySeries *es = r->energy;
        out->has_run_id = es->has_run_id;
        out->run_id = es->run_id;
        out->more = es->has_more && es->more;
        if (es->n_samples) {
            out->samples = malloc(es->n_samples * sizeof *out->samples);
            if (!out->samples) {
                mpp_reply_clear(out);
                return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
            }
            for (size_t i = 0; i < es->n_samples; i++)
                mpp_take_energy(&out->samples[i], es->samples[i]);
            out->n_samples = es->n_samples;
        }
        break;
    }
    case MPMD__REPLY__BODY_SNAPSHOT:
        if ((rc = mpp_take_snapshot(&out->snapshot, r->snapshot, err))) {
            mpp_reply_clear(out);
            return rc;
        }
        break;
    case MPMD__REPLY__BODY_PONG:
        out->server_version = str(r->pong->server_version);
        out->stream_endpoint = str(r->pong->stream_endpoint);
        out->server_schema = r->pong->schema_version;
        out->server_minor = r->pong->schema_minor;
        break;
    case MPMD__REPLY__BODY_VERSION:
        out->server_version = str(r->version->server_version);
        out->stream_endpoint = "";
        out->server_schema = r->version->schema_version;
        out->server_minor = r->version->schema_minor;
        out->n_components = r->version->n_components;
        break;
    default: break;
    }
    return 0;
}

void mpp_reply_clear(mpp_reply *r)
{
    if (!r) return;
    if (r->msg_) protobuf_c_message_free_unpacked(r->msg_, NULL);
    free(r->runs);
    free(r->energies_);
    free(r->samples);
    memset(r, 0, sizeof *r);
}
