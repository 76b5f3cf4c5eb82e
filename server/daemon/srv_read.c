/*
 * srv_read.c - the daemon's read requests, answered from committed data
 * once their ticket is done (srv_pending.c): Status and GetRun (a RunInfo:
 * the stored run, its last energy sample and snapshots, overlaid with a
 * live job's figures from the pool), ListRuns (pages cut by count, by
 * --page-max-ms of store reads and by --page-max-bytes), GetEnergy (pages
 * likewise), GetSnapshot; --private-runs' check of who may read a run;
 * and a Cancel's action, whose reply is the run read back.  Main thread
 * only.  Guarded by the daemon_replies_* and daemon_* read tests
 * (tests/daemon/t_daemon_replies.c, t_daemon.c).
 */
#include "srv_read.h"

#include "srv_auth.h"
#include "srv_log.h"
#include "srv_pool.h"
#include "srv_reply.h"
#include "srv_stream.h"
#include "store.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define ENERGY_PAGE_DEFAULT 10000u
#define ENERGY_PAGE_MAX 100000u
#define ENERGY_SAMPLE_MIN 40u /* wire bytes of the smallest energy sample, at least */
#define LIST_DEFAULT 100u
#define LIST_MAX 10000u /* a RunInfo costs a few store reads on the main thread */

/* RunInfo from a stored run, with its last energy sample and stored
 * snapshots (x, cleared by the caller after encoding) and the live figures
 * of a running job. */
static void run_info(daemon_t *d, const store_run *r, mpp_run_info *ri, mpm_energy_sample *e,
                     store_run_extra *x)
{
    memset(ri, 0, sizeof *ri);
    ri->run_id = ri->job_id = (uint64_t)r->id;
    ri->name = r->name;
    ri->status = (int)r->status;
    ri->error = r->error;
    ri->submitted_at = r->submitted_at;
    ri->started_at = r->started_at;
    ri->finished_at = r->finished_at;
    ri->steps = r->steps;
    /* a finished run took the steps it planned; one that failed, or was
     * cancelled or interrupted, planned more (absent: the client works them
     * out from the case when it can) */
    if (r->status == MPP_STATUS_FINISHED) ri->steps_total = r->steps;
    ri->wall_s = r->wall_s;
    ri->particles = (uint64_t)r->particles;
    ri->nodes = (uint64_t)r->nodes;
    ri->dim = r->dim;
    ri->method = r->method;
    ri->update = r->update;
    ri->transfer = r->transfer;
    ri->warning = r->warning;
    ri->owner = r->owner && r->owner[0] ? r->owner : NULL;
    ri->plan = r->plan && r->plan[0] ? r->plan : NULL;
    ri->has_balance = r->has_balance;
    ri->balance_error = r->balance_error;
    ri->has_checkpoint = r->has_checkpoint, ri->checkpoint_step = r->checkpoint_step;
    ri->checkpoint_t = r->checkpoint_t, ri->resumes = (uint32_t)r->resumes;
    if (!isnan(r->energy.total)) {
        memset(e, 0, sizeof *e);
        e->step = r->steps;
        e->dim = r->dim;
        e->e = r->energy;
        /* the run row keeps no angular momentum: not recorded (NaN) */
        for (int k = 0; k < 3; k++) e->e.angular_momentum[k] = NAN;
        ri->last_energy = e;
    }
    if (store_run_extras(d->st, r->id, x) == 0) {
        ri->energy_samples = (uint64_t)x->energy_count;
        ri->snapshot_steps = x->snapshot_steps;
        ri->n_snapshot_steps = x->n_snapshots;
        mpm_energy_sample *es = NULL;
        size_t n = 0;
        if (x->last_seq >= 0 && store_energy_read(d->st, r->id, x->last_seq, 1, &es, &n) == 0) {
            if (n == 1) {
                *e = es[0];
                ri->last_energy = e;
                ri->t = e->t;
            }
            free(es);
        }
    }
    srv_job_info ji;
    if (srv_pool_lost(d->pool, (uint64_t)r->id, &ji) == 0) {
        /* ended on a full disk: the store may still say running */
        ri->status = ji.status;
        ri->error = SRV_STORE_LOST;
        ri->steps = ji.steps;
        ri->t = ji.t;
        ri->wall_s = ji.wall_s;
    } else if (!MPP_STATUS_ENDED(r->status) && srv_pool_info(d->pool, (uint64_t)r->id, &ji) == 0) {
        /* a live job: the pool's figures (once its row has ended, the row
         * is the truth: the pool may hold the job, RUNNING, a moment
         * longer, after its Finished went out) */
        ri->status = ji.status;
        ri->steps = ji.steps;
        ri->steps_total = ji.steps_total;
        ri->t = ji.t;
        ri->wall_s = ji.wall_s;
        if (ji.particles) ri->particles = ji.particles;
        if (ji.nodes) ri->nodes = ji.nodes;
        /* the live figures are as of the last progress report; a stored
         * sample may be newer */
        if (ri->last_energy && ri->last_energy->step > ri->steps) {
            ri->steps = ri->last_energy->step;
            ri->t = ri->last_energy->t;
        }
    }
}

