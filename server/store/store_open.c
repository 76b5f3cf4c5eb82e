/*
 * store_open.c - opening and closing the run store (see store.h): the
 * one-daemon lock, the connection settings, the schema migrations, the
 * first upkeep (crash recovery: store_upkeep.c) and the writer thread's
 * start.  What every file of the store shares is in store_sql.c.
 *
 * Open.  store_open: the database file made owner-only and refused with
 * a second name (a hard link), then flock() on <realpath>.lock, a file of
 * its own that only mpmd's user can open (non-blocking; one daemon per
 * database: a symlink or another spelling of the path finds it held; no
 * other user can lock it to block a start), the holder's pid written into
 * it for the message a second daemon prints; then WAL, busy_timeout, foreign keys, schema
 * migrations (the table of steps `migrations[]`, the pending ones applied in order in one
 * transaction, the version recorded in PRAGMA user_version), crash
 * recovery (runs left 'running' or 'queued' become 'interrupted'; queued
 * ones too, because the daemon's job queue lives in memory and nothing would
 * ever start them; steps and final energies become those of the run's last
 * energy sample), the next run id, the commit-notification eventfd and the
 * writer thread (store_writer.c).  Reads use connections of their own
 * (store_read.c).
 */
#define _GNU_SOURCE
#include "store_internal.h"

#include "store_apply.h"
#include "store_ends.h"
#include "store_read.h"
#include "store_sql.h"
#include "store_upkeep.h"
#include "store_writer.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

/* ---------------------------------------------------------------------- */
/* Schema migrations: migrations[v] takes the schema from version v to v+1.
 * Append only; never edit a released step. */

static const char *const migrations[] = {
    /* 0 -> 1: everything */
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
    ");",
    /* 1 -> 2: the case hash goes (nothing ever read it), and the columns
     * take the schema's names (mpmd.RunInfo); "update" is an SQL keyword,
     * so every statement quotes it. */
    "DROP INDEX runs_by_case_hash;"
    "ALTER TABLE runs DROP COLUMN case_hash;"
    "ALTER TABLE runs RENAME COLUMN update_scheme TO \"update\";"
    "ALTER TABLE runs RENAME COLUMN ended_at TO finished_at;"
    "ALTER TABLE runs RENAME COLUMN steps_done TO steps;",
    /* 2 -> 3: the angular momentum of each energy sample (about the origin
     * of coordinates; mpmd.EnergySample.angular_momentum).  Rows written
     * before stay NULL, read back as NaN: not recorded, which 0 would hide. */
    "ALTER TABLE energy ADD COLUMN angular_momentum_x REAL;"
    "ALTER TABLE energy ADD COLUMN angular_momentum_y REAL;"
    "ALTER TABLE energy ADD COLUMN angular_momentum_z REAL;",
    /* 3 -> 4: runs.method takes the B-spline methods ('bspline2',
     * 'bspline3') and, reserved for the CPDI method, 'cpdi'.  SQLite cannot
     * alter a CHECK constraint, and rebuilding runs would cascade-delete its
     * energy and snapshot rows (foreign keys are on, and cannot be turned
     * off inside the migration's transaction), so the constraint's text is
     * widened in place: every stored value still satisfies it, which is
     * the case SQLite documents as safe for writable_schema; RESET reloads
     * the schema. */
    "PRAGMA writable_schema = ON;"
    "UPDATE sqlite_schema SET sql = replace(sql, 'CHECK (method IN (''mpm'',''gimp''))',"
    " 'CHECK (method IN (''mpm'',''gimp'',''bspline2'',''bspline3'',''cpdi''))')"
    " WHERE type = 'table' AND name = 'runs';"
    "PRAGMA writable_schema = RESET;",
    /* 4 -> 5: the run's particle-grid velocity transfer (mpmd.Case.transfer,
     * RunInfo.transfer).  Runs stored before take the default, 'flip': the
     * transfer of every run before APIC.  (An APIC run stored by a schema-4
     * build that had APIC also reads 'flip'; its stored case still names
     * APIC.) */
    "ALTER TABLE runs ADD COLUMN transfer TEXT NOT NULL DEFAULT 'flip'"
    " CHECK (transfer IN ('flip','apic'));",
    /* 5 -> 6: the extended energy balance (mpmd.EnergySample
     * fields 12-16): the four cumulative works and the balance error of
     * each sample, and the run's balance error at its end and budget warning
     * (RunInfo.balance_error, .warning).  Samples written before read the
     * works and the error as 0 (no such feature ran then; the error was
     * not measured; a NaN written later is NULL and reads NaN), runs
     * before as no balance recorded (NULL) and no warning. */
    "ALTER TABLE energy ADD COLUMN plastic_work REAL DEFAULT 0;"
    "ALTER TABLE energy ADD COLUMN damping_work REAL DEFAULT 0;"
    "ALTER TABLE energy ADD COLUMN friction_work REAL DEFAULT 0;"
    "ALTER TABLE energy ADD COLUMN prescribed_work REAL DEFAULT 0;"
    "ALTER TABLE energy ADD COLUMN balance_error REAL DEFAULT 0;"
    "ALTER TABLE runs ADD COLUMN balance_error REAL;"
    "ALTER TABLE runs ADD COLUMN warning TEXT;",
    /* 6 -> 7: the run's owner (RunInfo.owner): the submitter's
     * CURVE public key (Z85) or "local".  Runs stored before read '' (not
     * recorded); they have all ended (a cancel gets CONFLICT).  The
     * index serves the per-client disk quota (store_owner_bytes). */
    "ALTER TABLE runs ADD COLUMN owner TEXT NOT NULL DEFAULT '';"
    "CREATE INDEX runs_by_owner ON runs(owner, id);",
    /* 7 -> 8: resumable runs (RunInfo.checkpoint_step/_t,
     * .resumes): the run's last checkpoint (its step, simulated time, file
     * size and the seq of the next energy sample; NULL = none) and the
     * number of times it was resumed.  Runs stored before have none and
     * were never resumed. */
    "ALTER TABLE runs ADD COLUMN checkpoint_step INTEGER;"
    "ALTER TABLE runs ADD COLUMN checkpoint_t REAL;"
    "ALTER TABLE runs ADD COLUMN checkpoint_bytes INTEGER;"
    "ALTER TABLE runs ADD COLUMN checkpoint_seq INTEGER;"
    "ALTER TABLE runs ADD COLUMN resumes INTEGER NOT NULL DEFAULT 0;",
    /* 8 -> 9: the solver's plan of a run (RunInfo.plan), one line of
     * key=value pairs recorded when it starts.  Runs stored before have
     * none (NULL). */
    "ALTER TABLE runs ADD COLUMN plan TEXT;",
};

