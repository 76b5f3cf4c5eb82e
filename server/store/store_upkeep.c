/*
 * store_upkeep.c - the store's upkeep, on the writer connection (at open,
 * then from the writer thread): in one transaction, the run ends kept off
 * a full disk (store_ends.c) and the crash recovery of the runs an earlier
 * daemon left 'running' or 'queued', or a probe write when there is
 * neither; then the disk reserve put back.  It runs right after a lost
 * transaction and every UPKEEP_S while it has work (store_writer.c says
 * when).  Guarded by the daemon_disk_* tests (t_daemon_disk.c) and the
 * store's crash-recovery tests (t_store.c).
 */
#include "store_internal.h"

#include "store_apply.h"
#include "store_ends.h"
#include "store_sql.h"
#include "store_upkeep.h"

#include <inttypes.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

/* Runs `UPDATE ... SET status='interrupted', error=?1 WHERE status=?2`.
 * The steps done and the final energies become those of the run's last
 * stored energy sample: the progress figures in the row lag behind it or
 * run ahead of it by whatever the crash left, while the sample is a
 * consistent state (its step, t and energies belong together, and RunInfo
 * takes t and the last energies from it). */
static int recover_status(store *s, const char *from, const char *error, int64_t *count)
{
    sqlite3_stmt *st = NULL;
#define LAST_SAMPLE(cols) \
    "(SELECT " cols " FROM energy WHERE run_id = runs.id ORDER BY seq DESC LIMIT 1)"
    const char *sql =
        "UPDATE runs SET status = 'interrupted', error = ?1,"
        " steps = COALESCE(" LAST_SAMPLE(
            "step") ", steps),"
                    " (kinetic, strain, potential, external_work, total) ="
                    " " LAST_SAMPLE(
                        "kinetic, strain, potential, external_work, total") " WHERE status = ?2"
                                                                            " AND id < ?3";
#undef LAST_SAMPLE
    int rc = sqlite3_prepare_v2(s->wdb, sql, -1, &st, NULL);
    if (rc != SQLITE_OK) return sti_sql_fail(s->wdb, rc, "crash recovery");
    rc = sqlite3_bind_text(st, 1, error, -1, SQLITE_STATIC);
    if (rc == SQLITE_OK) rc = sqlite3_bind_text(st, 2, from, -1, SQLITE_STATIC);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 3, s->recover_below);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    int r = rc == SQLITE_DONE ? 0 : sti_sql_fail(s->wdb, rc, "crash recovery");
    *count = sqlite3_changes(s->wdb);
    rc = sqlite3_finalize(st);
    if (!r && rc != SQLITE_OK) r = sti_sql_fail(s->wdb, rc, "crash recovery");
    return r;
}

/* Crash recovery runs in the upkeep's transaction (sti_upkeep), at open
 * and, when the disk is full then, retried by the writer until it
 * commits; only the runs an earlier daemon left (ids below recover_below)
 * are concerned.  Guarded by daemon_disk_restart_full. */
int sti_recover_rows(store *s)
{
    int64_t running = 0, queued = 0;
    int r;
    if ((r = recover_status(s, "running", STORE_INTERRUPTED_RUNNING, &running)) ||
        (r = recover_status(s, "queued", STORE_INTERRUPTED_QUEUED, &queued)))
        return r;
    pthread_mutex_lock(&s->mu);
    s->rec_running = running;
    s->rec_queued = queued;
    pthread_mutex_unlock(&s->mu);
    return 0;
}

int sti_upkeep_due_locked(const store *s)
{
    return s->degraded || s->recovery_pending || s->ndefer ||
           (s->reserve_bytes > 0 && !s->reserve_ok);
}