/* Answers with the RunInfo of a run; field names the request's id field
 * ("job_id" or "run_id") for NOT_FOUND. */
static void reply_run(daemon_t *d, zmq_msg_t *id, uint64_t run, int with_case, const char *field)
{
    store_run r;
    int rc = store_run_get(d->st, (int64_t)run, &r);
    const char *what = strcmp(field, "job_id") ? "run" : "job";
    srv_job_info lost;
    if (rc == MPM_ENOTFOUND && srv_pool_lost(d->pool, run, &lost) == 0) {
        /* a job whose record the full disk lost, insert and all: what the
         * daemon knows of it (run_info() overlays its end) */
        memset(&r, 0, sizeof r);
        r.id = (int64_t)run;
        r.status = MPP_STATUS_FAILED;
        r.energy.total = NAN;
        rc = 0;
    }
    if (rc == MPM_ENOTFOUND) {
        srv_reply_error(d, id, MPM_ENOTFOUND, field, "no %s %llu", what, (unsigned long long)run);
        return;
    }
    if (rc) {
        srv_reply_error(d, id, MPM_EINTERNAL, "", "reading %s %llu: %s", what,
                        (unsigned long long)run, store_error()->message);
        return;
    }
    mpp_run_info ri;
    mpm_energy_sample e;
    store_run_extra x;
    run_info(d, &r, &ri, &e, &x);
    if (with_case) {
        ri.case_bytes = r.case_pb;
        ri.case_len = r.case_len;
    }
    uint8_t *buf = NULL;
    size_t len = 0;
    if (mpp_reply_run(&ri, &buf, &len))
        srv_reply_error(d, id, MPM_EINTERNAL, "", "cannot encode run %llu",
                        (unsigned long long)run);
    else
        srv_send_reply(d, id, buf, len);
    store_run_extra_clear(&x);
    store_run_clear(&r);
}

int srv_cancel_job(daemon_t *d, zmq_msg_t *id, const char *owner, uint64_t job)
{
    uint8_t *msg = NULL;
    size_t len = 0;
    /* only its owner or an admin key may cancel a job: the owner of a live
     * job is the pool's, of any other the store's */
    char who[OWNER_SIZE] = "";
    srv_job_info ji;
    if (srv_pool_info(d->pool, job, &ji) == 0) {
        snprintf(who, sizeof who, "%s", ji.owner);
    } else {
        store_run r;
        if (store_run_get(d->st, (int64_t)job, &r) == 0) {
            snprintf(who, sizeof who, "%s", r.owner ? r.owner : "");
            store_run_clear(&r);
        }
    }
    if (who[0] && strcmp(who, owner) && !srv_auth_is_admin(d->auth, owner)) {
        srv_warn(job, "cancel by %s refused: the job is %s's", owner, who);
        /* with --private-runs the owner's key is not told to another key
         * (daemon_names_forbidden_no_key) */
        srv_reply_error(d, id, MPM_EFORBIDDEN, "job_id",
                        "job %llu was submitted by %s: only its owner or an admin key "
                        "(--admin-keys) may cancel it",
                        (unsigned long long)job, d->cfg->private_runs ? "another key" : who);
        return 1;
    }
    int rc = srv_pool_cancel(d->pool, job, &msg, &len);
    srv_stream_publish(d, job, msg, len);
    if (rc == SRV_CANCEL_NONE) {
        store_run r;
        int src = store_run_get(d->st, (int64_t)job, &r);
        if (src == MPM_ENOTFOUND) {
            srv_reply_error(d, id, MPM_ENOTFOUND, "job_id", "no job %llu", (unsigned long long)job);
            return 1;
        }
        if (!src) {
            srv_reply_error(d, id, MPM_ECONFLICT, "job_id", "job %llu already ended (%s)",
                            (unsigned long long)job, mpp_status_name((int)r.status));
            store_run_clear(&r);
            return 1;
        }
        srv_reply_error(d, id, MPM_EINTERNAL, "", "reading job %llu: %s", (unsigned long long)job,
                        store_error()->message);
        return 1;
    }
    if (rc == SRV_CANCEL_RUNNING) srv_log(job, "cancel requested by %s", owner);
    return 0;
}

