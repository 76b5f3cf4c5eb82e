/*
 * mpm_team.c - the thread team that runs a simulation's passes.
 *
 * A simulation with nthreads > 1 keeps nthreads - 1 worker threads for its
 * whole life; the caller's thread is thread 0.  mpm_team_run() hands the
 * team one phase: every thread runs fn(s, tid) between two barriers
 * (bar_start, bar_end), and the phase's passes meet at bar_end in between
 * (mpm_team_sync()).  The workers are started behind a gate that opens
 * only once all of them exist, so a failed pthread_create() leaves no
 * thread waiting at a barrier of the wrong size: the started ones are
 * released through the gate, joined, and the simulation stays serial.
 * The barriers spin briefly before they sleep (mpm_bar, mpm_team.h).
 */
#include "mpm_team.h"
#include "mpm_internal.h"

#include <sched.h>
#include <stdlib.h>
#include <time.h>

int mpm_bar_init(mpm_bar *b, unsigned n)
{
    atomic_init(&b->count, 0);
    atomic_init(&b->gen, 0);
    b->n = n;
    if (pthread_mutex_init(&b->mu, NULL)) return -1;
    if (pthread_cond_init(&b->cv, NULL)) {
        pthread_mutex_destroy(&b->mu);
        return -1;
    }
    return 0;
}

void mpm_bar_destroy(mpm_bar *b)
{
    pthread_cond_destroy(&b->cv);
    pthread_mutex_destroy(&b->mu);
}

static long elapsed_ns(const struct timespec *t0)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (t.tv_sec - t0->tv_sec) * 1000000000L + (t.tv_nsec - t0->tv_nsec);
}

static inline void cpu_relax(void)
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
}

void mpm_bar_wait(mpm_bar *b)
{
    unsigned g = atomic_load_explicit(&b->gen, memory_order_acquire);
    if (atomic_fetch_add_explicit(&b->count, 1, memory_order_acq_rel) + 1 == b->n) {
        /* the last: the others read count only after they see gen move */
        atomic_store_explicit(&b->count, 0, memory_order_relaxed);
        pthread_mutex_lock(&b->mu);
        atomic_store_explicit(&b->gen, g + 1, memory_order_release);
        pthread_cond_broadcast(&b->cv);
        pthread_mutex_unlock(&b->mu);
        return;
    }
    struct timespec t0;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (unsigned i = 1;; i++) {
        if (atomic_load_explicit(&b->gen, memory_order_acquire) != g) return;
        cpu_relax();
        if (!(i & 63)) {
            if (elapsed_ns(&t0) > MPM_BAR_SPIN_NS) break;
            /* let the thread we wait for run if it shares our CPU
             * (more threads than CPUs: spinning alone slowed a 2-thread
             * job beside another) */
            sched_yield();
        }
    }
    pthread_mutex_lock(&b->mu);
    while (atomic_load_explicit(&b->gen, memory_order_acquire) == g)
        pthread_cond_wait(&b->cv, &b->mu);
    pthread_mutex_unlock(&b->mu);
}

typedef struct {
    mpm_sim *s;
    int tid;
} worker_arg;

static void *worker(void *arg)
{
    worker_arg wa = *(worker_arg *)arg;
    mpm_sim *s = wa.s;
    free(arg);
    /* the gate opens (1) once every thread exists, or aborts (-1) */
    pthread_mutex_lock(&s->gate_mu);
    while (s->gate == 0) pthread_cond_wait(&s->gate_cv, &s->gate_mu);
    int go = s->gate > 0;
    pthread_mutex_unlock(&s->gate_mu);
    if (!go) return NULL;
    for (;;) {
        mpm_bar_wait(&s->bar_start);
        if (s->quit) break;
        s->phase(s, wa.tid);
        mpm_bar_wait(&s->bar_end);
    }
    return NULL;
}

void mpm_team_run(mpm_sim *s, mpm_phase_fn fn)
{
    if (s->nthreads == 1) {
        fn(s, 0);
        return;
    }
    s->phase = fn;
    mpm_bar_wait(&s->bar_start);
    fn(s, 0);
    mpm_bar_wait(&s->bar_end);
}

static void open_gate(mpm_sim *s, int v)
{
    pthread_mutex_lock(&s->gate_mu);
    s->gate = v;
    pthread_cond_broadcast(&s->gate_cv);
    pthread_mutex_unlock(&s->gate_mu);
}

int mpm_team_start(mpm_sim *s)
{
    int T = s->nthreads, started = 1, rc = 0;
    if (T == 1) return 0;
    if (!(s->threads = calloc((size_t)T, sizeof *s->threads))) return MPM_ENOMEM;
    if (pthread_mutex_init(&s->gate_mu, NULL)) return MPM_ENOMEM;
    if (pthread_cond_init(&s->gate_cv, NULL)) {
        pthread_mutex_destroy(&s->gate_mu);
        return MPM_ENOMEM;
    }
    s->sync_init = 1;
    if (mpm_bar_init(&s->bar_start, (unsigned)T)) return MPM_ENOMEM;
    if (mpm_bar_init(&s->bar_end, (unsigned)T)) {
        mpm_bar_destroy(&s->bar_start);
        return MPM_ENOMEM;
    }
    s->sync_init = 2;
    for (; started < T; started++) {
        worker_arg *wa = malloc(sizeof *wa);
        if (!wa) {
            rc = MPM_ENOMEM;
            break;
        }
        wa->s = s;
        wa->tid = started;
        if (pthread_create(&s->threads[started], NULL, worker, wa)) {
            free(wa);
            rc = MPM_ENOMEM;
            break;
        }
    }
    if (rc) {
        open_gate(s, -1);
        for (int t = 1; t < started; t++) pthread_join(s->threads[t], NULL);
        free(s->threads);
        s->threads = NULL;
        return rc;
    }
    open_gate(s, 1);
    return 0;
}

void mpm_team_stop(mpm_sim *s)
{
    if (s->threads) {
        s->quit = 1;
        mpm_bar_wait(&s->bar_start);
        for (int t = 1; t < s->nthreads; t++) pthread_join(s->threads[t], NULL);
        free(s->threads);
        s->threads = NULL;
    }
    if (s->sync_init >= 2) {
        mpm_bar_destroy(&s->bar_start);
        mpm_bar_destroy(&s->bar_end);
    }
    if (s->sync_init >= 1) {
        pthread_mutex_destroy(&s->gate_mu);
        pthread_cond_destroy(&s->gate_cv);
    }
    s->sync_init = 0;
}
