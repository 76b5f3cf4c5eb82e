/*
 * t_team.c - the team's barrier (mpm_bar, solver/mpm_team.c): it
 * spins briefly, yields, then sleeps.  Every thread must see what every
 * other thread wrote before the barrier, in every round, whether the
 * waiters were still spinning (rounds that end within microseconds) or
 * already asleep (a thread that arrives milliseconds late), and with more
 * threads than CPUs.
 */
#include "mpm_team.h"
#include "t.h"

#include <pthread.h>
#include <stdlib.h>
#include <time.h>

#define NT 4         /* threads: more than the 2 CPUs of the test machines */
#define ROUNDS 20000 /* fast rounds */
#define SLOW 8       /* rounds in which one thread arrives 1.5 ms late */

typedef struct {
    mpm_bar bar;
    long slot[NT][8]; /* one cache line per thread: what it wrote this round */
    long bad[NT];     /* values a thread read that were not the round's */
} team_test;

typedef struct {
    team_test *tt;
    int tid;
} targ;

static void *member(void *arg)
{
    targ *a = arg;
    team_test *tt = a->tt;
    for (long r = 1; r <= ROUNDS + SLOW; r++) {
        if (r > ROUNDS && a->tid == (int)(r % NT)) {
            struct timespec d = {0, 1500000};
            nanosleep(&d, NULL);
        }
        tt->slot[a->tid][0] = r; /* plain stores: the barrier must order them */
        mpm_bar_wait(&tt->bar);
        for (int u = 0; u < NT; u++) tt->bad[a->tid] += tt->slot[u][0] != r;
        mpm_bar_wait(&tt->bar); /* nobody writes round r + 1 before all have read */
    }
    return NULL;
}

TEST(team_barrier_orders_memory)
{
    team_test *tt = calloc(1, sizeof *tt);
    CHECK(tt != NULL);
    if (mpm_bar_init(&tt->bar, NT)) {
        free(tt);
        CHECKF(0, "mpm_bar_init failed");
    }
    pthread_t th[NT];
    targ args[NT];
    int started = 0;
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (; started < NT; started++) {
        args[started] = (targ){tt, started};
        if (pthread_create(&th[started], NULL, member, &args[started])) break;
    }
    /* a thread that could not start would leave the others at the barrier */
    if (started < NT) {
        fprintf(stderr, "    pthread_create failed after %d threads\n", started);
        abort();
    }
    for (int t = 0; t < NT; t++) pthread_join(th[t], NULL);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    long bad = 0;
    for (int t = 0; t < NT; t++) bad += tt->bad[t];
    double s = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    TLOG("%d threads, %d rounds of two barriers (%d with a thread 1.5 ms late): %.3f s, "
         "%ld stale reads",
         NT, ROUNDS + SLOW, SLOW, s, bad);
    mpm_bar_destroy(&tt->bar);
    free(tt);
    CHECKF(bad == 0, "%ld reads saw another round's value", bad);
}
