/*
 * srv_daemon.c - the daemon's main thread: sockets, requests, the stream.
 *
 * Design.  The main thread owns every socket it polls: a ROUTER for
 * requests (ZMQ_ROUTER_MANDATORY, replies sent with ZMQ_DONTWAIT so a
 * vanished client never blocks it), an XPUB for job streams (its
 * subscription messages tell which jobs are watched, so snapshots are only
 * packed for watched jobs), an inproc PULL that collects the workers'
 * stream messages and forwards them to the XPUB unchanged, and the store's
 * commit notification fd.  Nothing on this loop waits for the store's
 * writer: a read (Status, GetRun, ListRuns, GetEnergy, GetSnapshot, the
 * reply of a Cancel) takes a ticket for the writes its run had enqueued and
 * is answered, through the store's own read connections, once they are
 * committed; until then it waits in a queue, and so does any later request
 * of the same client, so that each client gets its replies in order.
 * Listings, energy pages and snapshots always take that queue and run a
 * few milliseconds per turn of the loop, which reads up to ROUTER_BATCH
 * requests a turn, so that a cheap request is never stuck behind them.
 * Replies go to libzmq without a copy, their unread bytes bounded per
 * connection and in total (srv_outq.h); connections are capped at the
 * handshake (srv_conns.h).
 *
 * Frames on the ROUTER: [identity][empty][Request], answered with
 * [identity][empty][Reply] (a DEALER client sends [empty][Request]; a REQ
 * client does so by itself).  Anything else is logged and dropped, or
 * answered BAD_REQUEST when the identity and delimiter are right.
 *
 * Authentication (srv_auth.h): with CURVE, the ZAP handler has accepted
 * every connection's key before any of its messages arrives, and each
 * request carries that key as its "User-Id": the requester, who owns the
 * runs it submits (a request without CURVE is "local"'s), is counted
 * against the per-client quotas, and may cancel only its own jobs unless
 * its key is an admin's.  SIGHUP re-reads the key lists.
 *
 * Shutdown (SIGINT, SIGTERM): running jobs are told to stop before their
 * next step and queued ones end INTERRUPTED at once; until the workers are
 * done the main thread keeps relaying their stream messages and answering
 * requests (Submit gets UNAVAILABLE), then relays whatever is left, and
 * closes the XPUB and the ROUTER with a linger of SHUTDOWN_LINGER_MS, so
 * the Finished(INTERRUPTED) of every job still reaches its watchers.
 */
#include "srv_daemon.h"
#include "srv_daemon_int.h"

#include "mpm.h"
#include "mpp_msg.h"
#include "srv_auth.h"
#include "srv_budget.h"
#include "srv_conns.h"
#include "srv_log.h"
#include "srv_outq.h"
#include "srv_pool.h"
#include "srv_socket.h"
#include "srv_stream.h"
#include "store.h"

#include <errno.h>
#include <malloc.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>
#include <zmq.h>

#define EVENTS_EP "inproc://mpmd-events"
#define ENERGY_PAGE_DEFAULT 10000u
#define ENERGY_PAGE_MAX 100000u
#define ENERGY_SAMPLE_MIN 40u /* wire bytes of the smallest energy sample, at least */
#define LIST_DEFAULT 100u
#define LIST_MAX 10000u /* a RunInfo costs a few store reads on the main thread */
/* How long the last stream messages and replies may take to leave at
 * shutdown (a vanished peer holds the exit up this long, no longer). */
#define SHUTDOWN_LINGER_MS 1000

static volatile sig_atomic_t stop_signal, hup_signal;

/* After a large request or reply, glibc keeps the freed blocks (libzmq
 * frees them on its own thread, some time later, and glibc's mmap
 * threshold rises with the sizes it has seen): the main loop hands them
 * back with malloc_trim(0) once a second for TRIM_WINDOW_S after the last
 * one.  Guarded by the "after they left" checks of t_daemon_replies.c. */
#define TRIM_BIG ((size_t)256 << 10)
#define TRIM_WINDOW_S 30.0
static double trim_until, trim_last;

static void trim_note(size_t bytes)
{
    if (bytes >= TRIM_BIG) trim_until = srv_wall_now() + TRIM_WINDOW_S;
}

static void trim_tick(void)
{
    double now = srv_wall_now();
    if (now < trim_until && now - trim_last >= 1.0) {
        malloc_trim(0);
        trim_last = now;
    }
}

static void on_signal(int sig)
{
    stop_signal = sig;
}

int srv_daemon_stopping(const daemon_t *d)
{
    return stop_signal || d->stopping;
}

