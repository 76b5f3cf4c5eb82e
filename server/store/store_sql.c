/*
 * store_sql.c - what every file of the store shares, below them all: the
 * calling thread's error (store_error), logging through the store's sink,
 * the clocks, the on-disk names of the enums, the SQLite helpers (exec, a
 * one-value query, a connection's settings, closing one); store_sql.h
 * also grows arrays (sti_grow).  It calls no other file of the store (tests/include_graph.py
 * checks that the store's files form no circle).
 *
 * On disk, status, method, update and transfer are stored as text
 * ('queued', 'gimp', 'musl', 'apic'), so a database reads the same
 * whatever the C enums' values; the API speaks mpp_status, mpm_method,
 * mpm_update and mpm_transfer.
 */
#include "store_internal.h"

#include "store_sql.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* ---------------------------------------------------------------------- */
/* Errors, logging, time */

static _Thread_local mpm_error tl_err;

const mpm_error *store_error(void)
{
    return &tl_err;
}
mpm_error *sti_error(void)
{
    return &tl_err;
}

int sti_fail(int code, const char *fmt, ...)
{
    char msg[MPM_ERROR_MSG_MAX];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    return mpm_fail(&tl_err, code, NULL, "%s", msg);
}

int sti_sql_fail(sqlite3 *db, int rc, const char *what)
{
    const char *msg = db ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
    if (db && sqlite3_errcode(db) == SQLITE_OK) msg = sqlite3_errstr(rc);
    return sti_fail((rc & 0xff) == SQLITE_NOMEM ? MPM_ENOMEM : MPM_EIO, "%s: %s", what, msg);
}

void sti_log(store *s, const char *fmt, ...)
{
    char buf[768];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    s->log(s->log_ud, buf);
}

double sti_mono_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

double store_time_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

const char *store_sqlite_version(void)
{
    return sqlite3_libversion();
}

/* ---------------------------------------------------------------------- */
/* On-disk names of the enums */

const char *const sti_status_names[STORE_NSTATUS] = {"queued", "running",   "finished",
                                                     "failed", "cancelled", "interrupted"};

_Static_assert(MPP_STATUS_QUEUED == MPP_STATUS_MIN && MPP_STATUS_RUNNING == 2 &&
                   MPP_STATUS_FINISHED == 3 && MPP_STATUS_FAILED == 4 &&
                   MPP_STATUS_CANCELLED == 5 && MPP_STATUS_INTERRUPTED == MPP_STATUS_MAX,
               "sti_status_names follows mpp_status");

int sti_status_ok(mpp_status st)
{
    return st >= MPP_STATUS_MIN && st <= MPP_STATUS_MAX;
}
int sti_method_ok(mpm_method m)
{
    return (unsigned)m < MPM_N_METHODS;
}
int sti_update_ok(mpm_update u)
{
    return (unsigned)u < MPM_N_UPDATES;
}
int sti_transfer_ok(mpm_transfer t)
{
    return (unsigned)t < MPM_N_TRANSFERS;
}

const char *sti_status_name(mpp_status st)
{
    return sti_status_ok(st) ? sti_status_names[st - MPP_STATUS_MIN] : "?";
}

int sti_parse_name(const char *name, const char *const *names, int n)
{
    for (int i = 0; name && i < n; i++)
        if (!strcmp(name, names[i])) return i;
    return -1;
}

/* ---------------------------------------------------------------------- */
/* SQLite helpers */

int sti_exec(sqlite3 *db, const char *sql, const char *what)
{
    char *msg = NULL;
    int rc = sqlite3_exec(db, sql, NULL, NULL, &msg);
    if (rc != SQLITE_OK) {
        int code = (rc & 0xff) == SQLITE_NOMEM ? MPM_ENOMEM : MPM_EIO;
        sti_fail(code, "%s: %s", what, msg ? msg : sqlite3_errstr(rc));
        sqlite3_free(msg);
        return code;
    }
    return 0;
}

int sti_query1(sqlite3 *db, const char *sql, int64_t *v, char *txt, size_t txtlen)
{
    sqlite3_stmt *st = NULL;
    int rc = sqlite3_prepare_v2(db, sql, -1, &st, NULL);
    if (rc != SQLITE_OK) return sti_sql_fail(db, rc, sql);
    rc = sqlite3_step(st);
    if (rc != SQLITE_ROW) {
        int r =
            rc == SQLITE_DONE ? sti_fail(MPM_EIO, "%s: no result", sql) : sti_sql_fail(db, rc, sql);
        sqlite3_finalize(st); /* returns the step's error, reported above */
        return r;
    }
    if (v) *v = sqlite3_column_int64(st, 0);
    if (txt) {
        const unsigned char *t = sqlite3_column_text(st, 0);
        snprintf(txt, txtlen, "%s", t ? (const char *)t : "");
    }
    rc = sqlite3_finalize(st);
    if (rc != SQLITE_OK) return sti_sql_fail(db, rc, sql);
    return 0;
}

int sti_conn_setup(sqlite3 *db, int busy_ms)
{
    int rc = sqlite3_extended_result_codes(db, 1);
    if (rc != SQLITE_OK) return sti_sql_fail(db, rc, "extended result codes");
    rc = sqlite3_busy_timeout(db, busy_ms);
    if (rc != SQLITE_OK) return sti_sql_fail(db, rc, "busy_timeout");
    return sti_exec(db, "PRAGMA foreign_keys = ON", "enabling foreign keys");
}

void sti_close_db(store *s, sqlite3 *db)
{
    int rc = sqlite3_close(db);
    if (rc != SQLITE_OK) sti_log(s, "closing a connection: %s", sqlite3_errstr(rc));
}
