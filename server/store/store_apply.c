/*
 * store_apply.c - the writer thread's transactions (see store_writer.c for
 * the queue that feeds them): the writer's prepared statements, binding a
 * queue entry's values, applying a batch in one transaction, and what a
 * failed write leaves behind - the error counted and logged, the range of
 * enqueue numbers remembered for store_write_result(), and after a lost
 * transaction the store degraded, the disk reserve released and the
 * batch's run ends kept (store_ends.c).  The notify fd is written here
 * after each commit.  Guarded by the store_* tests and the daemon_disk_*
 * tests (tests/daemon/t_daemon_disk.c).
 */
#include "store_internal.h"

#include "store_apply.h"
#include "store_ends.h"
#include "store_sql.h"

#include <inttypes.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

/* Updates of a run apply only while it has not ended: a terminal status
 * is final (a late "running" cannot overwrite "cancelled"). */
#define NOT_ENDED " AND status IN ('queued','running')"

static const char *const writer_sql[WS_COUNT] = {
    [WS_BEGIN] = "BEGIN IMMEDIATE",
    [WS_COMMIT] = "COMMIT",
    [WS_ROLLBACK] = "ROLLBACK",
    [WS_INS_RUN] = "INSERT INTO runs (id, name, case_pb, method, \"update\","
                   " dim, particles, nodes, status, submitted_at, started_at, finished_at,"
                   " steps, wall_s, psteps_per_s, error, server_version, transfer, owner)"
                   " VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14,"
                   " ?15, ?16, ?17, ?18, ?19)",
    [WS_UPD_STATUS] = "UPDATE runs SET status = ?2,"
                      " started_at = CASE WHEN ?2 = 'running' THEN COALESCE(started_at, ?3)"
                      "   ELSE started_at END,"
                      " finished_at = CASE WHEN ?2 IN ('finished','failed','cancelled',"
                      "   'interrupted') THEN ?3 ELSE finished_at END,"
                      " error = COALESCE(?4, error)"
                      " WHERE id = ?1" NOT_ENDED,
    [WS_UPD_PROGRESS] = "UPDATE runs SET steps = ?2, wall_s = ?3, psteps_per_s = ?4"
                        " WHERE id = ?1" NOT_ENDED,
    [WS_PLAN] = "UPDATE runs SET plan = ?2 WHERE id = ?1" NOT_ENDED,
    [WS_FINISH] = "UPDATE runs SET status = ?2, finished_at = ?3, steps = ?4,"
                  " wall_s = ?5, psteps_per_s = ?6, kinetic = ?7, strain = ?8,"
                  " potential = ?9, external_work = ?10, total = ?11, error = ?12,"
                  " balance_error = ?13, warning = ?14"
                  " WHERE id = ?1" NOT_ENDED,
    [WS_INS_ENERGY] = "INSERT INTO energy (run_id, seq, step, t, kinetic, strain, potential,"
                      " external_work, total, momentum_x, momentum_y, momentum_z, mass,"
                      " angular_momentum_x, angular_momentum_y, angular_momentum_z,"
                      " plastic_work, damping_work, friction_work, prescribed_work,"
                      " balance_error)"
                      " VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15,"
                      " ?16, ?17, ?18, ?19, ?20, ?21)",
    [WS_PUT_SNAP] = "INSERT OR REPLACE INTO snapshots (run_id, step, t, n, dim, fields, data)"
                    " VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
    [WS_GET_STATUS] = "SELECT status FROM runs WHERE id = ?1",
    [WS_CHECKPOINT] = "UPDATE runs SET checkpoint_step = ?2, checkpoint_t = ?3,"
                      " checkpoint_bytes = ?4, checkpoint_seq = ?5 WHERE id = ?1",
    [WS_RESUME_RUN] = "UPDATE runs SET status = 'queued', finished_at = NULL, error = NULL,"
                      " warning = NULL, balance_error = NULL, steps = ?2,"
                      " kinetic = NULL, strain = NULL, potential = NULL, external_work = NULL,"
                      " total = NULL, checkpoint_step = ?2, checkpoint_t = ?3,"
                      " checkpoint_bytes = ?4, checkpoint_seq = ?5, resumes = resumes + 1"
                      " WHERE id = ?1 AND status = 'interrupted'",
    [WS_RESUME_ENERGY] = "DELETE FROM energy WHERE run_id = ?1 AND seq >= ?2",
    [WS_RESUME_SNAPS] = "DELETE FROM snapshots WHERE run_id = ?1 AND step > ?2",
};

