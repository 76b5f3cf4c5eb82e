/*
 * srv_pool.c - job queue and worker threads (see srv_pool.h); what a
 * worker does with one job is srv_job.c's.
 *
 * Design.  One mutex guards the pool: the FIFO of queued jobs, the table of
 * running jobs (one slot per worker) and the fields of a job that Status
 * reads.  The main thread only ever holds it briefly (submit, info,
 * cancel, watch); a worker takes it to dequeue, to publish progress
 * figures, and to retire its job.  The per-step loop itself runs without
 * the lock: it reads the job's `cancel` and `watched` flags, which are
 * atomics.
 *
 * Each worker owns a PUSH socket connected to the main thread's PULL; it
 * sends with ZMQ_DONTWAIT, so a main thread that falls behind costs the
 * simulation nothing (srv_job.c).
 */
#include "srv_pool.h"

#include "srv_budget.h"
#include "srv_job.h"
#include "srv_log.h"

#include <errno.h>
#include <limits.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zmq.h>

typedef struct {
    srv_pool *pool;
    int index;
    pthread_t thread;
    int started;
} worker;

struct srv_pool {
    void *zctx;
    const srv_config *cfg;
    store *st;
    char events_ep[128];
    pthread_mutex_t mu;
    pthread_cond_t cv;
    srv_job *head, *tail; /* queued */
    size_t nqueued;
    srv_job **running; /* one slot per worker */
    /* jobs ended by the store's losses, whose end the store may not have
     * (a ring, guarded by mu) */
    srv_job_lost lost;
    worker *workers;
    int nworkers;
    srv_budget *budget; /* the disk budgets (NULL: none) */
    int stopping;
    int joined;
};

static void *worker_main(void *arg)
{
    worker *w = arg;
    srv_pool *p = w->pool;
    void *push = zmq_socket(p->zctx, ZMQ_PUSH);
    int hwm = 100000, linger = 2000;
    if (!push || zmq_setsockopt(push, ZMQ_SNDHWM, &hwm, sizeof hwm) ||
        zmq_setsockopt(push, ZMQ_LINGER, &linger, sizeof linger) ||
        zmq_connect(push, p->events_ep)) {
        srv_warn(0, "worker %d: cannot connect to %s: %s; worker not started", w->index,
                 p->events_ep, zmq_strerror(errno));
        if (push) zmq_close(push);
        return NULL;
    }
    for (;;) {
        pthread_mutex_lock(&p->mu);
        while (!p->head && !p->stopping) pthread_cond_wait(&p->cv, &p->mu);
        if (p->stopping) {
            pthread_mutex_unlock(&p->mu);
            break;
        }
        srv_job *j = p->head;
        p->head = j->next;
        if (!p->head) p->tail = NULL;
        p->nqueued--;
        j->next = NULL;
        j->status = MPP_STATUS_RUNNING;
        p->running[w->index] = j;
        pthread_mutex_unlock(&p->mu);

        srv_job_env env = {p->cfg, p->st, p->budget, &p->mu, &p->lost};
        srv_job_run(&env, push, j);

        pthread_mutex_lock(&p->mu);
        p->running[w->index] = NULL;
        pthread_mutex_unlock(&p->mu);
        srv_job_free(j);
    }
    zmq_close(push);
    return NULL;
}

