/*
 * t_store.c - tests of the run-record store (server/store/) on real SQLite
 * files in the test's temporary directory: run lifecycle and read-back,
 * 10k energy samples, listing, reopening, crash recovery (a forked child
 * that exits without closing), the one-daemon lock, schema versions, the
 * migration of a database written with schema version 1, snapshots and
 * the queue cap, asynchronous write errors, readers running while the
 * writer batches, and commit tracking without blocking (tickets and the
 * notify fd).
 */
#include "store.h"
#include "t.h"
#include "t_daemon.h"

#include <errno.h>
#include <fcntl.h>
#include <float.h>
#include <math.h>
#include <poll.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

/* ---- helpers ---- */

static const char *db_path(const char *name)
{
    static char buf[512];
    snprintf(buf, sizeof buf, "%s/%s", t_tmpdir(), name);
    return buf;
}

/* Collects log lines (the store may log from its writer thread). */
typedef struct {
    pthread_mutex_t mu;
    int n_dropped, n_cap, n_interrupted, n_new, n_migrated, n_total;
    char migrated[200]; /* the last "schema migrated" line */
    char last[512];
} logcap;

static void cap_log(void *ud, const char *msg)
{
    logcap *lc = ud;
    pthread_mutex_lock(&lc->mu);
    lc->n_total++;
    if (strstr(msg, "dropped")) lc->n_dropped++;
    if (strstr(msg, "above its cap")) lc->n_cap++;
    if (strstr(msg, "'interrupted'")) lc->n_interrupted++;
    if (strstr(msg, "new database, schema version")) lc->n_new++;
    if (strstr(msg, "schema migrated from version")) {
        lc->n_migrated++;
        snprintf(lc->migrated, sizeof lc->migrated, "%s", msg);
    }
    snprintf(lc->last, sizeof lc->last, "%s", msg);
    pthread_mutex_unlock(&lc->mu);
}

static void quiet_log(void *ud, const char *msg)
{
    (void)ud;
    (void)msg;
}

static const unsigned char case_bytes[] = {0x0a, 0x04, 'b',  'a',  'r',  's',  0x00,
                                           0x10, 0x02, 0xff, 0x00, 0x7f, 0x80, 0x01};

static store_run sample_run(const char *name, mpp_status st)
{
    store_run r;
    memset(&r, 0, sizeof r);
    r.name = name;
    r.case_pb = case_bytes;
    r.case_len = sizeof case_bytes;
    r.method = MPM_METHOD_GIMP;
    r.update = MPM_MUSL;
    r.dim = 2;
    r.particles = 12345;
    r.nodes = 678;
    r.status = st;
    r.submitted_at = 1700000000.25;
    r.server_version = "mpmd 0.1-test";
    return r;
}

/* A deterministic sample with awkward values; the same call gives the same
 * bits, so read-back can be compared exactly.  dim is that of sample_run()'s
 * runs (reads give the run's dim). */
static mpm_energy_sample make_sample(int64_t run, int64_t i)
{
    mpm_energy_sample e;
    memset(&e, 0, sizeof e);
    double x = (double)i;
    e.seq = (uint64_t)i;
    e.step = 10 * i + 3;
    e.t = x * 1e-3 + 1.0 / 3.0;
    e.dim = 2;
    e.e.kinetic = sin(x) * 1e3 + (double)run;
    e.e.strain = cos(x) / 7.0;
    e.e.potential = -x * 9.81 / 3.0;
    e.e.external_work = i % 3 == 0 ? 1e-300 * x : DBL_MAX / (x + 1);
    e.e.total = e.e.kinetic + e.e.strain + e.e.potential - e.e.external_work;
    e.e.momentum[0] = 1.0 / (x + 1);
    e.e.momentum[1] = -exp(-x / 100);
    e.e.momentum[2] = i % 2 ? 5e-324 : -2.5;
    e.e.mass = 2.0 + x * 1e-9;
    e.e.angular_momentum[0] = 1.0 / (x + 3);
    e.e.angular_momentum[1] = -x * x * 1e200;
    e.e.angular_momentum[2] = i % 2 ? 5e-324 : 7.5 + x;
    return e;
}

/* 1 if sample es[i] equals make_sample(run, seq) bit for bit. */
static int sample_equals(const mpm_energy_sample *es, size_t i, int64_t run, int64_t seq)
{
    mpm_energy_sample e = make_sample(run, seq);
    const mpm_energy_sample *g = &es[i];
    return g->seq == e.seq && g->step == e.step && g->t == e.t && g->dim == e.dim &&
           g->e.kinetic == e.e.kinetic && g->e.strain == e.e.strain &&
           g->e.potential == e.e.potential && g->e.external_work == e.e.external_work &&
           g->e.total == e.e.total && g->e.momentum[0] == e.e.momentum[0] &&
           g->e.momentum[1] == e.e.momentum[1] && g->e.momentum[2] == e.e.momentum[2] &&
           g->e.mass == e.e.mass && g->e.angular_momentum[0] == e.e.angular_momentum[0] &&
           g->e.angular_momentum[1] == e.e.angular_momentum[1] &&
           g->e.angular_momentum[2] == e.e.angular_momentum[2];
}

static void sleep_ms(int ms)
{
    struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
    nanosleep(&ts, NULL);
}

/* Options with logging silenced (tests that check log lines use cap_log). */
static const store_options quiet = {.log = quiet_log};

/* ---- tests ---- */

TEST(store_run_lifecycle)
{
    store *s = NULL;
    int rc = store_open(db_path("runs.db"), NULL, &s);
    CHECKF(rc == 0 && s, "store_open: %d %s", rc, store_error()->message);

    store_run in = sample_run("bar \"one\" \xc3\xa9", MPP_STATUS_QUEUED);
    int64_t id = -1;
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(id == 1); /* fresh database: ids start at 1 */
    CHECK(store_flush(s) == 0);

    store_run r;
    CHECK(store_run_get(s, id, &r) == 0);
    int ok = r.id == id && !strcmp(r.name, in.name) && r.case_len == sizeof case_bytes &&
             r.case_pb && !memcmp(r.case_pb, case_bytes, sizeof case_bytes) &&
             r.method == MPM_METHOD_GIMP && r.update == MPM_MUSL && r.dim == 2 &&
             r.particles == 12345 && r.nodes == 678 && r.status == MPP_STATUS_QUEUED &&
             r.submitted_at == 1700000000.25 && r.started_at == 0 && r.finished_at == 0 &&
             r.steps == 0 && isnan(r.energy.kinetic) && isnan(r.energy.total) && r.error == NULL &&
             !strcmp(r.server_version, "mpmd 0.1-test");
    store_run_clear(&r);
    CHECKF(ok, "queued run read back differs");
    CHECK(r.name == NULL && r.case_pb == NULL); /* cleared */

    /* queued -> running */
    CHECK(store_run_set_status(s, id, MPP_STATUS_RUNNING, 1700000001.5, NULL) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.status == MPP_STATUS_RUNNING && r.started_at == 1700000001.5 && r.finished_at == 0;
    store_run_clear(&r);
    CHECKF(ok, "running: status/started_at wrong");

    /* progress */
    CHECK(store_run_progress(s, id, 50, 1.25, 4.0e6) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.status == MPP_STATUS_RUNNING && r.steps == 50 && r.wall_s == 1.25 &&
         r.psteps_per_s == 4.0e6;
    store_run_clear(&r);
    CHECKF(ok, "progress not recorded");

    /* finish with energies */
    store_run_end end = {.status = MPP_STATUS_FINISHED,
                         .finished_at = 1700000003.75,
                         .steps = 100,
                         .wall_s = 2.5,
                         .psteps_per_s = 8.0e6,
                         .has_energy = 1,
                         .energy = {1.5, 2.25, -3.0, 0.125, 0.625 - 1.0 / 3.0}};
    CHECK(store_run_finish(s, id, &end) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.status == MPP_STATUS_FINISHED && r.started_at == 1700000001.5 &&
         r.finished_at == 1700000003.75 && r.steps == 100 && r.wall_s == 2.5 &&
         r.psteps_per_s == 8.0e6 && r.energy.kinetic == 1.5 && r.energy.strain == 2.25 &&
         r.energy.potential == -3.0 && r.energy.external_work == 0.125 &&
         r.energy.total == 0.625 - 1.0 / 3.0 && r.error == NULL && !strcmp(r.name, in.name) &&
         !memcmp(r.case_pb, case_bytes, sizeof case_bytes);
    store_run_clear(&r);
    CHECKF(ok, "finished run read back differs");

    /* a failed run: error text, no energies; status time defaults to now */
    in = sample_run("fails", MPP_STATUS_QUEUED);
    in.case_pb = NULL;
    in.case_len = 0;
    in.submitted_at = 0; /* now */
    in.name = NULL;      /* "" */
    int64_t id2 = 0;
    double t0 = store_time_now();
    CHECK(store_run_insert(s, &in, &id2) == 0);
    CHECK(id2 == 2);
    CHECK(store_run_set_status(s, id2, MPP_STATUS_RUNNING, 0, NULL) == 0);
    store_run_end fe = {.status = MPP_STATUS_FAILED,
                        .steps = 7,
                        .wall_s = 0.5,
                        .error = "particle 3 left the grid at step 7"};
    CHECK(store_run_finish(s, id2, &fe) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id2, &r) == 0);
    ok = r.status == MPP_STATUS_FAILED && r.error &&
         !strcmp(r.error, "particle 3 left the grid at step 7") && isnan(r.energy.kinetic) &&
         isnan(r.energy.total) && r.steps == 7 && !strcmp(r.name, "") && r.case_len == 0 &&
         r.case_pb == NULL && r.submitted_at >= t0 - 1 && r.submitted_at <= store_time_now() + 1 &&
         r.started_at >= r.submitted_at && r.finished_at >= r.started_at;
    store_run_clear(&r);
    CHECKF(ok, "failed run read back differs");

    /* cancelled via set_status (a terminal status) keeps the error given */
    in = sample_run("cancel me", MPP_STATUS_QUEUED);
    int64_t id3 = 0;
    CHECK(store_run_insert(s, &in, &id3) == 0);
    CHECK(store_run_set_status(s, id3, MPP_STATUS_RUNNING, 1700000008.0, NULL) == 0);
    CHECK(store_run_set_status(s, id3, MPP_STATUS_CANCELLED, 1700000009.0, "cancelled by client") ==
          0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id3, &r) == 0);
    ok = r.status == MPP_STATUS_CANCELLED && r.started_at == 1700000008.0 &&
         r.finished_at == 1700000009.0 && r.error && !strcmp(r.error, "cancelled by client");
    store_run_clear(&r);
    CHECKF(ok, "set_status to a terminal status");

    /* a terminal status is final: late updates of an ended run fail */
    char msg[512];
    CHECK(store_run_set_status(s, id, MPP_STATUS_RUNNING, 1700000010.0, NULL) == 0);
    CHECK(store_flush(s) == MPM_EIO);
    store_last_write_error(s, msg, sizeof msg);
    CHECKF(strstr(msg, "already ended (finished)"), "error text: %s", msg);
    CHECK(store_run_progress(s, id3, 1, 1, 1) == 0);
    CHECK(store_run_finish(s, id3, &end) == 0);
    CHECK(store_flush(s) == MPM_EIO);
    store_last_write_error(s, msg, sizeof msg);
    CHECKF(strstr(msg, "already ended (cancelled)"), "error text: %s", msg);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.status == MPP_STATUS_FINISHED && r.started_at == 1700000001.5 && r.steps == 100;
    store_run_clear(&r);
    CHECKF(ok, "finished run changed by a late update");
    CHECK(store_run_get(s, id3, &r) == 0);
    ok = r.status == MPP_STATUS_CANCELLED && r.steps == 0 && isnan(r.energy.kinetic);
    store_run_clear(&r);
    CHECKF(ok, "cancelled run changed by late updates");
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.write_errors == 3);

    CHECK(store_run_get(s, 999, &r) == MPM_ENOTFOUND);
    store_close(&s);
    CHECK(s == NULL);
    store_close(&s); /* no-op */
}