_Static_assert(sizeof migrations / sizeof migrations[0] == STORE_SCHEMA_VERSION,
               "one migration step per schema version");

/* Prefixes the thread's error message with "database PATH: ". */
static int fail_in(const char *path, int code)
{
    char m[MPM_ERROR_MSG_MAX];
    snprintf(m, sizeof m, "%s", sti_error()->message);
    return sti_fail(code, "database %s: %s", path, m);
}

static void default_log(void *ud, const char *msg)
{
    (void)ud;
    fprintf(stderr, "mpmd store: %s\n", msg);
}

/* Keeps the first column of each row (the last one wins). */
static int raw_row(void *ud, int ncol, char **vals, char **names)
{
    (void)names;
    if (ud && ncol > 0 && vals[0]) *(int64_t *)ud = strtoll(vals[0], NULL, 10);
    return 0;
}

/* Opens path with a connection of its own (flags: SQLite's open flags),
 * runs sql with callback row(ud, ...) and closes it. */
static int raw_exec(const char *path, int flags, const char *sql,
                    int (*row)(void *, int, char **, char **), void *ud)
{
    sqlite3 *db = NULL;
    int rc = sqlite3_open_v2(path, &db, flags, NULL);
    if (rc != SQLITE_OK) {
        int r = sti_fail(MPM_EIO, "cannot open database %s: %s", path,
                         db ? sqlite3_errmsg(db) : sqlite3_errstr(rc));
        sqlite3_close(db);
        return r;
    }
    char *msg = NULL;
    rc = sqlite3_exec(db, sql, row, ud, &msg);
    int r = 0;
    if (rc != SQLITE_OK)
        r = sti_fail(MPM_EIO, "database %s: %s", path, msg ? msg : sqlite3_errstr(rc));
    sqlite3_free(msg);
    rc = sqlite3_close(db);
    if (!r && rc != SQLITE_OK)
        r = sti_fail(MPM_EIO, "closing database %s: %s", path, sqlite3_errstr(rc));
    return r;
}

