/*
 * t_store_migrate.c - the store opens databases written by earlier mpmd
 * releases: a schema-1 database (built here from that release's DDL,
 * verbatim), a schema-2 and a schema-4 one are migrated in place, and
 * every run, energy sample and snapshot reads back as it was written; runs
 * written before schema 5 read back as FLIP, the transfer they ran; runs
 * written before schema 7 read back with no owner (""), runs written before
 * schema 8 with no checkpoint and no resumes, runs written before schema 9
 * with no plan.
 */
#include "store.h"
#include "t.h"
#include "t_store.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

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
    CHECKF(lc.n_migrated == 1 && lc.n_new == 0 && strstr(lc.migrated, "from version 1 to 9"), "%s",
           lc.migrated);
    int v = -1;
    CHECK(store_schema_version(s, &v) == 0);
    CHECKF(v == 9 && v == STORE_SCHEMA_VERSION, "user_version %d after migration", v);
    store_stats st;
    store_get_stats(s, &st);
    CHECK(st.recovered_running == 1 && st.recovered_queued == 0);

    /* the finished run, every field */
    store_run r;
    CHECK(store_run_get(s, 1, &r) == 0);
    int ok = r.id == 1 && !strcmp(r.name, "old run") && r.case_len == case_bytes_len && r.case_pb &&
             !memcmp(r.case_pb, case_bytes, case_bytes_len) && r.method == MPM_METHOD_GIMP &&
             r.update == MPM_MUSL && r.dim == 2 && r.particles == 12345 && r.nodes == 678 &&
             r.status == MPP_STATUS_FINISHED && r.submitted_at == 1700000000.25 &&
             r.started_at == 1700000001.5 && r.finished_at == 1700000003.75 && r.steps == 100 &&
             r.wall_s == 2.5 && r.psteps_per_s == 8.0e6 && r.energy.kinetic == 1.5 &&
             r.energy.strain == 2.25 && r.energy.potential == -3.0 &&
             r.energy.external_work == 0.125 && r.energy.total == 0.625 && r.energy.mass == 0 &&
             r.error == NULL && !strcmp(r.server_version, "0.3.0") &&
             r.transfer == MPM_TRANSFER_FLIP && r.plan == NULL;
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
         r.transfer == MPM_TRANSFER_FLIP && r.dim == 1 && r.steps == 17 &&
         r.energy.kinetic == 3.0 && r.energy.strain == 6.0 && r.energy.total == 8.0 &&
         r.finished_at == 0 && r.started_at == 1700000011.0 && r.case_len == 0 && r.error &&
         !strcmp(r.error, STORE_INTERRUPTED_RUNNING);
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
    /* 3 -> 4: the method's CHECK takes the B-spline names, still refuses
     * others, and the widening in place kept every row (the energy and
     * snapshot checks above ran after it) */
    rc = store_exec_raw(path, "UPDATE runs SET method = 'bspline3' WHERE id = 1", NULL);
    CHECKF(rc == 0, "%d %s", rc, store_error()->message);
    rc = store_exec_raw(path, "UPDATE runs SET method = 'fem' WHERE id = 1", NULL);
    CHECKF(rc == MPM_EIO && strstr(store_error()->message, "CHECK"), "%d %s", rc,
           store_error()->message);
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM pragma_integrity_check WHERE"
                         " integrity_check != 'ok'",
                         &cnt) == 0 &&
          cnt == 0);

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
    CHECKF(lc.n_migrated == 1 && strstr(lc.migrated, "from version 2 to 9"), "%s", lc.migrated);
    int v = -1;
    CHECK(store_schema_version(s, &v) == 0 && v == 9);

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

/* Runs of every method are stored and read back with their method (the
 * B-splines since schema 4), on a new database and on one migrated from
 * version 3. */