static void on_hup(int sig)
{
    (void)sig;
    hup_signal = 1;
}

/* A request that waits, off the event loop: a read until the store has
 * committed every write its run (or, for a listing, any run) had enqueued
 * when it began, so it sees what the workers published before it and no
 * read ever blocks the loop on a commit; any request behind a waiting one
 * of the same client, so that a client's replies keep its order. */
typedef struct pending {
    zmq_msg_t id;           /* the client's identity frame */
    char owner[OWNER_SIZE]; /* who sent it (the CURVE key, or "local") */
    mpp_request rq;         /* the decoded request (a read: owns nothing big) */
    int begun;              /* its action is done and its ticket taken */
    uint64_t ticket;        /* store_ticket() when it began */
    srv_write_fn fn;        /* a Submit or Resume waiting for its write */
    void *fn_arg;           /* (srv_after_write()), or NULL */
    uint64_t seq;           /* ... the write's number */
    struct pending *next;
} pending;
/* Reads waiting at once, at most; more get UNAVAILABLE (a store that cannot
 * keep up is not hidden behind an ever longer queue). */
#define PENDING_MAX 4096
/* Heavy reads run for this long per turn of the loop, and requests read
 * per turn at most (a cheap one is answered as it is read). */
#define HEAVY_SLICE_S 0.005
#define ROUTER_BATCH 64
/* The waiting request serve_pending() is carrying on (main thread only). */
static struct pending *serving;

double srv_wall_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* ---- replies ---- */

/* A short error reply may pass a full reply queue by this much, so that a
 * client that reads at last learns why its big replies were not sent. */
#define REPLY_SLACK 65536

/* Logs a reply refused for a full queue: the first, then one line a second
 * with the count (a client that never reads could fill the log). */
static void log_refused(int conn, size_t len, size_t queued, int limit_mb, const char *setting)
{
    static double last;
    static unsigned long skipped;
    double now = srv_wall_now();
    if (now - last < 1.0) {
        skipped++;
        return;
    }
    srv_warn(0,
             "reply of %zu bytes not sent: %zu bytes of replies %s are unread (limit %d MiB, "
             "%s; %lu more refused in the last second)",
             len, queued, conn ? "to that connection" : "in all", limit_mb, setting, skipped);
    last = now;
    skipped = 0;
}

void srv_send_reply(daemon_t *d, zmq_msg_t *id, uint8_t *buf, size_t len)
{
    if (!buf) {
        srv_warn(0, "out of memory encoding a reply");
        return;
    }
    size_t queued = 0;
    trim_note(len);
    int rc =
        srv_outq_send(d->outq, d->router, zmq_msg_data(id), zmq_msg_size(id), buf, len, 0, &queued);
    if (rc == SRV_OUTQ_SENT) return;
    if (rc == SRV_OUTQ_ERROR) {
        srv_warn(0, "reply not sent: %s", zmq_strerror(errno));
        return;
    }
    /* the queue is full: the reply is dropped and, in its place, a short
     * error names the limit (guarded by daemon_replies_unread_bounded) */
    int conn = rc == SRV_OUTQ_CONN_FULL;
    int mb = conn ? d->cfg->connection_reply_buffer_mb : d->cfg->reply_buffer_mb;
    const char *setting = conn ? "--connection-reply-buffer-mb" : "--reply-buffer-mb";
    log_refused(conn, len, queued, mb, setting);
    mpm_error e;
    mpm_fail(&e, MPM_EUNAVAIL, "",
             "reply of %zu bytes not sent: %zu bytes of replies %s are still unread (limit %d "
             "MiB, %s); read them, then ask again",
             len, queued, conn ? "to this connection" : "to all clients", mb, setting);
    uint8_t *eb = NULL;
    size_t el = 0;
    if (mpp_reply_error_from(&e, &eb, &el) || !eb) return;
    if (srv_outq_send(d->outq, d->router, zmq_msg_data(id), zmq_msg_size(id), eb, el, REPLY_SLACK,
                      NULL) == SRV_OUTQ_ERROR)
        srv_debug(0, "error reply not sent: %s", zmq_strerror(errno));
}

/* Answers with the Error reply of an mpm_error (wire code, camelCase
 * field and text from the protocol library). */
void srv_reply_mpm_error(daemon_t *d, zmq_msg_t *id, const mpm_error *e)
{
    uint8_t *buf = NULL;
    size_t len = 0;
    mpp_reply_error_from(e, &buf, &len);
    srv_send_reply(d, id, buf, len);
}