int store_exec_raw(const char *path, const char *sql, int64_t *result)
{
    if (!path || !sql) return sti_fail(MPM_EINVAL, "store_exec_raw: NULL argument");
    return raw_exec(path, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, sql, raw_row, result);
}

/* What PRAGMA integrity_check said: its rows joined with "; ". */
typedef struct {
    char *buf;
    size_t len, used;
    int rows;
} check_report;

static int check_row(void *ud, int ncol, char **vals, char **names)
{
    check_report *c = ud;
    (void)names;
    const char *v = ncol > 0 && vals[0] ? vals[0] : "(null)";
    if (c->len > c->used) {
        int n = snprintf(c->buf + c->used, c->len - c->used, "%s%s", c->rows ? "; " : "", v);
        c->used = n < 0 ? c->used : c->used + (size_t)n;
        if (c->used >= c->len) c->used = c->len - 1;
    }
    c->rows++;
    return 0;
}

int store_integrity_check(const char *path, int *ok, char *report, size_t len)
{
    char dummy[8];
    check_report c = {report && len ? report : dummy, report && len ? len : sizeof dummy, 0, 0};
    if (!path || !ok) return sti_fail(MPM_EINVAL, "store_integrity_check: NULL argument");
    c.buf[0] = 0;
    *ok = 0;
    /* read-write without create: a missing file is an error, not a new
     * database; SQLite may need to write the -shm index of a WAL file
     * whose writer died */
    int rc = raw_exec(path, SQLITE_OPEN_READWRITE, "PRAGMA integrity_check", check_row, &c);
    if (rc) return rc;
    *ok = c.rows == 1 && !strcmp(c.buf, "ok");
    return 0;
}

/* ---------------------------------------------------------------------- */
/* Lock file: one daemon per database */

/* The pid in a lock file (read through fd), or 0. */
static long lock_pid(int fd)
{
    char buf[32] = {0};
    ssize_t n = pread(fd, buf, sizeof buf - 1, 0);
    char *end = NULL;
    long pid = n > 0 ? strtol(buf, &end, 10) : 0;
    return end != buf && pid > 0 ? pid : 0;
}

/* Makes an existing file of the store owner-only (0600) when this user
 * owns it; logs what it changed. */
static void owner_only(store *s, const char *path)
{
    struct stat sb;
    if (lstat(path, &sb) || !S_ISREG(sb.st_mode) || sb.st_uid != geteuid() || !(sb.st_mode & 077))
        return;
    if (chmod(path, 0600) == 0)
        sti_log(s, "%s was mode %04o: now 0600 (owner only)", path, (unsigned)(sb.st_mode & 07777));
    else
        sti_log(s, "cannot make %s owner-only: %s", path, strerror(errno));
}

/* Checks the database file (created empty, mode 0600, if absent: SQLite
 * takes an empty file for a new database): a regular file with one name
 * (SQLite finds its -wal and -shm by the name it is opened with, so a
 * second name, a hard link, would be a second database on the same
 * pages), made owner-only with its -wal, -shm and -journal when this user
 * owns them (SQLite gives the files it creates the database's mode). */