TEST(store_methods_round_trip)
{
    static const mpm_method ms[] = {MPM_METHOD_MPM, MPM_METHOD_GIMP, MPM_METHOD_BSPLINE2,
                                    MPM_METHOD_BSPLINE3};
    for (int db = 0; db < 2; db++) {
        const char *p = db_path(db ? "v3m.db" : "methods.db");
        char path[600];
        snprintf(path, sizeof path, "%s", p);
        if (db) { /* a version-3 database: the v1 script, 1 -> 2, 2 -> 3 as released */
            CHECKF(store_exec_raw(path, old_schema_v1, NULL) == 0, "%s", store_error()->message);
            CHECKF(store_exec_raw(path, migrate_v1_to_v2, NULL) == 0, "%s", store_error()->message);
            CHECKF(store_exec_raw(path,
                                  "ALTER TABLE energy ADD COLUMN angular_momentum_x REAL;"
                                  "ALTER TABLE energy ADD COLUMN angular_momentum_y REAL;"
                                  "ALTER TABLE energy ADD COLUMN angular_momentum_z REAL;"
                                  "PRAGMA user_version = 3;",
                                  NULL) == 0,
                   "%s", store_error()->message);
        }
        store_options o = {.log = quiet_log};
        store *s = NULL;
        CHECKF(store_open(path, &o, &s) == 0, "%s", store_error()->message);
        for (int k = 0; k < 4; k++) {
            store_run in = sample_run("m", MPP_STATUS_QUEUED);
            in.method = ms[k];
            int64_t id = -1;
            CHECKF(store_run_insert(s, &in, &id) == 0, "%s", store_error()->message);
            CHECK(store_flush(s) == 0);
            store_run r;
            CHECKF(store_run_get(s, id, &r) == 0, "%s", store_error()->message);
            int ok = r.method == ms[k];
            store_run_clear(&r);
            CHECKF(ok, "method %d read back differently", (int)ms[k]);
        }
        store_run bad = sample_run("m", MPP_STATUS_QUEUED);
        bad.method = (mpm_method)7;
        int64_t id = -1;
        CHECK(store_run_insert(s, &bad, &id) == MPM_EINVAL);
        store_close(&s);
    }
}

/* A version-4 database (the version-1 script, then 1 -> 2, 2 -> 3 and
 * 3 -> 4 as released) with a finished B-spline run, its energy samples and
 * a snapshot.  Opening it migrates 4 -> 5 alone: the run reads back as FLIP
 * (the column's default: the only transfer there was) with every other
 * field intact; runs stored after it keep their transfer, and the column's
 * CHECK refuses other names. */
static const char migrate_v2_to_v4[] =
    "ALTER TABLE energy ADD COLUMN angular_momentum_x REAL;"
    "ALTER TABLE energy ADD COLUMN angular_momentum_y REAL;"
    "ALTER TABLE energy ADD COLUMN angular_momentum_z REAL;"
    "PRAGMA user_version = 3;"
    "PRAGMA writable_schema = ON;"
    "UPDATE sqlite_schema SET sql = replace(sql, 'CHECK (method IN (''mpm'',''gimp''))',"
    " 'CHECK (method IN (''mpm'',''gimp'',''bspline2'',''bspline3'',''cpdi''))')"
    " WHERE type = 'table' AND name = 'runs';"
    "PRAGMA writable_schema = RESET;"
    "PRAGMA user_version = 4;";

static const char old_rows_v4[] =
    "INSERT INTO runs (id, name, case_pb, method, \"update\", dim, particles, nodes, status,"
    " submitted_at, started_at, finished_at, steps, wall_s, psteps_per_s, kinetic, strain,"
    " potential, external_work, total, error, server_version) VALUES"
    " (7, 'v4 run', X'0a0162', 'bspline2', 'musl', 2, 16, 25, 'finished', 1700000200.0,"
    "  1700000201.0, 1700000202.0, 30, 1.5, 320.0, 0.5, 0.25, 0.0, 0.0, 0.75, NULL, '0.3.0'),"
    " (8, 'v4 failed', X'', 'cpdi', 'usl', 3, 8, 64, 'failed', 1700000210.0,"
    "  1700000211.0, 1700000212.0, 3, 0.5, 48.0, NULL, NULL, NULL, NULL, NULL, 'diverged',"
    "  '0.3.0');"
    "INSERT INTO energy VALUES"
    " (7, 0, 0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.5, 1.0, 2.0, 0.0, 4.0, 0.0, 0.0, 0.5),"
    " (7, 1, 30, 0.25, 0.5, 0.25, 0.0, 0.0, 0.75, 1.5, 2.5, 0.0, 4.0, 0.0, 0.0, 0.625);"
    "INSERT INTO snapshots VALUES (7, 30, 0.25, 1, 2, 3, X'0a0b0c');";