TEST(store_energy_10k)
{
    store *s = NULL;
    int rc = store_open(db_path("energy.db"), &quiet, &s);
    CHECKF(rc == 0, "store_open: %s", store_error()->message);
    store_run in = sample_run("energy", MPP_STATUS_RUNNING);
    int64_t id = 0, id2 = 0;
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(store_run_insert(s, &in, &id2) == 0);
    store_stats st0;
    store_get_stats(s, &st0);

    const int N = 10000;
    double t0 = td_now();
    for (int i = 0; i < N; i++) {
        mpm_energy_sample e = make_sample(id, i);
        rc = store_energy_append(s, id, &e, 1);
        if (rc) CHECKF(0, "append %d: %d %s", i, rc, store_error()->message);
    }
    double t_enq = td_now() - t0;
    /* and 1000 in one call for the second run */
    mpm_energy_sample *v = malloc(1000 * sizeof *v);
    CHECK(v);
    for (int i = 0; i < 1000; i++) v[i] = make_sample(id2, i);
    rc = store_energy_append(s, id2, v, 1000);
    memset(v, 0, 1000 * sizeof *v); /* the store has its own copy */
    free(v);
    CHECK(rc == 0);
    CHECK(store_flush(s) == 0);
    double t_all = td_now() - t0;
    store_stats st;
    store_get_stats(s, &st);
    uint64_t txns = st.transactions - st0.transactions;
    TLOG("10000 samples: enqueue %.1f ms, committed after %.1f ms in %llu transactions",
         1e3 * t_enq, 1e3 * t_all, (unsigned long long)txns);
    CHECK(st.ops_committed == st.ops_enqueued);
    CHECK(st.write_errors == 0);
    CHECK(st.queue_ops == 0 && st.queue_bytes == 0);
    CHECKF(txns >= 1 && txns <= 100, "%llu transactions for 10001 ops: not batched",
           (unsigned long long)txns);

    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, id, 0, 0, &es, &nes) == 0);
    CHECKF(nes == (size_t)N, "read %zu samples, want %d", nes, N);
    size_t bad = SIZE_MAX;
    for (size_t i = 0; i < nes && bad == SIZE_MAX; i++)
        if (!sample_equals(es, i, id, (int64_t)i)) bad = i;
    free(es);
    CHECKF(bad == SIZE_MAX, "sample %zu differs", bad);

    CHECK(store_energy_read(s, id, 5000, 100, &es, &nes) == 0);
    int ok = nes == 100 && es[0].seq == 5000 && es[99].seq == 5099 &&
             sample_equals(es, 0, id, 5000) && sample_equals(es, 99, id, 5099);
    free(es);
    CHECKF(ok, "read from seq 5000, max 100");

    CHECK(store_energy_read(s, id, N, 0, &es, &nes) == 0);
    CHECK(nes == 0 && es == NULL);
    CHECK(store_energy_read(s, 424242, 0, 0, &es, &nes) == 0);
    CHECK(nes == 0);

    CHECK(store_energy_read(s, id2, 0, 0, &es, &nes) == 0);
    ok = nes == 1000;
    for (size_t i = 0; ok && i < nes; i++) ok = sample_equals(es, i, id2, (int64_t)i);
    free(es);
    CHECKF(ok, "append_n samples differ");
    store_close(&s);
}

TEST(store_nonfinite_values)
{
    store *s = NULL;
    CHECKF(store_open(db_path("nan.db"), &quiet, &s) == 0, "%s", store_error()->message);
    store_run in = sample_run("nan", MPP_STATUS_RUNNING);
    int64_t id = 0;
    CHECK(store_run_insert(s, &in, &id) == 0);
    mpm_energy_sample e = make_sample(id, 0);
    e.e.total = NAN;
    e.e.kinetic = INFINITY;
    e.e.strain = -INFINITY;
    CHECK(store_energy_append(s, id, &e, 1) == 0);
    store_run_end end = {.status = MPP_STATUS_FAILED,
                         .steps = 3,
                         .wall_s = NAN,
                         .has_energy = 1,
                         .energy = {INFINITY, NAN, 1.0, 0.0, NAN},
                         .error = "diverged"};
    CHECK(store_run_finish(s, id, &end) == 0);
    CHECK(store_flush(s) == 0);
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, id, 0, 0, &es, &nes) == 0);
    int ok = nes == 1 && isnan(es[0].e.total) && isinf(es[0].e.kinetic) && es[0].e.kinetic > 0 &&
             isinf(es[0].e.strain) && es[0].e.strain < 0 && es[0].e.mass == e.e.mass;
    free(es);
    CHECKF(ok, "non-finite energy sample");
    store_run r;
    CHECK(store_run_get(s, id, &r) == 0);
    ok = isinf(r.energy.kinetic) && isnan(r.energy.strain) && r.energy.potential == 1.0 &&
         r.energy.external_work == 0.0 && isnan(r.energy.total) && isnan(r.wall_s);
    store_run_clear(&r);
    CHECKF(ok, "non-finite final energies");
    store_close(&s);
}

TEST(store_list_filter_limit)
{
    store *s = NULL;
    CHECKF(store_open(db_path("list.db"), &quiet, &s) == 0, "%s", store_error()->message);
    /* ids 1..10, statuses cycling queued, running, finished, failed, cancelled */
    for (int i = 1; i <= 10; i++) {
        char name[32];
        snprintf(name, sizeof name, "run-%d", i);
        store_run in = sample_run(name, (mpp_status)(MPP_STATUS_MIN + (i - 1) % 5));
        int64_t id;
        CHECK(store_run_insert(s, &in, &id) == 0);
        CHECK(id == i);
    }
    CHECK(store_flush(s) == 0);

    store_run *v = NULL;
    size_t n = 0;
    CHECK(store_run_list(s, NULL, &v, &n) == 0);
    int ok = n == 10;
    for (size_t i = 0; ok && i < n; i++) {
        char name[32];
        snprintf(name, sizeof name, "run-%d", (int)(10 - i));
        ok = v[i].id == (int64_t)(10 - i) && !strcmp(v[i].name, name) && v[i].case_pb == NULL &&
             v[i].case_len == sizeof case_bytes &&
             v[i].status == (mpp_status)(MPP_STATUS_MIN + (9 - i) % 5);
    }
    store_run_list_free(v, n);
    CHECKF(ok, "list all: newest first, names, statuses");

    store_run_filter f = {.status_mask = STORE_STATUS_BIT(MPP_STATUS_FINISHED)};
    CHECK(store_run_list(s, &f, &v, &n) == 0);
    ok = n == 2 && v[0].id == 8 && v[1].id == 3 && v[0].status == MPP_STATUS_FINISHED;
    store_run_list_free(v, n);
    CHECKF(ok, "status filter finished");

    f.status_mask = STORE_STATUS_BIT(MPP_STATUS_FAILED) | STORE_STATUS_BIT(MPP_STATUS_QUEUED);
    f.limit = 3;
    CHECK(store_run_list(s, &f, &v, &n) == 0);
    ok = n == 3 && v[0].id == 9 && v[1].id == 6 && v[2].id == 4;
    store_run_list_free(v, n);
    CHECKF(ok, "failed|queued, limit 3");

    store_run_filter g = {.limit = 2, .before_id = 5, .with_case = 1};
    CHECK(store_run_list(s, &g, &v, &n) == 0);
    ok = n == 2 && v[0].id == 4 && v[1].id == 3 && v[0].case_pb &&
         v[0].case_len == sizeof case_bytes && !memcmp(v[0].case_pb, case_bytes, sizeof case_bytes);
    store_run_list_free(v, n);
    CHECKF(ok, "paging with before_id and limit, with case bytes");

    f.status_mask = STORE_STATUS_BIT(MPP_STATUS_INTERRUPTED);
    f.limit = 0;
    CHECK(store_run_list(s, &f, &v, &n) == 0);
    CHECK(n == 0 && v == NULL);
    f.status_mask = 1u << 12;
    CHECK(store_run_list(s, &f, &v, &n) == MPM_EINVAL);
    store_close(&s);
}