static int db_file_check(store *s)
{
    int fd = open(s->path, O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    if (fd < 0) return sti_fail(MPM_EIO, "cannot open database %s: %s", s->path, strerror(errno));
    struct stat sb;
    int rc = fstat(fd, &sb);
    close(fd); /* before SQLite opens it: closing drops fcntl locks */
    if (rc) return sti_fail(MPM_EIO, "cannot stat database %s: %s", s->path, strerror(errno));
    if (!S_ISREG(sb.st_mode)) return sti_fail(MPM_EIO, "database %s is not a file", s->path);
    if (sb.st_nlink > 1)
        return sti_fail(MPM_EIO,
                        "database %s has %lu names (hard links): SQLite keeps its -wal and -shm "
                        "by name, so each name would be another database on the same pages; "
                        "keep one name (a copy, not a link, for a backup)",
                        s->path, (unsigned long)sb.st_nlink);
    static const char *const suffix[] = {"", "-wal", "-shm", "-journal"};
    for (size_t k = 0; k < sizeof suffix / sizeof suffix[0]; k++) {
        size_t n = strlen(s->path);
        char *p = malloc(n + 9);
        if (!p) return sti_fail(MPM_ENOMEM, "out of memory");
        memcpy(p, s->path, n);
        memcpy(p + n, suffix[k], strlen(suffix[k]) + 1);
        owner_only(s, p);
        free(p);
    }
    return 0;
}

/* One daemon per database: an exclusive flock() on <realpath>.lock, a file
 * of mpmd's user, mode 0600, that no other user can open, so none can take
 * a lock on it to block a start (the database file itself is never locked:
 * any reader of it could).  A symlink or another spelling of the path
 * finds the same lock file (realpath); a hard link is refused by
 * db_file_check().  The lock file is checked: a regular file (O_NOFOLLOW),
 * this user's, one name, mode 0600 from its creation on: one that others
 * could open (0644, made by an older mpmd) may be open in another user's
 * process, to be locked at will, so it is replaced (unlinked and made
 * anew), never locked; a lock counts only once the path still names the
 * locked file (another start may have replaced it meanwhile).
 * Guarded by store_lock_one_daemon, store_lock_not_blocked_by_readers and
 * daemon_perms_*. */
static int lock_acquire(store *s)
{
    int r = db_file_check(s);
    if (r) return r;
    errno = 0;
    char *real = realpath(s->path, NULL);
    if (!real && errno == ENOMEM)
        return sti_fail(MPM_ENOMEM, "out of memory resolving the path %s", s->path);
    if (real) {
        size_t n = strlen(real);
        char *lp = malloc(n + sizeof ".lock");
        if (!lp) {
            /* not the path's own lock: another spelling would take another */
            free(real);
            return sti_fail(MPM_ENOMEM, "out of memory naming the lock file of %s", s->path);
        }
        memcpy(lp, real, n);
        memcpy(lp + n, ".lock", sizeof ".lock");
        free(s->lock_path);
        s->lock_path = lp;
        free(real);
    }
    for (int attempt = 0; attempt < 5; attempt++) {
        int fd = open(s->lock_path, O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0600);
        if (fd < 0)
            return sti_fail(MPM_EIO, "cannot open the lock file %s: %s", s->lock_path,
                            strerror(errno));
        struct stat sb, now;
        if (fstat(fd, &sb) || !S_ISREG(sb.st_mode) || sb.st_uid != geteuid() || sb.st_nlink != 1) {
            close(fd);
            return sti_fail(MPM_EIO,
                            "the lock file %s is not a file of its own of this user (uid %u): "
                            "remove it, and keep the database in a directory only mpmd's user "
                            "can write",
                            s->lock_path, (unsigned)geteuid());
        }
        if (sb.st_mode & 077) {
            /* others could open it (an older mpmd made it 0644), and may
             * still hold it open to lock it: never used, replaced */
            int same =
                stat(s->lock_path, &now) == 0 && now.st_dev == sb.st_dev && now.st_ino == sb.st_ino;
            close(fd);
            if (same && unlink(s->lock_path) != 0 && errno != ENOENT)
                return sti_fail(MPM_EIO, "cannot replace the lock file %s (mode %04o): %s",
                                s->lock_path, (unsigned)(sb.st_mode & 07777), strerror(errno));
            if (same)
                sti_log(s, "%s was mode %04o: replaced by an owner-only one", s->lock_path,
                        (unsigned)(sb.st_mode & 07777));
            continue;
        }
        if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
            int e = errno;
            if (e != EWOULDBLOCK) {
                close(fd);
                return sti_fail(MPM_EIO, "cannot lock %s: %s", s->lock_path, strerror(e));
            }
            long pid = lock_pid(fd);
            close(fd);
            if (pid > 0)
                return sti_fail(MPM_ELOCKED, "database %s is in use by another mpmd (pid %ld)",
                                s->path, pid);
            return sti_fail(MPM_ELOCKED, "database %s is in use by another mpmd (pid unknown)",
                            s->path);
        }
        /* locked; the path must still name this file (another start may
         * have replaced it meanwhile) */
        if (stat(s->lock_path, &now) != 0 || now.st_dev != sb.st_dev || now.st_ino != sb.st_ino) {
            close(fd);
            continue;
        }
        s->lock_fd = fd;
        /* the pid, for the message of a second daemon: nothing depends on
         * it, so a full disk does not stop the start */
        char pid[32];
        int n = snprintf(pid, sizeof pid, "%ld\n", (long)getpid());
        if (ftruncate(fd, 0) != 0 || pwrite(fd, pid, (size_t)n, 0) != n)
            sti_log(s, "cannot write the pid into %s: %s (the lock holds regardless)", s->lock_path,
                    strerror(errno));
        return 0;
    }
    return sti_fail(MPM_ELOCKED, "cannot take the lock file %s: it keeps being replaced",
                    s->lock_path);
}

