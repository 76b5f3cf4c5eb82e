/*
 * store_read.c - the store's read side (see store.h): a small pool of
 * read-only connections and every read (runs, run lists, energy samples,
 * snapshots, a run's extras, the schema version).
 *
 * Readers never use the write connection: each read takes a read-only
 * connection from the pool (opening one if the pool is empty), runs its
 * statements - in one read transaction when there are several - and puts
 * it back.  A connection is used by one thread at a time
 * (SQLITE_OPEN_NOMUTEX), and in WAL mode readers neither block nor are
 * blocked by the writer; they see committed data only.
 */
#include "store_internal.h"

#include "store_ends.h"
#include "store_read.h"
#include "store_sql.h"

#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------------- */
/* The pool of read connections */

static int open_reader(store *s, sqlite3 **out)
{
    sqlite3 *db = NULL;
    *out = NULL;
    int rc = sqlite3_open_v2(s->path, &db, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX, NULL);
    if (rc != SQLITE_OK) {
        int r = sti_fail(MPM_EIO, "cannot open database %s for reading: %s", s->path,
                         db ? sqlite3_errmsg(db) : sqlite3_errstr(rc));
        if (db) sti_close_db(s, db);
        return r;
    }
    int r = sti_conn_setup(db, s->busy_ms);
    if (!r) r = sti_exec(db, "PRAGMA query_only = ON", "query_only");
    if (r) {
        sti_close_db(s, db);
        return r;
    }
    *out = db;
    return 0;
}

/* Takes a read connection from the pool, or opens one. */
static int reader_get(store *s, sqlite3 **db)
{
    *db = NULL;
    pthread_mutex_lock(&s->pool_mu);
    if (s->npool) *db = s->pool[--s->npool];
    pthread_mutex_unlock(&s->pool_mu);
    if (*db) return 0;
    return open_reader(s, db);
}

/* Returns a read connection to the pool (closing it if the pool is full or
 * it may be in a bad state: a transaction left open). */
static void reader_put(store *s, sqlite3 *db)
{
    if (!db) return;
    if (!sqlite3_get_autocommit(db)) {
        if (sti_exec(db, "ROLLBACK", "rollback") != 0) {
            sti_close_db(s, db);
            return;
        }
    }
    pthread_mutex_lock(&s->pool_mu);
    if (s->npool < READER_POOL_MAX) {
        s->pool[s->npool++] = db;
        db = NULL;
    }
    pthread_mutex_unlock(&s->pool_mu);
    if (db) sti_close_db(s, db);
}

void sti_readers_close(store *s)
{
    for (int i = 0; i < s->npool; i++) sti_close_db(s, s->pool[i]);
    s->npool = 0;
}

/* Ends a read transaction left open by a read (after its statements). */
static int end_read(sqlite3 *db, int r)
{
    if (!sqlite3_get_autocommit(db)) {
        int r2 = sti_exec(db, "COMMIT", "ending the read transaction");
        if (!r) r = r2;
    }
    return r;
}

/* ---------------------------------------------------------------------- */
/* Column helpers */

static double col_real_nan(sqlite3_stmt *st, int i)
{
    return sqlite3_column_type(st, i) == SQLITE_NULL ? NAN : sqlite3_column_double(st, i);
}

static double col_time(sqlite3_stmt *st, int i)
{
    return sqlite3_column_type(st, i) == SQLITE_NULL ? 0 : sqlite3_column_double(st, i);
}

/* Copies a text column into a new string (NULL for SQL NULL). */
static int col_strdup(sqlite3 *db, sqlite3_stmt *st, int i, const char **out)
{
    *out = NULL;
    if (sqlite3_column_type(st, i) == SQLITE_NULL) return 0;
    const unsigned char *t = sqlite3_column_text(st, i);
    if (!t) return sti_sql_fail(db, sqlite3_errcode(db), "reading a text column");
    size_t n = (size_t)sqlite3_column_bytes(st, i);
    char *p = malloc(n + 1);
    if (!p) return sti_fail(MPM_ENOMEM, "out of memory reading a text column");
    memcpy(p, t, n);
    p[n] = 0;
    *out = p;
    return 0;
}