TEST(store_migrate_v4)
{
    const char *p = db_path("v4.db");
    char path[600];
    snprintf(path, sizeof path, "%s", p);
    CHECKF(store_exec_raw(path, old_schema_v1, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, migrate_v1_to_v2, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, migrate_v2_to_v4, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, old_rows_v4, NULL) == 0, "%s", store_error()->message);
    int64_t cnt = -1;
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM pragma_table_info('runs') WHERE name = 'transfer'",
                         &cnt) == 0 &&
          cnt == 0);

    logcap lc = {.mu = PTHREAD_MUTEX_INITIALIZER};
    store_options o = {.log = cap_log, .log_ud = &lc};
    store *s = NULL;
    CHECKF(store_open(path, &o, &s) == 0, "opening a version-4 database: %s",
           store_error()->message);
    CHECKF(lc.n_migrated == 1 && strstr(lc.migrated, "from version 4 to 9"), "%s", lc.migrated);
    int v = -1;
    CHECK(store_schema_version(s, &v) == 0 && v == 9 && v == STORE_SCHEMA_VERSION);

    /* the old runs: FLIP, everything else as written */
    store_run r;
    CHECK(store_run_get(s, 7, &r) == 0);
    int ok = r.transfer == MPM_TRANSFER_FLIP && !strcmp(r.name, "v4 run") &&
             r.method == MPM_METHOD_BSPLINE2 && r.update == MPM_MUSL && r.dim == 2 &&
             r.particles == 16 && r.nodes == 25 && r.status == MPP_STATUS_FINISHED &&
             r.submitted_at == 1700000200.0 && r.finished_at == 1700000202.0 && r.steps == 30 &&
             r.psteps_per_s == 320.0 && r.energy.total == 0.75 && r.case_len == 3 &&
             !memcmp(r.case_pb, "\x0a\x01\x62", 3) && r.error == NULL;
    store_run_clear(&r);
    CHECKF(ok, "the version-4 finished run reads back differently");
    CHECK(store_run_get(s, 8, &r) == 0);
    ok = r.transfer == MPM_TRANSFER_FLIP && r.method == MPM_METHOD_CPDI && r.update == MPM_USL &&
         r.status == MPP_STATUS_FAILED && r.error && !strcmp(r.error, "diverged") &&
         isnan(r.energy.total);
    store_run_clear(&r);
    CHECKF(ok, "the version-4 failed run reads back differently");
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, 7, 0, 0, &es, &nes) == 0);
    ok = nes == 2 && es[1].step == 30 && es[1].e.total == 0.75 &&
         es[1].e.angular_momentum[2] == 0.625 && es[0].e.angular_momentum[2] == 0.5;
    free(es);
    CHECKF(ok, "the version-4 samples read back differently");
    store_snapshot sn;
    CHECK(store_snapshot_get(s, 7, -1, &sn) == 0);
    ok = sn.step == 30 && sn.size == 3 && !memcmp(sn.data, "\x0a\x0b\x0c", 3);
    store_snapshot_clear(&sn);
    CHECK(ok);

    /* new runs keep their transfer, in a listing too */
    store_run in = sample_run("apic", MPP_STATUS_QUEUED);
    in.transfer = MPM_TRANSFER_APIC;
    int64_t id = 0;
    CHECK(store_run_insert(s, &in, &id) == 0 && id == 9);
    CHECK(store_flush(s) == 0);
    store_run *list = NULL;
    size_t n = 0;
    CHECK(store_run_list(s, NULL, &list, &n) == 0);
    ok = n == 3 && list[0].id == 9 && list[0].transfer == MPM_TRANSFER_APIC && list[1].id == 8 &&
         list[1].transfer == MPM_TRANSFER_FLIP && list[2].id == 7 &&
         list[2].transfer == MPM_TRANSFER_FLIP;
    store_run_list_free(list, n);
    CHECKF(ok, "listing after the migration");
    store_close(&s);

    /* on disk: old rows 'flip', the new one 'apic'; other names refused */
    CHECK(store_exec_raw(path, "SELECT count(*) FROM runs WHERE transfer = 'flip' AND id IN (7, 8)",
                         &cnt) == 0 &&
          cnt == 2);
    CHECK(store_exec_raw(path, "SELECT count(*) FROM runs WHERE transfer = 'apic' AND id = 9",
                         &cnt) == 0 &&
          cnt == 1);
    int rc = store_exec_raw(path, "UPDATE runs SET transfer = 'pic' WHERE id = 7", NULL);
    CHECKF(rc == MPM_EIO && strstr(store_error()->message, "CHECK"), "%d %s", rc,
           store_error()->message);
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM pragma_integrity_check WHERE"
                         " integrity_check != 'ok'",
                         &cnt) == 0 &&
          cnt == 0);
}