static void lock_release(store *s)
{
    if (s->lock_fd < 0) return;
    /* empty the pid before the lock goes; the file stays (unlinking a lock
     * file races with a process that has just opened it) */
    if (ftruncate(s->lock_fd, 0) != 0)
        sti_log(s, "cannot truncate %s: %s", s->lock_path, strerror(errno));
    close(s->lock_fd); /* releases the flock */
    s->lock_fd = -1;
}

/* ---------------------------------------------------------------------- */
/* The writer connection */

static int open_writer(store *s)
{
    int rc = sqlite3_open_v2(
        s->path, &s->wdb, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX, NULL);
    if (rc != SQLITE_OK) {
        int r = sti_fail(MPM_EIO, "cannot open database %s: %s", s->path,
                         s->wdb ? sqlite3_errmsg(s->wdb) : sqlite3_errstr(rc));
        if (s->wdb) sti_close_db(s, s->wdb);
        s->wdb = NULL;
        return r;
    }
    int r = sti_conn_setup(s->wdb, s->busy_ms);
    if (r) return r;
    char mode[16];
    r = sti_query1(s->wdb, "PRAGMA journal_mode = WAL", NULL, mode, sizeof mode);
    if (r) return fail_in(s->path, r); /* e.g. "file is not a database": name the file */
    if (strcmp(mode, "wal"))
        return sti_fail(MPM_EIO, "database %s: cannot enable WAL journal mode (got '%s')", s->path,
                        mode);
    r = sti_exec(s->wdb, "PRAGMA synchronous = NORMAL", "synchronous");
    if (r) return r;
    int64_t fk = 0;
    r = sti_query1(s->wdb, "PRAGMA foreign_keys", &fk, NULL, 0);
    if (r) return r;
    if (fk != 1) return sti_fail(MPM_EIO, "this SQLite does not enforce foreign keys");
    return 0;
}

/* Rolls back the writer's open transaction after a failure, keeping the
 * thread's error (a failed rollback is logged). */
static int rollback_keep(store *s, int r, const char *what)
{
    if (!sqlite3_get_autocommit(s->wdb)) {
        mpm_error keep = *sti_error();
        if (sti_exec(s->wdb, "ROLLBACK", "rollback"))
            sti_log(s, "rollback after %s: %s", what, sti_error()->message);
        *sti_error() = keep;
    }
    return r;
}

/* ---------------------------------------------------------------------- */
/* Migrations and crash recovery */

static int migrate(store *s)
{
    sqlite3 *db = s->wdb;
    int64_t uv = 0, appid = 0, ntables = 0;
    int r = sti_exec(db, "BEGIN IMMEDIATE", "starting the migration transaction");
    if (r) return r;
    if ((r = sti_query1(db, "PRAGMA user_version", &uv, NULL, 0)) ||
        (r = sti_query1(db, "PRAGMA application_id", &appid, NULL, 0)) ||
        (r = sti_query1(db, "SELECT count(*) FROM sqlite_master", &ntables, NULL, 0)))
        return rollback_keep(s, r, "a failed migration");
    if (appid != 0 && appid != STORE_APP_ID) {
        r = sti_fail(MPM_ESCHEMA, "%s is not an mpmd database (application_id 0x%" PRIx64 ")",
                     s->path, (uint64_t)appid);
        return rollback_keep(s, r, "a failed migration");
    }
    if (uv == 0 && ntables > 0) {
        r = sti_fail(MPM_ESCHEMA,
                     "%s is not an mpmd database (it has tables but no schema "
                     "version)",
                     s->path);
        return rollback_keep(s, r, "a failed migration");
    }
    if (uv > STORE_SCHEMA_VERSION || uv < 0) {
        r = sti_fail(MPM_ESCHEMA,
                     "database %s has schema version %" PRId64
                     ", newer than this mpmd supports (%d)",
                     s->path, uv, STORE_SCHEMA_VERSION);
        return rollback_keep(s, r, "a failed migration");
    }
    for (int64_t v = uv; v < STORE_SCHEMA_VERSION; v++) {
        char what[64], sql[64];
        snprintf(what, sizeof what, "schema migration %" PRId64 " -> %" PRId64, v, v + 1);
        if ((r = sti_exec(db, migrations[v], what)))
            return rollback_keep(s, r, "a failed migration");
        snprintf(sql, sizeof sql, "PRAGMA user_version = %" PRId64, v + 1);
        if ((r = sti_exec(db, sql, what))) return rollback_keep(s, r, "a failed migration");
    }
    if (uv == 0) {
        char sql[64];
        snprintf(sql, sizeof sql, "PRAGMA application_id = %d", STORE_APP_ID);
        if ((r = sti_exec(db, sql, "setting application_id")))
            return rollback_keep(s, r, "a failed migration");
    }
    if ((r = sti_exec(db, "COMMIT", "committing the schema migration")))
        return rollback_keep(s, r, "a failed migration");
    if (uv == 0)
        sti_log(s, "%s: new database, schema version %d", s->path, STORE_SCHEMA_VERSION);
    else if (uv < STORE_SCHEMA_VERSION)
        sti_log(s, "%s: schema migrated from version %" PRId64 " to %d", s->path, uv,
                STORE_SCHEMA_VERSION);
    return 0;
}