TEST(store_reopen_ids_continue)
{
    const char *path = db_path("reopen.db");
    store *s = NULL;
    CHECKF(store_open(path, &quiet, &s) == 0, "%s", store_error()->message);
    for (int i = 0; i < 3; i++) {
        store_run in = sample_run("persist", MPP_STATUS_QUEUED);
        int64_t id;
        CHECK(store_run_insert(s, &in, &id) == 0);
        store_run_end end = {.status = MPP_STATUS_FINISHED,
                             .steps = 10 * (i + 1),
                             .has_energy = 1,
                             .energy = {i, 0, 0, 0, i}};
        CHECK(store_run_finish(s, id, &end) == 0);
        mpm_energy_sample e = make_sample(id, 0);
        CHECK(store_energy_append(s, id, &e, 1) == 0);
    }
    store_close(&s); /* no flush: close flushes */

    CHECKF(store_open(path, &quiet, &s) == 0, "reopen: %s", store_error()->message);
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.recovered_running == 0 && st.recovered_queued == 0);
    store_run r;
    CHECK(store_run_get(s, 2, &r) == 0);
    int ok = r.status == MPP_STATUS_FINISHED && r.steps == 20 && r.energy.kinetic == 1 &&
             !strcmp(r.name, "persist");
    store_run_clear(&r);
    CHECKF(ok, "run 2 after reopen");
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, 3, 0, 0, &es, &nes) == 0);
    ok = nes == 1 && sample_equals(es, 0, 3, 0);
    free(es);
    CHECKF(ok, "energy sample of run 3 after reopen");

    CHECK(store_new_run_id(s) == 4);
    store_run in = sample_run("after", MPP_STATUS_QUEUED);
    int64_t id = 0;
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(id == 5);
    in.id = 100; /* explicit id moves the counter */
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(id == 100);
    in.id = 0;
    store_close(&s);

    CHECKF(store_open(path, &quiet, &s) == 0, "reopen 2: %s", store_error()->message);
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECKF(id == 101, "id %lld after reopen, want 101", (long long)id);
    CHECK(store_flush(s) == 0);
    store_run *v;
    size_t n;
    CHECK(store_run_list(s, NULL, &v, &n) == 0);
    ok = n == 6 && v[0].id == 101 && v[1].id == 100 && v[2].id == 5;
    store_run_list_free(v, n);
    CHECKF(ok, "runs after two reopens");
    store_close(&s);
}

TEST(store_crash_recovery)
{
    const char *path = db_path("crash.db");
    fflush(stdout);
    pid_t pid = fork();
    CHECK(pid >= 0);
    if (pid == 0) {
        /* the "daemon": leaves a running and a queued run, then dies */
        store *s = NULL;
        store_options o = {.log = quiet_log};
        if (store_open(path, &o, &s)) _exit(10);
        store_run a = sample_run("was running", MPP_STATUS_QUEUED);
        store_run b = sample_run("was queued", MPP_STATUS_QUEUED);
        store_run c = sample_run("was finished", MPP_STATUS_QUEUED);
        int64_t ia, ib, ic;
        if (store_run_insert(s, &a, &ia) || store_run_insert(s, &b, &ib) ||
            store_run_insert(s, &c, &ic))
            _exit(11);
        if (store_run_set_status(s, ia, MPP_STATUS_RUNNING, 1700000100.0, NULL)) _exit(12);
        for (int i = 0; i < 100; i++) {
            mpm_energy_sample e = make_sample(ia, i);
            if (store_energy_append(s, ia, &e, 1)) _exit(13);
        }
        /* progress recorded past the last sample (step 993) */
        if (store_run_progress(s, ia, 1234, 2.5, 1e6)) _exit(16);
        store_run_end end = {.status = MPP_STATUS_FINISHED, .steps = 5};
        if (store_run_finish(s, ic, &end)) _exit(14);
        if (store_flush(s)) _exit(15);
        _exit(0); /* no store_close */
    }
    int status = 0;
    CHECK(waitpid(pid, &status, 0) == pid);
    CHECKF(WIFEXITED(status) && WEXITSTATUS(status) == 0, "child status 0x%x", status);

    logcap lc = {.mu = PTHREAD_MUTEX_INITIALIZER};
    store_options o = {.log = cap_log, .log_ud = &lc};
    store *s = NULL;
    CHECKF(store_open(path, &o, &s) == 0, "reopen after crash: %s", store_error()->message);
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.recovered_running == 1 && st.recovered_queued == 1);
    CHECK(lc.n_interrupted == 1);

    store_run r;
    CHECK(store_run_get(s, 1, &r) == 0);
    int ok = r.status == MPP_STATUS_INTERRUPTED && r.error &&
             !strcmp(r.error, "daemon stopped before the run ended") &&
             r.started_at == 1700000100.0 && !strcmp(r.name, "was running");
    /* it stands at its last energy sample (seq 99, step 993), energies included */
    mpm_energy_sample last = make_sample(1, 99);
    int at_last = r.steps == last.step && r.energy.kinetic == last.e.kinetic &&
                  r.energy.strain == last.e.strain && r.energy.potential == last.e.potential &&
                  r.energy.external_work == last.e.external_work && r.energy.total == last.e.total;
    long long steps_done = (long long)r.steps;
    store_run_clear(&r);
    CHECKF(ok, "running run not marked interrupted");
    CHECKF(at_last,
           "interrupted run: steps_done %lld and final energies, want those of its last "
           "sample (step %lld)",
           steps_done, (long long)last.step);
    CHECK(store_run_get(s, 2, &r) == 0);
    ok = r.status == MPP_STATUS_INTERRUPTED && r.error &&
         !strcmp(r.error, STORE_INTERRUPTED_QUEUED) && r.started_at == 0 && r.steps == 0 &&
         isnan(r.energy.total);
    store_run_clear(&r);
    CHECKF(ok, "queued run not marked interrupted (or given energies it never had)");
    CHECK(store_run_get(s, 3, &r) == 0);
    ok = r.status == MPP_STATUS_FINISHED && r.error == NULL && r.steps == 5;
    store_run_clear(&r);
    CHECKF(ok, "finished run changed by recovery");

    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, 1, 0, 0, &es, &nes) == 0);
    ok = nes == 100 && sample_equals(es, 99, 1, 99);
    free(es);
    CHECKF(ok, "flushed samples lost in the crash");

    store_run_filter f = {.status_mask = STORE_STATUS_BIT(MPP_STATUS_INTERRUPTED)};
    store_run *v;
    size_t n;
    CHECK(store_run_list(s, &f, &v, &n) == 0);
    store_run_list_free(v, n);
    CHECK(n == 2);
    CHECK(store_new_run_id(s) == 4);
    store_close(&s);

    /* recovery is done once: a clean reopen recovers nothing */
    CHECKF(store_open(path, &o, &s) == 0, "%s", store_error()->message);
    store_get_stats(s, &st);
    CHECK(st.recovered_running == 0 && st.recovered_queued == 0);
    store_close(&s);
}

TEST(store_lock_one_daemon)
{
    const char *path = db_path("lock.db");
    char want[1024];
    store *s = NULL, *s2 = NULL;
    CHECKF(store_open(path, &quiet, &s) == 0, "%s", store_error()->message);
    snprintf(want, sizeof want, "database %s is in use by another mpmd (pid %ld)", path,
             (long)getpid());

    /* the pid is in the lock file */
    char lockp[600], buf[32] = {0};
    snprintf(lockp, sizeof lockp, "%s.lock", path);
    int fd = open(lockp, O_RDONLY);
    CHECK(fd >= 0);
    ssize_t nr = read(fd, buf, sizeof buf - 1);
    close(fd);
    CHECK(nr > 0 && strtol(buf, NULL, 10) == (long)getpid());

    /* a second open in this process is refused too (another open file
     * description) */
    int rc = store_open(path, &quiet, &s2);
    CHECKF(rc == MPM_ELOCKED && s2 == NULL, "second open: %d %s", rc, store_error()->message);
    CHECKF(!strcmp(store_error()->message, want), "message '%s', want '%s'", store_error()->message,
           want);

    /* ... and from another process */
    int pfd[2];
    CHECK(pipe(pfd) == 0);
    fflush(stdout);
    pid_t pid = fork();
    CHECK(pid >= 0);
    if (pid == 0) {
        store *c = NULL;
        close(pfd[0]);
        int crc = store_open(path, &quiet, &c);
        ssize_t w = write(pfd[1], store_error()->message, strlen(store_error()->message) + 1);
        _exit(crc == MPM_ELOCKED && c == NULL && w > 0 ? 0 : 1);
    }
    close(pfd[1]);
    char cmsg[1024] = {0};
    size_t got = 0;
    ssize_t k;
    while (got < sizeof cmsg - 1 && (k = read(pfd[0], cmsg + got, sizeof cmsg - 1 - got)) > 0)
        got += (size_t)k;
    close(pfd[0]);
    int status = 0;
    CHECK(waitpid(pid, &status, 0) == pid);
    CHECKF(WIFEXITED(status) && WEXITSTATUS(status) == 0, "child open was not refused");
    CHECKF(!strcmp(cmsg, want), "child message '%s', want '%s'", cmsg, want);

    /* the refused opens did not disturb the first store */
    store_run in = sample_run("still works", MPP_STATUS_QUEUED);
    int64_t id;
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(store_flush(s) == 0);
    store_run r;
    CHECK(store_run_get(s, id, &r) == 0);
    store_run_clear(&r);
    store_close(&s);

    /* released on close */
    CHECKF(store_open(path, &quiet, &s2) == 0, "open after close: %s", store_error()->message);
    store_close(&s2);
}

