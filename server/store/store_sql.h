/*
 * store_sql.h - store_sql.c: the helpers every file of the store shares
 * (errors, logging, clocks, the on-disk names of the enums, SQLite calls,
 * growing an array).  Private to server/store/.
 */
#ifndef STORE_SQL_H
#define STORE_SQL_H

#include "store_internal.h"

#include <sqlite3.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

/* ---- on-disk names ---- */

/* status_names[st - MPP_STATUS_MIN] for an mpp_status st. */
#define STORE_NSTATUS (MPP_STATUS_MAX - MPP_STATUS_MIN + 1)
extern const char *const sti_status_names[STORE_NSTATUS];
/* methods, updates and transfers: their keys (mpm_method_key(), ...) */
int sti_status_ok(mpp_status st);
int sti_method_ok(mpm_method m);
int sti_update_ok(mpm_update u);
int sti_transfer_ok(mpm_transfer t);
const char *sti_status_name(mpp_status st); /* "queued", ...; "?" */
/* Index of name in names[0..n), or -1. */
int sti_parse_name(const char *name, const char *const *names, int n);

/* ---- errors, logging, time ---- */

/* Sets the calling thread's error to code with the message; returns code. */
int sti_fail(int code, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* MPM_EIO with "what: sqlite message" (MPM_ENOMEM for SQLITE_NOMEM). */
int sti_sql_fail(sqlite3 *db, int rc, const char *what);
/* The thread's error value, to save and restore around a cleanup. */
mpm_error *sti_error(void);
void sti_log(store *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
double sti_mono_now(void);

/* ---- SQLite helpers ---- */

/* Runs one or more statements with no results. */
int sti_exec(sqlite3 *db, const char *sql, const char *what);
/* Runs a query returning one integer (or text into txt if not NULL). */
int sti_query1(sqlite3 *db, const char *sql, int64_t *v, char *txt, size_t txtlen);
/* Extended result codes, busy timeout, foreign keys. */
int sti_conn_setup(sqlite3 *db, int busy_ms);
void sti_close_db(store *s, sqlite3 *db);

/* ---- arrays ---- */

/* Room for need elements of size bytes in the array v of *cap: v itself
 * when it has it, else v grown (doubling from 16) with *cap updated, or
 * NULL when out of memory (v unchanged and still the caller's).  Inline,
 * so that gcc -fanalyzer follows the realloc into the callers. */
static inline void *sti_grow(void *v, size_t *cap, size_t need, size_t size)
{
    if (need <= *cap) return v;
    size_t nc = *cap ? *cap : 16;
    while (nc < need) {
        if (nc > SIZE_MAX / 2 / size) return NULL;
        nc *= 2;
    }
    void *nv = realloc(v, nc * size);
    if (nv) *cap = nc;
    return nv;
}

#endif
