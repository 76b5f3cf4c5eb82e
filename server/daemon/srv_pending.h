/*
 * srv_pending.h - the queue of requests waiting for a commit or behind
 * another request of their client (srv_pending.c).  Main thread only.
 */
#ifndef SRV_PENDING_H
#define SRV_PENDING_H

#include "srv_daemon_int.h"

#include <stdint.h>
#include <zmq.h>

/* Carries a request as far as it can go now: 1 when it is answered, 0
 * when its reply waits for *ticket; *begun says its action is done and
 * its ticket taken (srv_daemon.c's run_request). */
typedef int (*srv_run_fn)(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq,
                          int *begun, uint64_t *ticket);

/* Reads that cost the loop many store reads or bytes (ListRuns,
 * GetEnergy, GetSnapshot): they always wait in the queue, where
 * srv_pending_serve() runs them HEAVY_SLICE_S at a time, and the loop
 * reads new requests (a Ping is answered at once) in between. */
int srv_request_heavy(mpp_req_kind k);
/* 1 if a request of this client waits (a later one must wait behind it). */
int srv_pending_waits(daemon_t *d, zmq_msg_t *id);
/* Queues a request (taken over: *rq is emptied), its action begun or not
 * and its ticket; when the queue is full answers UNAVAILABLE. */
void srv_pending_add(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq, int begun,
                     uint64_t ticket);
/* Carries on the waiting requests whose writes are committed, in arrival
 * order per client, with run.  sliced: after HEAVY_SLICE_S of heavy reads
 * the rest wait for the next turn of the loop (returns 1 when some are
 * left that could go now), so that new requests are read in between. */
int srv_pending_serve(daemon_t *d, int sliced, srv_run_fn run);
/* Answers every waiting request after a last flush (shutdown). */
void srv_pending_drain(daemon_t *d, srv_run_fn run);

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

#endif
