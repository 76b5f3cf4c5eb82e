/*
 * triad.c - the STREAM-style triad of bin/mpmbench: the memory
 * bandwidth roof the rows' modelled particle traffic is set against,
 * measured in the same process run, on the same number of threads, before
 * the scenes.  a[i] = b[i] + s c[i] over three arrays of doubles, each
 * thread owning one contiguous slice of each array, which it also touches
 * first (so the pages sit where that thread runs, as the solver's
 * particle slices do).  One untimed pass, then PB_TRIAD_REPS timed passes
 * between barriers; the median counts 24 bytes per element (read b and c,
 * write a: STREAM's counting, without the write-allocate read of a).
 * How it works: the notes after the includes.
 */
#include "perf.h"

#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

/*
 * Array size: each array at least 4x the last-level cache (the largest
 * cache of /sys/devices/system/cpu/cpu0/cache, else sysconf) and at least
 * 64 MiB, capped so that the three fit in a quarter of the physical
 * memory; MPMBENCH_TRIAD_MIB overrides it (MiB per array, for quick runs:
 * a size inside the cache measures the cache, not the memory).  The
 * arrays are mapped for the measurement and unmapped at once, so that the
 * forked children that measure the scenes do not start with them resident;
 * they are advised to transparent huge pages, which cut the first touch of
 * 3 x 1920 MiB on this VM from ~12 s to a fraction (and can only make the
 * roof higher, the rows' fraction of it lower: the conservative side).
 */

#define MIB (1024.0 * 1024.0)

/* "32K", "4096K", "480M" -> bytes; 0 when unreadable */
static double cache_file_bytes(const char *path)
{
    FILE *f = fopen(path, "r");
    if (!f) return 0;
    double v = 0;
    char unit = 0;
    int k = fscanf(f, "%lf%c", &v, &unit);
    fclose(f);
    if (k < 1) return 0;
    if (unit == 'K' || unit == 'k') v *= 1024.0;
    if (unit == 'M' || unit == 'm') v *= MIB;
    if (unit == 'G' || unit == 'g') v *= 1024.0 * MIB;
    return v;
}

double pb_llc_bytes(void)
{
    double best = 0;
    for (int i = 0; i < 16; i++) {
        char path[128];
        snprintf(path, sizeof path, "/sys/devices/system/cpu/cpu0/cache/index%d/size", i);
        double b = cache_file_bytes(path);
        if (b > best) best = b;
    }
#ifdef _SC_LEVEL3_CACHE_SIZE
    if (best <= 0) {
        long l3 = sysconf(_SC_LEVEL3_CACHE_SIZE), l2 = sysconf(_SC_LEVEL2_CACHE_SIZE);
        best = l3 > 0 ? (double)l3 : l2 > 0 ? (double)l2 : 0;
    }
#endif
    return best;
}

size_t pb_triad_elements(void)
{
    const char *env = getenv("MPMBENCH_TRIAD_MIB");
    if (env && *env) {
        double mib = strtod(env, NULL);
        if (mib >= 1) return (size_t)(mib * MIB / sizeof(double));
    }
    double bytes = 4 * pb_llc_bytes();
    if (bytes < 64 * MIB) bytes = 64 * MIB;
    long pages = sysconf(_SC_PHYS_PAGES), psz = sysconf(_SC_PAGESIZE);
    if (pages > 0 && psz > 0) {
        double cap = (double)pages * (double)psz / 4 / 3;
        if (bytes > cap) bytes = cap;
    }
    return (size_t)(bytes / sizeof(double));
}

typedef struct {
    double *a, *b, *c;
    size_t n;
    int nthreads;
    pthread_barrier_t bar;
    pthread_mutex_t mu; /* the gate: every thread started (ok), or not */
    pthread_cond_t cv;
    int go, ok;
    double t[PB_TRIAD_REPS + 2]; /* barrier times (thread 0) */
} triad_job;

typedef struct {
    triad_job *j;
    int tid;
} triad_arg;