static void do_energy(daemon_t *d, zmq_msg_t *id, mpp_request *rq)
{
    size_t limit = rq->limit ? rq->limit : ENERGY_PAGE_DEFAULT;
    if (limit > ENERGY_PAGE_MAX) limit = ENERGY_PAGE_MAX;
    /* a sample takes more than ENERGY_SAMPLE_MIN bytes on the wire: no
     * more are read than a page of --page-max-bytes can carry */
    if (limit > (size_t)d->cfg->page_max_bytes / ENERGY_SAMPLE_MIN)
        limit = (size_t)d->cfg->page_max_bytes / ENERGY_SAMPLE_MIN;
    store_run r;
    int rc = store_run_get(d->st, (int64_t)rq->id, &r);
    if (rc == MPM_ENOTFOUND) {
        srv_reply_error(d, id, MPM_ENOTFOUND, "run_id", "no run %llu", (unsigned long long)rq->id);
        return;
    }
    int dim = rc ? 3 : r.dim;
    if (!rc) store_run_clear(&r);
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    int64_t from = rq->from_seq > (uint64_t)INT64_MAX ? INT64_MAX : (int64_t)rq->from_seq;
    rc = store_energy_read(d->st, (int64_t)rq->id, from, limit + 1, &es, &nes);
    if (rc) {
        srv_reply_error(d, id, MPM_EINTERNAL, "", "reading energies of run %llu: %s",
                        (unsigned long long)rq->id, store_error()->message);
        return;
    }
    int more = nes > limit;
    size_t n = more ? limit : nes;
    for (size_t i = 0; i < n; i++) es[i].dim = dim;
    uint8_t *buf = NULL;
    size_t len = 0;
    int rc2 = mpp_reply_energy(rq->id, es, n, more, &buf, &len);
    /* cut at --page-max-bytes: fewer samples, more = 1 (guarded by
     * daemon_replies_pages_by_bytes) */
    while (!rc2 && len > (size_t)d->cfg->page_max_bytes && n > 1) {
        size_t k = (size_t)((double)n * (double)d->cfg->page_max_bytes / (double)len * 0.95);
        n = k < 1 ? 1 : k < n ? k : n - 1;
        more = 1;
        free(buf);
        buf = NULL;
        rc2 = mpp_reply_energy(rq->id, es, n, more, &buf, &len);
    }
    if (rc2)
        srv_reply_error(d, id, MPM_EINTERNAL, "", "cannot encode %zu energy samples", n);
    else
        srv_send_reply(d, id, buf, len);
    free(es);
}