/* Answers with an error: code an MPM_E* code, field a path in the schema's
 * spelling ("" or NULL: none), the message without the field. */
void srv_reply_error(daemon_t *d, zmq_msg_t *id, int code, const char *field, const char *fmt, ...)
{
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    mpm_error e;
    mpm_fail(&e, code, field, "%s", msg);
    srv_reply_mpm_error(d, id, &e);
}

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

/* Publishes a stream message of a job that the main thread made itself
 * (the Finished of a job cancelled or interrupted while queued); frees it. */
static void publish(void *arg, uint64_t job, uint8_t *msg, size_t len)
{
    daemon_t *d = arg;
    char topic[SRV_TOPIC_LEN + 1];
    srv_topic(job, topic);
    if (msg && (zmq_send(d->xpub, topic, SRV_TOPIC_LEN, ZMQ_SNDMORE | ZMQ_DONTWAIT) < 0 ||
                zmq_send(d->xpub, msg, len, ZMQ_DONTWAIT) < 0))
        srv_warn(job, "stream message not published: %s", zmq_strerror(errno));
    free(msg);
}

/* ---- requests ---- */

/* Submit and Resume: srv_submit.c. */

/* ---- requests in order, reads after their commit ---- */

static void do_energy(daemon_t *d, zmq_msg_t *id, mpp_request *rq);
static void do_snapshot(daemon_t *d, zmq_msg_t *id, mpp_request *rq);
static void do_list(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq);
static int cancel_job(daemon_t *d, zmq_msg_t *id, const char *owner, uint64_t job);
static void do_other(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq);

static int is_read(mpp_req_kind k)
{
    return k == MPP_REQ_CANCEL || k == MPP_REQ_STATUS || k == MPP_REQ_GET_RUN ||
           k == MPP_REQ_LIST_RUNS || k == MPP_REQ_GET_ENERGY || k == MPP_REQ_GET_SNAPSHOT;
}

/* Reads that cost the loop many store reads or bytes: they always wait in
 * the queue, where serve_pending() runs them HEAVY_SLICE_S at a time, and
 * the loop reads new requests (a Ping is answered at once) in between.
 * Guarded by daemon_replies_listings_keep_loop. */
static int is_heavy(mpp_req_kind k)
{
    return k == MPP_REQ_LIST_RUNS || k == MPP_REQ_GET_ENERGY || k == MPP_REQ_GET_SNAPSHOT;
}

/* With --private-runs, a read of one run by a key that neither owns it nor
 * is an admin's is answered FORBIDDEN (1); else 0.  (A run that does not
 * exist gets its NOT_FOUND from the read itself.) */
static int read_denied(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq)
{
    if (!d->cfg->private_runs || rq->kind == MPP_REQ_LIST_RUNS || rq->kind == MPP_REQ_CANCEL)
        return 0;
    char who[OWNER_SIZE];
    if (srv_job_owner(d, rq->id, who, sizeof who) || !strcmp(who, owner) ||
        srv_auth_is_admin(d->auth, owner))
        return 0;
    srv_log(rq->id, "read by %s refused: the run is %s's (--private-runs)", owner, who);
    srv_reply_error(d, id, MPM_EFORBIDDEN, rq->kind == MPP_REQ_STATUS ? "job_id" : "run_id",
                    "run %llu is another client's: this server shows each key only its own runs "
                    "(--private-runs)",
                    (unsigned long long)rq->id);
    return 1;
}

/* Answers a read request from committed data. */
static void answer_read(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq)
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

/* Carries a request as far as it can go now: 1 when it is answered, 0 when
 * its reply waits for *ticket (a read: the writes its run, or any run for a
 * listing, had enqueued when it began, so that it sees everything the
 * workers published before it).  *begun says the request's action (a
 * cancel's) is done and its ticket taken. */
static int run_request(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq, int *begun,
                       uint64_t *ticket)
{
    if (!is_read(rq->kind)) {
        do_other(d, id, owner, rq);
        return 1;
    }
    if (!*begun) {
        if (rq->kind == MPP_REQ_CANCEL && cancel_job(d, id, owner, rq->id)) return 1;
        *ticket = store_ticket(d->st, rq->kind == MPP_REQ_LIST_RUNS ? 0 : (int64_t)rq->id);
        *begun = 1;
    }
    if (!store_ticket_done(d->st, *ticket)) return 0;
    answer_read(d, id, owner, rq);
    return 1;
}

static int same_peer(zmq_msg_t *a, zmq_msg_t *b)
{
    return zmq_msg_size(a) == zmq_msg_size(b) &&
           !memcmp(zmq_msg_data(a), zmq_msg_data(b), zmq_msg_size(a));
}

