/*
 * srv_submit.c - the requests that start a job: Submit (the case checked
 * and counted once, the server's limits, the client's quotas and the disk
 * budgets, then the run recorded and its job queued) and Resume (an
 * INTERRUPTED run continued from its checkpoint file, with the same
 * quotas).  Runs on the daemon's main thread, like every request handler.
 *
 * Durable before acknowledged.  Both write the run's record, then wait
 * (srv_after_write) until the store has committed that write; only then is
 * the job queued and the client told its id.  A write the store lost (a
 * full disk) or refused gets an error naming the cause, and no job runs.
 * While the store cannot take new work (store_writable: a lost
 * transaction, a crash recovery or a run end waiting for room, its disk
 * reserve spent) both are refused at once; reads go on.  Guarded by
 * daemon_disk_submit_full and daemon_disk_restart_full.
 */
#include "srv_submit.h"

#include "srv_ckpt.h"
#include "srv_log.h"
#include "srv_pending.h"
#include "srv_reply.h"
#include "srv_stream.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The client's quotas that do not depend on the case's records: its key's
 * settings, else the --client-max-* (particles per job, live jobs); *q gets
 * them for the disk checks that follow.  Replies and returns 1 when one
 * refuses, else 0.  Shared by Submit and Resume. */
static int quota_refused(daemon_t *d, zmq_msg_t *id, const char *owner, size_t nparticles,
                         srv_quota *q)
{
    srv_auth_quota(d->auth, d->cfg, owner, q);
    if (q->max_particles > 0 && nparticles > (unsigned long long)q->max_particles) {
        srv_reply_error(d, id, MPM_ETOOBIG, "bodies",
                        "the case has %zu particles, above this server's per-client quota of %lld "
                        "(%s) for %s",
                        nparticles, q->max_particles,
                        q->max_particles == d->cfg->client_max_particles
                            ? "--client-max-particles"
                            : "max-particles of its key",
                        owner);
        return 1;
    }
    if (q->max_jobs > 0) {
        int live = srv_pool_owner_jobs(d->pool, owner) + srv_writes_waiting(d, owner);
        if (live >= q->max_jobs) {
            srv_reply_error(d, id, MPM_EFULL, "",
                            "%s has %d queued or running jobs, this server's per-client quota "
                            "(%s %lld); retry when one has ended",
                            owner, live,
                            q->max_jobs == d->cfg->client_max_jobs ? "--client-max-jobs"
                                                                   : "max-jobs of its key",
                            q->max_jobs);
            return 1;
        }
    }
    return 0;
}

/* Resume: the client's recorded bytes below its disk quota, and room in
 * the queue (the budgets then count the resumed run's writes as it runs).
 * Replies and returns 1 when refused. */
static int resume_refused(daemon_t *d, zmq_msg_t *id, const char *owner, const srv_quota *q)
{
    if (q->max_disk_mb > 0) {
        int64_t used = 0;
        if (store_owner_bytes(d->st, owner, &used)) {
            srv_reply_error(d, id, MPM_EINTERNAL, "", "cannot check the disk quota: %s",
                            store_error()->message);
            return 1;
        }
        if (used >= q->max_disk_mb * 1048576LL) {
            srv_reply_error(d, id, MPM_ETOOBIG, "",
                            "%s's recorded runs take %.1f MiB, this server's per-client quota is "
                            "%lld MiB; ask its admin to free space",
                            owner, (double)used / 1048576.0, q->max_disk_mb);
            return 1;
        }
    }
    if (srv_pool_room(d->pool) <= srv_writes_waiting(d, NULL)) {
        srv_reply_error(d, id, MPM_EFULL, "",
                        "the job queue is full (%d running, %d queued at most); retry later",
                        d->cfg->workers, d->cfg->queue_max);
        return 1;
    }
    return 0;
}

/* Replies UNAVAILABLE and returns 1 while the store takes no new work
 * (store_writable: the disk is full), else 0. */
static int store_refuses(daemon_t *d, zmq_msg_t *id, const char *what)
{
    char why[512];
    if (!store_writable(d->st, why, sizeof why)) return 0;
    srv_reply_error(d, id, MPM_EUNAVAIL, "",
                    "%s refused: %s; this server takes no new runs until there is room on the "
                    "disk of %s (reads are served)",
                    what, why, d->cfg->db);
    return 1;
}

/* A submission recorded, waiting for its record's commit (submit_done). */
typedef struct {
    mpp_case *sc;
    int64_t run;
    double submitted_at;
    size_t particles, nodes;
    int dim; /* for the log line */
    mpm_method method;
    mpm_update update;
    mpm_transfer transfer;
    char name[128];
} submit_wait;

static void submit_wait_free(submit_wait *w)
{
    mpp_case_destroy(&w->sc);
    free(w);
}

