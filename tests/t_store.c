/*
 * t_store.c - tests of the run-record store (server/store.c) on real SQLite
 * files in the test's temporary directory: run lifecycle and read-back,
 * 10k energy samples, listing, reopening, crash recovery (a forked child
 * that exits without closing), the one-daemon lock, schema versions,
 * snapshots and the queue cap, asynchronous write errors, and readers
 * running while the writer batches.
 */
#include "store.h"
#include "t.h"
#include "t_daemon.h"

#include <errno.h>
#include <fcntl.h>
#include <float.h>
#include <math.h>
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
    int n_dropped, n_cap, n_interrupted, n_new, n_total;
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
    snprintf(lc->last, sizeof lc->last, "%s", msg);
    pthread_mutex_unlock(&lc->mu);
}

static void quiet_log(void *ud, const char *msg) { (void)ud; (void)msg; }

static const unsigned char case_bytes[] = {
    0x0a, 0x04, 'b', 'a', 'r', 's', 0x00, 0x10, 0x02, 0xff, 0x00, 0x7f, 0x80, 0x01
};

static store_run sample_run(const char *name, store_status st)
{
    store_run r;
    memset(&r, 0, sizeof r);
    r.name = name;
    r.case_pb = case_bytes;
    r.case_len = sizeof case_bytes;
    r.method = STORE_METHOD_GIMP;
    r.update = STORE_MUSL;
    r.dim = 2;
    r.particles = 12345;
    r.nodes = 678;
    r.status = st;
    r.submitted_at = 1700000000.25;
    r.server_version = "mpmd 0.1-test";
    return r;
}

/* A deterministic sample with awkward values; the same call gives the same
 * bits, so read-back can be compared exactly. */
static store_energy_sample make_sample(int64_t run, int64_t i)
{
    store_energy_sample e;
    double x = (double)i;
    e.run_id = run;
    e.seq = i;
    e.step = 10 * i + 3;
    e.t = x * 1e-3 + 1.0 / 3.0;
    e.kinetic = sin(x) * 1e3 + (double)run;
    e.strain = cos(x) / 7.0;
    e.potential = -x * 9.81 / 3.0;
    e.external_work = i % 3 == 0 ? 1e-300 * x : DBL_MAX / (x + 1);
    e.total = e.kinetic + e.strain + e.potential - e.external_work;
    e.momentum[0] = 1.0 / (x + 1);
    e.momentum[1] = -exp(-x / 100);
    e.momentum[2] = i % 2 ? 5e-324 : -2.5;
    e.mass = 2.0 + x * 1e-9;
    return e;
}

/* 1 if row i of the series equals make_sample(run, seq) bit for bit. */
static int series_row_equals(const store_energy_series *es, size_t i, int64_t run, int64_t seq)
{
    store_energy_sample e = make_sample(run, seq);
    return es->seq[i] == e.seq && es->step[i] == e.step && es->t[i] == e.t &&
           es->kinetic[i] == e.kinetic && es->strain[i] == e.strain &&
           es->potential[i] == e.potential && es->external_work[i] == e.external_work &&
           es->total[i] == e.total && es->momentum_x[i] == e.momentum[0] &&
           es->momentum_y[i] == e.momentum[1] && es->momentum_z[i] == e.momentum[2] &&
           es->mass[i] == e.mass;
}

static void sleep_ms(int ms)
{
    struct timespec ts = { ms / 1000, (long)(ms % 1000) * 1000000L };
    nanosleep(&ts, NULL);
}

/* Options with logging silenced (tests that check log lines use cap_log). */
static const store_options quiet = { .log = quiet_log };

/* ---- tests ---- */