/* 1 if a request of this client waits (a later one must wait behind it). */
static int peer_waits(daemon_t *d, zmq_msg_t *id, const pending *before)
{
    for (const pending *q = d->pending; q && q != before; q = q->next)
        if (same_peer((zmq_msg_t *)&q->id, id)) return 1;
    return 0;
}

/* Queues a request (taken over: *rq is emptied); on failure answers
 * UNAVAILABLE. */
static pending *enqueue(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq, int begun,
                        uint64_t ticket)
{
    pending *p = d->npending < PENDING_MAX ? calloc(1, sizeof *p) : NULL;
    if (p && zmq_msg_init(&p->id) == 0 && zmq_msg_copy(&p->id, id) == 0) {
        snprintf(p->owner, sizeof p->owner, "%s", owner);
        if (rq) {
            p->rq = *rq;
            memset(rq, 0, sizeof *rq);
        }
        p->begun = begun;
        p->ticket = ticket;
        if (!d->pending_tail) d->pending_tail = &d->pending;
        *d->pending_tail = p;
        d->pending_tail = &p->next;
        d->npending++;
        return p;
    }
    if (p) zmq_msg_close(&p->id);
    free(p);
    if (rq)
        srv_reply_error(d, id, MPM_EUNAVAIL, "",
                        "%zu requests are waiting for the store; retry "
                        "later",
                        d->npending);
    return NULL;
}

void srv_after_write(daemon_t *d, zmq_msg_t *id, const char *owner, int64_t run, uint64_t seq,
                     srv_write_fn fn, void *arg)
{
    char why[256];
    (void)store_ticket(d->st, run); /* the writer skips its batching window */
    int rc = store_write_result(d->st, seq, why, sizeof why);
    pending *p = NULL;
    if (rc == 1 && serving && same_peer(&serving->id, id)) {
        /* a queued Submit carried on by serve_pending(): it waits in its
         * own place, before its client's later requests */
        serving->fn = fn;
        serving->fn_arg = arg;
        serving->seq = seq;
        return;
    }
    if (rc == 1 && (p = enqueue(d, id, owner, NULL, 1, 0))) {
        p->fn = fn;
        p->fn_arg = arg;
        p->seq = seq;
        return;
    }
    /* done already, or no room to wait: the commit first (a blocking
     * flush; only when PENDING_MAX requests wait), then the answer */
    if (rc == 1) {
        store_flush(d->st);
        rc = store_write_result(d->st, seq, why, sizeof why);
    }
    fn(d, id, owner, rc == 1 ? MPM_EIO : rc, why, arg);
}

int srv_writes_waiting(const daemon_t *d, const char *owner)
{
    int n = 0;
    for (const pending *q = d->pending; q; q = q->next)
        n += q->fn && (!owner || !strcmp(q->owner, owner));
    return n;
}

/* Runs a decoded request, in arrival order per client: behind a waiting
 * request of the same client it queues; a read whose writes are not yet
 * committed queues; everything else is answered now. */
static void dispatch(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq)
{
    int begun = 0;
    uint64_t ticket = 0;
    if (peer_waits(d, id, NULL) || is_heavy(rq->kind) ||
        !run_request(d, id, owner, rq, &begun, &ticket))
        enqueue(d, id, owner, rq, begun, ticket);
}

/* Carries on the waiting requests whose writes are committed, in arrival
 * order per client.  sliced: after HEAVY_SLICE_S of heavy reads the rest
 * wait for the next turn of the loop (returns 1 when some are left that
 * could go now), so that new requests are read in between. */
static int serve_pending(daemon_t *d, int sliced)
{
    /* d->pending_tail stays the list's tail throughout: a request carried
     * on here may queue another (srv_after_write) */
    pending **pp = &d->pending;
    double t0 = sliced ? srv_wall_now() : 0;
    int spent = 0, left = 0;
    while (*pp) {
        pending *p = *pp;
        int done = 0;
        if (p->fn) {
            /* a Submit or Resume that waited for its write */
            char why[256];
            int rc = store_write_result(d->st, p->seq, why, sizeof why);
            if (rc != 1) {
                srv_write_fn fn = p->fn;
                p->fn = NULL;
                fn(d, &p->id, p->owner, rc, why, p->fn_arg);
                done = 1;
            }
        } else if (spent && is_heavy(p->rq.kind)) {
            left = 1;
        } else if (!peer_waits(d, &p->id, p)) {
            int heavy = is_heavy(p->rq.kind);
            serving = p;
            done = run_request(d, &p->id, p->owner, &p->rq, &p->begun, &p->ticket);
            serving = NULL;
            done = done && !p->fn; /* a Submit now waiting for its write, in place */
            if (done && heavy && sliced && srv_wall_now() - t0 >= HEAVY_SLICE_S) spent = 1;
        }
        if (done) {
            *pp = p->next;
            if (d->pending_tail == &p->next) d->pending_tail = pp;
            zmq_msg_close(&p->id);
            mpp_request_clear(&p->rq);
            free(p);
            d->npending--;
            continue;
        }
        pp = &p->next;
    }
    return left;
}