srv_pool *srv_pool_new(void *zctx, const srv_config *cfg, store *st, const char *events_ep,
                       char *err, size_t errlen)
{
    srv_pool *p = calloc(1, sizeof *p);
    if (!p) {
        snprintf(err, errlen, "out of memory");
        return NULL;
    }
    p->zctx = zctx;
    p->cfg = cfg;
    p->st = st;
    snprintf(p->events_ep, sizeof p->events_ep, "%s", events_ep);
    p->nworkers = cfg->workers;
    if (pthread_mutex_init(&p->mu, NULL)) {
        free(p);
        snprintf(err, errlen, "cannot create a mutex");
        return NULL;
    }
    if (pthread_cond_init(&p->cv, NULL)) {
        pthread_mutex_destroy(&p->mu);
        free(p);
        snprintf(err, errlen, "cannot create a condition variable");
        return NULL;
    }
    p->running = calloc((size_t)p->nworkers, sizeof *p->running);
    p->workers = calloc((size_t)p->nworkers, sizeof *p->workers);
    if (!p->running || !p->workers) {
        snprintf(err, errlen, "out of memory");
        srv_pool_destroy(&p);
        return NULL;
    }
    for (int i = 0; i < p->nworkers; i++) {
        p->workers[i].pool = p;
        p->workers[i].index = i;
        if (pthread_create(&p->workers[i].thread, NULL, worker_main, &p->workers[i])) {
            snprintf(err, errlen, "cannot start worker thread %d of %d", i + 1, p->nworkers);
            srv_pool_destroy(&p);
            return NULL;
        }
        p->workers[i].started = 1;
    }
    return p;
}

void srv_pool_set_budget(srv_pool *p, srv_budget *b)
{
    pthread_mutex_lock(&p->mu);
    p->budget = b;
    pthread_mutex_unlock(&p->mu);
}

int srv_pool_has_room(srv_pool *p)
{
    return srv_pool_room(p) > 0;
}

int srv_pool_room(srv_pool *p)
{
    pthread_mutex_lock(&p->mu);
    int busy = 0;
    for (int i = 0; i < p->nworkers; i++) busy += p->running[i] != NULL;
    /* a job goes straight to an idle worker, or waits in the queue */
    long room = p->stopping
                    ? 0
                    : (long)p->nworkers + (long)p->cfg->queue_max - (long)p->nqueued - (long)busy;
    pthread_mutex_unlock(&p->mu);
    return room > 0 ? (int)(room > INT_MAX ? INT_MAX : room) : 0;
}

static srv_job *job_new(uint64_t id, double submitted_at, size_t particles, size_t nodes,
                        int watched, const char *owner)
{
    srv_job *j = calloc(1, sizeof *j);
    if (!j) return NULL;
    j->id = id;
    j->last.step = -1;
    snprintf(j->owner, sizeof j->owner, "%s", owner ? owner : "");
    atomic_init(&j->cancel, 0);
    atomic_init(&j->watched, watched != 0);
    j->status = MPP_STATUS_QUEUED;
    j->submitted_at = submitted_at;
    j->particles = particles;
    j->nodes = nodes;
    return j;
}

/* Queues j (taking *sc on success); on failure j is the caller's. */
static int job_enqueue(srv_pool *p, srv_job *j, mpp_case **sc)
{
    pthread_mutex_lock(&p->mu);
    int busy = 0;
    for (int i = 0; i < p->nworkers; i++) busy += p->running[i] != NULL;
    int rc = p->stopping ? MPM_EUNAVAIL
             : p->nqueued + (size_t)busy >= (size_t)p->nworkers + (size_t)p->cfg->queue_max
                 ? MPM_EFULL
                 : 0;
    if (!rc) {
        j->sc = *sc;
        *sc = NULL;
        j->steps_total = j->sc->has_end_time ? 0 : (int64_t)j->sc->steps;
        if (p->tail)
            p->tail->next = j;
        else
            p->head = j;
        p->tail = j;
        p->nqueued++;
        pthread_cond_signal(&p->cv);
    }
    pthread_mutex_unlock(&p->mu);
    return rc;
}

int srv_pool_submit(srv_pool *p, uint64_t id, mpp_case **sc, double submitted_at, size_t particles,
                    size_t nodes, int watched, const char *owner)
{
    srv_job *j = job_new(id, submitted_at, particles, nodes, watched, owner);
    if (!j) return MPM_ENOMEM;
    int rc = job_enqueue(p, j, sc);
    if (rc) free(j);
    return rc;
}