/* 1 when an open failed for lack of room (SQLite's FULL, or an I/O error
 * sizing the WAL index or writing). */
static int no_room(store *s)
{
    int rc = s->wdb ? sqlite3_extended_errcode(s->wdb) : SQLITE_OK;
    return (rc & 0xff) == SQLITE_FULL || (rc & 0xff) == SQLITE_IOERR;
}

/* ---------------------------------------------------------------------- */
/* Open and close */

/* Frees everything; the writer thread must not be running. */
static void destroy(store *s)
{
    sti_readers_close(s);
    sti_writer_free(s);
    if (s->wdb) sti_close_db(s, s->wdb); /* last connection: checkpoints, drops the WAL */
    s->wdb = NULL;
    sti_ends_close(s);
    lock_release(s);
    if (s->notify_fd >= 0) close(s->notify_fd);
    if (s->sync_ready) {
        pthread_mutex_destroy(&s->mu);
        pthread_mutex_destroy(&s->pool_mu);
        pthread_cond_destroy(&s->cv_work);
        pthread_cond_destroy(&s->cv_done);
    }
    free(s->path);
    free(s->lock_path);
    free(s->ends_path);
    free(s->reserve_path);
    free(s);
}

static int init_sync(store *s)
{
    pthread_condattr_t ca;
    if (pthread_condattr_init(&ca)) return sti_fail(MPM_ENOMEM, "pthread_condattr_init failed");
    int e = pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    if (e) {
        pthread_condattr_destroy(&ca);
        return sti_fail(MPM_ENOMEM, "pthread_condattr_setclock: %s", strerror(e));
    }
    if (pthread_mutex_init(&s->mu, NULL)) goto f0;
    if (pthread_mutex_init(&s->pool_mu, NULL)) goto f1;
    if (pthread_cond_init(&s->cv_work, &ca)) goto f2;
    if (pthread_cond_init(&s->cv_done, &ca)) goto f3;
    pthread_condattr_destroy(&ca);
    s->sync_ready = 1;
    return 0;
f3:
    pthread_cond_destroy(&s->cv_work);
f2:
    pthread_mutex_destroy(&s->pool_mu);
f1:
    pthread_mutex_destroy(&s->mu);
f0:
    pthread_condattr_destroy(&ca);
    return sti_fail(MPM_ENOMEM, "cannot initialise the store's mutexes");
}

static int open_notify(store *s)
{
    s->notify_fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (s->notify_fd < 0)
        return sti_fail(MPM_EIO, "cannot create the commit eventfd: %s", strerror(errno));
    return 0;
}