/* Answers every waiting request after a last flush (shutdown). */
static void drain_pending(daemon_t *d)
{
    if (!d->pending) return;
    store_flush(d->st);
    serve_pending(d, 0);
    /* what still waits (a store that lost its writes): answered, freed */
    while (d->pending) {
        pending *p = d->pending;
        d->pending = p->next;
        if (p->fn)
            p->fn(d, &p->id, p->owner, MPM_EUNAVAIL, "mpmd is shutting down", p->fn_arg);
        else
            srv_reply_error(d, &p->id, MPM_EUNAVAIL, "", "mpmd is shutting down");
        zmq_msg_close(&p->id);
        mpp_request_clear(&p->rq);
        free(p);
        d->npending--;
    }
    d->pending_tail = &d->pending;
}

/* A cancel's action: 0 when the job was live (its reply, the run, follows
 * once the store has it), 1 when it was answered with an error. */
static int cancel_job(daemon_t *d, zmq_msg_t *id, const char *owner, uint64_t job)
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
    publish(d, job, msg, len);
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
    /* the stored layout of srv_pool.c: the arrays back to back in
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
    if (arr[7] && !yl) {
        srv_reply_error(d, id, MPM_ENOMEM, "", "out of memory for a snapshot of %zu particles", n);
        store_snapshot_clear(&ss);
        return;
    }
    for (size_t i = 0; yl && i < n; i++) yl[i] = arr[7][i] != 0.0;
    mpp_snapshot s = {ss.step, ss.t,   n,      (int)dim, arr[0], arr[1],
                      arr[2],  arr[3], arr[4], arr[5],   arr[6], yl};
    uint8_t *buf = NULL;
    size_t len = 0;
    if (mpp_reply_snapshot(&s, &buf, &len))
        srv_reply_error(d, id, MPM_EINTERNAL, "", "cannot encode the snapshot");
    else
        srv_send_reply(d, id, buf, len);
    free(yl);
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

/* Requests that read nothing a worker writes: Submit, Resume (of a run no
 * worker has), Ping, Version. */
static void do_other(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq)
{
    uint8_t *buf = NULL;
    size_t len = 0;
    switch (rq->kind) {
    case MPP_REQ_SUBMIT: srv_do_submit(d, id, owner, rq); break;
    case MPP_REQ_RESUME: srv_do_resume(d, id, owner, rq); break;
    case MPP_REQ_PING:
        mpp_reply_pong(MPP_VERSION, d->cfg->stream_endpoint, &buf, &len);
        srv_send_reply(d, id, buf, len);
        break;
    case MPP_REQ_VERSION: {
        int maj, min, pat;
        zmq_version(&maj, &min, &pat);
        char zv[32];
        snprintf(zv, sizeof zv, "%d.%d.%d", maj, min, pat);
        const char *names[] = {"libzmq", "sqlite", "protobuf-c", "schema"};
        char sv[8];
        snprintf(sv, sizeof sv, "%d", MPP_SCHEMA_VERSION);
        const char *vers[] = {zv, store_sqlite_version(), mpp_protobuf_c_version(), sv};
        mpp_reply_version(MPP_VERSION, names, vers, 4, &buf, &len);
        srv_send_reply(d, id, buf, len);
        break;
    }
    default: srv_reply_error(d, id, MPM_EREQUEST, "", "unknown request kind %d", (int)rq->kind);
    }
}