/* Overwrites 4 bytes (big-endian) of the database header. */
static int patch_header(const char *path, off_t off, uint32_t v)
{
    unsigned char b[4] = {(unsigned char)(v >> 24), (unsigned char)(v >> 16),
                          (unsigned char)(v >> 8), (unsigned char)v};
    int fd = open(path, O_WRONLY);
    if (fd < 0) return -1;
    ssize_t w = pwrite(fd, b, 4, off);
    close(fd);
    return w == 4 ? 0 : -1;
}

TEST(store_schema_versions)
{
    const char *p = db_path("schema.db");
    char path[600];
    snprintf(path, sizeof path, "%s", p);
    store *s = NULL;
    logcap lc = {.mu = PTHREAD_MUTEX_INITIALIZER};
    store_options o = {.log = cap_log, .log_ud = &lc};
    CHECKF(store_open(path, &o, &s) == 0, "%s", store_error()->message);
    CHECK(lc.n_new == 1);
    int v = -1;
    CHECK(store_schema_version(s, &v) == 0);
    CHECKF(v == STORE_SCHEMA_VERSION, "user_version %d, want %d", v, STORE_SCHEMA_VERSION);
    store_close(&s); /* last connection: the WAL is checkpointed */

    /* reopening an up-to-date database migrates nothing and keeps it */
    CHECKF(store_open(path, &o, &s) == 0, "%s", store_error()->message);
    CHECK(store_schema_version(s, &v) == 0 && v == STORE_SCHEMA_VERSION);
    store_close(&s);
    CHECK(lc.n_new == 1 && lc.n_total == 1);

    /* a newer schema (user_version at offset 60 of the header) is refused */
    CHECK(patch_header(path, 60, 99) == 0);
    int rc = store_open(path, &quiet, &s);
    CHECKF(rc == MPM_ESCHEMA && s == NULL, "newer schema: %d %s", rc, store_error()->message);
    CHECKF(strstr(store_error()->message, "schema version 99"), "message: %s",
           store_error()->message);
    CHECK(patch_header(path, 60, STORE_SCHEMA_VERSION) == 0);
    CHECKF(store_open(path, &quiet, &s) == 0, "restored: %s", store_error()->message);
    store_close(&s);

    /* another application's database (application_id at offset 68) */
    CHECK(patch_header(path, 68, 0x12345678) == 0);
    rc = store_open(path, &quiet, &s);
    CHECKF(rc == MPM_ESCHEMA && strstr(store_error()->message, "not an mpmd database"), "%d %s", rc,
           store_error()->message);

    /* not a database at all */
    const char *junk = db_path("junk.db");
    int fd = open(junk, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    CHECK(fd >= 0);
    char garbage[4096];
    for (size_t i = 0; i < sizeof garbage; i++) garbage[i] = (char)(i * 7 + 1);
    ssize_t w = write(fd, garbage, sizeof garbage);
    close(fd);
    CHECK(w == (ssize_t)sizeof garbage);
    rc = store_open(junk, &quiet, &s);
    CHECKF(rc == MPM_EIO && s == NULL && strstr(store_error()->message, "not a database"), "%d %s",
           rc, store_error()->message);

    /* a directory that does not exist */
    rc = store_open("/nonexistent-mpmd-dir/x.db", &quiet, &s);
    CHECKF(rc == MPM_EIO && strstr(store_error()->message, "lock file"), "%d %s", rc,
           store_error()->message);
}

TEST(store_snapshots)
{
    store *s = NULL;
    CHECKF(store_open(db_path("snap.db"), &quiet, &s) == 0, "%s", store_error()->message);
    store_run in = sample_run("snap", MPP_STATUS_RUNNING);
    int64_t id;
    CHECK(store_run_insert(s, &in, &id) == 0);
    unsigned char data[3][1024];
    for (int k = 0; k < 3; k++)
        for (int i = 0; i < 1024; i++) data[k][i] = (unsigned char)((i * (k + 3)) ^ (i >> 3));
    for (int k = 0; k < 3; k++) {
        store_snapshot sn = {.run_id = id,
                             .step = 10 * k,
                             .t = 0.5 * k,
                             .n = 64 + k,
                             .dim = 2,
                             .fields = 0x15u + (uint32_t)k,
                             .data = data[k],
                             .size = sizeof data[k]};
        CHECK(store_snapshot_put(s, &sn) == 0);
    }
    memset(data[1], 0, sizeof data[1]); /* the store copied it */
    CHECK(store_flush(s) == 0);
    store_snapshot out;
    CHECK(store_snapshot_get(s, id, 10, &out) == 0);
    unsigned char want[1024];
    for (int i = 0; i < 1024; i++) want[i] = (unsigned char)((i * 4) ^ (i >> 3));
    int ok = out.run_id == id && out.step == 10 && out.t == 0.5 && out.n == 65 && out.dim == 2 &&
             out.fields == 0x16u && out.size == 1024 && !memcmp(out.data, want, 1024);
    store_snapshot_clear(&out);
    CHECKF(ok, "snapshot at step 10");

    CHECK(store_snapshot_get(s, id, -1, &out) == 0);
    ok = out.step == 20 && out.size == 1024 && !memcmp(out.data, data[2], 1024);
    store_snapshot_clear(&out);
    CHECKF(ok, "last snapshot");

    /* replace step 20 with an empty one; add step 30 */
    store_snapshot e = {.run_id = id, .step = 20, .t = 1, .n = 0, .dim = 2};
    CHECK(store_snapshot_put(s, &e) == 0);
    store_snapshot e2 = {.run_id = id,
                         .step = 30,
                         .t = 1.5,
                         .n = 1,
                         .dim = 3,
                         .fields = 1,
                         .data = "xyz",
                         .size = 3};
    CHECK(store_snapshot_put(s, &e2) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_snapshot_get(s, id, 20, &out) == 0);
    ok = out.size == 0 && out.data == NULL && out.n == 0;
    store_snapshot_clear(&out);
    CHECKF(ok, "replaced snapshot");
    CHECK(store_snapshot_get(s, id, -1, &out) == 0);
    ok = out.step == 30 && out.size == 3 && !memcmp(out.data, "xyz", 3) && out.dim == 3;
    store_snapshot_clear(&out);
    CHECKF(ok, "last snapshot after adding step 30");

    CHECK(store_snapshot_get(s, id, 5, &out) == MPM_ENOTFOUND);
    CHECK(store_snapshot_get(s, 777, -1, &out) == MPM_ENOTFOUND);
    CHECK(strstr(store_error()->message, "777") != NULL);
    store_snapshot bad = {.run_id = id, .step = 1, .dim = 4};
    CHECK(store_snapshot_put(s, &bad) == MPM_EINVAL);
    store_close(&s);
}

TEST(store_queue_cap)
{
    logcap lc = {.mu = PTHREAD_MUTEX_INITIALIZER};
    /* nothing commits before store_flush: a 60 s batching window */
    store_options o = {.batch_ms = 60000,
                       .batch_ops = 1000000,
                       .queue_cap = 256 << 10,
                       .log = cap_log,
                       .log_ud = &lc};
    store *s = NULL;
    CHECKF(store_open(db_path("cap.db"), &o, &s) == 0, "%s", store_error()->message);
    store_run in = sample_run("cap", MPP_STATUS_RUNNING);
    int64_t id;
    CHECK(store_run_insert(s, &in, &id) == 0);
    static unsigned char big[100 << 10];
    memset(big, 0xab, sizeof big);
    store_snapshot sn = {
        .run_id = id, .step = 1, .n = 10, .dim = 3, .data = big, .size = sizeof big};
    CHECK(store_snapshot_put(s, &sn) == 0);
    sn.step = 2;
    CHECK(store_snapshot_put(s, &sn) == 0);
    sn.step = 3;
    int rc = store_snapshot_put(s, &sn);
    CHECKF(rc == MPM_EFULL, "third 100 KiB snapshot under a 256 KiB cap: %d", rc);
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.snapshots_dropped == 1);
    CHECK(lc.n_dropped == 1);
    CHECK(st.queue_ops == 3); /* nothing committed yet */

    /* energy samples are never dropped: the queue grows past the cap */
    for (int i = 0; i < 5000; i++) {
        mpm_energy_sample e = make_sample(id, i);
        rc = store_energy_append(s, id, &e, 1);
        if (rc) CHECKF(0, "append %d over the cap: %d", i, rc);
    }
    store_get_stats(s, &st);
    TLOG("queue %zu bytes in %zu ops, cap %zu", st.queue_bytes, st.queue_ops, o.queue_cap);
    CHECK(st.queue_bytes > o.queue_cap);
    CHECK(lc.n_cap == 1); /* logged once */
    store_snapshot small = {.run_id = id, .step = 4, .n = 1, .dim = 1, .data = "ab", .size = 2};
    CHECK(store_snapshot_put(s, &small) == MPM_EFULL);

    CHECK(store_flush(s) == 0);
    store_get_stats(s, &st);
    CHECK(st.queue_bytes == 0 && st.queue_ops == 0 && st.snapshots_dropped == 2);
    CHECK(st.queue_bytes_max > o.queue_cap);
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, id, 0, 0, &es, &nes) == 0);
    int ok = nes == 5000 && sample_equals(es, 4999, id, 4999);
    free(es);
    CHECKF(ok, "samples enqueued over the cap");
    store_snapshot out;
    CHECK(store_snapshot_get(s, id, 2, &out) == 0);
    ok = out.size == sizeof big && !memcmp(out.data, big, sizeof big);
    store_snapshot_clear(&out);
    CHECK(ok);
    CHECK(store_snapshot_get(s, id, 3, &out) == MPM_ENOTFOUND);
    /* below the cap again: accepted */
    CHECK(store_snapshot_put(s, &small) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_snapshot_get(s, id, -1, &out) == 0);
    ok = out.step == 4 && out.size == 2;
    store_snapshot_clear(&out);
    CHECK(ok);
    store_close(&s);
}