/* ---------------------------------------------------------------------- */
/* Binding */

/* Binds a double, NaN as NULL (SQLite would do so anyway; explicit). */
static int bind_real(sqlite3_stmt *st, int i, double v)
{
    return isnan(v) ? sqlite3_bind_null(st, i) : sqlite3_bind_double(st, i, v);
}

/* Binds a time: 0 (not set) as NULL. */
static int bind_time(sqlite3_stmt *st, int i, double v)
{
    return v == 0 || isnan(v) ? sqlite3_bind_null(st, i) : sqlite3_bind_double(st, i, v);
}

static int bind_text_or_null(sqlite3_stmt *st, int i, const char *v)
{
    return v ? sqlite3_bind_text(st, i, v, -1, SQLITE_STATIC) : sqlite3_bind_null(st, i);
}

/* Blob; an empty one as a zero-length blob (a NULL pointer would bind NULL). */
static int bind_blob(sqlite3_stmt *st, int i, const void *p, size_t n)
{
    if (!n) return sqlite3_bind_zeroblob(st, i, 0);
    return sqlite3_bind_blob64(st, i, p, (sqlite3_uint64)n, SQLITE_STATIC);
}

static int bind_static(sqlite3_stmt *st, int i, const char *v)
{
    return sqlite3_bind_text(st, i, v, -1, SQLITE_STATIC);
}

/* ---------------------------------------------------------------------- */
/* The writer thread */

/* Records a failed asynchronous write: logged, counted, reported by flush;
 * lost = 1 when a whole transaction was lost (disk full, I/O error), not
 * one refused statement. */