/* Copies a blob column into new memory (NULL when empty). */
static int col_blobdup(sqlite3 *db, sqlite3_stmt *st, int i, const void **out, size_t *len)
{
    *out = NULL;
    *len = 0;
    const void *b = sqlite3_column_blob(st, i);
    size_t n = (size_t)sqlite3_column_bytes(st, i);
    if (!n) return 0;
    if (!b) return sti_sql_fail(db, sqlite3_errcode(db), "reading a blob column");
    void *p = malloc(n);
    if (!p) return sti_fail(MPM_ENOMEM, "out of memory reading %zu bytes", n);
    memcpy(p, b, n);
    *out = p;
    *len = n;
    return 0;
}

/* ---------------------------------------------------------------------- */
/* Runs */

#define RUN_COLS                                                              \
    "id, name, length(case_pb), method, \"update\", dim, particles, nodes,"   \
    " status, submitted_at, started_at, finished_at, steps, wall_s,"          \
    " psteps_per_s, kinetic, strain, potential, external_work, total, error," \
    " server_version, transfer, balance_error, warning, owner,"               \
    " checkpoint_step, checkpoint_t, checkpoint_bytes, checkpoint_seq, resumes, plan"
#define RUN_COL_CASE 32

void store_run_clear(store_run *r)
{
    if (!r) return;
    free((void *)r->name);
    free((void *)r->case_pb);
    free((void *)r->error);
    free((void *)r->server_version);
    free((void *)r->warning);
    free((void *)r->owner);
    free((void *)r->plan);
    memset(r, 0, sizeof *r);
}

/* Fills r from the current row (columns RUN_COLS [, case_pb]). */
static int read_run_row(sqlite3 *db, sqlite3_stmt *st, store_run *r, int with_case)
{
    memset(r, 0, sizeof *r);
    r->id = sqlite3_column_int64(st, 0);
    r->case_len = (size_t)sqlite3_column_int64(st, 2);
    int m = mpm_method_parse((const char *)sqlite3_column_text(st, 3));
    int u = mpm_update_parse((const char *)sqlite3_column_text(st, 4));
    int stt =
        sti_parse_name((const char *)sqlite3_column_text(st, 8), sti_status_names, STORE_NSTATUS);
    int tr = mpm_transfer_parse((const char *)sqlite3_column_text(st, 22));
    if (m < 0 || u < 0 || stt < 0 || tr < 0)
        return sti_fail(MPM_EIO, "run %" PRId64 ": bad method, update, status or transfer value",
                        r->id);
    r->method = (mpm_method)m;
    r->update = (mpm_update)u;
    r->transfer = (mpm_transfer)tr;
    r->status = (mpp_status)(MPP_STATUS_MIN + stt);
    r->dim = sqlite3_column_int(st, 5);
    r->particles = sqlite3_column_int64(st, 6);
    r->nodes = sqlite3_column_int64(st, 7);
    r->submitted_at = col_time(st, 9);
    r->started_at = col_time(st, 10);
    r->finished_at = col_time(st, 11);
    r->steps = sqlite3_column_int64(st, 12);
    r->wall_s = col_real_nan(st, 13);
    r->psteps_per_s = col_real_nan(st, 14);
    r->energy.kinetic = col_real_nan(st, 15);
    r->energy.strain = col_real_nan(st, 16);
    r->energy.potential = col_real_nan(st, 17);
    r->energy.external_work = col_real_nan(st, 18);
    r->energy.total = col_real_nan(st, 19);
    r->has_balance = sqlite3_column_type(st, 23) != SQLITE_NULL;
    r->balance_error = r->has_balance ? sqlite3_column_double(st, 23) : 0;
    r->has_checkpoint = sqlite3_column_type(st, 26) != SQLITE_NULL;
    r->checkpoint_step = r->has_checkpoint ? sqlite3_column_int64(st, 26) : -1;
    r->checkpoint_t = r->has_checkpoint ? sqlite3_column_double(st, 27) : 0;
    r->checkpoint_bytes = r->has_checkpoint ? sqlite3_column_int64(st, 28) : 0;
    r->checkpoint_seq = r->has_checkpoint ? sqlite3_column_int64(st, 29) : 0;
    r->resumes = sqlite3_column_int64(st, 30);
    int rc;
    if ((rc = col_strdup(db, st, 1, &r->name)) || (rc = col_strdup(db, st, 20, &r->error)) ||
        (rc = col_strdup(db, st, 21, &r->server_version)) ||
        (rc = col_strdup(db, st, 24, &r->warning)) || (rc = col_strdup(db, st, 25, &r->owner)) ||
        (rc = col_strdup(db, st, 31, &r->plan))) {
        store_run_clear(r);
        return rc;
    }
    if (!r->name && !(r->name = calloc(1, 1))) goto nomem;
    if (!r->server_version && !(r->server_version = calloc(1, 1))) goto nomem;
    if (with_case) {
        size_t len;
        if ((rc = col_blobdup(db, st, RUN_COL_CASE, &r->case_pb, &len))) {
            store_run_clear(r);
            return rc;
        }
        r->case_len = len;
    }
    return 0;
nomem:
    store_run_clear(r);
    return sti_fail(MPM_ENOMEM, "out of memory reading run");
}