TEST(store_write_errors)
{
    logcap lc = {.mu = PTHREAD_MUTEX_INITIALIZER};
    store_options o = {.log = cap_log, .log_ud = &lc};
    char msg[512];
    store *s = NULL;
    CHECKF(store_open(db_path("errors.db"), &o, &s) == 0, "%s", store_error()->message);
    store_run in = sample_run("ok", MPP_STATUS_RUNNING);
    int64_t id;
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(store_flush(s) == 0);

    /* a bad op between good ones: only it fails, the batch commits */
    mpm_energy_sample e0 = make_sample(id, 0), bad = make_sample(999, 0), e1 = make_sample(id, 1);
    CHECK(store_energy_append(s, id, &e0, 1) == 0);
    CHECK(store_energy_append(s, 999, &bad, 1) == 0); /* accepted: checked on write */
    CHECK(store_energy_append(s, id, &e1, 1) == 0);
    CHECK(store_flush(s) == MPM_EIO);
    store_last_write_error(s, msg, sizeof msg);
    CHECKF(strstr(msg, "FOREIGN KEY") && strstr(msg, "run 999"), "error text: %s", msg);
    CHECK(store_flush(s) == 0); /* reported once */
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, id, 0, 0, &es, &nes) == 0);
    int ok = nes == 2 && es[0].seq == 0 && es[1].seq == 1;
    free(es);
    CHECKF(ok, "good samples around a bad one");

    CHECK(store_energy_append(s, id, &e1, 1) == 0); /* duplicate (run, seq) */
    CHECK(store_flush(s) == MPM_EIO);
    store_last_write_error(s, msg, sizeof msg);
    CHECKF(strstr(msg, "UNIQUE"), "%s", msg);

    CHECK(store_run_set_status(s, 7777, MPP_STATUS_RUNNING, 1, NULL) == 0);
    CHECK(store_flush(s) == MPM_EIO);
    store_last_write_error(s, msg, sizeof msg);
    CHECKF(strstr(msg, "no run 7777"), "%s", msg);
    CHECK(strstr(store_error()->message, "no run 7777") != NULL);

    in.id = id; /* duplicate run id */
    CHECK(store_run_insert(s, &in, NULL) == 0);
    CHECK(store_flush(s) == MPM_EIO);
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.write_errors == 4);
    pthread_mutex_lock(&lc.mu);
    int nlog = lc.n_total;
    pthread_mutex_unlock(&lc.mu);
    CHECK(nlog >= 4);

    /* argument errors come back at once */
    store_run_end end = {.status = MPP_STATUS_RUNNING};
    CHECK(store_run_finish(s, id, &end) == MPM_EINVAL);
    CHECK(strstr(store_error()->message, "not a final status") != NULL);
    store_run b = sample_run("bad", MPP_STATUS_QUEUED);
    b.dim = 4;
    CHECK(store_run_insert(s, &b, NULL) == MPM_EINVAL);
    b = sample_run("bad", (mpp_status)17);
    CHECK(store_run_insert(s, &b, NULL) == MPM_EINVAL);
    CHECK(store_run_set_status(s, id, (mpp_status)-1, 0, NULL) == MPM_EINVAL);
    CHECK(store_run_set_status(s, id, (mpp_status)0, 0, NULL) == MPM_EINVAL); /* 1..6 */
    CHECK(store_flush(s) == 0);
    CHECK(strcmp(mpm_strerror(MPM_ELOCKED), mpm_strerror(MPM_EIO)));
    CHECK(store_error()->code == MPM_EINVAL);

    /* the statuses, methods and updates are stored as their names */
    in = sample_run("names", MPP_STATUS_QUEUED);
    in.method = MPM_METHOD_MPM;
    in.update = MPM_USL;
    int64_t id2;
    CHECK(store_run_insert(s, &in, &id2) == 0);
    CHECK(store_run_set_status(s, id2, MPP_STATUS_INTERRUPTED, 0, NULL) == 0);
    store_close(&s);
    char sql[256];
    int64_t cnt = -1;
    snprintf(sql, sizeof sql,
             "SELECT count(*) FROM runs WHERE id = %lld AND status ="
             " 'interrupted' AND method = 'mpm' AND \"update\" = 'usl'",
             (long long)id2);
    CHECKF(store_exec_raw(db_path("errors.db"), sql, &cnt) == 0, "%s", store_error()->message);
    CHECK(cnt == 1);
    cnt = -1;
    snprintf(sql, sizeof sql,
             "SELECT count(*) FROM runs WHERE id = %lld AND status ="
             " 'running' AND method = 'gimp' AND \"update\" = 'musl'",
             (long long)id);
    CHECK(store_exec_raw(db_path("errors.db"), sql, &cnt) == 0 && cnt == 1);
}

TEST(store_commits_without_flush)
{
    store *s = NULL;
    CHECKF(store_open(db_path("latency.db"), &quiet, &s) == 0, "%s", store_error()->message);
    store_run in = sample_run("latency", MPP_STATUS_QUEUED);
    int64_t id;
    double t0 = td_now();
    CHECK(store_run_insert(s, &in, &id) == 0);
    store_run r;
    int rc;
    while ((rc = store_run_get(s, id, &r)) == MPM_ENOTFOUND && td_now() - t0 < 5) sleep_ms(2);
    double dt = td_now() - t0;
    CHECKF(rc == 0, "run not committed after %.2f s: %d %s", dt, rc, store_error()->message);
    store_run_clear(&r);
    TLOG("first write visible to readers after %.1f ms (batch window 50 ms)", 1e3 * dt);
    CHECK_LT(dt, 2.0);

    /* a burst of small ops shares transactions */
    store_stats a, b;
    store_get_stats(s, &a);
    for (int i = 0; i < 1000; i++) CHECK(store_run_progress(s, id, i, 0.001 * i, 1e6) == 0);
    CHECK(store_flush(s) == 0);
    store_get_stats(s, &b);
    TLOG("1000 progress updates in %llu transactions",
         (unsigned long long)(b.transactions - a.transactions));
    CHECK(b.transactions - a.transactions <= 20);
    CHECK(store_run_get(s, id, &r) == 0);
    int ok = r.steps == 999 && r.wall_s == 0.999;
    store_run_clear(&r);
    CHECKF(ok, "last progress update wins (enqueue order)");
    store_close(&s);
}

/* ---- readers while the writer batches ---- */

#define CR_RUNS 4
#define CR_SAMPLES 4000

typedef struct {
    store *s;
    int64_t ids[CR_RUNS];
    atomic_int producers_done;
    atomic_int errors;
    atomic_long reads, partial;
    char msg[256];
    pthread_mutex_t mu;
} cr_ctx;

typedef struct {
    cr_ctx *c;
    int k;
} cr_arg;

static void cr_error(cr_ctx *c, const char *what)
{
    pthread_mutex_lock(&c->mu);
    if (!atomic_load(&c->errors)) snprintf(c->msg, sizeof c->msg, "%s", what);
    atomic_fetch_add(&c->errors, 1);
    pthread_mutex_unlock(&c->mu);
}

static void *cr_producer(void *p)
{
    cr_arg *a = p;
    cr_ctx *c = a->c;
    for (int r = a->k; r < CR_RUNS; r += 2) {
        int64_t id = c->ids[r];
        for (int i = 0; i < CR_SAMPLES; i++) {
            mpm_energy_sample e = make_sample(id, i);
            if (store_energy_append(c->s, id, &e, 1)) {
                cr_error(c, "append failed");
                return NULL;
            }
            if (i % 200 == 199) {
                if (store_run_progress(c->s, id, i + 1, 0, 0)) cr_error(c, "progress failed");
                sleep_ms(2);
            }
        }
    }
    return NULL;
}

static void *cr_reader(void *p)
{
    cr_arg *a = p;
    cr_ctx *c = a->c;
    size_t last_n[CR_RUNS] = {0};
    unsigned seed = (unsigned)a->k * 7919u + 1;
    while (!atomic_load(&c->producers_done)) {
        seed = seed * 1103515245u + 12345u;
        int r = (int)((seed >> 16) % CR_RUNS);
        int64_t id = c->ids[r];
        mpm_energy_sample *es = NULL;
        size_t nes = 0;
        if (store_energy_read(c->s, id, 0, 0, &es, &nes)) {
            cr_error(c, store_error()->message);
            break;
        }
        int ok = nes >= last_n[r];
        for (size_t i = 0; ok && i < nes; i++) ok = sample_equals(es, i, id, (int64_t)i);
        if (nes > 0 && nes < CR_SAMPLES) atomic_fetch_add(&c->partial, 1);
        last_n[r] = nes;
        free(es);
        if (!ok) {
            cr_error(c, "energy series not a growing exact prefix");
            break;
        }
        store_run run;
        if (store_run_get(c->s, id, &run)) {
            cr_error(c, store_error()->message);
            break;
        }
        ok = run.id == id && run.steps <= CR_SAMPLES;
        store_run_clear(&run);
        if (!ok) {
            cr_error(c, "run record wrong");
            break;
        }
        if (a->k == 0) {
            store_run *v;
            size_t n;
            if (store_run_list(c->s, NULL, &v, &n)) {
                cr_error(c, store_error()->message);
                break;
            }
            store_run_list_free(v, n);
            if (n != CR_RUNS) {
                cr_error(c, "list count");
                break;
            }
        }
        atomic_fetch_add(&c->reads, 1);
    }
    return NULL;
}