/* The store with the options applied, or NULL (out of memory). */
static store *store_alloc(const char *path, const store_options *opt)
{
    store *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    s->lock_fd = -1;
    s->notify_fd = -1;
    s->ends_fd = -1;
    s->reserve_bytes = DEFAULT_RESERVE;
    s->log = default_log;
    s->batch_s = DEFAULT_BATCH_MS / 1000;
    s->batch_ops = DEFAULT_BATCH_OPS;
    s->cap = DEFAULT_QUEUE_CAP;
    s->busy_ms = DEFAULT_BUSY_MS;
    if (opt) {
        if (opt->batch_ms > 0) s->batch_s = opt->batch_ms / 1000;
        if (opt->batch_ops > 0) s->batch_ops = opt->batch_ops;
        if (opt->queue_cap > 0) s->cap = opt->queue_cap;
        if (opt->busy_timeout_ms > 0) s->busy_ms = opt->busy_timeout_ms;
        if (opt->reserve_bytes) s->reserve_bytes = opt->reserve_bytes > 0 ? opt->reserve_bytes : 0;
        if (opt->log) {
            s->log = opt->log;
            s->log_ud = opt->log_ud;
        }
    }
    size_t plen = strlen(path);
    s->path = malloc(plen + 1);
    s->lock_path = malloc(plen + sizeof ".lock");
    s->ends_path = malloc(plen + sizeof ".ends");
    s->reserve_path = malloc(plen + sizeof ".reserve");
    if (!s->path || !s->lock_path || !s->ends_path || !s->reserve_path) {
        free(s->path);
        free(s->lock_path);
        free(s->ends_path);
        free(s->reserve_path);
        free(s);
        return NULL;
    }
    memcpy(s->path, path, plen + 1);
    memcpy(s->lock_path, path, plen);
    memcpy(s->lock_path + plen, ".lock", sizeof ".lock");
    memcpy(s->ends_path, path, plen);
    memcpy(s->ends_path + plen, ".ends", sizeof ".ends");
    memcpy(s->reserve_path, path, plen);
    memcpy(s->reserve_path + plen, ".reserve", sizeof ".reserve");
    return s;
}

int store_open(const char *path, const store_options *opt, store **out)
{
    int r;
    if (out) *out = NULL;
    if (!path || !*path || !out) return sti_fail(MPM_EINVAL, "store_open: no database path");
    if (!sqlite3_threadsafe())
        return sti_fail(MPM_EIO, "this SQLite library is built without thread support");
    store *s = store_alloc(path, opt);
    if (!s) return sti_fail(MPM_ENOMEM, "out of memory opening %s", path);

    if ((r = init_sync(s)) || (r = lock_acquire(s)) || (r = open_notify(s))) goto fail;
    if ((r = open_writer(s)) || (r = migrate(s))) {
        /* a full disk: the reserve's room for SQLite's WAL index, once */
        if (!no_room(s) || !sti_reserve_exists(s)) goto fail;
        sti_reserve_release(s, store_error()->message);
        if (s->wdb) sti_close_db(s, s->wdb);
        s->wdb = NULL;
        if ((r = open_writer(s)) || (r = migrate(s))) goto fail;
    }
    int64_t next = 1;
    if ((r = sti_query1(s->wdb, "SELECT COALESCE(MAX(id), 0) + 1 FROM runs", &next, NULL, 0)))
        goto fail;
    s->next_id = next;
    s->recover_below = next;
    if ((r = sti_apply_prepare(s))) goto fail;
    /* the run ends a full disk kept, then crash recovery: written now, or
     * by the writer once there is room (reads show them meanwhile) */
    sti_ends_open(s);
    s->recovery_pending = 1;
    if (!s->reserve_ok && s->reserve_bytes > 0 && !sti_reserve_exists(s)) sti_reserve_make(s);
    sti_upkeep(s);
    int e = pthread_create(&s->writer, NULL, sti_writer_main, s);
    if (e) {
        r = sti_fail(MPM_ENOMEM, "cannot start the store writer thread: %s", strerror(e));
        goto fail;
    }
    s->writer_running = 1;
    (void)pthread_setname_np(s->writer, "mpmd-store"); /* cosmetic */
    *out = s;
    return 0;
fail:
    destroy(s);
    return r;
}

void store_close(store **sp)
{
    if (!sp || !*sp) return;
    store *s = *sp;
    *sp = NULL;
    if (s->writer_running) {
        pthread_mutex_lock(&s->mu);
        s->stopping = 1; /* the writer drains the queue first */
        pthread_cond_broadcast(&s->cv_work);
        pthread_mutex_unlock(&s->mu);
        pthread_join(s->writer, NULL);
        s->writer_running = 0;
        if (s->unreported)
            sti_log(s, "%" PRIu64 " asynchronous write(s) failed before close; last: %s",
                    s->unreported, s->last_werr);
    }
    destroy(s);
}