static void handle_request(daemon_t *d, zmq_msg_t *id, const char *owner, const void *data,
                           size_t size)
{
    mpp_request rq;
    d->requests++;
    trim_note(size);
    if (size > (size_t)d->cfg->max_request_bytes) {
        d->bad_requests++;
        srv_warn(0, "request of %zu bytes refused (limit %lld)", size, d->cfg->max_request_bytes);
        srv_reply_error(d, id, MPM_ETOOBIG, "",
                        "request of %zu bytes is above this server's "
                        "limit of %lld bytes (--max-request-bytes)",
                        size, d->cfg->max_request_bytes);
        return;
    }
    mpm_error rerr;
    int rc = mpp_request_decode(data, size, (size_t)d->cfg->max_request_bytes, &rq, &rerr);
    if (rc) {
        char text[sizeof rerr.message + 256];
        d->bad_requests++;
        srv_debug(0, "bad request: %s", mpm_error_text(&rerr, MPM_FIELD_JSON, text, sizeof text));
        srv_reply_mpm_error(d, id, &rerr);
        mpp_request_clear(&rq);
        return;
    }
    dispatch(d, id, owner, &rq);
    mpp_request_clear(&rq);
}

/* Reads one multipart message from the ROUTER and answers it (or queues
 * it); 0 when none was waiting. */
static int on_router(daemon_t *d)
{
    zmq_msg_t part[4];
    int nparts = 0, more = 1;
    size_t extra = 0;
    while (more) {
        zmq_msg_t m;
        zmq_msg_init(&m);
        if (zmq_msg_recv(&m, d->router, ZMQ_DONTWAIT) < 0) {
            zmq_msg_close(&m);
            if (errno != EAGAIN) srv_warn(0, "receive: %s", zmq_strerror(errno));
            break;
        }
        more = zmq_msg_more(&m);
        if (nparts < 4)
            part[nparts++] = m;
        else {
            extra++;
            zmq_msg_close(&m);
        }
    }
    if (nparts == 3 && !extra && zmq_msg_size(&part[1]) == 0) {
        /* the ZAP handler's user id: the client's CURVE key (Z85); none
         * without CURVE (loopback, ipc://) */
        const char *uid = zmq_msg_gets(&part[2], "User-Id");
        char owner[OWNER_SIZE];
        snprintf(owner, sizeof owner, "%s", uid && *uid ? uid : SRV_OWNER_LOCAL);
        /* a key removed at SIGHUP: its connection is closed then, and any
         * request that still comes is refused (srv_auth.h) */
        if (uid && *uid) srv_auth_note_peer(d->auth, &part[2], uid);
        if (uid && *uid && !srv_auth_key_ok(d->auth, uid)) {
            d->requests++;
            srv_debug(0, "request of the revoked key %s refused", uid);
            srv_reply_error(d, &part[0], MPM_EFORBIDDEN, "",
                            "this client's key is no longer authorized (removed from the "
                            "server's key lists)");
        } else {
            handle_request(d, &part[0], owner, zmq_msg_data(&part[2]), zmq_msg_size(&part[2]));
        }
    } else if (nparts >= 1) {
        d->bad_requests++;
        size_t total = (size_t)nparts + extra;
        srv_warn(0,
                 "malformed request: %zu frames (expected identity, empty delimiter, "
                 "request)",
                 total);
        /* answerable when the delimiter is there: the peer speaks the protocol */
        if (nparts >= 2 && zmq_msg_size(&part[1]) == 0)
            srv_reply_error(d, &part[0], MPM_EREQUEST, "",
                            "expected 1 request frame after the empty delimiter, got %zu",
                            total - 2);
    }
    for (int i = 0; i < nparts; i++) zmq_msg_close(&part[i]);
    return nparts > 0;
}

int srv_job_owner(daemon_t *d, uint64_t job, char *who, size_t n)
{
    srv_job_info ji;
    if (srv_pool_info(d->pool, job, &ji) == 0) {
        snprintf(who, n, "%s", ji.owner);
        return 0;
    }
    return store_run_owner(d->st, (int64_t)job, who, n) ? -1 : 0;
}

/* Closes a socket after giving what it still holds to send (the last stream
 * messages, the last replies) up to linger_ms to leave. */
static void close_socket(void **s, int linger_ms, const char *what)
{
    if (!*s) return;
    if (zmq_setsockopt(*s, ZMQ_LINGER, &linger_ms, sizeof linger_ms))
        srv_warn(0, "%s: ZMQ_LINGER: %s", what, zmq_strerror(errno));
    if (zmq_close(*s)) srv_warn(0, "closing the %s socket: %s", what, zmq_strerror(errno));
    *s = NULL;
}

/* The shutdown of the jobs: no new ones; running ones end INTERRUPTED
 * before their next step while their stream messages are still relayed and
 * requests still answered (a watcher asking Status gets its answer); queued
 * ones end INTERRUPTED with a Finished message of their own; then the
 * workers are joined and every message they sent is relayed. */