/* The client is told what became of its run's record: committed, the job
 * is queued and its id sent; else an error naming the cause, no job. */
static void submit_done(daemon_t *d, zmq_msg_t *id, const char *owner, int rc, const char *why,
                        void *arg)
{
    submit_wait *w = arg;
    int64_t run = w->run;
    if (rc) {
        srv_warn((uint64_t)run, "submission of %s not accepted: its record was not committed (%s)",
                 owner, why);
        /* a record that may exist after all (the store forgot the outcome)
         * must not stay queued without a job */
        if (rc == MPM_ESTATE) {
            store_run_end end = {0};
            end.status = MPP_STATUS_FAILED;
            end.error = "not started: its record's commit could not be confirmed";
            store_run_finish(d->st, run, &end);
        }
        srv_reply_error(d, id, rc == MPM_ECONFLICT ? MPM_ECONFLICT : MPM_EUNAVAIL, "",
                        "the run could not be recorded (%s): no job was queued%s", why,
                        rc == MPM_EUNAVAIL ? ""
                                           : "; retry when there is room on the disk of this "
                                             "server's run store");
        submit_wait_free(w);
        return;
    }
    /* a watcher may have subscribed before the job existed: it is watched
     * from its first step */
    int watched = srv_stream_watched(d->stream, (uint64_t)run);
    rc = d->pool ? srv_pool_submit(d->pool, (uint64_t)run, &w->sc, w->submitted_at, w->particles,
                                   w->nodes, watched, owner)
                 : MPM_EUNAVAIL;
    if (rc) {
        store_run_end end = {0};
        end.status = rc == MPM_EUNAVAIL ? MPP_STATUS_INTERRUPTED : MPP_STATUS_FAILED;
        end.error = rc == MPM_EFULL      ? "job queue full"
                    : rc == MPM_EUNAVAIL ? STORE_INTERRUPTED_QUEUED
                                         : "out of memory";
        store_run_finish(d->st, run, &end);
        srv_reply_error(d, id, rc, "", "%s", end.error);
        submit_wait_free(w);
        return;
    }
    srv_log((uint64_t)run, "queued '%s' of %s: %ldD %s %s %s, %zu particles", w->name, owner,
            (long)w->dim, mpm_method_name(w->method), mpm_update_name(w->update),
            mpm_transfer_name(w->transfer), w->particles);
    uint8_t *buf = NULL;
    size_t len = 0;
    mpp_reply_submit_ok((uint64_t)run, (uint64_t)run, &buf, &len);
    srv_send_reply(d, id, buf, len);
    submit_wait_free(w);
}

