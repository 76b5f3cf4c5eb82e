/*
 * srv_daemon.c - the daemon's main thread: sockets, requests, the stream.
 * This file starts and stops the daemon, owns the event loop, reads each
 * request and runs it in order (run_request); the rest of the main
 * thread's work has a file each, used from here down: srv_submit.c
 * (Submit, Resume), srv_read.c (reads, Cancel), srv_stream.c (the XPUB),
 * srv_pending.c (requests waiting for a commit), srv_reply.c (replies).
 * How it works: the notes after the includes.
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
#include "srv_pending.h"
#include "srv_pool.h"
#include "srv_read.h"
#include "srv_reply.h"
#include "srv_signal.h"
#include "srv_socket.h"
#include "srv_stream.h"
#include "srv_submit.h"
#include "store.h"

#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>
#include <zmq.h>

/*
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

#define EVENTS_EP "inproc://mpmd-events"
/* How long the last stream messages and replies may take to leave at
 * shutdown (a vanished peer holds the exit up this long, no longer). */
#define SHUTDOWN_LINGER_MS 1000

/* Requests read per turn of the loop at most (a cheap one is answered as
 * it is read; the heavy reads wait in srv_pending.c). */
#define ROUTER_BATCH 64

static int is_read(mpp_req_kind k)
{
    return k == MPP_REQ_CANCEL || k == MPP_REQ_STATUS || k == MPP_REQ_GET_RUN ||
           k == MPP_REQ_LIST_RUNS || k == MPP_REQ_GET_ENERGY || k == MPP_REQ_GET_SNAPSHOT;
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
        if (rq->kind == MPP_REQ_CANCEL && srv_cancel_job(d, id, owner, rq->id)) return 1;
        *ticket = store_ticket(d->st, rq->kind == MPP_REQ_LIST_RUNS ? 0 : (int64_t)rq->id);
        *begun = 1;
    }
    if (!store_ticket_done(d->st, *ticket)) return 0;
    srv_answer_read(d, id, owner, rq);
    return 1;
}

/* Runs a decoded request, in arrival order per client: behind a waiting
 * request of the same client it queues; a read whose writes are not yet
 * committed queues; everything else is answered now. */
static void dispatch(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq)
{
    int begun = 0;
    uint64_t ticket = 0;
    if (srv_pending_waits(d, id) || srv_request_heavy(rq->kind) ||
        !run_request(d, id, owner, rq, &begun, &ticket))
        srv_pending_add(d, id, owner, rq, begun, ticket);
}

static void handle_request(daemon_t *d, zmq_msg_t *id, const char *owner, const void *data,
                           size_t size)
{
    mpp_request rq;
    d->requests++;
    srv_trim_note(size);
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
    srv_pool_stop(d->pool, srv_stream_publish, d);
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
        if (d->pending) srv_pending_serve(d, 0, run_request);
    }
    srv_pool_destroy(&d->pool);
    srv_stream_relay(d, 0);
    srv_pending_drain(d, run_request);
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
    srv_signal_install();
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
    while (!srv_signal_stop()) {
        zmq_pollitem_t items[] = {{d.router, 0, ZMQ_POLLIN, 0},
                                  {d.xpub, 0, ZMQ_POLLIN, 0},
                                  {d.pull, 0, ZMQ_POLLIN, 0},
                                  {NULL, store_notify_fd(d.st), ZMQ_POLLIN, 0}};
        int n = zmq_poll(items, 4, busy ? 0 : 250);
        int perr = errno; /* the reload's file calls may change errno */
        if (srv_signal_hup()) srv_auth_reload(d.auth);
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
        busy = d.pending ? srv_pending_serve(&d, 1, run_request) : 0;
        srv_trim_tick();
    }
    srv_log(0, "%s: shutting down",
            srv_signal_stop() == SIGINT    ? "SIGINT"
            : srv_signal_stop() == SIGTERM ? "SIGTERM"
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
