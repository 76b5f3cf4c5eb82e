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
#include "t_store.h"
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

/* ---- helpers used only here ---- */

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
    int ok = r.id == id && !strcmp(r.name, in.name) && r.case_len == case_bytes_len && r.case_pb &&
             !memcmp(r.case_pb, case_bytes, case_bytes_len) && r.method == MPM_METHOD_GIMP &&
             r.update == MPM_MUSL && r.dim == 2 && r.particles == 12345 && r.nodes == 678 &&
             r.status == MPP_STATUS_QUEUED && r.submitted_at == 1700000000.25 &&
             r.started_at == 0 && r.finished_at == 0 && r.steps == 0 && isnan(r.energy.kinetic) &&
             isnan(r.energy.total) && r.error == NULL && !strcmp(r.server_version, "mpmd 0.1-test");
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

    /* the solver's plan (schema 9), then progress */
    CHECK(store_run_plan(s, id, "kernels=portable fuse=auto") == 0);
    CHECK(store_run_plan(s, id, NULL) == MPM_EINVAL);
    CHECK(store_run_progress(s, id, 50, 1.25, 4.0e6) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.status == MPP_STATUS_RUNNING && r.steps == 50 && r.wall_s == 1.25 &&
         r.psteps_per_s == 4.0e6 && r.plan && !strcmp(r.plan, "kernels=portable fuse=auto");
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
         !memcmp(r.case_pb, case_bytes, case_bytes_len);
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
             v[i].case_len == case_bytes_len &&
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
         v[0].case_len == case_bytes_len && !memcmp(v[0].case_pb, case_bytes, case_bytes_len);
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

    /* a directory that does not exist (the lock is taken on the database
     * file itself, so that is what cannot be opened) */
    rc = store_open("/nonexistent-mpmd-dir/x.db", &quiet, &s);
    CHECKF(rc == MPM_EIO && strstr(store_error()->message, "cannot open database"), "%d %s", rc,
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