void srv_do_submit(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq)
{
    if (srv_daemon_stopping(d)) {
        srv_reply_error(d, id, MPM_EUNAVAIL, "", "mpmd is shutting down");
        return;
    }
    if (store_refuses(d, id, "submission")) return;
    mpp_case *sc = NULL;
    mpm_error cerr;
    /* checked and counted once, under this server's --max-particles */
    int rc = mpp_case_from_pb(rq->case_pb, (size_t)d->cfg->max_particles, &sc, &cerr);
    if (rc) {
        srv_reply_mpm_error(d, id, &cerr);
        return;
    }
    size_t nparticles = sc->info.particles;
    /* the client's quotas: its key's settings, else the --client-max-* */
    srv_quota q;
    if (quota_refused(d, id, owner, nparticles, &q)) {
        mpp_case_destroy(&sc);
        return;
    }
    /* in floating point: endTime / dt can be far beyond any integer type.
     * With automatic dt, the largest dt the CFL condition can give (the
     * materials' wave speed alone, particles at rest) makes the fewest
     * steps: a case over the limit even so is refused now, any other is
     * stopped at the limit while it runs (FAILED). */
    double steps = 0;
    int automatic = sc->has_end_time && !(sc->c.dt > 0);
    if (!sc->has_end_time)
        steps = (double)sc->steps;
    else
        steps = ceil(sc->end_time / mpm_case_dt_max(&sc->c, &sc->info) - 0.5);
    if (!(steps <= (double)d->cfg->max_steps)) {
        srv_reply_error(d, id, MPM_ETOOBIG, sc->has_end_time ? "end_time" : "steps",
                        "the case asks for %s%.15g steps%s, above this server's limit %lld "
                        "(--max-steps)",
                        automatic ? "at least " : "", steps,
                        automatic          ? " (endTime / the largest CFL dt, C h / c)"
                        : sc->has_end_time ? " (endTime / dt)"
                                           : "",
                        d->cfg->max_steps);
        mpp_case_destroy(&sc);
        return;
    }
    /* the disk budgets, on the bytes the run would record in those steps */
    srv_disk_estimate de;
    srv_budget_estimate(sc, steps, &de);
    if (srv_budget_admit(d->budget, owner, q.max_disk_mb, &de, automatic, &cerr)) {
        srv_reply_mpm_error(d, id, &cerr);
        mpp_case_destroy(&sc);
        return;
    }
    if (srv_pool_room(d->pool) <= srv_writes_waiting(d, NULL)) {
        srv_reply_error(d, id, MPM_EFULL, "",
                        "the job queue is full (%d running, %d queued at most); retry later",
                        d->cfg->workers, d->cfg->queue_max);
        mpp_case_destroy(&sc);
        return;
    }
    uint8_t *pb = NULL;
    size_t pblen = 0;
    /* the stored case names its method and update: it keeps its meaning
     * whatever later defaults say */
    mpp_case_pin_defaults(rq->case_pb);
    if (mpp_case_pack(rq->case_pb, &pb, &pblen)) {
        srv_reply_error(d, id, MPM_EINTERNAL, "", "out of memory");
        mpp_case_destroy(&sc);
        return;
    }
    size_t nodes = sc->info.nodes;
    submit_wait *w = calloc(1, sizeof *w);
    if (!w) {
        srv_reply_error(d, id, MPM_EINTERNAL, "", "out of memory");
        free(pb);
        mpp_case_destroy(&sc);
        return;
    }
    store_run r = {0};
    r.name = sc->name;
    r.case_pb = pb;
    r.case_len = pblen;
    r.method = sc->c.method;
    r.update = sc->c.update;
    r.transfer = sc->c.transfer;
    r.dim = sc->c.grid.dim;
    r.particles = (int64_t)nparticles;
    r.nodes = (int64_t)nodes;
    r.status = MPP_STATUS_QUEUED;
    r.submitted_at = srv_wall_now();
    r.server_version = MPP_VERSION;
    r.owner = owner;
    int64_t run = 0;
    rc = store_run_insert(d->st, &r, &run);
    uint64_t seq = store_last_write();
    free(pb);
    if (rc) {
        srv_reply_error(d, id, MPM_EINTERNAL, "", "cannot record the run: %s",
                        store_error()->message);
        mpp_case_destroy(&sc);
        free(w);
        return;
    }
    snprintf(w->name, sizeof w->name, "%s", sc->name && sc->name[0] ? sc->name : "(unnamed)");
    w->sc = sc;
    w->run = run;
    w->submitted_at = r.submitted_at;
    w->particles = nparticles;
    w->nodes = nodes;
    w->dim = r.dim;
    w->method = r.method;
    w->update = r.update;
    w->transfer = r.transfer;
    /* "accepted" only once the run's row is on disk: a crash after the
     * reply cannot lose the job, and a lost commit is not acknowledged */
    srv_after_write(d, id, owner, run, seq, submit_done, w);
}

/* A resume recorded, waiting for its commit (resume_done). */
typedef struct {
    unsigned long long run;
    mpp_case *sc;
    srv_ckpt_file ck;
    double submitted_at, prior_wall;
    mpm_energy_sample last; /* step -1: none */
    char who[OWNER_SIZE];   /* the run's owner */
} resume_wait;

static void resume_done(daemon_t *d, zmq_msg_t *id, const char *owner, int rc, const char *why,
                        void *arg)
{
    resume_wait *w = arg;
    unsigned long long run = w->run;
    store_checkpoint rec = w->ck.rec;
    if (rc) {
        srv_warn(run, "resume by %s not accepted: its record was not committed (%s)", owner, why);
        srv_reply_error(d, id, rc == MPM_ECONFLICT ? MPM_ECONFLICT : MPM_EUNAVAIL,
                        rc == MPM_ECONFLICT ? "run_id" : "",
                        "the resume of run %llu could not be recorded (%s): the run stays as it "
                        "was",
                        run, why);
    } else {
        int watched = srv_stream_watched(d->stream, run);
        size_t np = w->sc->info.particles, nodes = w->sc->info.nodes;
        rc = d->pool ? srv_pool_resume(d->pool, run, &w->sc, w->submitted_at, np, nodes, watched,
                                       w->who, &w->ck, w->prior_wall,
                                       w->last.step >= 0 ? &w->last : NULL)
                     : MPM_EUNAVAIL;
        if (rc) {
            store_run_end end = {0};
            end.status = MPP_STATUS_INTERRUPTED;
            end.steps = rec.step;
            end.error = rc == MPM_EFULL ? "resume refused: job queue full" : "resume failed";
            store_run_finish(d->st, (int64_t)run, &end);
            srv_reply_error(d, id, rc, "", "%s", end.error);
        } else {
            srv_log(run, "resumed by %s from its checkpoint at step %lld (t = %g)", owner,
                    (long long)rec.step, rec.t);
            uint8_t *buf = NULL;
            size_t len = 0;
            mpp_reply_submit_ok(run, run, &buf, &len);
            srv_send_reply(d, id, buf, len);
        }
    }
    mpp_case_destroy(&w->sc);
    srv_ckpt_file_clear(&w->ck);
    free(w);
}