TEST(store_sha256_vectors)
{
    static const struct { size_t len; char fill; const char *hex; } v[] = {
        { 55, 'x', "d5e285683cd4efc02d021a5c62014694958901005d6f71e89e0989fac77e4072" },
        { 56, 'x', "04c26261370ee7541549d16dee320c723e3fd14671e66a099afe0a377c16888e" },
        { 63, 'x', "75220b47218278e656f2013bb8f0c455a25eaf01e86c64924e9d48d89776d6f2" },
        { 64, 'x', "7ce100971f64e7001e8fe5a51973ecdfe1ced42befe7ee8d5fd6219506b5393c" },
        { 65, 'x', "9537c5fdf120482f7d58d25e9ed583f52c02b4e304ea814db1633ad565aed7e9" },
        { 119, 'x', "000b48d4edf0fa7bee3c6236ecd2785baa5db4eeb8bb54341b029e0d9fa5fb0c" },
        { 120, 'x', "13f05a0b594787f5ecd315edc96141bd3243203d1b7d4f0836f37308b276ba98" },
        { 127, 'x', "70156a14adbabf98cff3a71c7084b417abf057a8efd27329ca36b7202c87d81f" },
        { 128, 'x', "24da1b81d0b16df6428eee73c69fcb2a93c76bc6df706f0c6670fe6bfe800464" },
        { 1000000, 'a', "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0" },
    };
    char hex[65];
    store_sha256_hex("", 0, hex);
    CHECKF(!strcmp(hex, "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"),
           "sha256('') = %s", hex);
    store_sha256_hex(NULL, 0, hex);
    CHECK(!strcmp(hex, "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"));
    store_sha256_hex("abc", 3, hex);
    CHECKF(!strcmp(hex, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"),
           "sha256('abc') = %s", hex);
    const char *m = "abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq";
    store_sha256_hex(m, strlen(m), hex);
    CHECKF(!strcmp(hex, "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1"),
           "sha256(448-bit message) = %s", hex);
    char *buf = malloc(1000000);
    CHECK(buf);
    for (size_t i = 0; i < sizeof v / sizeof v[0]; i++) {
        memset(buf, v[i].fill, v[i].len);
        store_sha256_hex(buf, v[i].len, hex);
        if (strcmp(hex, v[i].hex)) {
            free(buf);
            CHECKF(0, "sha256 of %zu x '%c' = %s, want %s", v[i].len, v[i].fill, hex, v[i].hex);
        }
    }
    free(buf);
}

TEST(store_run_lifecycle)
{
    char err[256];
    store *s = NULL;
    int rc = store_open(db_path("runs.db"), NULL, &s, err, sizeof err);
    CHECKF(rc == 0 && s, "store_open: %d %s", rc, err);

    store_run in = sample_run("bar \"one\" \xc3\xa9", STORE_QUEUED);
    int64_t id = -1;
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(id == 1);                       /* fresh database: ids start at 1 */
    CHECK(store_flush(s) == 0);

    store_run r;
    CHECK(store_run_get(s, id, &r) == 0);
    char hash[65];
    store_sha256_hex(case_bytes, sizeof case_bytes, hash);
    int ok = r.id == id && !strcmp(r.name, in.name) && r.case_len == sizeof case_bytes &&
             r.case_pb && !memcmp(r.case_pb, case_bytes, sizeof case_bytes) &&
             !strcmp(r.case_hash, hash) && r.method == STORE_METHOD_GIMP &&
             r.update == STORE_MUSL && r.dim == 2 && r.particles == 12345 &&
             r.nodes == 678 && r.status == STORE_QUEUED &&
             r.submitted_at == 1700000000.25 && r.started_at == 0 && r.ended_at == 0 &&
             r.steps_done == 0 && isnan(r.energy.kinetic) && isnan(r.energy.total) &&
             r.error == NULL && !strcmp(r.server_version, "mpmd 0.1-test");
    store_run_clear(&r);
    CHECKF(ok, "queued run read back differs");
    CHECK(r.name == NULL && r.case_pb == NULL);    /* cleared */

    /* queued -> running */
    CHECK(store_run_set_status(s, id, STORE_RUNNING, 1700000001.5, NULL) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.status == STORE_RUNNING && r.started_at == 1700000001.5 && r.ended_at == 0;
    store_run_clear(&r);
    CHECKF(ok, "running: status/started_at wrong");

    /* progress */
    CHECK(store_run_progress(s, id, 50, 1.25, 4.0e6) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.status == STORE_RUNNING && r.steps_done == 50 && r.wall_s == 1.25 &&
         r.psteps_per_s == 4.0e6;
    store_run_clear(&r);
    CHECKF(ok, "progress not recorded");

    /* finish with energies */
    store_run_end end = { .status = STORE_FINISHED, .ended_at = 1700000003.75,
                          .steps_done = 100, .wall_s = 2.5, .psteps_per_s = 8.0e6,
                          .has_energy = 1,
                          .energy = { 1.5, 2.25, -3.0, 0.125, 0.625 - 1.0 / 3.0 } };
    CHECK(store_run_finish(s, id, &end) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.status == STORE_FINISHED && r.started_at == 1700000001.5 &&
         r.ended_at == 1700000003.75 && r.steps_done == 100 && r.wall_s == 2.5 &&
         r.psteps_per_s == 8.0e6 && r.energy.kinetic == 1.5 && r.energy.strain == 2.25 &&
         r.energy.potential == -3.0 && r.energy.external_work == 0.125 &&
         r.energy.total == 0.625 - 1.0 / 3.0 && r.error == NULL &&
         !strcmp(r.name, in.name) && !memcmp(r.case_pb, case_bytes, sizeof case_bytes);
    store_run_clear(&r);
    CHECKF(ok, "finished run read back differs");

    /* a failed run: error text, no energies; status time defaults to now */
    in = sample_run("fails", STORE_QUEUED);
    in.case_pb = NULL;
    in.case_len = 0;
    in.submitted_at = 0;                     /* now */
    in.name = NULL;                          /* "" */
    int64_t id2 = 0;
    double t0 = store_time_now();
    CHECK(store_run_insert(s, &in, &id2) == 0);
    CHECK(id2 == 2);
    CHECK(store_run_set_status(s, id2, STORE_RUNNING, 0, NULL) == 0);
    store_run_end fe = { .status = STORE_FAILED, .steps_done = 7, .wall_s = 0.5,
                         .error = "particle 3 left the grid at step 7" };
    CHECK(store_run_finish(s, id2, &fe) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id2, &r) == 0);
    ok = r.status == STORE_FAILED && r.error &&
         !strcmp(r.error, "particle 3 left the grid at step 7") && isnan(r.energy.kinetic) &&
         isnan(r.energy.total) && r.steps_done == 7 && !strcmp(r.name, "") &&
         r.case_len == 0 && r.case_pb == NULL &&
         !strcmp(r.case_hash, "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855") &&
         r.submitted_at >= t0 - 1 && r.submitted_at <= store_time_now() + 1 &&
         r.started_at >= r.submitted_at && r.ended_at >= r.started_at;
    store_run_clear(&r);
    CHECKF(ok, "failed run read back differs");

    /* cancelled via set_status (a terminal status) keeps the error given */
    in = sample_run("cancel me", STORE_QUEUED);
    int64_t id3 = 0;
    CHECK(store_run_insert(s, &in, &id3) == 0);
    CHECK(store_run_set_status(s, id3, STORE_RUNNING, 1700000008.0, NULL) == 0);
    CHECK(store_run_set_status(s, id3, STORE_CANCELLED, 1700000009.0, "cancelled by client") == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id3, &r) == 0);
    ok = r.status == STORE_CANCELLED && r.started_at == 1700000008.0 &&
         r.ended_at == 1700000009.0 && r.error && !strcmp(r.error, "cancelled by client");
    store_run_clear(&r);
    CHECKF(ok, "set_status to a terminal status");

    /* a terminal status is final: late updates of an ended run fail */
    char msg[512];
    CHECK(store_run_set_status(s, id, STORE_RUNNING, 1700000010.0, NULL) == 0);
    CHECK(store_flush(s) == STORE_EWRITE);
    store_last_write_error(s, msg, sizeof msg);
    CHECKF(strstr(msg, "already ended (finished)"), "error text: %s", msg);
    CHECK(store_run_progress(s, id3, 1, 1, 1) == 0);
    CHECK(store_run_finish(s, id3, &end) == 0);
    CHECK(store_flush(s) == STORE_EWRITE);
    store_last_write_error(s, msg, sizeof msg);
    CHECKF(strstr(msg, "already ended (cancelled)"), "error text: %s", msg);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.status == STORE_FINISHED && r.started_at == 1700000001.5 && r.steps_done == 100;
    store_run_clear(&r);
    CHECKF(ok, "finished run changed by a late update");
    CHECK(store_run_get(s, id3, &r) == 0);
    ok = r.status == STORE_CANCELLED && r.steps_done == 0 && isnan(r.energy.kinetic);
    store_run_clear(&r);
    CHECKF(ok, "cancelled run changed by late updates");
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.write_errors == 3);

    CHECK(store_run_get(s, 999, &r) == STORE_ENOTFOUND);
    store_close(&s);
    CHECK(s == NULL);
    store_close(&s);                         /* no-op */
}

TEST(store_energy_10k)
{
    char err[256];
    store *s = NULL;
    int rc = store_open(db_path("energy.db"), &quiet, &s, err, sizeof err);
    CHECKF(rc == 0, "store_open: %s", err);
    store_run in = sample_run("energy", STORE_RUNNING);
    int64_t id = 0, id2 = 0;
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(store_run_insert(s, &in, &id2) == 0);
    store_stats st0;
    store_get_stats(s, &st0);

    const int N = 10000;
    double t0 = td_now();
    for (int i = 0; i < N; i++) {
        store_energy_sample e = make_sample(id, i);
        rc = store_energy_append(s, &e);
        if (rc) CHECKF(0, "append %d: %d %s", i, rc, store_errmsg());
    }
    double t_enq = td_now() - t0;
    /* and 1000 in one call for the second run */
    store_energy_sample *v = malloc(1000 * sizeof *v);
    CHECK(v);
    for (int i = 0; i < 1000; i++) v[i] = make_sample(id2, i);
    rc = store_energy_append_n(s, v, 1000);
    memset(v, 0, 1000 * sizeof *v);          /* the store has its own copy */
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

    store_energy_series es;
    CHECK(store_energy_read(s, id, 0, 0, &es) == 0);
    CHECKF(es.n == (size_t)N, "read %zu samples, want %d", es.n, N);
    size_t bad = SIZE_MAX;
    for (size_t i = 0; i < es.n && bad == SIZE_MAX; i++)
        if (!series_row_equals(&es, i, id, (int64_t)i)) bad = i;
    store_energy_series_free(&es);
    CHECKF(bad == SIZE_MAX, "sample %zu differs", bad);
    CHECK(es.n == 0 && es.seq == NULL);

    CHECK(store_energy_read(s, id, 5000, 100, &es) == 0);
    int ok = es.n == 100 && es.seq[0] == 5000 && es.seq[99] == 5099 &&
             series_row_equals(&es, 0, id, 5000) && series_row_equals(&es, 99, id, 5099);
    store_energy_series_free(&es);
    CHECKF(ok, "read from seq 5000, max 100");

    CHECK(store_energy_read(s, id, N, 0, &es) == 0);
    CHECK(es.n == 0 && es.seq == NULL);
    CHECK(store_energy_read(s, 424242, 0, 0, &es) == 0);
    CHECK(es.n == 0);

    CHECK(store_energy_read(s, id2, 0, 0, &es) == 0);
    ok = es.n == 1000;
    for (size_t i = 0; ok && i < es.n; i++) ok = series_row_equals(&es, i, id2, (int64_t)i);
    store_energy_series_free(&es);
    CHECKF(ok, "append_n samples differ");
    store_close(&s);
}

TEST(store_nonfinite_values)
{
    char err[256];
    store *s = NULL;
    CHECKF(store_open(db_path("nan.db"), &quiet, &s, err, sizeof err) == 0, "%s", err);
    store_run in = sample_run("nan", STORE_RUNNING);
    int64_t id = 0;
    CHECK(store_run_insert(s, &in, &id) == 0);
    store_energy_sample e = make_sample(id, 0);
    e.total = NAN;
    e.kinetic = INFINITY;
    e.strain = -INFINITY;
    CHECK(store_energy_append(s, &e) == 0);
    store_run_end end = { .status = STORE_FAILED, .steps_done = 3, .wall_s = NAN,
                          .has_energy = 1, .energy = { INFINITY, NAN, 1.0, 0.0, NAN },
                          .error = "diverged" };
    CHECK(store_run_finish(s, id, &end) == 0);
    CHECK(store_flush(s) == 0);
    store_energy_series es;
    CHECK(store_energy_read(s, id, 0, 0, &es) == 0);
    int ok = es.n == 1 && isnan(es.total[0]) && isinf(es.kinetic[0]) && es.kinetic[0] > 0 &&
             isinf(es.strain[0]) && es.strain[0] < 0 && es.mass[0] == e.mass;
    store_energy_series_free(&es);
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
    char err[256];
    store *s = NULL;
    CHECKF(store_open(db_path("list.db"), &quiet, &s, err, sizeof err) == 0, "%s", err);
    /* ids 1..10, statuses cycling queued, running, finished, failed, cancelled */
    for (int i = 1; i <= 10; i++) {
        char name[32];
        snprintf(name, sizeof name, "run-%d", i);
        store_run in = sample_run(name, (store_status)((i - 1) % 5));
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
        ok = v[i].id == (int64_t)(10 - i) && !strcmp(v[i].name, name) &&
             v[i].case_pb == NULL && v[i].case_len == sizeof case_bytes &&
             v[i].status == (store_status)((9 - i) % 5);
    }
    store_run_list_free(v, n);
    CHECKF(ok, "list all: newest first, names, statuses");

    store_run_filter f = { .status_mask = STORE_STATUS_BIT(STORE_FINISHED) };
    CHECK(store_run_list(s, &f, &v, &n) == 0);
    ok = n == 2 && v[0].id == 8 && v[1].id == 3 && v[0].status == STORE_FINISHED;
    store_run_list_free(v, n);
    CHECKF(ok, "status filter finished");

    f.status_mask = STORE_STATUS_BIT(STORE_FAILED) | STORE_STATUS_BIT(STORE_QUEUED);
    f.limit = 3;
    CHECK(store_run_list(s, &f, &v, &n) == 0);
    ok = n == 3 && v[0].id == 9 && v[1].id == 6 && v[2].id == 4;
    store_run_list_free(v, n);
    CHECKF(ok, "failed|queued, limit 3");

    store_run_filter g = { .limit = 2, .before_id = 5, .with_case = 1 };
    CHECK(store_run_list(s, &g, &v, &n) == 0);
    ok = n == 2 && v[0].id == 4 && v[1].id == 3 && v[0].case_pb &&
         v[0].case_len == sizeof case_bytes && !memcmp(v[0].case_pb, case_bytes, sizeof case_bytes);
    store_run_list_free(v, n);
    CHECKF(ok, "paging with before_id and limit, with case bytes");

    f.status_mask = STORE_STATUS_BIT(STORE_INTERRUPTED);
    f.limit = 0;
    CHECK(store_run_list(s, &f, &v, &n) == 0);
    CHECK(n == 0 && v == NULL);
    f.status_mask = 1u << 12;
    CHECK(store_run_list(s, &f, &v, &n) == STORE_EINVAL);
    store_close(&s);
}

TEST(store_reopen_ids_continue)
{
    char err[256];
    const char *path = db_path("reopen.db");
    store *s = NULL;
    CHECKF(store_open(path, &quiet, &s, err, sizeof err) == 0, "%s", err);
    for (int i = 0; i < 3; i++) {
        store_run in = sample_run("persist", STORE_QUEUED);
        int64_t id;
        CHECK(store_run_insert(s, &in, &id) == 0);
        store_run_end end = { .status = STORE_FINISHED, .steps_done = 10 * (i + 1),
                              .has_energy = 1, .energy = { i, 0, 0, 0, i } };
        CHECK(store_run_finish(s, id, &end) == 0);
        store_energy_sample e = make_sample(id, 0);
        CHECK(store_energy_append(s, &e) == 0);
    }
    store_close(&s);                            /* no flush: close flushes */

    CHECKF(store_open(path, &quiet, &s, err, sizeof err) == 0, "reopen: %s", err);
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.recovered_running == 0 && st.recovered_queued == 0);
    store_run r;
    CHECK(store_run_get(s, 2, &r) == 0);
    int ok = r.status == STORE_FINISHED && r.steps_done == 20 && r.energy.kinetic == 1 &&
             !strcmp(r.name, "persist");
    store_run_clear(&r);
    CHECKF(ok, "run 2 after reopen");
    store_energy_series es;
    CHECK(store_energy_read(s, 3, 0, 0, &es) == 0);
    ok = es.n == 1 && series_row_equals(&es, 0, 3, 0);
    store_energy_series_free(&es);
    CHECKF(ok, "energy sample of run 3 after reopen");

    CHECK(store_new_run_id(s) == 4);
    store_run in = sample_run("after", STORE_QUEUED);
    int64_t id = 0;
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(id == 5);
    in.id = 100;                                /* explicit id moves the counter */
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(id == 100);
    in.id = 0;
    store_close(&s);

    CHECKF(store_open(path, &quiet, &s, err, sizeof err) == 0, "reopen 2: %s", err);
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
        char err[256];
        store_options o = { .log = quiet_log };
        if (store_open(path, &o, &s, err, sizeof err)) _exit(10);
        store_run a = sample_run("was running", STORE_QUEUED);
        store_run b = sample_run("was queued", STORE_QUEUED);
        store_run c = sample_run("was finished", STORE_QUEUED);
        int64_t ia, ib, ic;
        if (store_run_insert(s, &a, &ia) || store_run_insert(s, &b, &ib) ||
            store_run_insert(s, &c, &ic)) _exit(11);
        if (store_run_set_status(s, ia, STORE_RUNNING, 1700000100.0, NULL)) _exit(12);
        for (int i = 0; i < 100; i++) {
            store_energy_sample e = make_sample(ia, i);
            if (store_energy_append(s, &e)) _exit(13);
        }
        /* progress recorded past the last sample (step 993) */
        if (store_run_progress(s, ia, 1234, 2.5, 1e6)) _exit(16);
        store_run_end end = { .status = STORE_FINISHED, .steps_done = 5 };
        if (store_run_finish(s, ic, &end)) _exit(14);
        if (store_flush(s)) _exit(15);
        _exit(0);                                  /* no store_close */
    }
    int status = 0;
    CHECK(waitpid(pid, &status, 0) == pid);
    CHECKF(WIFEXITED(status) && WEXITSTATUS(status) == 0, "child status 0x%x", status);

    logcap lc = { .mu = PTHREAD_MUTEX_INITIALIZER };
    store_options o = { .log = cap_log, .log_ud = &lc };
    store *s = NULL;
    char err[256];
    CHECKF(store_open(path, &o, &s, err, sizeof err) == 0, "reopen after crash: %s", err);
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.recovered_running == 1 && st.recovered_queued == 1);
    CHECK(lc.n_interrupted == 1);

    store_run r;
    CHECK(store_run_get(s, 1, &r) == 0);
    int ok = r.status == STORE_INTERRUPTED && r.error &&
             !strcmp(r.error, "daemon stopped before the run ended") &&
             r.started_at == 1700000100.0 && !strcmp(r.name, "was running");
    /* it stands at its last energy sample (seq 99, step 993), energies included */
    store_energy_sample last = make_sample(1, 99);
    int at_last = r.steps_done == last.step && r.energy.kinetic == last.kinetic &&
                  r.energy.strain == last.strain && r.energy.potential == last.potential &&
                  r.energy.external_work == last.external_work && r.energy.total == last.total;
    long long steps_done = (long long)r.steps_done;
    store_run_clear(&r);
    CHECKF(ok, "running run not marked interrupted");
    CHECKF(at_last, "interrupted run: steps_done %lld and final energies, want those of its last "
           "sample (step %lld)", steps_done, (long long)last.step);
    CHECK(store_run_get(s, 2, &r) == 0);
    ok = r.status == STORE_INTERRUPTED && r.error &&
         !strcmp(r.error, STORE_INTERRUPTED_QUEUED) && r.started_at == 0 && r.steps_done == 0 &&
         isnan(r.energy.total);
    store_run_clear(&r);
    CHECKF(ok, "queued run not marked interrupted (or given energies it never had)");
    CHECK(store_run_get(s, 3, &r) == 0);
    ok = r.status == STORE_FINISHED && r.error == NULL && r.steps_done == 5;
    store_run_clear(&r);
    CHECKF(ok, "finished run changed by recovery");

    store_energy_series es;
    CHECK(store_energy_read(s, 1, 0, 0, &es) == 0);
    ok = es.n == 100 && series_row_equals(&es, 99, 1, 99);
    store_energy_series_free(&es);
    CHECKF(ok, "flushed samples lost in the crash");

    store_run_filter f = { .status_mask = STORE_STATUS_BIT(STORE_INTERRUPTED) };
    store_run *v;
    size_t n;
    CHECK(store_run_list(s, &f, &v, &n) == 0);
    store_run_list_free(v, n);
    CHECK(n == 2);
    CHECK(store_new_run_id(s) == 4);
    store_close(&s);

    /* recovery is done once: a clean reopen recovers nothing */
    CHECKF(store_open(path, &o, &s, err, sizeof err) == 0, "%s", err);
    store_get_stats(s, &st);
    CHECK(st.recovered_running == 0 && st.recovered_queued == 0);
    store_close(&s);
}