int store_run_get(store *s, int64_t id, store_run *out)
{
    if (!s || !out) return sti_fail(MPM_EINVAL, "store_run_get: NULL argument");
    memset(out, 0, sizeof *out);
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    int rc = sqlite3_prepare_v2(db, "SELECT " RUN_COLS ", case_pb FROM runs WHERE id = ?1", -1, &st,
                                NULL);
    if (rc != SQLITE_OK) {
        r = sti_sql_fail(db, rc, "reading a run");
        goto out;
    }
    rc = sqlite3_bind_int64(st, 1, id);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    if (rc == SQLITE_ROW) {
        /* a failed copy keeps its own error (alloc_fail_store) */
        if (!(r = read_run_row(db, st, out, 1)))
            sti_ends_overlay(s, out); /* an end or a recovery still to write */
    } else if (rc == SQLITE_DONE)
        r = sti_fail(MPM_ENOTFOUND, "no run %" PRId64, id);
    else
        r = sti_sql_fail(db, rc, "reading a run");
    rc = sqlite3_finalize(st);
    if (!r && rc != SQLITE_OK) {
        r = sti_sql_fail(db, rc, "reading a run");
        store_run_clear(out);
    }
out:
    reader_put(s, db);
    return r;
}

void store_run_list_free(store_run *runs, size_t n)
{
    for (size_t i = 0; runs && i < n; i++) store_run_clear(&runs[i]);
    free(runs);
}