/* Both transfers are stored and read back (get and list) on a new
 * database; an unknown one is refused at insert. */
TEST(store_transfer_round_trip)
{
    store_options o = {.log = quiet_log};
    store *s = NULL;
    CHECKF(store_open(db_path("transfer.db"), &o, &s) == 0, "%s", store_error()->message);
    static const mpm_transfer ts[] = {MPM_TRANSFER_APIC, MPM_TRANSFER_FLIP, MPM_TRANSFER_APIC};
    for (int k = 0; k < 3; k++) {
        store_run in = sample_run("t", MPP_STATUS_QUEUED);
        in.transfer = ts[k];
        in.method = k == 2 ? MPM_METHOD_BSPLINE3 : MPM_METHOD_GIMP;
        int64_t id = -1;
        CHECKF(store_run_insert(s, &in, &id) == 0, "%s", store_error()->message);
        CHECK(id == k + 1);
    }
    CHECK(store_flush(s) == 0);
    for (int k = 0; k < 3; k++) {
        store_run r;
        CHECKF(store_run_get(s, k + 1, &r) == 0, "%s", store_error()->message);
        int ok = r.transfer == ts[k] &&
                 r.method == (k == 2 ? MPM_METHOD_BSPLINE3 : MPM_METHOD_GIMP) &&
                 r.update == MPM_MUSL;
        store_run_clear(&r);
        CHECKF(ok, "run %d: transfer read back differently", k + 1);
    }
    store_run_filter f = {.status_mask = STORE_STATUS_BIT(MPP_STATUS_QUEUED), .with_case = 1};
    store_run *list = NULL;
    size_t n = 0;
    CHECK(store_run_list(s, &f, &list, &n) == 0);
    int ok = n == 3;
    for (size_t i = 0; ok && i < n; i++)
        ok = list[i].transfer == ts[2 - i] && list[i].case_len == case_bytes_len &&
             !memcmp(list[i].case_pb, case_bytes, case_bytes_len);
    store_run_list_free(list, n);
    CHECKF(ok, "listing: transfers read back differently");
    store_run bad = sample_run("t", MPP_STATUS_QUEUED);
    bad.transfer = (mpm_transfer)2;
    int64_t id = -1;
    CHECK(store_run_insert(s, &bad, &id) == MPM_EINVAL &&
          strstr(store_error()->message, "unknown transfer"));
    store_close(&s);
}

/* A version-5 database (version 4 as above, then 4 -> 5 as released) with
 * the version-4 rows.  Opening it migrates 5 -> 6 alone: the old samples
 * read the four works and the balance error as 0, the old runs no balance
 * recorded and no warning; a run finished after it keeps its balance error
 * and warning, and its samples their works. */