int srv_pool_resume(srv_pool *p, uint64_t id, mpp_case **sc, double submitted_at, size_t particles,
                    size_t nodes, int watched, const char *owner, srv_ckpt_file *ck,
                    double prior_wall_s, const mpm_energy_sample *last)
{
    srv_job *j = job_new(id, submitted_at, particles, nodes, watched, owner);
    if (!j) return MPM_ENOMEM;
    j->resume = 1;
    j->ck = *ck;
    j->prior_wall = prior_wall_s > 0 ? prior_wall_s : 0;
    if (last) j->last = *last;
    int rc = job_enqueue(p, j, sc);
    if (rc) {
        *ck = j->ck; /* still the caller's */
        free(j);
    } else {
        memset(ck, 0, sizeof *ck);
    }
    return rc;
}

static srv_job *find_locked(srv_pool *p, uint64_t id, srv_job **prev)
{
    if (prev) *prev = NULL;
    for (srv_job *j = p->head, *pv = NULL; j; pv = j, j = j->next)
        if (j->id == id) {
            if (prev) *prev = pv;
            return j;
        }
    for (int i = 0; i < p->nworkers; i++)
        if (p->running[i] && p->running[i]->id == id) return p->running[i];
    return NULL;
}

int srv_pool_owner_jobs(srv_pool *p, const char *owner)
{
    int n = 0;
    pthread_mutex_lock(&p->mu);
    for (srv_job *j = p->head; j; j = j->next) n += !strcmp(j->owner, owner);
    for (int i = 0; i < p->nworkers; i++)
        n += p->running[i] && !strcmp(p->running[i]->owner, owner);
    pthread_mutex_unlock(&p->mu);
    return n;
}

int srv_pool_info(srv_pool *p, uint64_t id, srv_job_info *out)
{
    pthread_mutex_lock(&p->mu);
    srv_job *j = find_locked(p, id, NULL);
    if (j) {
        out->status = j->status;
        out->steps = j->steps;
        out->steps_total = j->steps_total;
        out->t = j->t;
        out->wall_s = j->wall_s;
        out->submitted_at = j->submitted_at;
        out->started_at = j->started_at;
        out->particles = j->particles;
        out->nodes = j->nodes;
        out->dim = j->sc ? j->sc->c.grid.dim : 0;
        out->name = j->sc ? j->sc->name : "";
        memcpy(out->owner, j->owner, sizeof out->owner);
    }
    pthread_mutex_unlock(&p->mu);
    return j ? 0 : -1;
}

int srv_pool_job_owner(srv_pool *p, store *st, uint64_t job, char *who, size_t n)
{
    srv_job_info ji;
    if (srv_pool_info(p, job, &ji) == 0) {
        snprintf(who, n, "%s", ji.owner);
        return 0;
    }
    return store_run_owner(st, (int64_t)job, who, n) ? -1 : 0;
}

int srv_pool_cancel(srv_pool *p, uint64_t id, uint8_t **msg, size_t *len)
{
    *msg = NULL;
    *len = 0;
    pthread_mutex_lock(&p->mu);
    srv_job *prev, *j = find_locked(p, id, &prev);
    int rc = SRV_CANCEL_NONE;
    if (j && j->status == MPP_STATUS_QUEUED) {
        if (prev)
            prev->next = j->next;
        else
            p->head = j->next;
        if (p->tail == j) p->tail = prev;
        p->nqueued--;
        rc = SRV_CANCEL_QUEUED;
    } else if (j) {
        /* a shutdown already under way keeps its INTERRUPTED */
        int none = 0;
        atomic_compare_exchange_strong(&j->cancel, &none, SRV_JOB_CANCEL_USER);
        rc = SRV_CANCEL_RUNNING;
    }
    pthread_mutex_unlock(&p->mu);
    if (rc == SRV_CANCEL_QUEUED) {
        store_run_end end = {0};
        end.status = MPP_STATUS_CANCELLED;
        end.error = "cancelled by a client before it started";
        int src = store_run_finish(p->st, (int64_t)id, &end);
        if (src) srv_warn(id, "cancellation not recorded: %s", store_error()->message);
        mpp_finished f = {MPP_STATUS_CANCELLED, end.error, 0, 0, 0, NULL, 0, 0, NULL};
        if (mpp_stream_finished(id, j->msg_seq++, &f, msg, len))
            srv_warn(id, "out of memory encoding the end of the stream");
        if (j->resume && (srv_ckpt_remove(p->cfg->db, (int64_t)id) ||
                          store_run_checkpoint(p->st, (int64_t)id, NULL)))
            srv_warn(id, "its checkpoint not removed");
        else if (j->resume && p->budget) {
            int64_t none = j->ck.rec.bytes; /* its file no longer takes room */
            srv_budget_refund(p->budget, j->owner, &none, j->ck.rec.bytes);
        }
        srv_log(id, "cancelled while queued");
        srv_job_free(j);
    }
    return rc;
}