static void *triad_thread(void *p)
{
    triad_arg *ta = p;
    triad_job *j = ta->j;
    size_t lo = j->n * (size_t)ta->tid / (size_t)j->nthreads;
    size_t hi = j->n * (size_t)(ta->tid + 1) / (size_t)j->nthreads;
    double *restrict a = j->a, *restrict b = j->b, *restrict c = j->c;
    const double s = 3.0;
    pthread_mutex_lock(&j->mu);
    while (!j->go) pthread_cond_wait(&j->cv, &j->mu);
    int ok = j->ok;
    pthread_mutex_unlock(&j->mu);
    if (!ok) return NULL;
    for (size_t i = lo; i < hi; i++) { /* first touch */
        a[i] = 1.0;
        b[i] = 2.0;
        c[i] = 0.5;
    }
    for (int r = 0; r < PB_TRIAD_REPS + 1; r++) { /* pass 0: untimed */
        pthread_barrier_wait(&j->bar);
        if (ta->tid == 0) j->t[r] = pb_now();
        for (size_t i = lo; i < hi; i++) a[i] = b[i] + s * c[i];
    }
    pthread_barrier_wait(&j->bar);
    if (ta->tid == 0) j->t[PB_TRIAD_REPS + 1] = pb_now();
    return NULL;
}

int pb_triad_measure(int threads, pb_triad *out)
{
    memset(out, 0, sizeof *out);
    out->threads = threads;
    triad_job j;
    memset(&j, 0, sizeof j);
    j.n = pb_triad_elements();
    j.nthreads = threads;
    size_t bytes = j.n * sizeof(double);
    void *m = mmap(NULL, 3 * bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (m == MAP_FAILED) {
        snprintf(out->msg, sizeof out->msg, "mmap of 3 x %.0f MiB: %s", bytes / MIB,
                 strerror(errno));
        return -1;
    }
#ifdef MADV_HUGEPAGE
    madvise(m, 3 * bytes, MADV_HUGEPAGE); /* fewer page faults (advice; may be ignored) */
#endif
    j.a = m;
    j.b = j.a + j.n;
    j.c = j.b + j.n;
    pthread_t th[MPM_MAX_THREADS];
    triad_arg args[MPM_MAX_THREADS];
    int started = 0;
    if (threads < 1 || threads > MPM_MAX_THREADS || pthread_barrier_init(&j.bar, NULL, threads)) {
        snprintf(out->msg, sizeof out->msg, "cannot set up %d threads", threads);
        munmap(m, 3 * bytes);
        return -1;
    }
    pthread_mutex_init(&j.mu, NULL);
    pthread_cond_init(&j.cv, NULL);
    for (int t = 1; t < threads; t++) {
        args[t] = (triad_arg){&j, t};
        if (pthread_create(&th[t], NULL, triad_thread, &args[t])) break;
        started++;
    }
    pthread_mutex_lock(&j.mu); /* open the gate: all started, or all leave */
    j.go = 1;
    j.ok = started == threads - 1;
    pthread_cond_broadcast(&j.cv);
    pthread_mutex_unlock(&j.mu);
    int rc = j.ok ? 0 : -1;
    if (!rc) {
        args[0] = (triad_arg){&j, 0};
        triad_thread(&args[0]);
    } else {
        snprintf(out->msg, sizeof out->msg, "pthread_create failed after %d threads", started);
    }
    for (int t = 1; t <= started; t++) pthread_join(th[t], NULL);
    pthread_barrier_destroy(&j.bar);
    pthread_mutex_destroy(&j.mu);
    pthread_cond_destroy(&j.cv);
    if (rc) {
        munmap(m, 3 * bytes);
        return rc;
    }
    double chk = j.a[j.n / 2];
    munmap(m, 3 * bytes);
    double gbs[PB_TRIAD_REPS];
    for (int r = 0; r < PB_TRIAD_REPS; r++) {
        double dt = j.t[r + 2] - j.t[r + 1];
        gbs[r] = dt > 0 ? 24.0 * (double)j.n / dt / 1e9 : 0;
    }
    out->gbs = pb_median(gbs, PB_TRIAD_REPS);
    out->lo = out->hi = gbs[0];
    for (int r = 1; r < PB_TRIAD_REPS; r++) {
        if (gbs[r] < out->lo) out->lo = gbs[r];
        if (gbs[r] > out->hi) out->hi = gbs[r];
    }
    out->array_mib = bytes / MIB;
    out->reps = PB_TRIAD_REPS;
    if (chk != 2.0 + 3.0 * 0.5) {
        snprintf(out->msg, sizeof out->msg, "triad result wrong (%g)", chk);
        return -1;
    }
    return 0;
}
