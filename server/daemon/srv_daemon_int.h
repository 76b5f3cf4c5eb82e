/*
 * srv_daemon_int.h - what the daemon's files share inside it: the daemon's
 * state (daemon_t, owned by srv_daemon.c's event loop, used on the main
 * thread only), the reply helpers, and the request handlers that live
 * outside srv_daemon.c (srv_submit.c: Submit and Resume).  Not an API:
 * nothing outside server/daemon/srv_daemon*.c, srv_submit.c and srv_stream.c includes it.
 */
#ifndef SRV_DAEMON_INT_H
#define SRV_DAEMON_INT_H

#include "mpp_msg.h"
#include "srv_auth.h"
#include "srv_budget.h"
#include "srv_config.h"
#include "srv_pool.h"
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
int srv_daemon_stopping(const daemon_t *d);

/* Sends one reply (buf, len; freed; NULL: out of memory, logged) to the
 * client whose identity frame is id. */
void srv_send_reply(daemon_t *d, zmq_msg_t *id, uint8_t *buf, size_t len);
/* Answers with the Error reply of an mpm_error (wire code, camelCase
 * field and text from the protocol library). */
void srv_reply_mpm_error(daemon_t *d, zmq_msg_t *id, const mpm_error *e);
/* Answers with an error: code an MPM_E* code, field a path in the schema's
 * spelling ("" or NULL: none), the message without the field. */
void srv_reply_error(daemon_t *d, zmq_msg_t *id, int code, const char *field, const char *fmt, ...)
    __attribute__((format(printf, 5, 6)));
/* What a Submit or a Resume does once the write that records it is done:
 * rc 0 when it is committed, else store_write_result()'s code (MPM_EIO:
 * its transaction was lost, e.g. the disk is full; MPM_ECONFLICT: refused;
 * MPM_EUNAVAIL: the daemon stops first) with why; it answers the client
 * and frees arg. */
typedef void (*srv_write_fn)(daemon_t *d, zmq_msg_t *id, const char *owner, int rc, const char *why,
                             void *arg);
/* Calls fn(arg) once the store is done with write seq (store_last_write()
 * after the write of run `run`): at once if it is, else from the event
 * loop, later requests of the same client waiting behind it.  So a client
 * is told "accepted" only once its run's record is committed, and told
 * why not when the commit failed. */
void srv_after_write(daemon_t *d, zmq_msg_t *id, const char *owner, int64_t run, uint64_t seq,
                     srv_write_fn fn, void *arg);
/* Submits and resumes of owner (NULL: anyone's) waiting for their commit:
 * counted in its job quota and against the pool's room. */
int srv_writes_waiting(const daemon_t *d, const char *owner);
/* Unix time now, in seconds. */
double srv_wall_now(void);

/* Who submitted a job (live: the pool's; else the store's): 0 with it in
 * who, or -1 if there is no such job. */
int srv_job_owner(daemon_t *d, uint64_t job, char *who, size_t n);
/* The stream socket's subscription messages (at most a budget of them a
 * call) and the relay of the workers' stream messages to it (budget
 * frames, 0: until none is left): srv_stream.c. */
void srv_stream_on_xpub(daemon_t *d);
void srv_stream_relay(daemon_t *d, long budget);

/* Submit: checks the case, the limits, the quotas and the disk budgets,
 * records the run and queues its job; answers SubmitOk or an Error. */
void srv_do_submit(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq);
/* Resume: an INTERRUPTED run of the requester's (or any, for an admin key)
 * goes on from its checkpoint file; answers SubmitOk or an Error. */
void srv_do_resume(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq);

#endif