TEST(store_lock_one_daemon)
{
    const char *path = db_path("lock.db");
    char err[1024], want[1024];
    store *s = NULL, *s2 = NULL;
    CHECKF(store_open(path, &quiet, &s, err, sizeof err) == 0, "%s", err);
    snprintf(want, sizeof want, "database %s is in use by another mpmd (pid %ld)", path,
             (long)getpid());

    /* the pid is in the lock file */
    char lockp[600], buf[32] = { 0 };
    snprintf(lockp, sizeof lockp, "%s.lock", path);
    int fd = open(lockp, O_RDONLY);
    CHECK(fd >= 0);
    ssize_t nr = read(fd, buf, sizeof buf - 1);
    close(fd);
    CHECK(nr > 0 && strtol(buf, NULL, 10) == (long)getpid());

    /* a second open in this process is refused too (another open file
     * description) */
    int rc = store_open(path, &quiet, &s2, err, sizeof err);
    CHECKF(rc == STORE_ELOCKED && s2 == NULL, "second open: %d %s", rc, err);
    CHECKF(!strcmp(err, want), "message '%s', want '%s'", err, want);

    /* ... and from another process */
    int pfd[2];
    CHECK(pipe(pfd) == 0);
    fflush(stdout);
    pid_t pid = fork();
    CHECK(pid >= 0);
    if (pid == 0) {
        store *c = NULL;
        char cerr[1024];
        close(pfd[0]);
        int crc = store_open(path, &quiet, &c, cerr, sizeof cerr);
        ssize_t w = write(pfd[1], cerr, strlen(cerr) + 1);
        _exit(crc == STORE_ELOCKED && c == NULL && w > 0 ? 0 : 1);
    }
    close(pfd[1]);
    char cmsg[1024] = { 0 };
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
    store_run in = sample_run("still works", STORE_QUEUED);
    int64_t id;
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(store_flush(s) == 0);
    store_run r;
    CHECK(store_run_get(s, id, &r) == 0);
    store_run_clear(&r);
    store_close(&s);

    /* released on close */
    CHECKF(store_open(path, &quiet, &s2, err, sizeof err) == 0, "open after close: %s", err);
    store_close(&s2);
}