int store_run_list(store *s, const store_run_filter *f, store_run **runs, size_t *n)
{
    static const store_run_filter none;
    if (!s || !runs || !n) return sti_fail(MPM_EINVAL, "store_run_list: NULL argument");
    *runs = NULL;
    *n = 0;
    if (!f) f = &none;
    unsigned known = 0;
    for (int st = MPP_STATUS_MIN; st <= MPP_STATUS_MAX; st++) known |= STORE_STATUS_BIT(st);
    if (f->status_mask & ~known)
        return sti_fail(MPM_EINVAL, "status mask 0x%x has unknown bits", f->status_mask);
    if (f->limit > INT64_MAX) return sti_fail(MPM_EINVAL, "limit too large");

    char sql[1024];
    size_t len = (size_t)snprintf(sql, sizeof sql, "SELECT " RUN_COLS ", %s FROM runs WHERE 1",
                                  f->with_case ? "case_pb" : "NULL");
    if (f->status_mask) {
        len += (size_t)snprintf(sql + len, sizeof sql - len, " AND status IN (");
        int first = 1;
        for (int st = MPP_STATUS_MIN; st <= MPP_STATUS_MAX; st++)
            if (f->status_mask & STORE_STATUS_BIT(st)) {
                len += (size_t)snprintf(sql + len, sizeof sql - len, "%s'%s'", first ? "" : ",",
                                        sti_status_name((mpp_status)st));
                first = 0;
            }
        len += (size_t)snprintf(sql + len, sizeof sql - len, ")");
    }
    if (f->before_id > 0) len += (size_t)snprintf(sql + len, sizeof sql - len, " AND id < ?1");
    if (f->owner) len += (size_t)snprintf(sql + len, sizeof sql - len, " AND owner = ?3");
    len += (size_t)snprintf(sql + len, sizeof sql - len, " ORDER BY id DESC");
    if (f->limit) len += (size_t)snprintf(sql + len, sizeof sql - len, " LIMIT ?2");
    if (len >= sizeof sql) return sti_fail(MPM_EINVAL, "run list query too long");

    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    store_run *v = NULL;
    size_t cnt = 0, capn = 0;
    int rc = sqlite3_prepare_v2(db, sql, -1, &st, NULL);
    if (rc != SQLITE_OK) {
        r = sti_sql_fail(db, rc, "listing runs");
        goto out;
    }
    if (f->before_id > 0) rc = sqlite3_bind_int64(st, 1, f->before_id);
    if (rc == SQLITE_OK && f->limit) rc = sqlite3_bind_int64(st, 2, (sqlite3_int64)f->limit);
    if (rc == SQLITE_OK && f->owner) rc = sqlite3_bind_text(st, 3, f->owner, -1, SQLITE_STATIC);
    if (rc != SQLITE_OK) {
        r = sti_sql_fail(db, rc, "listing runs");
        goto out;
    }
    while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
        store_run *nv = sti_grow(v, &capn, cnt + 1, sizeof *nv);
        if (!nv) {
            r = sti_fail(MPM_ENOMEM, "out of memory listing runs");
            goto out;
        }
        v = nv;
        if ((r = read_run_row(db, st, &v[cnt], f->with_case))) goto out;
        sti_ends_overlay(s, &v[cnt++]);
    }
    if (rc != SQLITE_DONE) r = sti_sql_fail(db, rc, "listing runs");
out:
    if (st) {
        rc = sqlite3_finalize(st);
        if (!r && rc != SQLITE_OK) r = sti_sql_fail(db, rc, "listing runs");
    }
    reader_put(s, db);
    if (r) {
        store_run_list_free(v, cnt);
        return r;
    }
    *runs = v;
    *n = cnt;
    return 0;
}

/* ---------------------------------------------------------------------- */
/* Energy samples */