TEST(store_migrate_v5)
{
    const char *p = db_path("v5.db");
    char path[600];
    snprintf(path, sizeof path, "%s", p);
    CHECKF(store_exec_raw(path, old_schema_v1, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, migrate_v1_to_v2, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, migrate_v2_to_v4, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path,
                          "ALTER TABLE runs ADD COLUMN transfer TEXT NOT NULL DEFAULT 'flip'"
                          " CHECK (transfer IN ('flip','apic'));"
                          "PRAGMA user_version = 5;",
                          NULL) == 0,
           "%s", store_error()->message);
    CHECKF(store_exec_raw(path, old_rows_v4, NULL) == 0, "%s", store_error()->message);

    logcap lc = {.mu = PTHREAD_MUTEX_INITIALIZER};
    store_options o = {.log = cap_log, .log_ud = &lc};
    store *s = NULL;
    CHECKF(store_open(path, &o, &s) == 0, "opening a version-5 database: %s",
           store_error()->message);
    CHECKF(lc.n_migrated == 1 && strstr(lc.migrated, "from version 5 to 9"), "%s", lc.migrated);
    int v = -1;
    CHECK(store_schema_version(s, &v) == 0 && v == 9 && v == STORE_SCHEMA_VERSION);

    store_run r;
    CHECK(store_run_get(s, 7, &r) == 0);
    int ok = !r.has_balance && r.warning == NULL && r.energy.total == 0.75 &&
             !strcmp(r.name, "v4 run") && r.transfer == MPM_TRANSFER_FLIP;
    store_run_clear(&r);
    CHECKF(ok, "the version-5 run reads back differently");
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, 7, 0, 0, &es, &nes) == 0);
    ok = nes == 2 && es[1].e.total == 0.75 && es[1].e.angular_momentum[2] == 0.625;
    for (size_t i = 0; ok && i < nes; i++)
        ok = es[i].e.plastic_work == 0 && es[i].e.damping_work == 0 && es[i].e.friction_work == 0 &&
             es[i].e.prescribed_work == 0 && es[i].e.balance_error == 0;
    free(es);
    CHECKF(ok, "the version-5 samples read back differently");

    /* a new run: its samples' works and its end's balance and warning */
    store_run in = sample_run("balance", MPP_STATUS_QUEUED);
    int64_t id = 0;
    CHECK(store_run_insert(s, &in, &id) == 0 && id == 9);
    mpm_energy_sample smp = {.seq = 0, .step = 4, .t = 0.5, .dim = 2};
    smp.e.total = 1.5;
    smp.e.plastic_work = 0.125;
    smp.e.damping_work = 0.25;
    smp.e.friction_work = 0.375;
    smp.e.prescribed_work = -0.5;
    smp.e.balance_error = 0.0625;
    CHECK(store_energy_append(s, id, &smp, 1) == 0);
    store_run_end end = {.status = MPP_STATUS_FINISHED,
                         .steps = 4,
                         .has_energy = 1,
                         .energy = smp.e,
                         .has_balance = 1,
                         .balance_error = 0.0625,
                         .warning = "energy balance error 6.25% exceeds the budget 5%"};
    CHECK(store_run_finish(s, id, &end) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.has_balance && r.balance_error == 0.0625 && r.warning &&
         !strcmp(r.warning, end.warning) && r.status == MPP_STATUS_FINISHED;
    store_run_clear(&r);
    CHECKF(ok, "the balance and warning of a new run read back differently");
    CHECK(store_energy_read(s, id, 0, 0, &es, &nes) == 0);
    ok = nes == 1 && es[0].e.plastic_work == 0.125 && es[0].e.damping_work == 0.25 &&
         es[0].e.friction_work == 0.375 && es[0].e.prescribed_work == -0.5 &&
         es[0].e.balance_error == 0.0625;
    free(es);
    CHECKF(ok, "the new sample's works read back differently");
    store_close(&s);
    int64_t cnt = -1;
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM pragma_integrity_check WHERE"
                         " integrity_check != 'ok'",
                         &cnt) == 0 &&
          cnt == 0);
}