/* Overwrites 4 bytes (big-endian) of the database header. */
static int patch_header(const char *path, off_t off, uint32_t v)
{
    unsigned char b[4] = { (unsigned char)(v >> 24), (unsigned char)(v >> 16),
                           (unsigned char)(v >> 8), (unsigned char)v };
    int fd = open(path, O_WRONLY);
    if (fd < 0) return -1;
    ssize_t w = pwrite(fd, b, 4, off);
    close(fd);
    return w == 4 ? 0 : -1;
}

TEST(store_schema_versions)
{
    const char *p = db_path("schema.db");
    char path[600], err[256];
    snprintf(path, sizeof path, "%s", p);
    store *s = NULL;
    logcap lc = { .mu = PTHREAD_MUTEX_INITIALIZER };
    store_options o = { .log = cap_log, .log_ud = &lc };
    CHECKF(store_open(path, &o, &s, err, sizeof err) == 0, "%s", err);
    CHECK(lc.n_new == 1);
    int v = -1;
    CHECK(store_schema_version(s, &v) == 0);
    CHECKF(v == STORE_SCHEMA_VERSION, "user_version %d, want %d", v, STORE_SCHEMA_VERSION);
    store_close(&s);                /* last connection: the WAL is checkpointed */

    /* reopening an up-to-date database migrates nothing and keeps it */
    CHECKF(store_open(path, &o, &s, err, sizeof err) == 0, "%s", err);
    CHECK(store_schema_version(s, &v) == 0 && v == STORE_SCHEMA_VERSION);
    store_close(&s);
    CHECK(lc.n_new == 1 && lc.n_total == 1);

    /* a newer schema (user_version at offset 60 of the header) is refused */
    CHECK(patch_header(path, 60, 99) == 0);
    int rc = store_open(path, &quiet, &s, err, sizeof err);
    CHECKF(rc == STORE_ESCHEMA && s == NULL, "newer schema: %d %s", rc, err);
    CHECKF(strstr(err, "schema version 99"), "message: %s", err);
    CHECK(patch_header(path, 60, STORE_SCHEMA_VERSION) == 0);
    CHECKF(store_open(path, &quiet, &s, err, sizeof err) == 0, "restored: %s", err);
    store_close(&s);

    /* another application's database (application_id at offset 68) */
    CHECK(patch_header(path, 68, 0x12345678) == 0);
    rc = store_open(path, &quiet, &s, err, sizeof err);
    CHECKF(rc == STORE_ESCHEMA && strstr(err, "not an mpmd database"), "%d %s", rc, err);

    /* not a database at all */
    const char *junk = db_path("junk.db");
    int fd = open(junk, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    CHECK(fd >= 0);
    char garbage[4096];
    for (size_t i = 0; i < sizeof garbage; i++) garbage[i] = (char)(i * 7 + 1);
    ssize_t w = write(fd, garbage, sizeof garbage);
    close(fd);
    CHECK(w == (ssize_t)sizeof garbage);
    rc = store_open(junk, &quiet, &s, err, sizeof err);
    CHECKF(rc == STORE_ESQL && s == NULL && strstr(err, "not a database"), "%d %s", rc, err);

    /* a directory that does not exist */
    rc = store_open("/nonexistent-mpmd-dir/x.db", &quiet, &s, err, sizeof err);
    CHECKF(rc == STORE_EIO && strstr(err, "lock file"), "%d %s", rc, err);
}

TEST(store_snapshots)
{
    char err[256];
    store *s = NULL;
    CHECKF(store_open(db_path("snap.db"), &quiet, &s, err, sizeof err) == 0, "%s", err);
    store_run in = sample_run("snap", STORE_RUNNING);
    int64_t id;
    CHECK(store_run_insert(s, &in, &id) == 0);
    unsigned char data[3][1024];
    for (int k = 0; k < 3; k++)
        for (int i = 0; i < 1024; i++) data[k][i] = (unsigned char)((i * (k + 3)) ^ (i >> 3));
    for (int k = 0; k < 3; k++) {
        store_snapshot sn = { .run_id = id, .step = 10 * k, .t = 0.5 * k, .n = 64 + k,
                              .dim = 2, .fields = 0x15u + (uint32_t)k,
                              .data = data[k], .size = sizeof data[k] };
        CHECK(store_snapshot_put(s, &sn) == 0);
    }
    memset(data[1], 0, sizeof data[1]);     /* the store copied it */
    CHECK(store_flush(s) == 0);
    store_snapshot out;
    CHECK(store_snapshot_get(s, id, 10, &out) == 0);
    unsigned char want[1024];
    for (int i = 0; i < 1024; i++) want[i] = (unsigned char)((i * 4) ^ (i >> 3));
    int ok = out.run_id == id && out.step == 10 && out.t == 0.5 && out.n == 65 &&
             out.dim == 2 && out.fields == 0x16u && out.size == 1024 &&
             !memcmp(out.data, want, 1024);
    store_snapshot_clear(&out);
    CHECKF(ok, "snapshot at step 10");

    CHECK(store_snapshot_get(s, id, -1, &out) == 0);
    ok = out.step == 20 && out.size == 1024 && !memcmp(out.data, data[2], 1024);
    store_snapshot_clear(&out);
    CHECKF(ok, "last snapshot");

    /* replace step 20 with an empty one; add step 30 */
    store_snapshot e = { .run_id = id, .step = 20, .t = 1, .n = 0, .dim = 2 };
    CHECK(store_snapshot_put(s, &e) == 0);
    store_snapshot e2 = { .run_id = id, .step = 30, .t = 1.5, .n = 1, .dim = 3, .fields = 1,
                          .data = "xyz", .size = 3 };
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

    CHECK(store_snapshot_get(s, id, 5, &out) == STORE_ENOTFOUND);
    CHECK(store_snapshot_get(s, 777, -1, &out) == STORE_ENOTFOUND);
    CHECK(strstr(store_errmsg(), "777") != NULL);
    store_snapshot bad = { .run_id = id, .step = 1, .dim = 4 };
    CHECK(store_snapshot_put(s, &bad) == STORE_EINVAL);
    store_close(&s);
}

TEST(store_queue_cap)
{
    logcap lc = { .mu = PTHREAD_MUTEX_INITIALIZER };
    /* nothing commits before store_flush: a 60 s batching window */
    store_options o = { .batch_ms = 60000, .batch_ops = 1000000, .queue_cap = 256 << 10,
                        .log = cap_log, .log_ud = &lc };
    char err[256];
    store *s = NULL;
    CHECKF(store_open(db_path("cap.db"), &o, &s, err, sizeof err) == 0, "%s", err);
    store_run in = sample_run("cap", STORE_RUNNING);
    int64_t id;
    CHECK(store_run_insert(s, &in, &id) == 0);
    static unsigned char big[100 << 10];
    memset(big, 0xab, sizeof big);
    store_snapshot sn = { .run_id = id, .step = 1, .n = 10, .dim = 3, .data = big,
                          .size = sizeof big };
    CHECK(store_snapshot_put(s, &sn) == 0);
    sn.step = 2;
    CHECK(store_snapshot_put(s, &sn) == 0);
    sn.step = 3;
    int rc = store_snapshot_put(s, &sn);
    CHECKF(rc == STORE_EFULL, "third 100 KiB snapshot under a 256 KiB cap: %d", rc);
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.snapshots_dropped == 1);
    CHECK(lc.n_dropped == 1);
    CHECK(st.queue_ops == 3);              /* nothing committed yet */

    /* energy samples are never dropped: the queue grows past the cap */
    for (int i = 0; i < 5000; i++) {
        store_energy_sample e = make_sample(id, i);
        rc = store_energy_append(s, &e);
        if (rc) CHECKF(0, "append %d over the cap: %d", i, rc);
    }
    store_get_stats(s, &st);
    TLOG("queue %zu bytes in %zu ops, cap %zu", st.queue_bytes, st.queue_ops, o.queue_cap);
    CHECK(st.queue_bytes > o.queue_cap);
    CHECK(lc.n_cap == 1);                  /* logged once */
    store_snapshot small = { .run_id = id, .step = 4, .n = 1, .dim = 1, .data = "ab", .size = 2 };
    CHECK(store_snapshot_put(s, &small) == STORE_EFULL);

    CHECK(store_flush(s) == 0);
    store_get_stats(s, &st);
    CHECK(st.queue_bytes == 0 && st.queue_ops == 0 && st.snapshots_dropped == 2);
    CHECK(st.queue_bytes_max > o.queue_cap);
    store_energy_series es;
    CHECK(store_energy_read(s, id, 0, 0, &es) == 0);
    int ok = es.n == 5000 && series_row_equals(&es, 4999, id, 4999);
    store_energy_series_free(&es);
    CHECKF(ok, "samples enqueued over the cap");
    store_snapshot out;
    CHECK(store_snapshot_get(s, id, 2, &out) == 0);
    ok = out.size == sizeof big && !memcmp(out.data, big, sizeof big);
    store_snapshot_clear(&out);
    CHECK(ok);
    CHECK(store_snapshot_get(s, id, 3, &out) == STORE_ENOTFOUND);
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
    logcap lc = { .mu = PTHREAD_MUTEX_INITIALIZER };
    store_options o = { .log = cap_log, .log_ud = &lc };
    char err[256], msg[512];
    store *s = NULL;
    CHECKF(store_open(db_path("errors.db"), &o, &s, err, sizeof err) == 0, "%s", err);
    store_run in = sample_run("ok", STORE_RUNNING);
    int64_t id;
    CHECK(store_run_insert(s, &in, &id) == 0);
    CHECK(store_flush(s) == 0);

    /* a bad op between good ones: only it fails, the batch commits */
    store_energy_sample e0 = make_sample(id, 0), bad = make_sample(999, 0),
                        e1 = make_sample(id, 1);
    CHECK(store_energy_append(s, &e0) == 0);
    CHECK(store_energy_append(s, &bad) == 0);      /* accepted: checked on write */
    CHECK(store_energy_append(s, &e1) == 0);
    CHECK(store_flush(s) == STORE_EWRITE);
    store_last_write_error(s, msg, sizeof msg);
    CHECKF(strstr(msg, "FOREIGN KEY") && strstr(msg, "run 999"), "error text: %s", msg);
    CHECK(store_flush(s) == 0);                    /* reported once */
    store_energy_series es;
    CHECK(store_energy_read(s, id, 0, 0, &es) == 0);
    int ok = es.n == 2 && es.seq[0] == 0 && es.seq[1] == 1;
    store_energy_series_free(&es);
    CHECKF(ok, "good samples around a bad one");

    CHECK(store_energy_append(s, &e1) == 0);       /* duplicate (run, seq) */
    CHECK(store_flush(s) == STORE_EWRITE);
    store_last_write_error(s, msg, sizeof msg);
    CHECKF(strstr(msg, "UNIQUE"), "%s", msg);

    CHECK(store_run_set_status(s, 7777, STORE_RUNNING, 1, NULL) == 0);
    CHECK(store_flush(s) == STORE_EWRITE);
    store_last_write_error(s, msg, sizeof msg);
    CHECKF(strstr(msg, "no run 7777"), "%s", msg);
    CHECK(strstr(store_errmsg(), "no run 7777") != NULL);

    in.id = id;                                    /* duplicate run id */
    CHECK(store_run_insert(s, &in, NULL) == 0);
    CHECK(store_flush(s) == STORE_EWRITE);
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.write_errors == 4);
    pthread_mutex_lock(&lc.mu);
    int nlog = lc.n_total;
    pthread_mutex_unlock(&lc.mu);
    CHECK(nlog >= 4);

    /* argument errors come back at once */
    store_run_end end = { .status = STORE_RUNNING };
    CHECK(store_run_finish(s, id, &end) == STORE_EINVAL);
    CHECK(strstr(store_errmsg(), "not a final status") != NULL);
    store_run b = sample_run("bad", STORE_QUEUED);
    b.dim = 4;
    CHECK(store_run_insert(s, &b, NULL) == STORE_EINVAL);
    b = sample_run("bad", (store_status)17);
    CHECK(store_run_insert(s, &b, NULL) == STORE_EINVAL);
    CHECK(store_run_set_status(s, id, (store_status)-1, 0, NULL) == STORE_EINVAL);
    CHECK(store_flush(s) == 0);
    CHECK(strcmp(store_strerror(STORE_ELOCKED), store_strerror(STORE_ESQL)));
    store_status ps;
    CHECK(store_status_parse("cancelled", &ps) == 0 && ps == STORE_CANCELLED);
    CHECK(store_status_parse("done", &ps) == STORE_EINVAL);
    CHECK(!strcmp(store_status_name(STORE_INTERRUPTED), "interrupted"));
    CHECK(!strcmp(store_update_name(STORE_USL), "usl"));
    CHECK(!strcmp(store_method_name(STORE_METHOD_MPM), "mpm"));
    store_close(&s);
}