static void do_snapshot(daemon_t *d, zmq_msg_t *id, mpp_request *rq)
{
    store_run r;
    int rc = store_run_get(d->st, (int64_t)rq->id, &r);
    if (rc == MPM_ENOTFOUND) {
        srv_reply_error(d, id, MPM_ENOTFOUND, "run_id", "no run %llu", (unsigned long long)rq->id);
        return;
    }
    if (!rc) store_run_clear(&r); /* else the snapshot read reports it */
    store_snapshot ss;
    /* a negative step is no step (the store would read it as "latest") */
    rc = rq->has_step && rq->step < 0
             ? MPM_ENOTFOUND
             : store_snapshot_get(d->st, (int64_t)rq->id, rq->has_step ? rq->step : -1, &ss);
    if (rc == MPM_ENOTFOUND) {
        if (rq->has_step)
            srv_reply_error(d, id, MPM_ENOTFOUND, "step",
                            "run %llu has no stored snapshot at "
                            "step %lld",
                            (unsigned long long)rq->id, (long long)rq->step);
        else
            srv_reply_error(d, id, MPM_ENOTFOUND, "run_id",
                            "run %llu has no stored snapshot "
                            "(the case must set output.recordSnapshots)",
                            (unsigned long long)rq->id);
        return;
    }
    if (rc) {
        srv_reply_error(d, id, MPM_EINTERNAL, "", "reading a snapshot: %s", store_error()->message);
        return;
    }
    size_t n = (size_t)ss.n, dim = (size_t)ss.dim, off = 0;
    const double *data = ss.data;
    /* the stored layout of srv_job.c: the arrays back to back in
     * field-bit order (MPP_SNAP_*), the yield flags as doubles 0/1 */
    const double *arr[8] = {0};
    size_t cnt[8] = {n * dim, n * dim, n * 6, n, n, n, n * dim * dim, n};
    for (int i = 0; i < 8; i++)
        if (ss.fields & (1u << i)) {
            arr[i] = data + off;
            off += cnt[i];
        }
    if (off * sizeof(double) != ss.size) {
        srv_reply_error(d, id, MPM_EINTERNAL, "",
                        "stored snapshot of run %llu at step %lld is "
                        "corrupt (%zu bytes, expected %zu)",
                        (unsigned long long)rq->id, (long long)ss.step, ss.size,
                        off * sizeof(double));
        store_snapshot_clear(&ss);
        return;
    }
    int *yl = arr[7] ? malloc(n * sizeof(int) + 1) : NULL;
    double *pr = arr[3] ? malloc(n * sizeof(double) + 1) : NULL; /* the pressure, -mean */
    if ((arr[7] && !yl) || (arr[3] && !pr)) {
        free(yl);
        free(pr);
        srv_reply_error(d, id, MPM_ENOMEM, "", "out of memory for a snapshot of %zu particles", n);
        store_snapshot_clear(&ss);
        return;
    }
    for (size_t i = 0; yl && i < n; i++) yl[i] = arr[7][i] != 0.0;
    if (pr) mpp_snapshot_pressure(arr[3], n, pr);
    mpp_snapshot s = {.step = ss.step,
                      .t = ss.t,
                      .n = n,
                      .dim = (int)dim,
                      .x = arr[0],
                      .v = arr[1],
                      .stress = arr[2],
                      .mean_stress = arr[3],
                      .volume = arr[4],
                      .plastic_strain = arr[5],
                      .deformation_gradient = arr[6],
                      .yielded = yl,
                      .pressure = pr};
    uint8_t *buf = NULL;
    size_t len = 0;
    if (mpp_reply_snapshot(&s, &buf, &len))
        srv_reply_error(d, id, MPM_EINTERNAL, "", "cannot encode the snapshot");
    else
        srv_send_reply(d, id, buf, len);
    free(yl);
    free(pr);
    store_snapshot_clear(&ss);
}