/* A version-6 database (version 5 as above, then 5 -> 6 as released) with
 * the version-4 rows.  Opening it migrates 6 -> 7 alone: the old run reads
 * back with no owner (""), a new run keeps the owner it was inserted with,
 * and one inserted without an owner reads "". */
TEST(store_migrate_v6)
{
    const char *p = db_path("v6.db");
    char path[600];
    snprintf(path, sizeof path, "%s", p);
    CHECKF(store_exec_raw(path, old_schema_v1, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, migrate_v1_to_v2, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, migrate_v2_to_v4, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, old_rows_v4, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path,
                          "ALTER TABLE runs ADD COLUMN transfer TEXT NOT NULL DEFAULT 'flip'"
                          " CHECK (transfer IN ('flip','apic'));"
                          "ALTER TABLE energy ADD COLUMN plastic_work REAL DEFAULT 0;"
                          "ALTER TABLE energy ADD COLUMN damping_work REAL DEFAULT 0;"
                          "ALTER TABLE energy ADD COLUMN friction_work REAL DEFAULT 0;"
                          "ALTER TABLE energy ADD COLUMN prescribed_work REAL DEFAULT 0;"
                          "ALTER TABLE energy ADD COLUMN balance_error REAL DEFAULT 0;"
                          "ALTER TABLE runs ADD COLUMN balance_error REAL;"
                          "ALTER TABLE runs ADD COLUMN warning TEXT;"
                          "PRAGMA user_version = 6;",
                          NULL) == 0,
           "%s", store_error()->message);

    logcap lc = {.mu = PTHREAD_MUTEX_INITIALIZER};
    store_options o = {.log = cap_log, .log_ud = &lc};
    store *s = NULL;
    CHECKF(store_open(path, &o, &s) == 0, "opening a version-6 database: %s",
           store_error()->message);
    CHECKF(lc.n_migrated == 1 && strstr(lc.migrated, "from version 6 to 9"), "%s", lc.migrated);
    int v = -1;
    CHECK(store_schema_version(s, &v) == 0 && v == 9 && v == STORE_SCHEMA_VERSION);

    store_run r;
    CHECK(store_run_get(s, 7, &r) == 0);
    int ok = r.owner && !strcmp(r.owner, "") && !strcmp(r.name, "v4 run") &&
             r.energy.total == 0.75 && r.transfer == MPM_TRANSFER_FLIP;
    store_run_clear(&r);
    CHECKF(ok, "the version-6 run reads back differently");

    /* new runs: with an owner (a Z85 key) and without */
    const char *key = "rq:rM>}U?@Lns47E1%kR.o@n%FcmmsL/@{H8]yf7";
    store_run in = sample_run("owned", MPP_STATUS_QUEUED);
    in.owner = key;
    int64_t id = 0, id2 = 0;
    CHECK(store_run_insert(s, &in, &id) == 0 && id == 9);
    in = sample_run("unowned", MPP_STATUS_QUEUED);
    CHECK(store_run_insert(s, &in, &id2) == 0 && id2 == 10);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, id, &r) == 0);
    ok = r.owner && !strcmp(r.owner, key);
    store_run_clear(&r);
    CHECKF(ok, "the owner of a new run reads back differently");
    CHECK(store_run_get(s, id2, &r) == 0);
    ok = r.owner && !strcmp(r.owner, "");
    store_run_clear(&r);
    CHECKF(ok, "a run inserted without an owner reads back with one");
    /* listings carry it too */
    store_run_filter f = {0};
    store_run *list = NULL;
    size_t n = 0;
    CHECK(store_run_list(s, &f, &list, &n) == 0);
    ok = n == 4 && list[1].id == 9 && list[1].owner && !strcmp(list[1].owner, key) &&
         list[3].id == 7 && list[3].owner && !strcmp(list[3].owner, "");
    store_run_list_free(list, n);
    CHECKF(ok, "the listing's owners differ");
    store_close(&s);
    int64_t cnt = -1;
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM pragma_integrity_check WHERE"
                         " integrity_check != 'ok'",
                         &cnt) == 0 &&
          cnt == 0);
}