TEST(store_commits_without_flush)
{
    char err[256];
    store *s = NULL;
    CHECKF(store_open(db_path("latency.db"), &quiet, &s, err, sizeof err) == 0, "%s", err);
    store_run in = sample_run("latency", STORE_QUEUED);
    int64_t id;
    double t0 = td_now();
    CHECK(store_run_insert(s, &in, &id) == 0);
    store_run r;
    int rc;
    while ((rc = store_run_get(s, id, &r)) == STORE_ENOTFOUND && td_now() - t0 < 5)
        sleep_ms(2);
    double dt = td_now() - t0;
    CHECKF(rc == 0, "run not committed after %.2f s: %d %s", dt, rc, store_errmsg());
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
    int ok = r.steps_done == 999 && r.wall_s == 0.999;
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

typedef struct { cr_ctx *c; int k; } cr_arg;

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
            store_energy_sample e = make_sample(id, i);
            if (store_energy_append(c->s, &e)) { cr_error(c, "append failed"); return NULL; }
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
    size_t last_n[CR_RUNS] = { 0 };
    unsigned seed = (unsigned)a->k * 7919u + 1;
    while (!atomic_load(&c->producers_done)) {
        seed = seed * 1103515245u + 12345u;
        int r = (int)((seed >> 16) % CR_RUNS);
        int64_t id = c->ids[r];
        store_energy_series es;
        if (store_energy_read(c->s, id, 0, 0, &es)) { cr_error(c, store_errmsg()); break; }
        int ok = es.n >= last_n[r];
        for (size_t i = 0; ok && i < es.n; i++) ok = series_row_equals(&es, i, id, (int64_t)i);
        if (es.n > 0 && es.n < CR_SAMPLES) atomic_fetch_add(&c->partial, 1);
        last_n[r] = es.n;
        store_energy_series_free(&es);
        if (!ok) { cr_error(c, "energy series not a growing exact prefix"); break; }
        store_run run;
        if (store_run_get(c->s, id, &run)) { cr_error(c, store_errmsg()); break; }
        ok = run.id == id && run.steps_done <= CR_SAMPLES;
        store_run_clear(&run);
        if (!ok) { cr_error(c, "run record wrong"); break; }
        if (a->k == 0) {
            store_run *v;
            size_t n;
            if (store_run_list(c->s, NULL, &v, &n)) { cr_error(c, store_errmsg()); break; }
            store_run_list_free(v, n);
            if (n != CR_RUNS) { cr_error(c, "list count"); break; }
        }
        atomic_fetch_add(&c->reads, 1);
    }
    return NULL;
}

TEST(store_concurrent_readers)
{
    store_options o = { .batch_ms = 5, .log = quiet_log };
    char err[256];
    static cr_ctx c;
    memset(&c, 0, sizeof c);
    pthread_mutex_init(&c.mu, NULL);
    CHECKF(store_open(db_path("concurrent.db"), &o, &c.s, err, sizeof err) == 0, "%s", err);
    for (int r = 0; r < CR_RUNS; r++) {
        store_run in = sample_run("concurrent", STORE_RUNNING);
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
        ra[i] = (cr_arg){ &c, i };
        CHECK(pthread_create(&rd[i], NULL, cr_reader, &ra[i]) == 0);
    }
    for (int i = 0; i < NP; i++) {
        pa[i] = (cr_arg){ &c, i };
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
        store_energy_series es;
        CHECK(store_energy_read(c.s, c.ids[r], 0, 0, &es) == 0);
        int ok = es.n == CR_SAMPLES && series_row_equals(&es, CR_SAMPLES - 1, c.ids[r],
                                                         CR_SAMPLES - 1);
        store_energy_series_free(&es);
        CHECKF(ok, "run %d incomplete after flush", r);
    }
    store_close(&c.s);
    pthread_mutex_destroy(&c.mu);
}
