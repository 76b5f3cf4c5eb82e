/*
 * srv_pool.h - the job queue and the worker threads that run jobs.
 *
 * The main thread submits checked cases; a bounded FIFO holds them until a
 * worker is free.  Each worker runs one job at a time with the solver,
 * records its energies, progress, snapshots and end in the store, and
 * publishes its stream messages to the main thread over an inproc PUSH
 * socket of its own (frames: topic, StreamMsg bytes); the main thread
 * forwards them to the stream socket.  No ZeroMQ socket is shared between
 * threads.  A job is cancelled between two steps.
 */
#ifndef SRV_POOL_H
#define SRV_POOL_H

#include <stddef.h>
#include <stdint.h>

#include "mpp_msg.h"
#include "srv_ckpt.h"
#include "srv_config.h"
#include "srv_job.h"
#include "store.h"

/* What Cancel found. */
enum { SRV_CANCEL_NONE = 0, SRV_CANCEL_QUEUED = 1, SRV_CANCEL_RUNNING = 2 };

/* A live job's state, for Status replies. */
typedef struct {
    int status; /* mpp_status: QUEUED or RUNNING */
    int64_t steps, steps_total;
    double t, wall_s, submitted_at, started_at;
    size_t particles, nodes;
    int dim;
    const char *name; /* valid until the next pool call */
    char owner[48];   /* who submitted it (srv_pool_submit) */
} srv_job_info;

typedef struct srv_pool srv_pool;

/* Starts cfg->workers threads whose PUSH sockets connect to events_ep
 * (bound by the caller).  Returns NULL with a message on failure. */
srv_pool *srv_pool_new(void *zctx, const srv_config *cfg, store *st, const char *events_ep,
                       char *err, size_t errlen);

/* The disk budgets the workers charge each recorded write to (see
 * srv_budget.h); call before the first submit.  NULL: none. */
struct srv_budget;
void srv_pool_set_budget(srv_pool *p, struct srv_budget *b);

/* Queues job `id` (its run record already inserted); watched: somebody
 * subscribed to its stream already; owner: who submitted it (a CURVE key
 * in Z85, or "local"; at most 47 bytes kept).  Takes ownership of *sc (set
 * to NULL) on success.  Returns 0, MPM_EFULL or MPM_EUNAVAIL. */
int srv_pool_submit(srv_pool *p, uint64_t id, mpp_case **sc, double submitted_at, size_t particles,
                    size_t nodes, int watched, const char *owner);

/* Queues run `id` again to continue from checkpoint *ck (read and
 * verified by srv_ckpt_read(); the run already set 'queued' by
 * store_run_resume()), as srv_pool_submit() does a new one: the worker
 * builds the simulation from *sc, loads the checkpoint (a blob the solver
 * refuses ends the job INTERRUPTED again, its checkpoint kept, the reason
 * in its error), numbers its energy samples from ck->rec.energy_seq on and
 * adds its wall time to prior_wall_s.  last: the run's last energy sample
 * before the checkpoint (NULL: none).  Takes ownership of *sc and of
 * ck's buffer (both emptied) on success. */
int srv_pool_resume(srv_pool *p, uint64_t id, mpp_case **sc, double submitted_at, size_t particles,
                    size_t nodes, int watched, const char *owner, srv_ckpt_file *ck,
                    double prior_wall_s, const mpm_energy_sample *last);

/* Number of queued and running jobs whose owner is `owner`. */
int srv_pool_owner_jobs(srv_pool *p, const char *owner);

/* 1 if the queue has room for another job. */
int srv_pool_has_room(srv_pool *p);
/* How many more jobs it takes now (idle workers and free queue places). */
int srv_pool_room(srv_pool *p);

/* State of a queued or running job: 0, or -1 if it is not live. */
int srv_pool_info(srv_pool *p, uint64_t id, srv_job_info *out);

/* Who submitted a job (live: the pool's; else the store's): 0 with it in
 * who, or -1 if there is no such job. */
int srv_pool_job_owner(srv_pool *p, store *st, uint64_t job, char *who, size_t n);

/* Cancels a live job.  A queued one is removed and recorded CANCELLED at
 * once, and *msg / *len get its Finished stream message for the caller to
 * publish (free() it); a running one stops before its next step.  Returns
 * SRV_CANCEL_NONE, SRV_CANCEL_QUEUED or SRV_CANCEL_RUNNING. */
int srv_pool_cancel(srv_pool *p, uint64_t id, uint8_t **msg, size_t *len);

/* A job that ended FAILED with SRV_STORE_LOST lately (its end may not be
 * in the store: the disk was full): its status, steps, t and wall time in
 * *out (name unset), 0; -1 if it is not one of the last 64 such jobs. */
int srv_pool_lost(srv_pool *p, uint64_t id, srv_job_info *out);

/* Somebody subscribed to (on = 1) or left (on = 0) the job's stream. */
void srv_pool_watch(srv_pool *p, uint64_t id, int on);

/* Called for each stream message the pool hands back to the main thread
 * (topic of job `id`): publish msg (len bytes), then free() it. */
typedef void (*srv_pool_publish_fn)(void *arg, uint64_t id, uint8_t *msg, size_t len);

/* Begins the shutdown without waiting: no job is accepted any more,
 * running jobs are told to end INTERRUPTED before their next step (their
 * workers first save a checkpoint of a run that takes them, unless its
 * last one is of the current step, then publish Finished as usual), and queued ones are recorded
 * INTERRUPTED at once, each with its Finished message passed to publish
 * (may be NULL: dropped).  Idempotent. */
void srv_pool_stop(srv_pool *p, srv_pool_publish_fn publish, void *arg);

/* Number of jobs still running (0 once every worker is done with its
 * job, so its last stream message has been sent). */
int srv_pool_busy(srv_pool *p);

/* Stops (srv_pool_stop without publishing) if not done yet and joins the
 * workers. */
void srv_pool_shutdown(srv_pool *p);

/* Shuts down if needed and frees the pool; nulls the pointer. */
void srv_pool_destroy(srv_pool **p);

#endif
