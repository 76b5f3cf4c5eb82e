/*
 * srv_daemon_int.h - the daemon's state (daemon_t, owned by srv_daemon.c's
 * event loop, used on the main thread only), which the main thread's
 * files share.  It declares no function of theirs: each declares its own
 * in its header, from the bottom up srv_reply.h (replies), srv_pending.h
 * (requests waiting for a commit), srv_stream.h (the stream socket),
 * srv_submit.h (Submit, Resume), srv_read.h (reads, Cancel), so that they
 * depend on each other one way (tests/include_graph.py checks it).  Not an
 * API: only the daemon's main-thread files include it.
 */
#ifndef SRV_DAEMON_INT_H
#define SRV_DAEMON_INT_H

#include "mpp_msg.h"
#include "srv_auth.h"
#include "srv_budget.h"
#include "srv_config.h"
#include "srv_pool.h"
#include "srv_signal.h"
#include "store.h"

#include <stddef.h>
#include <stdint.h>
#include <zmq.h>

/* Size of an owner string: a Z85 key or SRV_OWNER_LOCAL, with its NUL. */
#define OWNER_SIZE 48

typedef struct {
    const srv_config *cfg;
    void *zctx, *router, *xpub, *pull;
    store *st;
    srv_pool *pool;
    srv_auth *auth;
    srv_budget *budget;      /* the disk budgets */
    struct srv_outq *outq;   /* unread replies' bytes (srv_outq.h) */
    struct srv_conns *conns; /* request connections counted (srv_conns.h) */
    int stopping;            /* shutting down: no new jobs */
    uint64_t requests, bad_requests;
    struct pending *pending, **pending_tail; /* reads waiting for a commit */
    size_t npending;
    struct srv_stream *stream; /* the stream's subscriptions */
} daemon_t;

/* 1 once a signal asked the daemon to stop or it is shutting down: no new
 * jobs. */
static inline int srv_daemon_stopping(const daemon_t *d)
{
    return srv_signal_stop() || d->stopping;
}

/* What a Submit or a Resume does once the write that records it is done:
 * rc 0 when it is committed, else store_write_result()'s code (MPM_EIO:
 * its transaction was lost, e.g. the disk is full; MPM_ECONFLICT: refused;
 * MPM_EUNAVAIL: the daemon stops first) with why; it answers the client
 * and frees arg (srv_pending.h). */
typedef void (*srv_write_fn)(daemon_t *d, zmq_msg_t *id, const char *owner, int rc, const char *why,
                             void *arg);

#endif
