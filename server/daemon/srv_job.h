/*
 * srv_job.h - a job, and its run on a worker thread (srv_job.c); the
 * stream topic of a job.  The pool (srv_pool.c) queues jobs and runs them
 * on its workers with srv_job_run().
 */
#ifndef SRV_JOB_H
#define SRV_JOB_H

#include "mpp_msg.h"
#include "srv_ckpt.h"
#include "srv_config.h"
#include "store.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

/* Length of a stream topic: "job:%016llx:" */
#define SRV_TOPIC_LEN 21
/* Writes the topic of a job into buf (SRV_TOPIC_LEN + 1 bytes). */
void srv_topic(uint64_t job, char *buf);
/* Parses a topic prefix of exactly SRV_TOPIC_LEN bytes; 0 if it is one. */
int srv_topic_parse(const char *buf, size_t len, uint64_t *job);

/* The error of a run that ended because the store lost writes (disk full,
 * I/O error); the reason follows it in the log and the Finished message. */
#define SRV_STORE_LOST "the run store lost writes (disk full or I/O error)"

/* Why a job stops before its next step (srv_job.cancel). */
enum { SRV_JOB_CANCEL_USER = 1, SRV_JOB_CANCEL_SHUTDOWN = 2 };

typedef struct srv_job {
    uint64_t id;
    mpp_case *sc;
    atomic_int cancel;  /* 0, SRV_JOB_CANCEL_USER, SRV_JOB_CANCEL_SHUTDOWN */
    atomic_int watched; /* someone subscribes to the job's stream */
    /* guarded by the pool mutex */
    int status;
    int64_t steps, steps_total;
    double t, wall_s, submitted_at, started_at;
    size_t particles, nodes;
    char owner[48];       /* who submitted it */
    struct srv_job *next; /* FIFO link */
    /* worker-private */
    uint64_t msg_seq, energy_seq;
    /* a resumed run (srv_pool_resume) */
    int resume;
    srv_ckpt_file ck;
    double prior_wall;
    mpm_energy_sample last; /* step -1: none */
} srv_job;

/* The last jobs that ended FAILED with SRV_STORE_LOST (a ring of
 * SRV_JOB_LOST_MAX, guarded by the pool's mutex): their end may not be in
 * the store (srv_pool_lost). */
#define SRV_JOB_LOST_MAX 64
typedef struct {
    struct {
        uint64_t id;
        int64_t steps;
        double t, wall_s;
    } v[SRV_JOB_LOST_MAX];
    unsigned n;
} srv_job_lost;

struct srv_budget;
/* What a job runs with: the pool's settings, store, disk budgets (NULL:
 * none), its mutex (guards the job's fields that Status reads) and its
 * ring of jobs the store lost. */
typedef struct {
    const srv_config *cfg;
    store *st;
    struct srv_budget *budget;
    pthread_mutex_t *mu;
    srv_job_lost *lost;
} srv_job_env;

/* Runs job j to its end on the calling worker thread, its stream messages
 * sent through push (the worker's PUSH socket). */
void srv_job_run(const srv_job_env *e, void *push, srv_job *j);
/* Frees a job (NULL: nothing). */
void srv_job_free(srv_job *j);

#endif