TEST(store_concurrent_readers)
{
    store_options o = {.batch_ms = 5, .log = quiet_log};
    static cr_ctx c;
    memset(&c, 0, sizeof c);
    pthread_mutex_init(&c.mu, NULL);
    CHECKF(store_open(db_path("concurrent.db"), &o, &c.s) == 0, "%s", store_error()->message);
    for (int r = 0; r < CR_RUNS; r++) {
        store_run in = sample_run("concurrent", MPP_STATUS_RUNNING);
        CHECK(store_run_insert(c.s, &in, &c.ids[r]) == 0);
    }
    CHECK(store_flush(c.s) == 0);
    store_stats a;
    store_get_stats(c.s, &a);

    enum { NP = 2, NR = 4 };
    pthread_t prod[NP], rd[NR];
    cr_arg pa[NP], ra[NR];
    double t0 = td_now();
    for (int i = 0; i < NR; i++) {
        ra[i] = (cr_arg){&c, i};
        CHECK(pthread_create(&rd[i], NULL, cr_reader, &ra[i]) == 0);
    }
    for (int i = 0; i < NP; i++) {
        pa[i] = (cr_arg){&c, i};
        CHECK(pthread_create(&prod[i], NULL, cr_producer, &pa[i]) == 0);
    }
    for (int i = 0; i < NP; i++) pthread_join(prod[i], NULL);
    int frc = store_flush(c.s);
    atomic_store(&c.producers_done, 1);
    for (int i = 0; i < NR; i++) pthread_join(rd[i], NULL);
    double dt = td_now() - t0;
    store_stats b;
    store_get_stats(c.s, &b);
    TLOG("%d samples by %d producers while %d readers did %ld reads (%ld saw a partial"
         " series) in %.2f s; %llu transactions",
         CR_RUNS * CR_SAMPLES, NP, NR, atomic_load(&c.reads), atomic_load(&c.partial), dt,
         (unsigned long long)(b.transactions - a.transactions));
    CHECKF(atomic_load(&c.errors) == 0, "%d reader/producer errors; first: %s",
           atomic_load(&c.errors), c.msg);
    CHECK(frc == 0);
    CHECK(atomic_load(&c.reads) > 0);
    CHECKF(atomic_load(&c.partial) > 0, "readers never saw a batch in progress");
    CHECK(b.transactions - a.transactions > 1);
    for (int r = 0; r < CR_RUNS; r++) {
        mpm_energy_sample *es = NULL;
        size_t nes = 0;
        CHECK(store_energy_read(c.s, c.ids[r], 0, 0, &es, &nes) == 0);
        int ok = nes == CR_SAMPLES && sample_equals(es, CR_SAMPLES - 1, c.ids[r], CR_SAMPLES - 1);
        free(es);
        CHECKF(ok, "run %d incomplete after flush", r);
    }
    store_close(&c.s);
    pthread_mutex_destroy(&c.mu);
}

/* ---- a database written by the store of schema version 1 ---- */

/* Schema version 1 as the store before the vocabulary change created it
 * (its migration 0 -> 1, copied verbatim), with the header fields it set. */
static const char old_schema_v1[] =
    "CREATE TABLE runs ("
    "  id             INTEGER PRIMARY KEY,"
    "  name           TEXT NOT NULL DEFAULT '',"
    "  case_pb        BLOB NOT NULL,"
    "  case_hash      TEXT NOT NULL,"
    "  method         TEXT NOT NULL CHECK (method IN ('mpm','gimp')),"
    "  update_scheme  TEXT NOT NULL CHECK (update_scheme IN ('usf','usl','musl')),"
    "  dim            INTEGER NOT NULL CHECK (dim BETWEEN 1 AND 3),"
    "  particles      INTEGER NOT NULL DEFAULT 0,"
    "  nodes          INTEGER NOT NULL DEFAULT 0,"
    "  status         TEXT NOT NULL CHECK (status IN ('queued','running',"
    "                   'finished','failed','cancelled','interrupted')),"
    "  submitted_at   REAL NOT NULL,"
    "  started_at     REAL,"
    "  ended_at       REAL,"
    "  steps_done     INTEGER NOT NULL DEFAULT 0,"
    "  wall_s         REAL,"
    "  psteps_per_s   REAL,"
    "  kinetic        REAL,"
    "  strain         REAL,"
    "  potential      REAL,"
    "  external_work  REAL,"
    "  total          REAL,"
    "  error          TEXT,"
    "  server_version TEXT NOT NULL DEFAULT ''"
    ");"
    "CREATE INDEX runs_by_status ON runs(status, id);"
    "CREATE INDEX runs_by_case_hash ON runs(case_hash);"
    "CREATE TABLE energy ("
    "  run_id        INTEGER NOT NULL REFERENCES runs(id) ON DELETE CASCADE,"
    "  seq           INTEGER NOT NULL,"
    "  step          INTEGER NOT NULL,"
    "  t             REAL,"
    "  kinetic       REAL,"
    "  strain        REAL,"
    "  potential     REAL,"
    "  external_work REAL,"
    "  total         REAL,"
    "  momentum_x    REAL,"
    "  momentum_y    REAL,"
    "  momentum_z    REAL,"
    "  mass          REAL,"
    "  PRIMARY KEY (run_id, seq)"
    ") WITHOUT ROWID;"
    "CREATE TABLE snapshots ("
    "  run_id INTEGER NOT NULL REFERENCES runs(id) ON DELETE CASCADE,"
    "  step   INTEGER NOT NULL,"
    "  t      REAL,"
    "  n      INTEGER NOT NULL CHECK (n >= 0),"
    "  dim    INTEGER NOT NULL CHECK (dim BETWEEN 1 AND 3),"
    "  fields INTEGER NOT NULL,"
    "  data   BLOB NOT NULL,"
    "  PRIMARY KEY (run_id, step)"
    ");"
    "PRAGMA user_version = 1;"
    "PRAGMA application_id = 1836084580;" /* 0x6d706d64, "mpmd" */
    "PRAGMA journal_mode = WAL;";

/* Rows as the old store wrote them: a finished run (case bytes = case_bytes,
 * its SHA-256 in case_hash) with 3 energy samples and a snapshot, and a run
 * left 'running' by a daemon that died, with 2 samples. */
static const char old_rows_v1[] =
    "INSERT INTO runs (id, name, case_pb, case_hash, method, update_scheme, dim,"
    " particles, nodes, status, submitted_at, started_at, ended_at, steps_done, wall_s,"
    " psteps_per_s, kinetic, strain, potential, external_work, total, error,"
    " server_version) VALUES"
    " (1, 'old run', X'0a0462617273001002ff007f8001', "
    "  '02889ebafb3a820c7cc3d95866a4e025251e2164330e197de95f145922d98af9',"
    "  'gimp', 'musl', 2, 12345, 678, 'finished', 1700000000.25, 1700000001.5,"
    "  1700000003.75, 100, 2.5, 8000000.0, 1.5, 2.25, -3.0, 0.125, 0.625, NULL,"
    "  '0.3.0'),"
    " (2, 'old running', X'', "
    "  'e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855',"
    "  'mpm', 'usl', 1, 10, 11, 'running', 1700000010.0, 1700000011.0, NULL, 1234,"
    "  0.5, 1000.0, NULL, NULL, NULL, NULL, NULL, NULL, '0.3.0');"
    "INSERT INTO energy VALUES"
    " (1, 0, 3, 0.0, 0.25, 0.0, 2.5, 0.0, 2.75, 0.0, 0.0, 0.0, 2.0),"
    " (1, 1, 13, 0.5, 1.25, -1.0, 2.5, 0.125, 2.625, 1.0, -1.0, 0.0, 2.0),"
    " (1, 2, 23, 1.0, 2.25, -2.0, 2.5, 0.25, 2.5, 2.0, -2.0, NULL, 2.0),"
    " (2, 0, 7, 0.0625, 4.0, 5.0, 0.0, 1.0, 8.0, 0.5, 0.0, 0.0, 1.0),"
    " (2, 1, 17, 0.125, 3.0, 6.0, 0.0, 1.0, 8.0, 0.25, 0.0, 0.0, 1.0);"
    "INSERT INTO snapshots VALUES (1, 100, 0.125, 1, 2, 3, X'0102030405');";