static void do_list(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq)
{
    store_run_filter f = {0};
    /* --private-runs: a key lists its own runs (an admin's: all) */
    if (d->cfg->private_runs && !srv_auth_is_admin(d->auth, owner)) f.owner = owner;
    if (rq->status) {
        if (rq->status < MPP_STATUS_MIN || rq->status > MPP_STATUS_MAX) {
            srv_reply_error(d, id, MPM_EREQUEST, "list_runs.status",
                            "unknown "
                            "value %d",
                            rq->status);
            return;
        }
        f.status_mask = STORE_STATUS_BIT(rq->status);
    }
    if (rq->limit > LIST_MAX) {
        srv_reply_error(d, id, MPM_ETOOBIG, "list_runs.limit",
                        "%u is above this "
                        "server's maximum of %u runs per listing",
                        rq->limit, LIST_MAX);
        return;
    }
    if (rq->before_id > (uint64_t)INT64_MAX) {
        srv_reply_error(d, id, MPM_EREQUEST, "list_runs.before_run_id", "%llu: not a run id",
                        (unsigned long long)rq->before_id);
        return;
    }
    /* one more than asked for: whether a next page exists */
    f.limit = (rq->limit ? rq->limit : LIST_DEFAULT) + 1;
    f.before_id = (int64_t)rq->before_id;
    store_run *runs = NULL;
    size_t n = 0;
    if (store_run_list(d->st, &f, &runs, &n)) {
        srv_reply_error(d, id, MPM_EINTERNAL, "", "listing runs: %s", store_error()->message);
        return;
    }
    mpp_run_info *ri = calloc(n ? n : 1, sizeof *ri);
    mpm_energy_sample *es = calloc(n ? n : 1, sizeof *es);
    store_run_extra *xs = calloc(n ? n : 1, sizeof *xs);
    if (!ri || !es || !xs) {
        srv_reply_error(d, id, MPM_EINTERNAL, "", "out of memory");
    } else {
        uint64_t next = 0;
        size_t ns = n;
        if (n == f.limit) { /* the extra one is not sent: it says there is more */
            ns = n - 1;
            next = (uint64_t)runs[ns - 1].id;
        }
        /* a RunInfo costs a few store reads: the page ends after
         * --page-max-ms of them, the cursor after the last one made */
        double t0 = srv_wall_now();
        for (size_t i = 0; i < ns; i++) {
            run_info(d, &runs[i], &ri[i], &es[i], &xs[i]);
            if (i + 1 < ns && srv_wall_now() - t0 > 1e-3 * d->cfg->page_max_ms) {
                ns = i + 1;
                next = (uint64_t)runs[i].id;
            }
        }
        uint8_t *buf = NULL;
        size_t len = 0;
        int rc = mpp_reply_runs_page(ri, ns, next, &buf, &len);
        /* cut at --page-max-bytes, the cursor after the last one sent
         * (guarded by daemon_replies_pages_by_bytes) */
        while (!rc && len > (size_t)d->cfg->page_max_bytes && ns > 1) {
            size_t k = (size_t)((double)ns * (double)d->cfg->page_max_bytes / (double)len * 0.95);
            ns = k < 1 ? 1 : k < ns ? k : ns - 1;
            next = (uint64_t)runs[ns - 1].id;
            free(buf);
            buf = NULL;
            rc = mpp_reply_runs_page(ri, ns, next, &buf, &len);
        }
        if (rc)
            srv_reply_error(d, id, MPM_EINTERNAL, "", "cannot encode %zu runs", ns);
        else
            srv_send_reply(d, id, buf, len);
    }
    if (xs) /* calloc'd: an entry run_info() did not fill clears as nothing */
        for (size_t i = 0; i < n; i++) store_run_extra_clear(&xs[i]);
    free(xs);
    free(ri);
    free(es);
    store_run_list_free(runs, n);
}

/* With --private-runs, a read of one run by a key that neither owns it nor
 * is an admin's is answered FORBIDDEN (1); else 0.  (A run that does not
 * exist gets its NOT_FOUND from the read itself.) */
static int read_denied(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq)
{
    if (!d->cfg->private_runs || rq->kind == MPP_REQ_LIST_RUNS || rq->kind == MPP_REQ_CANCEL)
        return 0;
    char who[OWNER_SIZE];
    if (srv_pool_job_owner(d->pool, d->st, rq->id, who, sizeof who) || !strcmp(who, owner) ||
        srv_auth_is_admin(d->auth, owner))
        return 0;
    srv_log(rq->id, "read by %s refused: the run is %s's (--private-runs)", owner, who);
    srv_reply_error(d, id, MPM_EFORBIDDEN, rq->kind == MPP_REQ_STATUS ? "job_id" : "run_id",
                    "run %llu is another client's: this server shows each key only its own runs "
                    "(--private-runs)",
                    (unsigned long long)rq->id);
    return 1;
}

void srv_answer_read(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq)
{
    if (read_denied(d, id, owner, rq)) return;
    switch (rq->kind) {
    case MPP_REQ_CANCEL:
    case MPP_REQ_STATUS: reply_run(d, id, rq->id, 0, "job_id"); break;
    case MPP_REQ_GET_RUN: reply_run(d, id, rq->id, rq->with_case, "run_id"); break;
    case MPP_REQ_LIST_RUNS: do_list(d, id, owner, rq); break;
    case MPP_REQ_GET_ENERGY: do_energy(d, id, rq); break;
    case MPP_REQ_GET_SNAPSHOT: do_snapshot(d, id, rq); break;
    default:
        srv_reply_error(d, id, MPM_EINTERNAL, "", "request kind %d is not a read", (int)rq->kind);
    }
}