int srv_pool_lost(srv_pool *p, uint64_t id, srv_job_info *out)
{
    int rc = -1;
    pthread_mutex_lock(&p->mu);
    for (size_t i = 0; i < SRV_JOB_LOST_MAX; i++)
        if (p->lost.v[i].id == id && id) {
            memset(out, 0, sizeof *out);
            out->status = MPP_STATUS_FAILED;
            out->steps = p->lost.v[i].steps;
            out->t = p->lost.v[i].t;
            out->wall_s = p->lost.v[i].wall_s;
            rc = 0;
        }
    pthread_mutex_unlock(&p->mu);
    return rc;
}

void srv_pool_watch(srv_pool *p, uint64_t id, int on)
{
    pthread_mutex_lock(&p->mu);
    srv_job *j = find_locked(p, id, NULL);
    if (j) atomic_store(&j->watched, on);
    pthread_mutex_unlock(&p->mu);
}

void srv_pool_stop(srv_pool *p, srv_pool_publish_fn pub, void *arg)
{
    pthread_mutex_lock(&p->mu);
    p->stopping = 1;
    for (int i = 0; i < p->nworkers; i++)
        if (p->running[i]) {
            /* a user's cancel already under way stays CANCELLED */
            int none = 0;
            atomic_compare_exchange_strong(&p->running[i]->cancel, &none, SRV_JOB_CANCEL_SHUTDOWN);
        }
    srv_job *q = p->head;
    p->head = p->tail = NULL;
    p->nqueued = 0;
    pthread_cond_broadcast(&p->cv);
    pthread_mutex_unlock(&p->mu);
    while (q) {
        srv_job *nx = q->next;
        store_run_end end = {0};
        end.status = MPP_STATUS_INTERRUPTED;
        end.error = STORE_INTERRUPTED_QUEUED;
        int rc = store_run_finish(p->st, (int64_t)q->id, &end);
        if (rc) srv_warn(q->id, "interruption not recorded: %s", store_error()->message);
        srv_log(q->id, "interrupted while queued");
        if (pub) {
            mpp_finished f = {MPP_STATUS_INTERRUPTED, end.error, 0, 0, 0, NULL, 0, 0, NULL};
            uint8_t *msg = NULL;
            size_t len = 0;
            if (mpp_stream_finished(q->id, q->msg_seq++, &f, &msg, &len))
                srv_warn(q->id, "out of memory encoding the end of the stream");
            else
                pub(arg, q->id, msg, len);
        }
        srv_job_free(q);
        q = nx;
    }
}

int srv_pool_busy(srv_pool *p)
{
    int busy = 0;
    pthread_mutex_lock(&p->mu);
    for (int i = 0; i < p->nworkers; i++) busy += p->running[i] != NULL;
    pthread_mutex_unlock(&p->mu);
    return busy;
}

void srv_pool_shutdown(srv_pool *p)
{
    if (p->joined) return;
    srv_pool_stop(p, NULL, NULL);
    for (int i = 0; i < p->nworkers; i++)
        if (p->workers[i].started) pthread_join(p->workers[i].thread, NULL);
    p->joined = 1;
}

void srv_pool_destroy(srv_pool **pp)
{
    srv_pool *p = pp ? *pp : NULL;
    if (!p) return;
    if (p->workers && p->running) srv_pool_shutdown(p);
    pthread_cond_destroy(&p->cv);
    pthread_mutex_destroy(&p->mu);
    free(p->running);
    free(p->workers);
    free(p);
    *pp = NULL;
}