TEST(store_migrate_old_schema)
{
    const char *p = db_path("old.db");
    char path[600];
    snprintf(path, sizeof path, "%s", p);
    CHECKF(store_exec_raw(path, old_schema_v1, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, old_rows_v1, NULL) == 0, "%s", store_error()->message);

    logcap lc = {.mu = PTHREAD_MUTEX_INITIALIZER};
    store_options o = {.log = cap_log, .log_ud = &lc};
    store *s = NULL;
    CHECKF(store_open(path, &o, &s) == 0, "opening a version-1 database: %s",
           store_error()->message);
    CHECKF(lc.n_migrated == 1 && lc.n_new == 0 && strstr(lc.migrated, "from version 1 to 3"), "%s",
           lc.migrated);
    int v = -1;
    CHECK(store_schema_version(s, &v) == 0);
    CHECKF(v == 3 && v == STORE_SCHEMA_VERSION, "user_version %d after migration", v);
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.recovered_running == 1 && st.recovered_queued == 0);

    /* the finished run, every field */
    store_run r;
    CHECK(store_run_get(s, 1, &r) == 0);
    int ok = r.id == 1 && !strcmp(r.name, "old run") && r.case_len == sizeof case_bytes &&
             r.case_pb && !memcmp(r.case_pb, case_bytes, sizeof case_bytes) &&
             r.method == MPM_METHOD_GIMP && r.update == MPM_MUSL && r.dim == 2 &&
             r.particles == 12345 && r.nodes == 678 && r.status == MPP_STATUS_FINISHED &&
             r.submitted_at == 1700000000.25 && r.started_at == 1700000001.5 &&
             r.finished_at == 1700000003.75 && r.steps == 100 && r.wall_s == 2.5 &&
             r.psteps_per_s == 8.0e6 && r.energy.kinetic == 1.5 && r.energy.strain == 2.25 &&
             r.energy.potential == -3.0 && r.energy.external_work == 0.125 &&
             r.energy.total == 0.625 && r.energy.mass == 0 && r.error == NULL &&
             !strcmp(r.server_version, "0.3.0");
    store_run_clear(&r);
    CHECKF(ok, "the old finished run reads back differently");

    /* its energy samples (the run's dim) and its snapshot */
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, 1, 0, 0, &es, &nes) == 0);
    ok = nes == 3;
    for (size_t i = 0; ok && i < nes; i++) {
        double x = (double)i;
        ok = es[i].seq == i && es[i].step == 10 * (int64_t)i + 3 && es[i].t == 0.5 * x &&
             es[i].dim == 2 && es[i].e.kinetic == x + 0.25 && es[i].e.strain == -x &&
             es[i].e.potential == 2.5 && es[i].e.external_work == 0.125 * x &&
             es[i].e.total == 2.75 - 0.125 * x && es[i].e.momentum[0] == x &&
             es[i].e.momentum[1] == -x && es[i].e.mass == 2.0 &&
             (i == 2 ? isnan(es[i].e.momentum[2]) : es[i].e.momentum[2] == 0.0) &&
             /* not recorded before schema 3: NaN */
             isnan(es[i].e.angular_momentum[0]) && isnan(es[i].e.angular_momentum[1]) &&
             isnan(es[i].e.angular_momentum[2]);
    }
    free(es);
    CHECKF(ok, "the old run's energy samples read back differently");
    store_snapshot sn;
    CHECK(store_snapshot_get(s, 1, -1, &sn) == 0);
    ok = sn.run_id == 1 && sn.step == 100 && sn.t == 0.125 && sn.n == 1 && sn.dim == 2 &&
         sn.fields == 3 && sn.size == 5 && !memcmp(sn.data, "\1\2\3\4\5", 5);
    store_snapshot_clear(&sn);
    CHECKF(ok, "the old snapshot reads back differently");
    store_run_extra x;
    CHECK(store_run_extras(s, 1, &x) == 0);
    ok = x.energy_count == 3 && x.last_seq == 2 && x.n_snapshots == 1 && x.snapshot_steps[0] == 100;
    store_run_extra_clear(&x);
    CHECK(ok);

    /* the run left running: interrupted at its last sample (step 17) */
    CHECK(store_run_get(s, 2, &r) == 0);
    ok = r.status == MPP_STATUS_INTERRUPTED && r.method == MPM_METHOD_MPM && r.update == MPM_USL &&
         r.dim == 1 && r.steps == 17 && r.energy.kinetic == 3.0 && r.energy.strain == 6.0 &&
         r.energy.total == 8.0 && r.finished_at == 0 && r.started_at == 1700000011.0 &&
         r.case_len == 0 && r.error && !strcmp(r.error, STORE_INTERRUPTED_RUNNING);
    store_run_clear(&r);
    CHECKF(ok, "the old running run after migration and recovery");
    store_run_filter f = {.status_mask = STORE_STATUS_BIT(MPP_STATUS_FINISHED)};
    store_run *list;
    size_t n;
    CHECK(store_run_list(s, &f, &list, &n) == 0);
    ok = n == 1 && list[0].id == 1;
    store_run_list_free(list, n);
    CHECK(ok);

    /* the migrated database takes new runs, ids continuing */
    store_run in = sample_run("new", MPP_STATUS_QUEUED);
    int64_t id = 0;
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(id == 3);
    store_run_end end = {.status = MPP_STATUS_FINISHED, .finished_at = 1700000020.0, .steps = 9};
    mpm_energy_sample ne[2] = {make_sample(id, 0), make_sample(id, 1)};
    CHECK(store_energy_append(s, id, ne, 2) == 0);
    CHECK(store_run_finish(s, id, &end) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.update == MPM_MUSL && r.status == MPP_STATUS_FINISHED && r.finished_at == 1700000020.0 &&
         r.steps == 9;
    store_run_clear(&r);
    CHECK(ok);
    /* and its samples with their angular momentum, bit for bit */
    CHECK(store_energy_read(s, id, 0, 0, &es, &nes) == 0);
    ok = nes == 2 && sample_equals(es, 0, id, 0) && sample_equals(es, 1, id, 1);
    free(es);
    CHECKF(ok, "new samples in the migrated database");
    store_close(&s);

    /* on disk: the energy table has the angular momentum columns */
    int64_t na = -1;
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM pragma_table_info('energy') WHERE name IN"
                         " ('angular_momentum_x', 'angular_momentum_y', 'angular_momentum_z')",
                         &na) == 0 &&
          na == 3);

    /* on disk: the hash column and its index are gone, the columns renamed */
    int64_t cnt = -1;
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM pragma_table_info('runs') WHERE name IN"
                         " ('case_hash', 'update_scheme', 'ended_at', 'steps_done')",
                         &cnt) == 0);
    CHECKF(cnt == 0, "%lld old columns left", (long long)cnt);
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM pragma_table_info('runs') WHERE name IN"
                         " ('update', 'finished_at', 'steps')",
                         &cnt) == 0 &&
          cnt == 3);
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM sqlite_master WHERE name ="
                         " 'runs_by_case_hash'",
                         &cnt) == 0 &&
          cnt == 0);
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM sqlite_master WHERE name ="
                         " 'runs_by_status'",
                         &cnt) == 0 &&
          cnt == 1);
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM pragma_integrity_check WHERE"
                         " integrity_check != 'ok'",
                         &cnt) == 0 &&
          cnt == 0);
    /* the renamed column keeps its CHECK constraint */
    int rc = store_exec_raw(path, "UPDATE runs SET \"update\" = 'bogus' WHERE id = 1", NULL);
    CHECKF(rc == MPM_EIO && strstr(store_error()->message, "CHECK"), "%d %s", rc,
           store_error()->message);

    /* a second open migrates nothing */
    lc.n_migrated = 0;
    CHECKF(store_open(path, &o, &s) == 0, "%s", store_error()->message);
    CHECK(store_schema_version(s, &v) == 0 && v == STORE_SCHEMA_VERSION);
    store_close(&s);
    CHECK(lc.n_migrated == 0);
}

/* A version-2 database (the version-1 script, then 1 -> 2 as it was
 * released): a finished 3D run with two energy samples.  Opening it migrates
 * 2 -> 3 alone: the old samples read back with every other field intact and
 * the angular momentum NaN (not recorded); new samples keep theirs. */
static const char migrate_v1_to_v2[] = "DROP INDEX runs_by_case_hash;"
                                       "ALTER TABLE runs DROP COLUMN case_hash;"
                                       "ALTER TABLE runs RENAME COLUMN update_scheme TO \"update\";"
                                       "ALTER TABLE runs RENAME COLUMN ended_at TO finished_at;"
                                       "ALTER TABLE runs RENAME COLUMN steps_done TO steps;"
                                       "PRAGMA user_version = 2;";

static const char old_rows_v2[] =
    "INSERT INTO runs (id, name, case_pb, method, \"update\", dim, particles, nodes, status,"
    " submitted_at, started_at, finished_at, steps, wall_s, psteps_per_s, kinetic, strain,"
    " potential, external_work, total, error, server_version) VALUES"
    " (4, 'v2 run', X'0a0162', 'gimp', 'usf', 3, 8, 27, 'finished', 1700000100.0,"
    "  1700000101.0, 1700000102.0, 20, 1.0, 160.0, 0.5, 0.25, 0.0, 0.0, 0.75, NULL, '0.4.0');"
    "INSERT INTO energy VALUES"
    " (4, 0, 0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.5, 1.0, 2.0, 3.0, 4.0),"
    " (4, 1, 20, 0.25, 0.5, 0.25, 0.0, 0.0, 0.75, 1.5, 2.5, 3.5, 4.0);";