/* Logs a failed upkeep once per distinct reason (not every second). */
static void upkeep_log(store *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void upkeep_log(store *s, const char *fmt, ...)
{
    char buf[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    uint64_t h = 0xcbf29ce484222325ULL;
    for (const char *p = buf; *p; p++) h = (h ^ (unsigned char)*p) * 0x100000001b3ULL;
    if (h == s->upkeep_logged) return;
    s->upkeep_logged = h;
    sti_log(s, "%s", buf);
}

int sti_upkeep(store *s)
{
    pthread_mutex_lock(&s->mu);
    int recover = s->recovery_pending, degraded = s->degraded;
    size_t nd = s->ndefer;
    pthread_mutex_unlock(&s->mu);
    if (recover || degraded || nd) {
        int64_t run0 = s->rec_running, queued0 = s->rec_queued;
        int rc = sti_ws_simple(s, WS_BEGIN), r = 0;
        const char *what = "BEGIN";
        /* the kept ends first: a run the disk stopped ends FAILED with its
         * reason, not 'interrupted' by the recovery */
        for (size_t i = 0; rc == SQLITE_OK && i < nd; i++) {
            op o;
            memset(&o, 0, sizeof o);
            o.kind = OP_RUN_FINISH;
            o.run_id = s->defer[i].run_id;
            o.u.fin = s->defer[i].end;
            o.u.fin.error = s->defer[i].end.error ? s->defer[i].error : NULL;
            o.u.fin.warning = s->defer[i].end.warning ? s->defer[i].warning : NULL;
            /* a run that ended meanwhile or has no row: logged, skipped */
            if (sti_apply_op(s, &o) && sqlite3_get_autocommit(s->wdb)) {
                rc = sqlite3_errcode(s->wdb);
                what = "a kept run end";
            }
        }
        if (rc == SQLITE_OK && recover && (r = sti_recover_rows(s))) {
            rc = sqlite3_errcode(s->wdb);
            what = "crash recovery";
        }
        if (rc == SQLITE_OK && !recover && !nd) {
            /* a probe: one page written */
            char sql[64];
            snprintf(sql, sizeof sql, "PRAGMA user_version = %d", STORE_SCHEMA_VERSION);
            if (sti_exec(s->wdb, sql, "probe")) {
                rc = sqlite3_errcode(s->wdb);
                what = "a probe write";
            }
        }
        if (rc == SQLITE_OK) {
            rc = sti_ws_simple(s, WS_COMMIT);
            what = "COMMIT";
        }
        if (rc != SQLITE_OK) {
            if (!sqlite3_get_autocommit(s->wdb) && sti_ws_simple(s, WS_ROLLBACK) != SQLITE_OK)
                sti_log(s, "ROLLBACK: %s", sqlite3_errmsg(s->wdb));
            char why[200];
            snprintf(why, sizeof why, "%s (%s)", sqlite3_errstr(rc ? rc : SQLITE_ERROR), what);
            pthread_mutex_lock(&s->mu);
            s->rec_running = run0; /* rolled back */
            s->rec_queued = queued0;
            s->degraded = 1;
            snprintf(s->degraded_why, sizeof s->degraded_why, "%s", why);
            pthread_mutex_unlock(&s->mu);
            upkeep_log(s,
                       "cannot write yet: %s;%s%s retried every %g s while the store refuses new "
                       "runs",
                       why, nd ? " run ends kept," : "", recover ? " crash recovery pending," : "",
                       UPKEEP_S);
            return MPM_EIO;
        }
        sti_ends_drop(s, nd);
        pthread_mutex_lock(&s->mu);
        s->degraded = 0;
        s->recovery_pending = 0;
        s->transactions++;
        pthread_mutex_unlock(&s->mu);
        s->upkeep_logged = 0;
        if (nd) sti_log(s, "recorded %zu run end(s) kept while the store could not write", nd);
        if (recover && (s->rec_running || s->rec_queued))
            sti_log(s,
                    "%s: marked %" PRId64 " running and %" PRId64
                    " queued runs of a previous daemon 'interrupted'",
                    s->path, s->rec_running, s->rec_queued);
        else if (degraded && !nd && !recover)
            sti_log(s, "the store writes again");
        sti_notify(s);
    }
    double now = sti_mono_now();
    if (s->reserve_bytes > 0 && !s->reserve_ok && now >= s->reserve_next) {
        if (sti_reserve_make(s)) s->reserve_next = now + UPKEEP_S;
    }
    return 0;
}