static void stop_jobs(daemon_t *d)
{
    d->stopping = 1;
    srv_pool_stop(d->pool, publish, d);
    while (srv_pool_busy(d->pool)) {
        zmq_pollitem_t items[] = {{d->router, 0, ZMQ_POLLIN, 0},
                                  {d->pull, 0, ZMQ_POLLIN, 0},
                                  {NULL, store_notify_fd(d->st), ZMQ_POLLIN, 0}};
        int n = zmq_poll(items, 3, 50);
        if (n < 0 && errno != EINTR) {
            srv_warn(0, "zmq_poll while stopping: %s", zmq_strerror(errno));
            break;
        }
        if (n > 0 && (items[1].revents & ZMQ_POLLIN)) srv_stream_relay(d, 10000);
        if (n > 0 && (items[2].revents & ZMQ_POLLIN)) store_notify_drain(d->st);
        if (n > 0 && (items[0].revents & ZMQ_POLLIN)) on_router(d);
        if (d->pending) serve_pending(d, 0);
    }
    srv_pool_destroy(&d->pool);
    srv_stream_relay(d, 0);
    drain_pending(d);
}

/* Raises the soft limit on descriptors to the hard one: every connection,
 * accepted before any check, takes one (systemd's default soft limit is
 * 1024; deploy/mpmd.service raises the hard one). */
static void raise_nofile(void)
{
    struct rlimit rl;
    if (getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur < rl.rlim_max) {
        rlim_t was = rl.rlim_cur;
        rl.rlim_cur = rl.rlim_max;
        if (setrlimit(RLIMIT_NOFILE, &rl))
            srv_warn(0, "cannot raise the descriptor limit from %llu: %s", (unsigned long long)was,
                     strerror(errno));
    }
    if (getrlimit(RLIMIT_NOFILE, &rl) == 0)
        srv_debug(0, "descriptor limit %llu", (unsigned long long)rl.rlim_cur);
}