int store_energy_read(store *s, int64_t run_id, int64_t from_seq, size_t max,
                      mpm_energy_sample **out, size_t *n)
{
    if (!s || !out || !n) return sti_fail(MPM_EINVAL, "store_energy_read: NULL argument");
    *out = NULL;
    *n = 0;
    if (max > INT64_MAX) max = 0;
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    mpm_energy_sample *v = NULL;
    int64_t total = 0;
    int rc;
    /* count and rows in one read transaction: the same snapshot */
    if ((r = sti_exec(db, "BEGIN", "reading energy samples"))) goto out;
    rc = sqlite3_prepare_v2(db, "SELECT count(*) FROM energy WHERE run_id = ?1 AND seq >= ?2", -1,
                            &st, NULL);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 1, run_id);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 2, from_seq);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    if (rc != SQLITE_ROW) {
        r = sti_sql_fail(db, rc, "counting energy samples");
        goto out;
    }
    total = sqlite3_column_int64(st, 0);
    rc = sqlite3_finalize(st);
    st = NULL;
    if (rc != SQLITE_OK) {
        r = sti_sql_fail(db, rc, "counting energy samples");
        goto out;
    }
    size_t cnt = (size_t)total;
    if (max && cnt > max) cnt = max;
    if (!cnt) goto out;
    if (cnt > SIZE_MAX / sizeof *v) {
        r = sti_fail(MPM_ENOMEM, "%zu energy samples do not fit in memory", cnt);
        goto out;
    }
    v = malloc(cnt * sizeof *v);
    if (!v) {
        r = sti_fail(MPM_ENOMEM, "out of memory reading %zu energy samples", cnt);
        goto out;
    }
    /* the run's dim: a sample holds it, the energy table does not */
    rc = sqlite3_prepare_v2(
        db,
        "SELECT e.seq, e.step, e.t, e.kinetic, e.strain, e.potential, e.external_work,"
        " e.total, e.momentum_x, e.momentum_y, e.momentum_z, e.mass,"
        " (SELECT dim FROM runs WHERE id = ?1),"
        " e.angular_momentum_x, e.angular_momentum_y, e.angular_momentum_z,"
        " e.plastic_work, e.damping_work, e.friction_work, e.prescribed_work, e.balance_error"
        " FROM energy e WHERE e.run_id = ?1 AND e.seq >= ?2 ORDER BY e.seq LIMIT ?3",
        -1, &st, NULL);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 1, run_id);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 2, from_seq);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 3, (sqlite3_int64)cnt);
    if (rc != SQLITE_OK) {
        r = sti_sql_fail(db, rc, "reading energy samples");
        goto out;
    }
    size_t i = 0;
    while (i < cnt && (rc = sqlite3_step(st)) == SQLITE_ROW) {
        mpm_energy_sample *e = &v[i++];
        memset(e, 0, sizeof *e);
        e->seq = (uint64_t)sqlite3_column_int64(st, 0);
        e->step = sqlite3_column_int64(st, 1);
        e->t = col_real_nan(st, 2);
        e->e.kinetic = col_real_nan(st, 3);
        e->e.strain = col_real_nan(st, 4);
        e->e.potential = col_real_nan(st, 5);
        e->e.external_work = col_real_nan(st, 6);
        e->e.total = col_real_nan(st, 7);
        for (int k = 0; k < 3; k++) e->e.momentum[k] = col_real_nan(st, 8 + k);
        e->e.mass = col_real_nan(st, 11);
        e->dim = sqlite3_column_int(st, 12);
        for (int k = 0; k < 3; k++) e->e.angular_momentum[k] = col_real_nan(st, 13 + k);
        e->e.plastic_work = col_real_nan(st, 16);
        e->e.damping_work = col_real_nan(st, 17);
        e->e.friction_work = col_real_nan(st, 18);
        e->e.prescribed_work = col_real_nan(st, 19);
        e->e.balance_error = col_real_nan(st, 20);
    }
    if (i < cnt && rc != SQLITE_DONE) {
        r = sti_sql_fail(db, rc, "reading energy samples");
        goto out;
    }
    *out = v;
    *n = i;
    v = NULL; /* owned by the caller */
out:
    if (st) {
        rc = sqlite3_finalize(st);
        if (!r && rc != SQLITE_OK) r = sti_sql_fail(db, rc, "reading energy samples");
    }
    r = end_read(db, r);
    reader_put(s, db);
    free(v);
    if (r) {
        free(*out);
        *out = NULL;
        *n = 0;
    }
    return r;
}

/* ---------------------------------------------------------------------- */
/* A run's extras */

int store_run_extras(store *s, int64_t run_id, store_run_extra *out)
{
    if (!s || !out) return sti_fail(MPM_EINVAL, "store_run_extras: NULL argument");
    memset(out, 0, sizeof *out);
    out->last_seq = -1;
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    int rc;
    size_t cap = 0;
    if ((r = sti_exec(db, "BEGIN", "reading a run's extras"))) goto out;
    rc = sqlite3_prepare_v2(db, "SELECT count(*), max(seq) FROM energy WHERE run_id = ?1", -1, &st,
                            NULL);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 1, run_id);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    if (rc != SQLITE_ROW) {
        r = sti_sql_fail(db, rc, "counting energy samples");
        goto out;
    }
    out->energy_count = sqlite3_column_int64(st, 0);
    if (sqlite3_column_type(st, 1) != SQLITE_NULL) out->last_seq = sqlite3_column_int64(st, 1);
    sqlite3_finalize(st);
    st = NULL;
    rc = sqlite3_prepare_v2(db, "SELECT step FROM snapshots WHERE run_id = ?1 ORDER BY step", -1,
                            &st, NULL);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 1, run_id);
    if (rc != SQLITE_OK) {
        r = sti_sql_fail(db, rc, "listing snapshots");
        goto out;
    }
    while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
        int64_t *nb = sti_grow(out->snapshot_steps, &cap, out->n_snapshots + 1, sizeof *nb);
        if (!nb) {
            r = sti_fail(MPM_ENOMEM, "out of memory listing snapshots");
            goto out;
        }
        out->snapshot_steps = nb;
        out->snapshot_steps[out->n_snapshots++] = sqlite3_column_int64(st, 0);
    }
    if (rc != SQLITE_DONE) r = sti_sql_fail(db, rc, "listing snapshots");