TEST(store_migrate_v2)
{
    const char *p = db_path("v2.db");
    char path[600];
    snprintf(path, sizeof path, "%s", p);
    CHECKF(store_exec_raw(path, old_schema_v1, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, migrate_v1_to_v2, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, old_rows_v2, NULL) == 0, "%s", store_error()->message);

    logcap lc = {.mu = PTHREAD_MUTEX_INITIALIZER};
    store_options o = {.log = cap_log, .log_ud = &lc};
    store *s = NULL;
    CHECKF(store_open(path, &o, &s) == 0, "opening a version-2 database: %s",
           store_error()->message);
    CHECKF(lc.n_migrated == 1 && strstr(lc.migrated, "from version 2 to 3"), "%s", lc.migrated);
    int v = -1;
    CHECK(store_schema_version(s, &v) == 0 && v == 3);

    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, 4, 0, 0, &es, &nes) == 0);
    int ok = nes == 2;
    for (size_t i = 0; ok && i < nes; i++) {
        double x = (double)i;
        ok = es[i].seq == i && es[i].step == 20 * (int64_t)i && es[i].dim == 3 &&
             es[i].e.kinetic == 0.5 && es[i].e.total == 0.5 + 0.25 * x &&
             es[i].e.momentum[0] == 1 + 0.5 * x && es[i].e.momentum[1] == 2 + 0.5 * x &&
             es[i].e.momentum[2] == 3 + 0.5 * x && es[i].e.mass == 4 &&
             isnan(es[i].e.angular_momentum[0]) && isnan(es[i].e.angular_momentum[1]) &&
             isnan(es[i].e.angular_momentum[2]);
    }
    free(es);
    CHECKF(ok, "the version-2 samples read back differently");
    store_run r;
    CHECK(store_run_get(s, 4, &r) == 0);
    ok = r.status == MPP_STATUS_FINISHED && r.dim == 3 && r.steps == 20 && r.energy.total == 0.75;
    store_run_clear(&r);
    CHECK(ok);

    /* a new run's samples carry their angular momentum */
    store_run in = sample_run("new", MPP_STATUS_RUNNING);
    int64_t id = 0;
    CHECK(store_run_insert(s, &in, &id) == 0 && id == 5);
    mpm_energy_sample ne = make_sample(id, 0);
    CHECK(store_energy_append(s, id, &ne, 1) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_energy_read(s, id, 0, 0, &es, &nes) == 0);
    ok = nes == 1 && sample_equals(es, 0, id, 0) && es[0].e.angular_momentum[2] == 7.5;
    free(es);
    CHECK(ok);
    store_close(&s);
    int64_t cnt = -1;
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM pragma_integrity_check WHERE"
                         " integrity_check != 'ok'",
                         &cnt) == 0 &&
          cnt == 0);
}

/* ---- commit tracking without blocking ---- */

/* 1 when fd becomes readable within ms milliseconds. */
static int readable_within(int fd, int ms)
{
    struct pollfd p = {.fd = fd, .events = POLLIN};
    return poll(&p, 1, ms) == 1 && (p.revents & POLLIN);
}

/* Waits (at most 5 s) in a poll loop on the notify fd until the ticket is
 * done, as the daemon's event loop would; 1 if it is. */
static int wait_ticket(store *s, uint64_t t)
{
    double t0 = td_now();
    while (!store_ticket_done(s, t) && td_now() - t0 < 5)
        if (readable_within(store_notify_fd(s), 1000)) store_notify_drain(s);
    return store_ticket_done(s, t);
}

TEST(store_tickets)
{
    /* nothing commits on its own for 60 s: whatever commits does so because
     * a ticket (or a flush) asked for it */
    store_options o = {.batch_ms = 60000, .log = quiet_log};
    store *s = NULL;
    CHECKF(store_open(db_path("tickets.db"), &o, &s) == 0, "%s", store_error()->message);
    int fd = store_notify_fd(s);
    CHECK(fd >= 0);
    CHECK(fcntl(fd, F_GETFL) & O_NONBLOCK);
    store_run in = sample_run("A", MPP_STATUS_RUNNING);
    int64_t a, b;
    CHECK(store_run_insert(s, &in, &a) == 0);
    in.name = "B";
    CHECK(store_run_insert(s, &in, &b) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(readable_within(fd, 0)); /* the flush's commit */
    store_notify_drain(s);
    CHECK(!readable_within(fd, 0)); /* drained */
    store_notify_drain(s);          /* draining an empty fd: no-op */

    /* nothing pending: tickets are done at once */
    CHECK(store_ticket(s, a) == 0 && store_ticket_done(s, 0));
    CHECK(store_ticket(s, 0) == 0);
    CHECK(store_ticket(s, 424242) == 0);

    /* samples for A and B; A's ticket is that of A's write, and it is done
     * (and the fd readable) after a commit the ticket asked for */
    store_stats st0;
    store_get_stats(s, &st0);
    mpm_energy_sample ea = make_sample(a, 0), eb = make_sample(b, 0);
    CHECK(store_energy_append(s, a, &ea, 1) == 0);
    CHECK(store_energy_append(s, b, &eb, 1) == 0);
    uint64_t ta = store_ticket(s, a);
    CHECKF(ta == st0.ops_enqueued + 1, "ticket %llu, want %llu", (unsigned long long)ta,
           (unsigned long long)st0.ops_enqueued + 1);
    double t0 = td_now();
    CHECK(readable_within(fd, 5000));
    CHECKF(wait_ticket(s, ta), "run A's ticket not done");
    double dt = td_now() - t0;
    TLOG("run A's ticket done after %.1f ms (batching window 60 s)", 1e3 * dt);
    CHECK_LT(dt, 5.0);
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, a, 0, 0, &es, &nes) == 0);
    int ok = nes == 1 && sample_equals(es, 0, a, 0);
    free(es);
    CHECKF(ok, "run A's sample not readable when its ticket is done");
    store_notify_drain(s);

    /* a write for B only: A's ticket does not wait for it */
    CHECK(wait_ticket(s, store_ticket(s, b))); /* B's first sample is in */
    mpm_energy_sample eb1 = make_sample(b, 1);
    CHECK(store_energy_append(s, b, &eb1, 1) == 0);
    CHECK(store_ticket(s, a) == 0); /* A has nothing pending */
    store_stats st1;
    store_get_stats(s, &st1);
    CHECKF(st1.queue_ops == 1, "%zu writes pending, want B's", st1.queue_ops);
    CHECK(store_energy_read(s, b, 0, 0, &es, &nes) == 0);
    free(es);
    CHECKF(nes == 1, "B's second sample committed without being asked for (%zu)", nes);
    uint64_t tb = store_ticket(s, b);
    CHECK(tb == st1.ops_enqueued);
    CHECK(wait_ticket(s, tb));
    CHECK(store_energy_read(s, b, 0, 0, &es, &nes) == 0);
    ok = nes == 2 && sample_equals(es, 0, b, 0) && sample_equals(es, 1, b, 1);
    free(es);
    CHECK(ok);
    CHECK(store_ticket(s, b) == 0 && store_ticket(s, 0) == 0);

    /* any run: a ticket covers every write enqueued before it */
    CHECK(store_run_progress(s, a, 5, 1, 1) == 0);
    CHECK(store_run_progress(s, b, 6, 1, 1) == 0);
    uint64_t tall = store_ticket(s, 0);
    CHECK(tall == tb + 2);
    CHECK(wait_ticket(s, tall));
    store_run r;
    CHECK(store_run_get(s, a, &r) == 0);
    ok = r.steps == 5;
    store_run_clear(&r);
    CHECK(store_run_get(s, b, &r) == 0);
    ok = ok && r.steps == 6;
    store_run_clear(&r);
    CHECK(ok);

    /* a failed write completes its ticket too (flush reports it) */
    CHECK(store_run_progress(s, 9999, 1, 1, 1) == 0);
    uint64_t tf = store_ticket(s, 9999);
    CHECK(tf == tall + 1);
    CHECK(wait_ticket(s, tf));
    CHECK(store_flush(s) == MPM_EIO);
    store_close(&s);
}

TEST(store_tickets_many_runs)
{
    /* more runs than the ticket map's first size: it is rebuilt, and every
     * run's ticket stays that of its last write */
    store_options o = {.batch_ms = 60000, .log = quiet_log};
    store *s = NULL;
    CHECKF(store_open(db_path("tickets2.db"), &o, &s) == 0, "%s", store_error()->message);
    enum { NRUNS = 300 };
    int64_t ids[NRUNS];
    store_stats st0;
    store_get_stats(s, &st0);
    for (int i = 0; i < NRUNS; i++) {
        store_run in = sample_run("many", MPP_STATUS_QUEUED);
        CHECK(store_run_insert(s, &in, &ids[i]) == 0);
    }
    /* a second write for the even runs, after all the inserts */
    for (int i = 0; i < NRUNS; i += 2) CHECK(store_run_progress(s, ids[i], i, 1, 1) == 0);
    store_stats st1;
    store_get_stats(s, &st1);
    CHECK(st1.queue_ops == NRUNS + NRUNS / 2); /* nothing committed yet */
    /* run_ticket(i): insert i is op base + i + 1, progress of 2k op base + NRUNS + k + 1 */
    uint64_t base = st0.ops_enqueued;
    int pending = 0;
    for (int i = NRUNS - 1; i >= 0; i--) {
        uint64_t want = i % 2 ? base + (uint64_t)i + 1 : base + NRUNS + (uint64_t)i / 2 + 1;
        uint64_t t = store_ticket(s, ids[i]);
        /* an earlier ticket may have had it committed already */
        if (t != 0 && t != want)
            CHECKF(0, "run %d: ticket %llu, want %llu", i, (unsigned long long)t,
                   (unsigned long long)want);
        pending += t != 0;
    }
    TLOG("%d of %d tickets taken while their writes were pending", pending, NRUNS);
    CHECK(pending > 0); /* the first at least: nothing had committed */
    CHECK(store_flush(s) == 0);
    for (int i = 0; i < NRUNS; i++) CHECK(store_ticket(s, ids[i]) == 0);
    /* after the commits, the map is rebuilt without them */
    for (int i = 0; i < NRUNS; i++) CHECK(store_run_progress(s, ids[i], 1000 + i, 1, 1) == 0);
    uint64_t last = store_ticket(s, ids[NRUNS - 1]);
    CHECK(last == st1.ops_enqueued + NRUNS);
    CHECK(store_flush(s) == 0);
    CHECK(store_ticket_done(s, last));
    store_close(&s);
}