/* A version-7 database (version 6 as above, then 6 -> 7 as released) with
 * the version-4 rows and an interrupted run 9 with three energy samples
 * and two snapshots.  Opening it migrates 7 -> 8 alone: the old runs read
 * back with no checkpoint and no resumes.  Then the checkpoint calls: one
 * recorded reads back; a resume of the interrupted run from it deletes the
 * samples and snapshots after it and queues the run again, in one write;
 * a resume of a finished run is refused (a write error) and changes
 * nothing; a cleared checkpoint reads back as none. */
TEST(store_migrate_v7)
{
    const char *p = db_path("v7.db");
    char path[600];
    snprintf(path, sizeof path, "%s", p);
    CHECKF(store_exec_raw(path, old_schema_v1, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, migrate_v1_to_v2, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, migrate_v2_to_v4, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path, old_rows_v4, NULL) == 0, "%s", store_error()->message);
    CHECKF(store_exec_raw(path,
                          "ALTER TABLE runs ADD COLUMN transfer TEXT NOT NULL DEFAULT 'flip'"
                          " CHECK (transfer IN ('flip','apic'));"
                          "ALTER TABLE energy ADD COLUMN plastic_work REAL DEFAULT 0;"
                          "ALTER TABLE energy ADD COLUMN damping_work REAL DEFAULT 0;"
                          "ALTER TABLE energy ADD COLUMN friction_work REAL DEFAULT 0;"
                          "ALTER TABLE energy ADD COLUMN prescribed_work REAL DEFAULT 0;"
                          "ALTER TABLE energy ADD COLUMN balance_error REAL DEFAULT 0;"
                          "ALTER TABLE runs ADD COLUMN balance_error REAL;"
                          "ALTER TABLE runs ADD COLUMN warning TEXT;"
                          "ALTER TABLE runs ADD COLUMN owner TEXT NOT NULL DEFAULT '';"
                          "CREATE INDEX runs_by_owner ON runs(owner, id);"
                          "INSERT INTO runs (id, name, case_pb, method, \"update\", dim,"
                          " particles, nodes, status, submitted_at, started_at, steps, wall_s,"
                          " error, owner) VALUES (9, 'v7 cut', X'', 'mpm', 'musl', 2, 4, 9,"
                          " 'interrupted', 1700000300.0, 1700000301.0, 20, 2.0,"
                          " 'daemon stopped before the run ended', 'local');"
                          "INSERT INTO energy (run_id, seq, step, t, total) VALUES"
                          " (9, 0, 0, 0.0, 1.0), (9, 1, 10, 0.1, 1.0), (9, 2, 20, 0.2, 1.0);"
                          "INSERT INTO snapshots VALUES (9, 10, 0.1, 1, 2, 1, X'01'),"
                          " (9, 20, 0.2, 1, 2, 1, X'02');"
                          "PRAGMA user_version = 7;",
                          NULL) == 0,
           "%s", store_error()->message);

    logcap lc = {.mu = PTHREAD_MUTEX_INITIALIZER};
    store_options o = {.log = cap_log, .log_ud = &lc};
    store *s = NULL;
    CHECKF(store_open(path, &o, &s) == 0, "opening a version-7 database: %s",
           store_error()->message);
    CHECKF(lc.n_migrated == 1 && strstr(lc.migrated, "from version 7 to 9"), "%s", lc.migrated);
    int v = -1;
    CHECK(store_schema_version(s, &v) == 0 && v == 9 && v == STORE_SCHEMA_VERSION);

    store_run r;
    CHECK(store_run_get(s, 7, &r) == 0);
    int ok = !r.has_checkpoint && r.checkpoint_step == -1 && r.resumes == 0 &&
             !strcmp(r.name, "v4 run") && r.energy.total == 0.75;
    store_run_clear(&r);
    CHECKF(ok, "the version-7 finished run reads back differently");
    CHECK(store_run_get(s, 9, &r) == 0);
    ok = !r.has_checkpoint && r.resumes == 0 && r.status == MPP_STATUS_INTERRUPTED &&
         r.steps == 20 && r.owner && !strcmp(r.owner, "local");
    store_run_clear(&r);
    CHECKF(ok, "the version-7 interrupted run reads back differently");

    /* a checkpoint at step 10 (after samples 0 and 1) */
    store_checkpoint ck = {.step = 10, .t = 0.1, .bytes = 4096, .energy_seq = 2};
    CHECK(store_run_checkpoint(s, 9, &ck) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, 9, &r) == 0);
    ok = r.has_checkpoint && r.checkpoint_step == 10 && r.checkpoint_t == 0.1 &&
         r.checkpoint_bytes == 4096 && r.checkpoint_seq == 2 && r.resumes == 0 &&
         r.status == MPP_STATUS_INTERRUPTED;
    store_run_clear(&r);
    CHECKF(ok, "the recorded checkpoint reads back differently");

    /* the resume: samples seq >= 2 and the snapshot at 20 go */
    CHECK(store_run_resume(s, 9, &ck) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, 9, &r) == 0);
    ok = r.status == MPP_STATUS_QUEUED && r.steps == 10 && r.resumes == 1 && r.error == NULL &&
         r.finished_at == 0 && r.started_at == 1700000301.0 && r.has_checkpoint &&
         r.checkpoint_step == 10;
    store_run_clear(&r);
    CHECKF(ok, "the resumed run reads back differently");
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, 9, 0, 0, &es, &nes) == 0);
    ok = nes == 2 && es[0].step == 0 && es[1].step == 10;
    free(es);
    CHECKF(ok, "%zu samples after the resume, expected 2", nes);
    store_run_extra x;
    CHECK(store_run_extras(s, 9, &x) == 0);
    ok = x.n_snapshots == 1 && x.snapshot_steps[0] == 10 && x.energy_count == 2 && x.last_seq == 1;
    store_run_extra_clear(&x);
    CHECKF(ok, "the snapshots after the checkpoint were not deleted");
    /* running again: started_at stays the first start */
    CHECK(store_run_set_status(s, 9, MPP_STATUS_RUNNING, 1700000400.0, NULL) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, 9, &r) == 0);
    ok = r.status == MPP_STATUS_RUNNING && r.started_at == 1700000301.0;
    store_run_clear(&r);
    CHECKF(ok, "a resumed run's start time changed");

    /* a finished run cannot be resumed: nothing of it changes */
    CHECK(store_run_resume(s, 7, &ck) == 0); /* enqueued; fails when applied */
    char werr[512];
    CHECK(store_flush(s) == MPM_EIO);
    store_last_write_error(s, werr, sizeof werr);
    CHECKF(strstr(werr, "run 7 already ended (finished)"), "%s", werr);
    CHECK(store_energy_read(s, 7, 0, 0, &es, &nes) == 0);
    free(es);
    CHECKF(nes == 2, "a refused resume deleted samples (%zu left)", nes);
    CHECK(store_run_get(s, 7, &r) == 0);
    ok = r.status == MPP_STATUS_FINISHED && r.resumes == 0 && !r.has_checkpoint;
    store_run_clear(&r);
    CHECKF(ok, "a refused resume changed the run");

    /* cleared */
    CHECK(store_run_checkpoint(s, 9, NULL) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(store_run_get(s, 9, &r) == 0);
    ok = !r.has_checkpoint && r.checkpoint_step == -1 && r.resumes == 1;
    store_run_clear(&r);
    CHECKF(ok, "a cleared checkpoint still reads back");
    store_close(&s);
    int64_t cnt = -1;
    CHECK(store_exec_raw(path,
                         "SELECT count(*) FROM pragma_integrity_check WHERE"
                         " integrity_check != 'ok'",
                         &cnt) == 0 &&
          cnt == 0);
}
