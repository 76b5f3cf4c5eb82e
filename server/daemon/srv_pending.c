/*
 * srv_pending.c - the daemon's queue of requests waiting off the event
 * loop (d->pending): a read until the store has committed the writes its
 * run had enqueued when it began (store_ticket), a Submit or Resume until
 * the write that records it is done (srv_after_write), and any request
 * behind a waiting one of the same client, so that each client gets its
 * replies in order.  The heavy reads (listings, energy pages, snapshots)
 * always wait here and run HEAVY_SLICE_S per turn of the loop.  What a
 * request does is the caller's (a srv_run_fn: srv_daemon.c's
 * run_request), so this queue calls no request handler by name.  Main
 * thread only.  Guarded by daemon_replies_listings_keep_loop and the
 * daemon_disk_* tests (a Submit told only once its row is committed).
 */
#include "srv_pending.h"

#include "srv_log.h"
#include "srv_reply.h"
#include "store.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zmq.h>

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

/* The waiting request srv_pending_serve() is carrying on (main thread only). */
static struct pending *serving;

int srv_request_heavy(mpp_req_kind k)
{
    return k == MPP_REQ_LIST_RUNS || k == MPP_REQ_GET_ENERGY || k == MPP_REQ_GET_SNAPSHOT;
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

/* Queues a request (taken over: *rq is emptied; NULL: a write's wait); on
 * failure answers UNAVAILABLE (a request) and returns NULL. */
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
        /* a queued Submit carried on by srv_pending_serve(): it waits in its
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

int srv_pending_serve(daemon_t *d, int sliced, srv_run_fn run)
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
        } else if (spent && srv_request_heavy(p->rq.kind)) {
            left = 1;
        } else if (!peer_waits(d, &p->id, p)) {
            int heavy = srv_request_heavy(p->rq.kind);
            serving = p;
            done = run(d, &p->id, p->owner, &p->rq, &p->begun, &p->ticket);
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

void srv_pending_drain(daemon_t *d, srv_run_fn run)
{
    if (!d->pending) return;
    store_flush(d->st);
    srv_pending_serve(d, 0, run);
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

int srv_pending_waits(daemon_t *d, zmq_msg_t *id)
{
    return peer_waits(d, id, NULL);
}

void srv_pending_add(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq, int begun,
                     uint64_t ticket)
{
    enqueue(d, id, owner, rq, begun, ticket);
}