out:
    if (st) sqlite3_finalize(st);
    r = end_read(db, r);
    reader_put(s, db);
    if (r) store_run_extra_clear(out);
    return r;
}

int store_owner_bytes(store *s, const char *owner, int64_t *bytes)
{
    if (!s || !owner || !bytes) return sti_fail(MPM_EINVAL, "store_owner_bytes: NULL argument");
    *bytes = 0;
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    /* length() of a blob reads its size from the record header, not its
     * pages; runs_by_owner finds the runs */
    int rc = sqlite3_prepare_v2(
        db,
        "SELECT (SELECT coalesce(sum(length(data)), 0) FROM snapshots WHERE run_id IN"
        " (SELECT id FROM runs WHERE owner = ?1)) + ?2 * (SELECT count(*) FROM energy"
        " WHERE run_id IN (SELECT id FROM runs WHERE owner = ?1))"
        " + (SELECT coalesce(sum(checkpoint_bytes), 0) FROM runs WHERE owner = ?1)",
        -1, &st, NULL);
    if (rc == SQLITE_OK) rc = sqlite3_bind_text(st, 1, owner, -1, SQLITE_STATIC);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 2, STORE_ENERGY_ROW_BYTES);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    if (rc == SQLITE_ROW)
        *bytes = sqlite3_column_int64(st, 0);
    else
        r = sti_sql_fail(db, rc, "summing an owner's stored bytes");
    sqlite3_finalize(st);
    reader_put(s, db);
    return r;
}

int store_owner_totals(store *s, store_owner_total **rows, size_t *n)
{
    if (!s || !rows || !n) return sti_fail(MPM_EINVAL, "store_owner_totals: NULL argument");
    *rows = NULL;
    *n = 0;
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    store_owner_total *v = NULL;
    size_t cnt = 0, capn = 0;
    /* one statement: each run's snapshot bytes (length() reads a blob's
     * size from its record header) and sample count, summed per owner */
    int rc = sqlite3_prepare_v2(
        db,
        "SELECT r.owner, coalesce(sum(s.b), 0) + ?1 * coalesce(sum(e.c), 0)"
        " + coalesce(sum(r.checkpoint_bytes), 0) FROM runs r"
        " LEFT JOIN (SELECT run_id, sum(length(data)) AS b FROM snapshots GROUP BY run_id) s"
        " ON s.run_id = r.id"
        " LEFT JOIN (SELECT run_id, count(*) AS c FROM energy GROUP BY run_id) e"
        " ON e.run_id = r.id GROUP BY r.owner",
        -1, &st, NULL);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 1, STORE_ENERGY_ROW_BYTES);
    if (rc != SQLITE_OK) {
        r = sti_sql_fail(db, rc, "summing the owners' stored bytes");
        goto out;
    }
    while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
        store_owner_total *nv = sti_grow(v, &capn, cnt + 1, sizeof *nv);
        if (!nv) {
            r = sti_fail(MPM_ENOMEM, "out of memory reading the owners' totals");
            goto out;
        }
        v = nv;
        v[cnt].bytes = sqlite3_column_int64(st, 1);
        if ((r = col_strdup(db, st, 0, &v[cnt].owner))) goto out;
        cnt++;
    }
    if (rc != SQLITE_DONE) r = sti_sql_fail(db, rc, "summing the owners' stored bytes");