/* Queues an INTERRUPTED run again to continue from its checkpoint file,
 * read and verified here (a damaged one is refused in the reply), with the
 * stored case; the job keeps the run's id and owner. */
void srv_do_resume(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq)
{
    unsigned long long run = rq->id;
    srv_job_info ji;
    store_run r;
    if (srv_daemon_stopping(d)) {
        srv_reply_error(d, id, MPM_EUNAVAIL, "", "mpmd is shutting down");
        return;
    }
    if (srv_pool_info(d->pool, run, &ji) == 0) {
        srv_reply_error(d, id, MPM_ECONFLICT, "run_id", "run %llu is %s", run,
                        mpp_status_name(ji.status));
        return;
    }
    if (store_refuses(d, id, "resume")) return;
    int rc = store_run_get(d->st, (int64_t)run, &r), nf = rc == MPM_ENOTFOUND;
    if (rc) {
        srv_reply_error(d, id, nf ? rc : MPM_EINTERNAL, nf ? "run_id" : "", "%s %llu%s%s",
                        nf ? "no run" : "reading run", run, nf ? "" : ": ",
                        nf ? "" : store_error()->message);
        return;
    }
    const char *who = r.owner && r.owner[0] ? r.owner : owner;
    char err[1700];
    srv_ckpt_file ck = {0};
    Mpmd__Case *pb = NULL;
    mpp_case *sc = NULL;
    mpm_error cerr;
    srv_quota q;
    if (strcmp(who, owner) && !srv_auth_is_admin(d->auth, owner)) {
        srv_reply_error(d, id, MPM_EFORBIDDEN, "run_id",
                        "run %llu was submitted by %s: only its owner or an admin key "
                        "(--admin-keys) may resume it",
                        run, d->cfg->private_runs ? "another key" : who);
    } else if (r.status != MPP_STATUS_INTERRUPTED) {
        srv_reply_error(d, id, MPM_ECONFLICT, "run_id",
                        "run %llu is %s: only an INTERRUPTED run can be resumed", run,
                        mpp_status_name((int)r.status));
    } else if ((rc = srv_ckpt_read(d->cfg->db, (int64_t)run, &ck, err, sizeof err))) {
        if (rc == MPM_ESYNTAX) srv_warn(run, "resume refused: %s", err);
        srv_reply_error(d, id, rc == MPM_ENOTFOUND || rc == MPM_ESYNTAX ? MPM_ECONFLICT : rc,
                        "run_id", "%s%s", err,
                        rc == MPM_ESYNTAX ? "; the run stays INTERRUPTED" : "");
    } else if (mpp_case_unpack(r.case_pb, r.case_len, 0, &pb, &cerr) ||
               mpp_case_from_pb(pb, (size_t)d->cfg->max_particles, &sc, &cerr)) {
        srv_reply_mpm_error(d, id, &cerr);
    } else if (!quota_refused(d, id, who, sc->info.particles, &q) &&
               !resume_refused(d, id, who, &q)) {
        /* the last sample before the checkpoint (the end's if it ends there) */
        mpm_energy_sample last = {.step = -1}, *es = NULL;
        size_t n = 0;
        if (ck.rec.energy_seq > 0 &&
            store_energy_read(d->st, (int64_t)run, ck.rec.energy_seq - 1, 1, &es, &n) == 0 &&
            n == 1 && es[0].seq == (uint64_t)(ck.rec.energy_seq - 1))
            last = es[0];
        free(es);
        resume_wait *w = calloc(1, sizeof *w);
        if (!w) {
            srv_reply_error(d, id, MPM_EINTERNAL, "", "out of memory");
        } else if ((rc = store_run_resume(d->st, (int64_t)run, &ck.rec))) {
            srv_reply_error(d, id, MPM_EINTERNAL, "", "cannot record the resume: %s",
                            store_error()->message);
            free(w);
        } else {
            uint64_t seq = store_last_write();
            w->run = run;
            w->sc = sc;
            sc = NULL;
            w->ck = ck;
            memset(&ck, 0, sizeof ck);
            w->submitted_at = r.submitted_at;
            w->prior_wall = isnan(r.wall_s) ? 0 : r.wall_s;
            w->last = last;
            snprintf(w->who, sizeof w->who, "%s", who);
            srv_after_write(d, id, owner, (int64_t)run, seq, resume_done, w);
        }
    }
    mpp_case_destroy(&sc);
    mpp_case_pb_free(&pb);
    srv_ckpt_file_clear(&ck);
    store_run_clear(&r);
}