int srv_daemon_run(const srv_config *cfg)
{
    daemon_t d = {0};
    char err[1024];
    int rc = 1;
    d.cfg = cfg;
    srv_log_set_verbose(cfg->verbose);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    sa.sa_handler = on_hup;
    sigaction(SIGHUP, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
    /* over a file-size limit (RLIMIT_FSIZE) a write fails with EFBIG, as on
     * a full disk, instead of killing the daemon */
    signal(SIGXFSZ, SIG_IGN);
    raise_nofile();

    if (srv_auth_new(cfg, &d.auth, err, sizeof err)) {
        srv_error(0, "%s", err);
        srv_auth_destroy(&d.auth);
        return 1;
    }
    store_options so = {0};
    so.log = srv_log_store;
    so.reserve_bytes = cfg->disk_reserve_mb > 0 ? (long long)cfg->disk_reserve_mb << 20 : -1;
    if (store_open(cfg->db, &so, &d.st)) {
        srv_error(0, "%s", store_error()->message);
        srv_auth_destroy(&d.auth);
        return 1;
    }
    if (srv_ckpt_init(cfg->db, err, sizeof err)) {
        srv_error(0, "%s", err);
        store_close(&d.st);
        srv_auth_destroy(&d.auth);
        return 1;
    }
    store_stats ss;
    store_get_stats(d.st, &ss);
    if (ss.recovered_running || ss.recovered_queued)
        srv_log(0,
                "%lld run(s) left running and %lld left queued by an earlier mpmd are now "
                "interrupted",
                (long long)ss.recovered_running, (long long)ss.recovered_queued);
    d.budget = srv_budget_new(cfg, d.st, err, sizeof err);
    if (!d.budget) {
        srv_error(0, "%s", err);
        goto out;
    }
    d.zctx = zmq_ctx_new();
    if (!d.zctx) {
        srv_error(0, "zmq_ctx_new: %s", zmq_strerror(errno));
        goto out;
    }
    srv_config inproc = *cfg;
    inproc.insecure_remote = 0;
    d.outq = srv_outq_new((size_t)cfg->connection_reply_buffer_mb << 20,
                          (size_t)cfg->reply_buffer_mb << 20);
    if (!d.outq) {
        srv_error(0, "out of memory");
        goto out;
    }
    if (cfg->max_connections) {
        d.conns = srv_conns_new(d.zctx, cfg->max_connections, err, sizeof err);
        if (!d.conns) {
            srv_error(0, "%s", err);
            goto out;
        }
        srv_auth_gate g = {srv_conns_admit, srv_conns_drain, d.conns, srv_conns_socket(d.conns),
                           cfg->max_connections};
        srv_auth_set_gate(d.auth, &g);
    }
    if (srv_auth_start(d.auth, d.zctx, err, sizeof err)) {
        /* the handler's thread did not take the monitor's socket */
        if (d.conns) zmq_close(srv_conns_socket(d.conns));
        srv_error(0, "%s", err);
        goto out;
    }
    if (srv_socket_open(d.zctx, ZMQ_ROUTER, cfg->endpoint, cfg, d.auth, &d.router, err,
                        sizeof err) ||
        (d.conns && srv_conns_watch(d.conns, d.router, err, sizeof err)) ||
        srv_socket_open(d.zctx, ZMQ_XPUB, cfg->stream_endpoint, cfg, d.auth, &d.xpub, err,
                        sizeof err) ||
        srv_socket_open(d.zctx, ZMQ_PULL, EVENTS_EP, &inproc, NULL, &d.pull, err, sizeof err)) {
        srv_error(0, "%s", err);
        goto out;
    }
    d.stream = srv_stream_new(cfg);
    if (!d.stream) {
        srv_error(0, "out of memory for the stream's subscriptions");
        goto out;
    }
    d.pool = srv_pool_new(d.zctx, cfg, d.st, EVENTS_EP, err, sizeof err);
    if (!d.pool) {
        srv_error(0, "%s", err);
        goto out;
    }
    srv_pool_set_budget(d.pool, d.budget);
    srv_log(0,
            "mpmd %s ready: requests on %s, streams on %s, runs in %s, %d worker(s), "
            "queue %d, %s kernels, %s",
            MPP_VERSION, cfg->endpoint, cfg->stream_endpoint, cfg->db, cfg->workers, cfg->queue_max,
            cfg->portable_kernels || !mpm_kernels_avx2_available() ? "portable" : "avx2-fma",
            srv_auth_curve(d.auth) ? "CURVE" : "no authentication");
    int busy = 0; /* heavy reads left for the next turn */
    while (!stop_signal) {
        zmq_pollitem_t items[] = {{d.router, 0, ZMQ_POLLIN, 0},
                                  {d.xpub, 0, ZMQ_POLLIN, 0},
                                  {d.pull, 0, ZMQ_POLLIN, 0},
                                  {NULL, store_notify_fd(d.st), ZMQ_POLLIN, 0}};
        int n = zmq_poll(items, 4, busy ? 0 : 250);
        int perr = errno; /* the reload's file calls may change errno */
        if (hup_signal) {
            hup_signal = 0;
            srv_auth_reload(d.auth);
        }
        if (n < 0) {
            if (perr == EINTR) continue;
            srv_warn(0, "zmq_poll: %s", zmq_strerror(perr));
            break;
        }
        if (items[3].revents & ZMQ_POLLIN) store_notify_drain(d.st);
        if (items[2].revents & ZMQ_POLLIN) srv_stream_relay(&d, 10000);
        if (items[1].revents & ZMQ_POLLIN) srv_stream_on_xpub(&d);
        if (items[0].revents & ZMQ_POLLIN)
            for (int k = 0; k < ROUTER_BATCH && on_router(&d); k++) {
            }
        busy = d.pending ? serve_pending(&d, 1) : 0;
        trim_tick();
    }
    srv_log(0, "%s: shutting down",
            stop_signal == SIGINT    ? "SIGINT"
            : stop_signal == SIGTERM ? "SIGTERM"
                                     : "stopping");
    rc = 0;
out:
    if (d.pool) stop_jobs(&d); /* the pool exists only with all three sockets */
    close_socket(&d.pull, 0, "inproc");
    close_socket(&d.xpub, SHUTDOWN_LINGER_MS, "stream");
    /* the monitor stops before its socket closes: libzmq 4.3 leaks an
     * event it fails to send to a monitor that is going away */
    if (d.conns && d.router && zmq_socket_monitor(d.router, NULL, 0))
        srv_warn(0, "stopping the connection monitor: %s", zmq_strerror(errno));
    close_socket(&d.router, SHUTDOWN_LINGER_MS, "request");
    if (d.zctx) {
        while (zmq_ctx_term(d.zctx) && errno == EINTR) {
        }
    }
    srv_auth_destroy(&d.auth); /* its thread ended with the context */
    srv_stream_destroy(&d.stream);
    srv_conns_destroy(&d.conns);
    srv_outq_destroy(&d.outq); /* libzmq has freed every reply */
    store_close(&d.st);
    srv_budget_destroy(&d.budget); /* after the workers: they charge it */
    srv_log(0, "stopped (%llu requests, %llu malformed)", (unsigned long long)d.requests,
            (unsigned long long)d.bad_requests);
    return rc;
}