out:
    sqlite3_finalize(st);
    reader_put(s, db);
    if (r) {
        store_owner_totals_free(v, cnt);
        return r;
    }
    *rows = v;
    *n = cnt;
    return 0;
}

int store_run_owner(store *s, int64_t id, char *buf, size_t len)
{
    if (!s || !buf || !len) return sti_fail(MPM_EINVAL, "store_run_owner: NULL argument");
    buf[0] = 0;
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    int rc = sqlite3_prepare_v2(db, "SELECT owner FROM runs WHERE id = ?1", -1, &st, NULL);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 1, id);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    if (rc == SQLITE_ROW) {
        const unsigned char *t = sqlite3_column_text(st, 0);
        snprintf(buf, len, "%s", t ? (const char *)t : "");
    } else if (rc == SQLITE_DONE) {
        r = sti_fail(MPM_ENOTFOUND, "no run %lld", (long long)id);
    } else {
        r = sti_sql_fail(db, rc, "reading a run's owner");
    }
    sqlite3_finalize(st);
    reader_put(s, db);
    return r;
}

void store_owner_totals_free(store_owner_total *rows, size_t n)
{
    for (size_t i = 0; rows && i < n; i++) free((void *)rows[i].owner);
    free(rows);
}

void store_run_extra_clear(store_run_extra *x)
{
    if (!x) return;
    free(x->snapshot_steps);
    memset(x, 0, sizeof *x);
    x->last_seq = -1;
}

/* ---------------------------------------------------------------------- */
/* Snapshots */

void store_snapshot_clear(store_snapshot *snap)
{
    if (!snap) return;
    free((void *)snap->data);
    memset(snap, 0, sizeof *snap);
}

int store_snapshot_get(store *s, int64_t run_id, int64_t step, store_snapshot *out)
{
    if (!s || !out) return sti_fail(MPM_EINVAL, "store_snapshot_get: NULL argument");
    memset(out, 0, sizeof *out);
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    const char *sql = step >= 0 ? "SELECT run_id, step, t, n, dim, fields, data FROM snapshots"
                                  " WHERE run_id = ?1 AND step = ?2"
                                : "SELECT run_id, step, t, n, dim, fields, data FROM snapshots"
                                  " WHERE run_id = ?1 ORDER BY step DESC LIMIT 1";
    int rc = sqlite3_prepare_v2(db, sql, -1, &st, NULL);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 1, run_id);
    if (rc == SQLITE_OK && step >= 0) rc = sqlite3_bind_int64(st, 2, step);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    if (rc == SQLITE_ROW) {
        out->run_id = sqlite3_column_int64(st, 0);
        out->step = sqlite3_column_int64(st, 1);
        out->t = col_real_nan(st, 2);
        out->n = sqlite3_column_int64(st, 3);
        out->dim = sqlite3_column_int(st, 4);
        out->fields = (uint32_t)sqlite3_column_int64(st, 5);
        r = col_blobdup(db, st, 6, &out->data, &out->size);
    } else if (rc == SQLITE_DONE) {
        r = step >= 0 ? sti_fail(MPM_ENOTFOUND, "no snapshot of run %" PRId64 " at step %" PRId64,
                                 run_id, step)
                      : sti_fail(MPM_ENOTFOUND, "no snapshot of run %" PRId64, run_id);
    } else {
        r = sti_sql_fail(db, rc, "reading a snapshot");
    }
    if (st) {
        rc = sqlite3_finalize(st);
        if (!r && rc != SQLITE_OK) r = sti_sql_fail(db, rc, "reading a snapshot");
    }
    reader_put(s, db);
    if (r) store_snapshot_clear(out);
    return r;
}

int store_schema_version(store *s, int *version)
{
    if (!s || !version) return sti_fail(MPM_EINVAL, "store_schema_version: NULL argument");
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    int64_t v = 0;
    r = sti_query1(db, "PRAGMA user_version", &v, NULL, 0);
    reader_put(s, db);
    if (!r) *version = (int)v;
    return r;
}