__attribute__((format(printf, 4, 5))) static void write_error_(store *s, int lost, uint64_t nops,
                                                               const char *fmt, ...)
{
    char buf[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    pthread_mutex_lock(&s->mu);
    s->write_errors += nops;
    s->unreported += nops;
    snprintf(s->last_werr, sizeof s->last_werr, "%s", buf);
    if (lost) {
        s->batches_lost++;
        snprintf(s->last_loss, sizeof s->last_loss, "%s", buf);
    }
    pthread_mutex_unlock(&s->mu);
    sti_log(s, "write failed: %s", buf);
}
#define write_error(s, nops, ...) write_error_(s, 0, nops, __VA_ARGS__)
#define write_loss(s, nops, ...) write_error_(s, 1, nops, __VA_ARGS__)

/* Remembers that the writes lo..hi failed (under s->mu): merged into the
 * last range when it continues it for the same reason. */
static void fail_record_locked(store *s, uint64_t lo, uint64_t hi, int lost, const char *why)
{
    if (s->nfails) {
        fail_range *last = &s->fails[(s->nfails - 1) % FAIL_RING];
        if (last->hi + 1 == lo && last->lost == lost && !strcmp(last->why, why)) {
            last->hi = hi;
            return;
        }
    }
    fail_range *f = &s->fails[s->nfails % FAIL_RING];
    if (s->nfails >= FAIL_RING && f->hi > s->fail_horizon) s->fail_horizon = f->hi;
    f->lo = lo;
    f->hi = hi;
    f->lost = lost;
    snprintf(f->why, sizeof f->why, "%s", why);
    s->nfails++;
}

/* A transaction lost whole (BEGIN, a statement or COMMIT failed, SQLite's
 * code rc): every write of the batch failed; the store is degraded, the
 * disk reserve goes (its room is for the upkeep), and the run ends in the
 * batch are kept (see the header). */
static void batch_lost(store *s, op *batch, int rc, const char *what)
{
    char why[200];
    snprintf(why, sizeof why, "%s (%s)", sqlite3_errstr(rc), what);
    uint64_t hi = batch->seq;
    for (op *o = batch; o; o = o->next) {
        hi = o->seq;
        if (o->kind == OP_RUN_FINISH) sti_ends_keep(s, o->run_id, &o->u.fin);
    }
    pthread_mutex_lock(&s->mu);
    fail_record_locked(s, batch->seq, hi, 1, why);
    s->degraded = 1;
    snprintf(s->degraded_why, sizeof s->degraded_why, "%s", why);
    pthread_mutex_unlock(&s->mu);
    sti_reserve_release(s, why);
}

/* Why an update of run id matched no row: "no run N" or "run N already
 * ended (status)". */
static void run_state(store *s, int64_t id, char *buf, size_t len)
{
    sqlite3_stmt *st = s->ws[WS_GET_STATUS];
    int rc = sqlite3_bind_int64(st, 1, id);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    if (rc == SQLITE_ROW) {
        const unsigned char *t = sqlite3_column_text(st, 0);
        snprintf(buf, len, "run %" PRId64 " already ended (%s)", id, t ? (const char *)t : "?");
    } else if (rc == SQLITE_DONE) {
        snprintf(buf, len, "no run %" PRId64, id);
    } else {
        snprintf(buf, len, "run %" PRId64 " not updated (%s)", id, sqlite3_errmsg(s->wdb));
    }
    if (sqlite3_reset(st) != SQLITE_OK || sqlite3_clear_bindings(st) != SQLITE_OK)
        sti_log(s, "reading the status of run %" PRId64 ": %s", id, sqlite3_errmsg(s->wdb));
}

#define BIND(call)                        \
    do {                                  \
        if (rc == SQLITE_OK) rc = (call); \
    } while (0)

/* Steps a bound writer statement to completion and resets it.  Returns the
 * SQLite code of the step (SQLITE_DONE on success) or of a failed bind. */
static int ws_run(sqlite3_stmt *st, int bind_rc)
{
    int rc = bind_rc == SQLITE_OK ? sqlite3_step(st) : bind_rc;
    int rrc = sqlite3_reset(st); /* repeats a step error; else must be OK */
    int crc = sqlite3_clear_bindings(st);
    if (rc == SQLITE_DONE && rrc != SQLITE_OK) rc = rrc;
    if (rc == SQLITE_DONE && crc != SQLITE_OK) rc = crc;
    return rc;
}

/* Inserts the energy samples of an op; 0 or -1 after recording the error. */
static int apply_energy(store *s, const op *o)
{
    sqlite3_stmt *st = s->ws[WS_INS_ENERGY];
    size_t bad = 0;
    char msg[256] = "";
    for (size_t i = 0; i < o->u.en.n; i++) {
        const mpm_energy_sample *e = &o->u.en.v[i];
        int rc = SQLITE_OK;
        BIND(sqlite3_bind_int64(st, 1, o->run_id));
        BIND(sqlite3_bind_int64(st, 2, (sqlite3_int64)e->seq));
        BIND(sqlite3_bind_int64(st, 3, e->step));
        BIND(bind_real(st, 4, e->t));
        BIND(bind_real(st, 5, e->e.kinetic));
        BIND(bind_real(st, 6, e->e.strain));
        BIND(bind_real(st, 7, e->e.potential));
        BIND(bind_real(st, 8, e->e.external_work));
        BIND(bind_real(st, 9, e->e.total));
        BIND(bind_real(st, 10, e->e.momentum[0]));
        BIND(bind_real(st, 11, e->e.momentum[1]));
        BIND(bind_real(st, 12, e->e.momentum[2]));
        BIND(bind_real(st, 13, e->e.mass));
        BIND(bind_real(st, 14, e->e.angular_momentum[0]));
        BIND(bind_real(st, 15, e->e.angular_momentum[1]));
        BIND(bind_real(st, 16, e->e.angular_momentum[2]));
        BIND(bind_real(st, 17, e->e.plastic_work));
        BIND(bind_real(st, 18, e->e.damping_work));
        BIND(bind_real(st, 19, e->e.friction_work));
        BIND(bind_real(st, 20, e->e.prescribed_work));
        BIND(bind_real(st, 21, e->e.balance_error));
        rc = ws_run(st, rc);
        if (rc != SQLITE_DONE) {
            if (!bad++)
                snprintf(msg, sizeof msg, "run %" PRId64 " seq %" PRIu64 ": %s", o->run_id, e->seq,
                         sqlite3_errmsg(s->wdb));
            if (sqlite3_get_autocommit(s->wdb)) break; /* txn gone */
        }
    }
    if (bad) {
        write_error(s, bad, "append energy sample: %zu of %zu samples failed; first: %s", bad,
                    o->u.en.n, msg);
        return -1;
    }
    return 0;
}

/* Records a checkpoint (OP_RUN_CHECKPOINT), or resumes a run from one
 * (OP_RUN_RESUME: the run first, then, if it was interrupted, what the
 * resumed run records again goes); 0 or -1 after recording the error. */
static int apply_checkpoint(store *s, const op *o)
{
    const store_checkpoint *ck = &o->u.ck.ck;
    int resume = o->kind == OP_RUN_RESUME, has = o->u.ck.has;
    sqlite3_stmt *st = s->ws[resume ? WS_RESUME_RUN : WS_CHECKPOINT];
    const char *what = resume ? "resume run" : "record checkpoint";
    int rc = SQLITE_OK;
    BIND(sqlite3_bind_int64(st, 1, o->run_id));
    BIND(has ? sqlite3_bind_int64(st, 2, ck->step) : sqlite3_bind_null(st, 2));
    BIND(has ? sqlite3_bind_double(st, 3, ck->t) : sqlite3_bind_null(st, 3));
    BIND(has ? sqlite3_bind_int64(st, 4, ck->bytes) : sqlite3_bind_null(st, 4));
    BIND(has ? sqlite3_bind_int64(st, 5, ck->energy_seq) : sqlite3_bind_null(st, 5));
    rc = ws_run(st, rc);
    if (rc == SQLITE_DONE && sqlite3_changes(s->wdb) == 0) {
        char why[160];
        run_state(s, o->run_id, why, sizeof why);
        write_error(s, 1, "%s: %s%s", what, why, resume ? " (not interrupted)" : "");
        return -1;
    }
    for (int k = 0; resume && rc == SQLITE_DONE && k < 2; k++) {
        st = s->ws[k ? WS_RESUME_SNAPS : WS_RESUME_ENERGY];
        rc = SQLITE_OK;
        BIND(sqlite3_bind_int64(st, 1, o->run_id));
        BIND(sqlite3_bind_int64(st, 2, k ? ck->step : ck->energy_seq));
        rc = ws_run(st, rc);
    }
    if (rc != SQLITE_DONE) {
        write_error(s, 1, "%s (run %" PRId64 "): %s", what, o->run_id, sqlite3_errmsg(s->wdb));
        return -1;
    }
    return 0;
}

/* Applies one op inside the open transaction.  Returns 0, or -1 after
 * recording the error. */
int sti_apply_op(store *s, op *o)
{
    sqlite3_stmt *st = NULL;
    int rc = SQLITE_OK;
    int64_t id = o->run_id;
    const char *what = "";
    int is_update = 0;

    switch (o->kind) {
    case OP_RUN_INSERT: {
        const store_run *r = &o->u.run;
        st = s->ws[WS_INS_RUN];
        what = "insert run";
        BIND(sqlite3_bind_int64(st, 1, r->id));
        BIND(bind_static(st, 2, r->name));
        BIND(bind_blob(st, 3, r->case_pb, r->case_len));
        BIND(bind_static(st, 4, mpm_method_key(r->method)));
        BIND(bind_static(st, 5, mpm_update_key(r->update)));
        BIND(sqlite3_bind_int(st, 6, r->dim));
        BIND(sqlite3_bind_int64(st, 7, r->particles));
        BIND(sqlite3_bind_int64(st, 8, r->nodes));
        BIND(bind_static(st, 9, sti_status_name(r->status)));
        BIND(sqlite3_bind_double(st, 10, r->submitted_at));
        BIND(bind_time(st, 11, r->started_at));
        BIND(bind_time(st, 12, r->finished_at));
        BIND(sqlite3_bind_int64(st, 13, r->steps));
        BIND(bind_real(st, 14, r->wall_s));
        BIND(bind_real(st, 15, r->psteps_per_s));
        BIND(bind_text_or_null(st, 16, r->error));
        BIND(bind_static(st, 17, r->server_version));
        BIND(bind_static(st, 18, mpm_transfer_key(r->transfer)));
        BIND(bind_static(st, 19, r->owner));
        break;
    }
    case OP_RUN_STATUS:
        st = s->ws[WS_UPD_STATUS];
        what = "update run status";
        is_update = 1;
        BIND(sqlite3_bind_int64(st, 1, id));
        BIND(bind_static(st, 2, sti_status_name(o->u.st.status)));
        BIND(bind_time(st, 3, o->u.st.at));
        BIND(bind_text_or_null(st, 4, o->u.st.error));
        break;
    case OP_RUN_PLAN:
        st = s->ws[WS_PLAN];
        what = "record run plan";
        is_update = 1;
        BIND(sqlite3_bind_int64(st, 1, id));
        BIND(bind_static(st, 2, o->u.plan));
        break;
    case OP_RUN_PROGRESS:
        st = s->ws[WS_UPD_PROGRESS];
        what = "update run progress";
        is_update = 1;
        BIND(sqlite3_bind_int64(st, 1, id));
        BIND(sqlite3_bind_int64(st, 2, o->u.prog.steps));
        BIND(bind_real(st, 3, o->u.prog.wall));
        BIND(bind_real(st, 4, o->u.prog.rate));
        break;
    case OP_RUN_FINISH: {
        const store_run_end *e = &o->u.fin;
        st = s->ws[WS_FINISH];
        what = "finish run";
        is_update = 1;
        BIND(sqlite3_bind_int64(st, 1, id));
        BIND(bind_static(st, 2, sti_status_name(e->status)));
        BIND(bind_time(st, 3, e->finished_at));
        BIND(sqlite3_bind_int64(st, 4, e->steps));
        BIND(bind_real(st, 5, e->wall_s));
        BIND(bind_real(st, 6, e->psteps_per_s));
        BIND(bind_real(st, 7, e->has_energy ? e->energy.kinetic : NAN));
        BIND(bind_real(st, 8, e->has_energy ? e->energy.strain : NAN));
        BIND(bind_real(st, 9, e->has_energy ? e->energy.potential : NAN));
        BIND(bind_real(st, 10, e->has_energy ? e->energy.external_work : NAN));
        BIND(bind_real(st, 11, e->has_energy ? e->energy.total : NAN));
        BIND(bind_text_or_null(st, 12, e->error));
        BIND(bind_real(st, 13, e->has_balance ? e->balance_error : NAN));
        BIND(bind_text_or_null(st, 14, e->warning));
        break;
    }
    case OP_ENERGY: return apply_energy(s, o);
    case OP_RUN_CHECKPOINT:
    case OP_RUN_RESUME: return apply_checkpoint(s, o);
    case OP_SNAPSHOT: {
        const store_snapshot *sn = &o->u.snap;
        st = s->ws[WS_PUT_SNAP];
        what = "put snapshot";
        BIND(sqlite3_bind_int64(st, 1, sn->run_id));
        BIND(sqlite3_bind_int64(st, 2, sn->step));
        BIND(bind_real(st, 3, sn->t));
        BIND(sqlite3_bind_int64(st, 4, sn->n));
        BIND(sqlite3_bind_int(st, 5, sn->dim));
        BIND(sqlite3_bind_int64(st, 6, sn->fields));
        BIND(bind_blob(st, 7, sn->data, sn->size));
        break;
    }
    default: write_error(s, 1, "unknown queue entry kind %d", (int)o->kind); return -1;
    }
    rc = ws_run(st, rc);
    if (rc != SQLITE_DONE) {
        write_error(s, 1, "%s (run %" PRId64 "): %s", what, id, sqlite3_errmsg(s->wdb));
        return -1;
    }
    if (is_update && sqlite3_changes(s->wdb) == 0) {
        char why[160];
        run_state(s, id, why, sizeof why);
        write_error(s, 1, "%s: %s", what, why);
        return -1;
    }
    return 0;
}

/* Makes the notify fd readable (an eventfd never blocks a write of 1 short
 * of 2^64 - 1 pending, so EAGAIN cannot happen in practice). */
void sti_notify(store *s)
{
    uint64_t one = 1;
    ssize_t w = write(s->notify_fd, &one, sizeof one);
    (void)w;
}

int sti_ws_simple(store *s, int which)
{
    int rc = ws_run(s->ws[which], SQLITE_OK);
    return rc == SQLITE_DONE ? SQLITE_OK : rc;
}

/* Applies a batch of n ops in one transaction; records every failure. */
void sti_apply_batch(store *s, op *batch, size_t n)
{
    uint64_t failed = 0;
    int rc;
    for (int attempt = 0;; attempt++) {
        rc = sti_ws_simple(s, WS_BEGIN);
        if (rc == SQLITE_OK) break;
        if ((rc & 0xff) == SQLITE_BUSY && attempt < BEGIN_RETRIES) {
            sti_log(s, "database busy, retrying a batch of %zu writes", n);
            struct timespec ts = {0, 100 * 1000 * 1000};
            nanosleep(&ts, NULL);
            continue;
        }
        write_loss(s, n, "BEGIN: %s; %zu writes lost", sqlite3_errmsg(s->wdb), n);
        batch_lost(s, batch, rc, "BEGIN");
        return;
    }
    for (op *o = batch; o; o = o->next) {
        if (sti_apply_op(s, o) == 0) continue;
        failed++;
        if (sqlite3_get_autocommit(s->wdb)) {
            /* SQLite rolled the whole transaction back (disk full, I/O) */
            rc = sqlite3_errcode(s->wdb);
            write_loss(s, n - failed, "transaction rolled back (%s); %zu more writes lost",
                       sqlite3_errmsg(s->wdb), (size_t)(n - failed));
            batch_lost(s, batch, rc, "a write");
            return;
        }
        if (o->kind == OP_RUN_INSERT || o->kind == OP_RUN_RESUME) {
            /* refused alone (a duplicate id, a resume of a run no longer
             * interrupted): its client is told */
            pthread_mutex_lock(&s->mu);
            fail_record_locked(s, o->seq, o->seq, 0, s->last_werr);
            pthread_mutex_unlock(&s->mu);
        }
    }
    rc = sti_ws_simple(s, WS_COMMIT);
    if (rc != SQLITE_OK) {
        write_loss(s, n - failed, "COMMIT: %s; %zu writes lost", sqlite3_errmsg(s->wdb),
                   (size_t)(n - failed));
        if (!sqlite3_get_autocommit(s->wdb) && sti_ws_simple(s, WS_ROLLBACK) != SQLITE_OK)
            sti_log(s, "ROLLBACK: %s", sqlite3_errmsg(s->wdb));
        batch_lost(s, batch, rc, "COMMIT");
        return;
    }
    pthread_mutex_lock(&s->mu);
    s->transactions++;
    s->ops_committed += n - failed;
    s->degraded = 0;
    pthread_mutex_unlock(&s->mu);
}

int sti_apply_prepare(store *s)
{
    for (int i = 0; i < WS_COUNT; i++) {
        int rc = sqlite3_prepare_v3(s->wdb, writer_sql[i], -1, SQLITE_PREPARE_PERSISTENT, &s->ws[i],
                                    NULL);
        if (rc != SQLITE_OK) return sti_sql_fail(s->wdb, rc, writer_sql[i]);
    }
    return 0;
}

void sti_apply_free(store *s)
{
    for (int i = 0; i < WS_COUNT; i++) {
        if (s->ws[i] && sqlite3_finalize(s->ws[i]) != SQLITE_OK)
            sti_log(s, "finalizing a statement: %s", sqlite3_errmsg(s->wdb));
        s->ws[i] = NULL;
    }
}
