/*
 * store.c - the mpmd run-record store on SQLite (see store.h for the API).
 * This is the only file of mpmd that includes sqlite3.h: runs, energy
 * samples and snapshots go through here, and no SQLite type leaks out.
 *
 * Design
 * ------
 * Writer thread.  One thread owns the write connection.  Every write
 * function (store_run_insert, store_run_set_status, store_run_progress,
 * store_run_finish, store_energy_append[_n], store_snapshot_put) copies its
 * arguments into one heap block (an `op`, strings and blobs appended to the
 * struct), and appends it to a FIFO under s->mu, numbering it with
 * s->enq_seq; it never touches the disk, so a solver thread appending an
 * energy sample costs a malloc, a memcpy and a mutex hold of a few
 * instructions.  Like the job queues of Redis's bio.c, the queue is a plain
 * linked list guarded by one mutex and a condition variable the writer
 * sleeps on.
 *
 * Batching.  When the queue becomes non-empty the writer waits until the
 * oldest pending op is batch_ms (50 ms) old, or batch_ops (1024) ops are
 * pending, or someone calls store_flush(), or the store is closing; then it
 * detaches up to batch_ops ops from the head and applies them in ONE
 * transaction (BEGIN IMMEDIATE ... COMMIT) with prepared statements, outside
 * the mutex, so producers keep enqueueing while it writes.  A commit in WAL
 * mode with synchronous=NORMAL costs no fsync (the WAL is synced at
 * checkpoints), so a batch is cheap and a crash of the daemon loses nothing
 * committed (a power loss may lose the last transactions).
 *
 * Ordering.  There is one queue and one writer, and ops are applied in
 * enqueue order: whatever one thread enqueues is applied in its program
 * order, and an op enqueued after another returned (in any thread) is
 * applied after it.  So a run's insert always precedes its samples, and the
 * foreign keys hold.  done_seq is the seq of the last op of the last
 * committed batch; store_flush() waits for done_seq >= the enq_seq it saw
 * on entry (and asks the writer to skip the batching wait).
 *
 * Errors of asynchronous writes.  An op that fails (a constraint: duplicate
 * run id, a sample for an unknown run; an update of a missing run or of one
 * that already ended - terminal statuses are final, so a late "running"
 * cannot overwrite "cancelled") is skipped - SQLite undoes only that
 * statement - and the rest of the batch commits.  If SQLite rolls back the whole transaction (disk full, I/O
 * error) the batch is lost.  BEGIN failing with SQLITE_BUSY (another
 * process writing; not another mpmd, the lock prevents that) is retried.
 * Every failure is logged, counted (store_get_stats) and reported once by
 * the next store_flush() as STORE_EWRITE.
 *
 * Memory cap.  s->qbytes counts the bytes of ops not yet committed.  Above
 * queue_cap (64 MiB): snapshots (the bulky items) are dropped with a log
 * line and STORE_EFULL; every other op - energy samples, run inserts and
 * updates - is still accepted and the queue GROWS (logged once each time it
 * crosses the cap).  We chose growing over blocking the producer because
 * enqueue must never wait on disk I/O (a solver step stalled behind a slow
 * disk would distort its timings), and because those ops are small: past
 * the cap the queue grows by one queue entry (~430 bytes) per
 * store_energy_append, or 112 bytes per sample with store_energy_append_n,
 * so memory stays near the cap unless the disk stops for good, which the
 * log shows.
 *
 * Reads.  Readers never use the write connection: each read takes a
 * read-only connection from a small pool (opening one if the pool is
 * empty), runs its statements - in one read transaction when there are
 * several - and puts it back.  A connection is used by one thread at a time
 * (SQLITE_OPEN_NOMUTEX), and in WAL mode readers neither block nor are
 * blocked by the writer; they see committed data only.
 *
 * Open.  store_open: flock(<path>.lock) (non-blocking; one daemon per
 * database), then WAL, busy_timeout, foreign keys, schema migrations (the
 * table of steps `migrations[]`, the pending ones applied in order in one
 * transaction, the version recorded in PRAGMA user_version), crash
 * recovery (runs left 'running' or 'queued' become 'interrupted'; queued
 * ones too, because the daemon's job queue lives in memory and nothing would
 * ever start them; steps and final energies become those of the run's last
 * energy sample), the next run id, and the writer thread.
 */
#define _GNU_SOURCE
#include "store.h"

#include <sqlite3.h>

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <time.h>
#include <unistd.h>

#define STORE_APP_ID 0x6d706d64            /* "mpmd" in PRAGMA application_id */
#define DEFAULT_BATCH_MS 50.0
#define DEFAULT_BATCH_OPS 1024
#define DEFAULT_QUEUE_CAP ((size_t)64 << 20)
#define DEFAULT_BUSY_MS 5000
#define READER_POOL_MAX 8                  /* idle read connections kept */
#define BEGIN_RETRIES 3

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
};

_Static_assert(sizeof migrations / sizeof migrations[0] == STORE_SCHEMA_VERSION,
               "one migration step per schema version");

/* ---------------------------------------------------------------------- */
/* Queue entries */

typedef enum {
    OP_RUN_INSERT,
    OP_RUN_STATUS,
    OP_RUN_PROGRESS,
    OP_RUN_FINISH,
    OP_ENERGY,
    OP_SNAPSHOT
} op_kind;

typedef struct op {
    struct op *next;
    op_kind kind;
    uint64_t seq;        /* enqueue number */
    double t_enq;        /* monotonic time of enqueue */
    size_t bytes;        /* size of this allocation (queue accounting) */
    union {
        store_run run;                                   /* RUN_INSERT */
        struct { int64_t id; store_status status; double at;
                 const char *error; } st;                /* RUN_STATUS */
        struct { int64_t id, steps; double wall, rate; } prog;
        struct { int64_t id; store_run_end end; } fin;   /* RUN_FINISH */
        struct { size_t n; store_energy_sample *v; } en; /* ENERGY */
        store_snapshot snap;                             /* SNAPSHOT */
    } u;
    /* copies of strings / blobs / samples follow, at OP_HDR */
} op;

#define OP_ALIGN 16
#define OP_HDR ((sizeof(op) + OP_ALIGN - 1) / OP_ALIGN * OP_ALIGN)

/* Prepared statements of the writer connection. */
enum {
    WS_BEGIN, WS_COMMIT, WS_ROLLBACK, WS_INS_RUN, WS_UPD_STATUS,
    WS_UPD_PROGRESS, WS_FINISH, WS_INS_ENERGY, WS_PUT_SNAP, WS_GET_STATUS,
    WS_COUNT
};

/* Updates of a run apply only while it has not ended: a terminal status
 * is final (a late "running" cannot overwrite "cancelled"). */
#define NOT_ENDED " AND status IN ('queued','running')"

static const char *const writer_sql[WS_COUNT] = {
    [WS_BEGIN] = "BEGIN IMMEDIATE",
    [WS_COMMIT] = "COMMIT",
    [WS_ROLLBACK] = "ROLLBACK",
    [WS_INS_RUN] =
        "INSERT INTO runs (id, name, case_pb, case_hash, method, update_scheme,"
        " dim, particles, nodes, status, submitted_at, started_at, ended_at,"
        " steps_done, wall_s, psteps_per_s, error, server_version)"
        " VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14,"
        " ?15, ?16, ?17, ?18)",
    [WS_UPD_STATUS] =
        "UPDATE runs SET status = ?2,"
        " started_at = CASE WHEN ?2 = 'running' THEN ?3 ELSE started_at END,"
        " ended_at = CASE WHEN ?2 IN ('finished','failed','cancelled',"
        "   'interrupted') THEN ?3 ELSE ended_at END,"
        " error = COALESCE(?4, error)"
        " WHERE id = ?1" NOT_ENDED,
    [WS_UPD_PROGRESS] =
        "UPDATE runs SET steps_done = ?2, wall_s = ?3, psteps_per_s = ?4"
        " WHERE id = ?1" NOT_ENDED,
    [WS_FINISH] =
        "UPDATE runs SET status = ?2, ended_at = ?3, steps_done = ?4,"
        " wall_s = ?5, psteps_per_s = ?6, kinetic = ?7, strain = ?8,"
        " potential = ?9, external_work = ?10, total = ?11, error = ?12"
        " WHERE id = ?1" NOT_ENDED,
    [WS_INS_ENERGY] =
        "INSERT INTO energy (run_id, seq, step, t, kinetic, strain, potential,"
        " external_work, total, momentum_x, momentum_y, momentum_z, mass)"
        " VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13)",
    [WS_PUT_SNAP] =
        "INSERT OR REPLACE INTO snapshots (run_id, step, t, n, dim, fields, data)"
        " VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
    [WS_GET_STATUS] = "SELECT status FROM runs WHERE id = ?1",
};

struct store {
    char *path;
    char *lock_path;
    int lock_fd;

    /* options */
    double batch_s;
    size_t batch_ops;
    size_t cap;
    int busy_ms;
    store_log_fn log;
    void *log_ud;

    /* writer connection: used by store_open, then only by the writer */
    sqlite3 *wdb;
    sqlite3_stmt *ws[WS_COUNT];

    /* queue and writer state, under mu */
    pthread_mutex_t mu;
    pthread_cond_t cv_work;      /* writer waits: work, flush, stop */
    pthread_cond_t cv_done;      /* flushers wait: done_seq advanced */
    int sync_ready;
    pthread_t writer;
    int writer_running;
    op *head, *tail;
    size_t qops;                 /* ops in the queue (not yet taken) */
    size_t qbytes;               /* bytes of ops not yet committed */
    size_t qbytes_max;
    uint64_t enq_seq, done_seq, flush_target;
    int stopping;
    int over_cap;                /* logged that the queue passed the cap */
    int64_t next_id;
    uint64_t ops_committed, transactions, write_errors, unreported;
    uint64_t snapshots_dropped;
    char last_werr[512];
    int64_t rec_running, rec_queued;

    /* idle read connections, under pool_mu */
    pthread_mutex_t pool_mu;
    sqlite3 *pool[READER_POOL_MAX];
    int npool;
};

/* ---------------------------------------------------------------------- */
/* Errors, logging, time */

static _Thread_local char tl_err[512];

__attribute__((format(printf, 2, 3)))
static int fail(int code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(tl_err, sizeof tl_err, fmt, ap);
    va_end(ap);
    return code;
}

/* STORE_ESQL with "what: sqlite message" (or STORE_ENOMEM for SQLITE_NOMEM). */
static int sql_fail(sqlite3 *db, int rc, const char *what)
{
    const char *msg = db ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
    if (db && sqlite3_errcode(db) == SQLITE_OK)
        msg = sqlite3_errstr(rc);
    return fail((rc & 0xff) == SQLITE_NOMEM ? STORE_ENOMEM : STORE_ESQL,
                "%s: %s", what, msg);
}

const char *store_errmsg(void) { return tl_err; }

static void default_log(void *ud, const char *msg)
{
    (void)ud;
    fprintf(stderr, "mpmd store: %s\n", msg);
}

__attribute__((format(printf, 2, 3)))
static void slog(store *s, const char *fmt, ...)
{
    char buf[768];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    s->log(s->log_ud, buf);
}

static double mono_now(void)
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

static struct timespec to_timespec(double t)
{
    struct timespec ts;
    if (t < 0) t = 0;
    ts.tv_sec = (time_t)t;
    ts.tv_nsec = (long)((t - (double)ts.tv_sec) * 1e9);
    if (ts.tv_nsec >= 1000000000L) { ts.tv_sec++; ts.tv_nsec -= 1000000000L; }
    if (ts.tv_nsec < 0) ts.tv_nsec = 0;
    return ts;
}

const char *store_strerror(int code)
{
    switch (code) {
    case STORE_OK: return "ok";
    case STORE_EINVAL: return "invalid argument";
    case STORE_ENOMEM: return "out of memory";
    case STORE_ESQL: return "database error";
    case STORE_EIO: return "file-system error";
    case STORE_ELOCKED: return "database in use by another mpmd";
    case STORE_ESCHEMA: return "not an mpmd database or newer schema";
    case STORE_ENOTFOUND: return "not found";
    case STORE_EFULL: return "write queue full, snapshot dropped";
    case STORE_ECLOSED: return "store closing";
    case STORE_EWRITE: return "an asynchronous write failed";
    default: return "unknown store error";
    }
}

/* ---------------------------------------------------------------------- */
/* Names of enums */

static const char *const status_names[STORE_NSTATUS] = {
    "queued", "running", "finished", "failed", "cancelled", "interrupted"
};
static const char *const method_names[] = { "mpm", "gimp" };
static const char *const update_names[] = { "usf", "usl", "musl" };

static int status_ok(store_status st) { return (unsigned)st < STORE_NSTATUS; }
static int method_ok(store_method m) { return (unsigned)m < 2; }
static int update_ok(store_update u) { return (unsigned)u < 3; }

const char *store_status_name(store_status st)
{
    return status_ok(st) ? status_names[st] : "?";
}
const char *store_method_name(store_method m)
{
    return method_ok(m) ? method_names[m] : "?";
}
const char *store_sqlite_version(void)
{
    return sqlite3_libversion();
}

const char *store_update_name(store_update u)
{
    return update_ok(u) ? update_names[u] : "?";
}

int store_status_parse(const char *name, store_status *st)
{
    for (int i = 0; name && i < STORE_NSTATUS; i++)
        if (!strcmp(name, status_names[i])) { *st = (store_status)i; return 0; }
    return fail(STORE_EINVAL, "unknown run status '%s'", name ? name : "(null)");
}

static int parse_name(const char *name, const char *const *names, int n)
{
    for (int i = 0; name && i < n; i++)
        if (!strcmp(name, names[i])) return i;
    return -1;
}

/* ---------------------------------------------------------------------- */
/* SHA-256 (FIPS 180-4) */

typedef struct {
    uint32_t h[8];
    uint64_t len;        /* bytes hashed */
    unsigned char buf[64];
    size_t nbuf;
} sha256_ctx;

static const uint32_t sha256_k[64] = {
    0x428a2f98, 0x71374491, 0xb5c0fbcf, 0xe9b5dba5, 0x3956c25b, 0x59f111f1,
    0x923f82a4, 0xab1c5ed5, 0xd807aa98, 0x12835b01, 0x243185be, 0x550c7dc3,
    0x72be5d74, 0x80deb1fe, 0x9bdc06a7, 0xc19bf174, 0xe49b69c1, 0xefbe4786,
    0x0fc19dc6, 0x240ca1cc, 0x2de92c6f, 0x4a7484aa, 0x5cb0a9dc, 0x76f988da,
    0x983e5152, 0xa831c66d, 0xb00327c8, 0xbf597fc7, 0xc6e00bf3, 0xd5a79147,
    0x06ca6351, 0x14292967, 0x27b70a85, 0x2e1b2138, 0x4d2c6dfc, 0x53380d13,
    0x650a7354, 0x766a0abb, 0x81c2c92e, 0x92722c85, 0xa2bfe8a1, 0xa81a664b,
    0xc24b8b70, 0xc76c51a3, 0xd192e819, 0xd6990624, 0xf40e3585, 0x106aa070,
    0x19a4c116, 0x1e376c08, 0x2748774c, 0x34b0bcb5, 0x391c0cb3, 0x4ed8aa4a,
    0x5b9cca4f, 0x682e6ff3, 0x748f82ee, 0x78a5636f, 0x84c87814, 0x8cc70208,
    0x90befffa, 0xa4506ceb, 0xbef9a3f7, 0xc67178f2
};

static uint32_t ror32(uint32_t x, unsigned n) { return (x >> n) | (x << (32 - n)); }

static void sha256_block(sha256_ctx *c, const unsigned char *p)
{
    uint32_t w[64], a, b, cc, d, e, f, g, h;
    for (int i = 0; i < 16; i++)
        w[i] = (uint32_t)p[4 * i] << 24 | (uint32_t)p[4 * i + 1] << 16 |
               (uint32_t)p[4 * i + 2] << 8 | (uint32_t)p[4 * i + 3];
    for (int i = 16; i < 64; i++) {
        uint32_t s0 = ror32(w[i - 15], 7) ^ ror32(w[i - 15], 18) ^ (w[i - 15] >> 3);
        uint32_t s1 = ror32(w[i - 2], 17) ^ ror32(w[i - 2], 19) ^ (w[i - 2] >> 10);
        w[i] = w[i - 16] + s0 + w[i - 7] + s1;
    }
    a = c->h[0]; b = c->h[1]; cc = c->h[2]; d = c->h[3];
    e = c->h[4]; f = c->h[5]; g = c->h[6]; h = c->h[7];
    for (int i = 0; i < 64; i++) {
        uint32_t S1 = ror32(e, 6) ^ ror32(e, 11) ^ ror32(e, 25);
        uint32_t ch = (e & f) ^ (~e & g);
        uint32_t t1 = h + S1 + ch + sha256_k[i] + w[i];
        uint32_t S0 = ror32(a, 2) ^ ror32(a, 13) ^ ror32(a, 22);
        uint32_t maj = (a & b) ^ (a & cc) ^ (b & cc);
        uint32_t t2 = S0 + maj;
        h = g; g = f; f = e; e = d + t1;
        d = cc; cc = b; b = a; a = t1 + t2;
    }
    c->h[0] += a; c->h[1] += b; c->h[2] += cc; c->h[3] += d;
    c->h[4] += e; c->h[5] += f; c->h[6] += g; c->h[7] += h;
}

static void sha256_init(sha256_ctx *c)
{
    static const uint32_t h0[8] = {
        0x6a09e667, 0xbb67ae85, 0x3c6ef372, 0xa54ff53a,
        0x510e527f, 0x9b05688c, 0x1f83d9ab, 0x5be0cd19
    };
    memcpy(c->h, h0, sizeof h0);
    c->len = 0;
    c->nbuf = 0;
}

static void sha256_update(sha256_ctx *c, const unsigned char *p, size_t n)
{
    c->len += n;
    if (c->nbuf) {
        size_t k = 64 - c->nbuf < n ? 64 - c->nbuf : n;
        memcpy(c->buf + c->nbuf, p, k);
        c->nbuf += k; p += k; n -= k;
        if (c->nbuf < 64) return;
        sha256_block(c, c->buf);
        c->nbuf = 0;
    }
    for (; n >= 64; p += 64, n -= 64) sha256_block(c, p);
    memcpy(c->buf, p, n);
    c->nbuf = n;
}

static void sha256_final(sha256_ctx *c, unsigned char out[32])
{
    uint64_t bits = c->len * 8;
    unsigned char pad[72] = { 0x80 };
    size_t npad = (c->nbuf < 56 ? 56 : 120) - c->nbuf;
    for (int i = 0; i < 8; i++) pad[npad + i] = (unsigned char)(bits >> (56 - 8 * i));
    sha256_update(c, pad, npad + 8);
    for (int i = 0; i < 8; i++) {
        out[4 * i] = (unsigned char)(c->h[i] >> 24);
        out[4 * i + 1] = (unsigned char)(c->h[i] >> 16);
        out[4 * i + 2] = (unsigned char)(c->h[i] >> 8);
        out[4 * i + 3] = (unsigned char)c->h[i];
    }
}

void store_sha256_hex(const void *data, size_t len, char out[65])
{
    static const char hex[] = "0123456789abcdef";
    sha256_ctx c;
    unsigned char d[32];
    sha256_init(&c);
    if (len) sha256_update(&c, data, len);
    sha256_final(&c, d);
    for (int i = 0; i < 32; i++) {
        out[2 * i] = hex[d[i] >> 4];
        out[2 * i + 1] = hex[d[i] & 15];
    }
    out[64] = 0;
}

/* ---------------------------------------------------------------------- */
/* SQLite helpers */

/* Runs one or more statements with no results. */
static int db_exec(sqlite3 *db, const char *sql, const char *what)
{
    char *msg = NULL;
    int rc = sqlite3_exec(db, sql, NULL, NULL, &msg);
    if (rc != SQLITE_OK) {
        int code = (rc & 0xff) == SQLITE_NOMEM ? STORE_ENOMEM : STORE_ESQL;
        fail(code, "%s: %s", what, msg ? msg : sqlite3_errstr(rc));
        sqlite3_free(msg);
        return code;
    }
    return 0;
}

/* Runs a query returning one integer (or text into txt if not NULL). */
static int db_query1(sqlite3 *db, const char *sql, int64_t *v, char *txt,
                     size_t txtlen)
{
    sqlite3_stmt *st = NULL;
    int rc = sqlite3_prepare_v2(db, sql, -1, &st, NULL);
    if (rc != SQLITE_OK) return sql_fail(db, rc, sql);
    rc = sqlite3_step(st);
    if (rc != SQLITE_ROW) {
        int r = rc == SQLITE_DONE ? fail(STORE_ESQL, "%s: no result", sql)
                                  : sql_fail(db, rc, sql);
        sqlite3_finalize(st);   /* returns the step's error, reported above */
        return r;
    }
    if (v) *v = sqlite3_column_int64(st, 0);
    if (txt) {
        const unsigned char *t = sqlite3_column_text(st, 0);
        snprintf(txt, txtlen, "%s", t ? (const char *)t : "");
    }
    rc = sqlite3_finalize(st);
    if (rc != SQLITE_OK) return sql_fail(db, rc, sql);
    return 0;
}

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
    if (!t) return sql_fail(db, sqlite3_errcode(db), "reading a text column");
    size_t n = (size_t)sqlite3_column_bytes(st, i);
    char *p = malloc(n + 1);
    if (!p) return fail(STORE_ENOMEM, "out of memory reading a text column");
    memcpy(p, t, n);
    p[n] = 0;
    *out = p;
    return 0;
}

/* Copies a blob column into new memory (NULL when empty). */
static int col_blobdup(sqlite3 *db, sqlite3_stmt *st, int i, const void **out,
                       size_t *len)
{
    *out = NULL;
    *len = 0;
    const void *b = sqlite3_column_blob(st, i);
    size_t n = (size_t)sqlite3_column_bytes(st, i);
    if (!n) return 0;
    if (!b) return sql_fail(db, sqlite3_errcode(db), "reading a blob column");
    void *p = malloc(n);
    if (!p) return fail(STORE_ENOMEM, "out of memory reading %zu bytes", n);
    memcpy(p, b, n);
    *out = p;
    *len = n;
    return 0;
}

/* ---------------------------------------------------------------------- */
/* Lock file: one daemon per database */

static int lock_acquire(store *s)
{
    int fd = open(s->lock_path, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0)
        return fail(STORE_EIO, "cannot open lock file %s: %s", s->lock_path,
                    strerror(errno));
    if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
        int e = errno;
        if (e == EWOULDBLOCK) {
            char buf[32] = { 0 };
            ssize_t n = pread(fd, buf, sizeof buf - 1, 0);
            long pid = 0;
            char *end = NULL;
            if (n > 0) pid = strtol(buf, &end, 10);
            close(fd);
            if (n > 0 && end != buf && pid > 0)
                return fail(STORE_ELOCKED, "database %s is in use by another mpmd (pid %ld)",
                            s->path, pid);
            return fail(STORE_ELOCKED, "database %s is in use by another mpmd (pid unknown)",
                        s->path);
        }
        close(fd);
        return fail(STORE_EIO, "cannot lock %s: %s", s->lock_path, strerror(e));
    }
    char pid[32];
    int n = snprintf(pid, sizeof pid, "%ld\n", (long)getpid());
    if (ftruncate(fd, 0) != 0 || pwrite(fd, pid, (size_t)n, 0) != n) {
        int e = errno;
        close(fd);
        return fail(STORE_EIO, "cannot write pid into %s: %s", s->lock_path, strerror(e));
    }
    s->lock_fd = fd;
    return 0;
}

static void lock_release(store *s)
{
    if (s->lock_fd < 0) return;
    /* empty the pid before the lock goes; the file stays (unlinking a lock
     * file races with a process that has just opened it) */
    if (ftruncate(s->lock_fd, 0) != 0)
        slog(s, "cannot truncate %s: %s", s->lock_path, strerror(errno));
    close(s->lock_fd);        /* releases the flock */
    s->lock_fd = -1;
}

/* ---------------------------------------------------------------------- */
/* Connections */

static void close_db(store *s, sqlite3 *db)
{
    int rc = sqlite3_close(db);
    if (rc != SQLITE_OK) slog(s, "closing a connection: %s", sqlite3_errstr(rc));
}

static int conn_setup(sqlite3 *db, int busy_ms)
{
    int rc = sqlite3_extended_result_codes(db, 1);
    if (rc != SQLITE_OK) return sql_fail(db, rc, "extended result codes");
    rc = sqlite3_busy_timeout(db, busy_ms);
    if (rc != SQLITE_OK) return sql_fail(db, rc, "busy_timeout");
    return db_exec(db, "PRAGMA foreign_keys = ON", "enabling foreign keys");
}

static int open_writer(store *s)
{
    int rc = sqlite3_open_v2(s->path, &s->wdb,
                             SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE |
                             SQLITE_OPEN_NOMUTEX, NULL);
    if (rc != SQLITE_OK) {
        int r = fail(STORE_ESQL, "cannot open database %s: %s", s->path,
                     s->wdb ? sqlite3_errmsg(s->wdb) : sqlite3_errstr(rc));
        if (s->wdb) close_db(s, s->wdb);
        s->wdb = NULL;
        return r;
    }
    int r = conn_setup(s->wdb, s->busy_ms);
    if (r) return r;
    char mode[16];
    r = db_query1(s->wdb, "PRAGMA journal_mode = WAL", NULL, mode, sizeof mode);
    if (r) {
        /* e.g. "file is not a database": name the file */
        char m[sizeof tl_err];
        snprintf(m, sizeof m, "%s", tl_err);
        return fail(r, "database %s: %s", s->path, m);
    }
    if (strcmp(mode, "wal"))
        return fail(STORE_ESQL, "database %s: cannot enable WAL journal mode (got '%s')",
                    s->path, mode);
    r = db_exec(s->wdb, "PRAGMA synchronous = NORMAL", "synchronous");
    if (r) return r;
    int64_t fk = 0;
    r = db_query1(s->wdb, "PRAGMA foreign_keys", &fk, NULL, 0);
    if (r) return r;
    if (fk != 1) return fail(STORE_ESQL, "this SQLite does not enforce foreign keys");
    return 0;
}

static int open_reader(store *s, sqlite3 **out)
{
    sqlite3 *db = NULL;
    *out = NULL;
    int rc = sqlite3_open_v2(s->path, &db, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX, NULL);
    if (rc != SQLITE_OK) {
        int r = fail(STORE_ESQL, "cannot open database %s for reading: %s", s->path,
                     db ? sqlite3_errmsg(db) : sqlite3_errstr(rc));
        if (db) close_db(s, db);
        return r;
    }
    int r = conn_setup(db, s->busy_ms);
    if (!r) r = db_exec(db, "PRAGMA query_only = ON", "query_only");
    if (r) {
        close_db(s, db);
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
        if (db_exec(db, "ROLLBACK", "rollback") != 0) {
            close_db(s, db);
            return;
        }
    }
    pthread_mutex_lock(&s->pool_mu);
    if (s->npool < READER_POOL_MAX) {
        s->pool[s->npool++] = db;
        db = NULL;
    }
    pthread_mutex_unlock(&s->pool_mu);
    if (db) close_db(s, db);
}

/* ---------------------------------------------------------------------- */
/* Open: migrations, recovery */

static int migrate(store *s)
{
    sqlite3 *db = s->wdb;
    int64_t uv = 0, appid = 0, ntables = 0;
    int r = db_exec(db, "BEGIN IMMEDIATE", "starting the migration transaction");
    if (r) return r;
    if ((r = db_query1(db, "PRAGMA user_version", &uv, NULL, 0)) ||
        (r = db_query1(db, "PRAGMA application_id", &appid, NULL, 0)) ||
        (r = db_query1(db, "SELECT count(*) FROM sqlite_master", &ntables, NULL, 0)))
        goto rollback;
    if (appid != 0 && appid != STORE_APP_ID) {
        r = fail(STORE_ESCHEMA, "%s is not an mpmd database (application_id 0x%" PRIx64 ")",
                 s->path, (uint64_t)appid);
        goto rollback;
    }
    if (uv == 0 && ntables > 0) {
        r = fail(STORE_ESCHEMA, "%s is not an mpmd database (it has tables but no schema version)",
                 s->path);
        goto rollback;
    }
    if (uv > STORE_SCHEMA_VERSION || uv < 0) {
        r = fail(STORE_ESCHEMA, "database %s has schema version %" PRId64
                 ", newer than this mpmd supports (%d)", s->path, uv, STORE_SCHEMA_VERSION);
        goto rollback;
    }
    for (int64_t v = uv; v < STORE_SCHEMA_VERSION; v++) {
        char what[64], sql[64];
        snprintf(what, sizeof what, "schema migration %" PRId64 " -> %" PRId64, v, v + 1);
        if ((r = db_exec(db, migrations[v], what))) goto rollback;
        snprintf(sql, sizeof sql, "PRAGMA user_version = %" PRId64, v + 1);
        if ((r = db_exec(db, sql, what))) goto rollback;
    }
    if (uv == 0) {
        char sql[64];
        snprintf(sql, sizeof sql, "PRAGMA application_id = %d", STORE_APP_ID);
        if ((r = db_exec(db, sql, "setting application_id"))) goto rollback;
    }
    if ((r = db_exec(db, "COMMIT", "committing the schema migration"))) goto rollback;
    if (uv == 0)
        slog(s, "%s: new database, schema version %d", s->path, STORE_SCHEMA_VERSION);
    else if (uv < STORE_SCHEMA_VERSION)
        slog(s, "%s: schema migrated from version %" PRId64 " to %d", s->path, uv,
             STORE_SCHEMA_VERSION);
    return 0;
rollback:
    if (!sqlite3_get_autocommit(db)) {
        char m[sizeof tl_err];
        snprintf(m, sizeof m, "%s", tl_err);
        if (db_exec(db, "ROLLBACK", "rollback"))
            slog(s, "rollback after a failed migration: %s", tl_err);
        snprintf(tl_err, sizeof tl_err, "%s", m);
    }
    return r;
}

/* Runs `UPDATE ... SET status='interrupted', error=?1 WHERE status=?2`.
 * The steps done and the final energies become those of the run's last
 * stored energy sample: the progress figures in the row lag behind it or
 * run ahead of it by whatever the crash left, while the sample is a
 * consistent state (its step, t and energies belong together, and RunInfo
 * takes t and the last energies from it). */
static int recover_status(store *s, const char *from, const char *error, int64_t *count)
{
    sqlite3_stmt *st = NULL;
#define LAST_SAMPLE(cols) "(SELECT " cols " FROM energy WHERE run_id = runs.id ORDER BY seq DESC LIMIT 1)"
    const char *sql =
        "UPDATE runs SET status = 'interrupted', error = ?1,"
        " steps_done = COALESCE(" LAST_SAMPLE("step") ", steps_done),"
        " (kinetic, strain, potential, external_work, total) ="
        " " LAST_SAMPLE("kinetic, strain, potential, external_work, total")
        " WHERE status = ?2";
#undef LAST_SAMPLE
    int rc = sqlite3_prepare_v2(s->wdb, sql, -1, &st, NULL);
    if (rc != SQLITE_OK) return sql_fail(s->wdb, rc, "crash recovery");
    rc = sqlite3_bind_text(st, 1, error, -1, SQLITE_STATIC);
    if (rc == SQLITE_OK) rc = sqlite3_bind_text(st, 2, from, -1, SQLITE_STATIC);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    int r = rc == SQLITE_DONE ? 0 : sql_fail(s->wdb, rc, "crash recovery");
    *count = sqlite3_changes(s->wdb);
    rc = sqlite3_finalize(st);
    if (!r && rc != SQLITE_OK) r = sql_fail(s->wdb, rc, "crash recovery");
    return r;
}

static int recover(store *s)
{
    int r = db_exec(s->wdb, "BEGIN IMMEDIATE", "crash recovery");
    if (r) return r;
    if ((r = recover_status(s, "running", STORE_INTERRUPTED_RUNNING, &s->rec_running)) ||
        (r = recover_status(s, "queued", STORE_INTERRUPTED_QUEUED, &s->rec_queued)) ||
        (r = db_exec(s->wdb, "COMMIT", "crash recovery"))) {
        if (!sqlite3_get_autocommit(s->wdb)) {
            char m[sizeof tl_err];
            snprintf(m, sizeof m, "%s", tl_err);
            if (db_exec(s->wdb, "ROLLBACK", "rollback"))
                slog(s, "rollback after failed recovery: %s", tl_err);
            snprintf(tl_err, sizeof tl_err, "%s", m);
        }
        return r;
    }
    if (s->rec_running || s->rec_queued)
        slog(s, "%s: marked %" PRId64 " running and %" PRId64
             " queued runs of a previous daemon 'interrupted'",
             s->path, s->rec_running, s->rec_queued);
    return 0;
}

/* ---------------------------------------------------------------------- */
/* The writer thread */

/* Records a failed asynchronous write: logged, counted, reported by flush. */
__attribute__((format(printf, 3, 4)))
static void write_error(store *s, uint64_t nops, const char *fmt, ...)
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
    pthread_mutex_unlock(&s->mu);
    slog(s, "write failed: %s", buf);
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
        snprintf(buf, len, "run %" PRId64 " already ended (%s)", id,
                 t ? (const char *)t : "?");
    } else if (rc == SQLITE_DONE) {
        snprintf(buf, len, "no run %" PRId64, id);
    } else {
        snprintf(buf, len, "run %" PRId64 " not updated (%s)", id, sqlite3_errmsg(s->wdb));
    }
    if (sqlite3_reset(st) != SQLITE_OK || sqlite3_clear_bindings(st) != SQLITE_OK)
        slog(s, "reading the status of run %" PRId64 ": %s", id, sqlite3_errmsg(s->wdb));
}

#define BIND(call) do { if (rc == SQLITE_OK) rc = (call); } while (0)

/* Steps a bound writer statement to completion and resets it.  Returns the
 * SQLite code of the step (SQLITE_DONE on success) or of a failed bind. */
static int ws_run(sqlite3_stmt *st, int bind_rc)
{
    int rc = bind_rc == SQLITE_OK ? sqlite3_step(st) : bind_rc;
    int rrc = sqlite3_reset(st);   /* repeats a step error; else must be OK */
    int crc = sqlite3_clear_bindings(st);
    if (rc == SQLITE_DONE && rrc != SQLITE_OK) rc = rrc;
    if (rc == SQLITE_DONE && crc != SQLITE_OK) rc = crc;
    return rc;
}

/* Applies one op inside the open transaction.  Returns 0, or -1 after
 * recording the error. */
static int apply_op(store *s, op *o)
{
    sqlite3_stmt *st = NULL;
    int rc = SQLITE_OK;
    int64_t id = 0;
    const char *what = "";
    int is_update = 0;

    switch (o->kind) {
    case OP_RUN_INSERT: {
        const store_run *r = &o->u.run;
        st = s->ws[WS_INS_RUN];
        id = r->id;
        what = "insert run";
        BIND(sqlite3_bind_int64(st, 1, r->id));
        BIND(sqlite3_bind_text(st, 2, r->name, -1, SQLITE_STATIC));
        BIND(bind_blob(st, 3, r->case_pb, r->case_len));
        BIND(sqlite3_bind_text(st, 4, r->case_hash, 64, SQLITE_STATIC));
        BIND(sqlite3_bind_text(st, 5, method_names[r->method], -1, SQLITE_STATIC));
        BIND(sqlite3_bind_text(st, 6, update_names[r->update], -1, SQLITE_STATIC));
        BIND(sqlite3_bind_int(st, 7, r->dim));
        BIND(sqlite3_bind_int64(st, 8, r->particles));
        BIND(sqlite3_bind_int64(st, 9, r->nodes));
        BIND(sqlite3_bind_text(st, 10, status_names[r->status], -1, SQLITE_STATIC));
        BIND(sqlite3_bind_double(st, 11, r->submitted_at));
        BIND(bind_time(st, 12, r->started_at));
        BIND(bind_time(st, 13, r->ended_at));
        BIND(sqlite3_bind_int64(st, 14, r->steps_done));
        BIND(bind_real(st, 15, r->wall_s));
        BIND(bind_real(st, 16, r->psteps_per_s));
        BIND(bind_text_or_null(st, 17, r->error));
        BIND(sqlite3_bind_text(st, 18, r->server_version, -1, SQLITE_STATIC));
        break;
    }
    case OP_RUN_STATUS:
        st = s->ws[WS_UPD_STATUS];
        id = o->u.st.id;
        what = "update run status";
        is_update = 1;
        BIND(sqlite3_bind_int64(st, 1, id));
        BIND(sqlite3_bind_text(st, 2, status_names[o->u.st.status], -1, SQLITE_STATIC));
        BIND(bind_time(st, 3, o->u.st.at));
        BIND(bind_text_or_null(st, 4, o->u.st.error));
        break;
    case OP_RUN_PROGRESS:
        st = s->ws[WS_UPD_PROGRESS];
        id = o->u.prog.id;
        what = "update run progress";
        is_update = 1;
        BIND(sqlite3_bind_int64(st, 1, id));
        BIND(sqlite3_bind_int64(st, 2, o->u.prog.steps));
        BIND(bind_real(st, 3, o->u.prog.wall));
        BIND(bind_real(st, 4, o->u.prog.rate));
        break;
    case OP_RUN_FINISH: {
        const store_run_end *e = &o->u.fin.end;
        st = s->ws[WS_FINISH];
        id = o->u.fin.id;
        what = "finish run";
        is_update = 1;
        BIND(sqlite3_bind_int64(st, 1, id));
        BIND(sqlite3_bind_text(st, 2, status_names[e->status], -1, SQLITE_STATIC));
        BIND(bind_time(st, 3, e->ended_at));
        BIND(sqlite3_bind_int64(st, 4, e->steps_done));
        BIND(bind_real(st, 5, e->wall_s));
        BIND(bind_real(st, 6, e->psteps_per_s));
        BIND(bind_real(st, 7, e->has_energy ? e->energy.kinetic : NAN));
        BIND(bind_real(st, 8, e->has_energy ? e->energy.strain : NAN));
        BIND(bind_real(st, 9, e->has_energy ? e->energy.potential : NAN));
        BIND(bind_real(st, 10, e->has_energy ? e->energy.external_work : NAN));
        BIND(bind_real(st, 11, e->has_energy ? e->energy.total : NAN));
        BIND(bind_text_or_null(st, 12, e->error));
        break;
    }
    case OP_ENERGY: {
        st = s->ws[WS_INS_ENERGY];
        what = "append energy sample";
        size_t bad = 0;
        char msg[256] = "";
        for (size_t i = 0; i < o->u.en.n; i++) {
            const store_energy_sample *e = &o->u.en.v[i];
            rc = SQLITE_OK;
            BIND(sqlite3_bind_int64(st, 1, e->run_id));
            BIND(sqlite3_bind_int64(st, 2, e->seq));
            BIND(sqlite3_bind_int64(st, 3, e->step));
            BIND(bind_real(st, 4, e->t));
            BIND(bind_real(st, 5, e->kinetic));
            BIND(bind_real(st, 6, e->strain));
            BIND(bind_real(st, 7, e->potential));
            BIND(bind_real(st, 8, e->external_work));
            BIND(bind_real(st, 9, e->total));
            BIND(bind_real(st, 10, e->momentum[0]));
            BIND(bind_real(st, 11, e->momentum[1]));
            BIND(bind_real(st, 12, e->momentum[2]));
            BIND(bind_real(st, 13, e->mass));
            rc = ws_run(st, rc);
            if (rc != SQLITE_DONE) {
                if (!bad++)
                    snprintf(msg, sizeof msg, "run %" PRId64 " seq %" PRId64 ": %s",
                             e->run_id, e->seq, sqlite3_errmsg(s->wdb));
                if (sqlite3_get_autocommit(s->wdb)) break;   /* txn gone */
            }
        }
        if (bad) {
            write_error(s, bad, "%s: %zu of %zu samples failed; first: %s", what, bad,
                        o->u.en.n, msg);
            return -1;
        }
        return 0;
    }
    case OP_SNAPSHOT: {
        const store_snapshot *sn = &o->u.snap;
        st = s->ws[WS_PUT_SNAP];
        id = sn->run_id;
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
    default:
        write_error(s, 1, "unknown queue entry kind %d", (int)o->kind);
        return -1;
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

static int ws_simple(store *s, int which)
{
    int rc = ws_run(s->ws[which], SQLITE_OK);
    return rc == SQLITE_DONE ? SQLITE_OK : rc;
}

/* Applies a batch of n ops in one transaction; records every failure. */
static void apply_batch(store *s, op *batch, size_t n)
{
    uint64_t failed = 0;
    int rc;
    for (int attempt = 0;; attempt++) {
        rc = ws_simple(s, WS_BEGIN);
        if (rc == SQLITE_OK) break;
        if ((rc & 0xff) == SQLITE_BUSY && attempt < BEGIN_RETRIES) {
            slog(s, "database busy, retrying a batch of %zu writes", n);
            struct timespec ts = { 0, 100 * 1000 * 1000 };
            nanosleep(&ts, NULL);
            continue;
        }
        write_error(s, n, "BEGIN: %s; %zu writes lost", sqlite3_errmsg(s->wdb), n);
        return;
    }
    for (op *o = batch; o; o = o->next) {
        if (apply_op(s, o) == 0) continue;
        failed++;
        if (sqlite3_get_autocommit(s->wdb)) {
            /* SQLite rolled the whole transaction back (disk full, I/O) */
            write_error(s, n - failed, "transaction rolled back (%s); %zu more writes lost",
                        sqlite3_errmsg(s->wdb), (size_t)(n - failed));
            return;
        }
    }
    rc = ws_simple(s, WS_COMMIT);
    if (rc != SQLITE_OK) {
        write_error(s, n - failed, "COMMIT: %s; %zu writes lost", sqlite3_errmsg(s->wdb),
                    (size_t)(n - failed));
        if (!sqlite3_get_autocommit(s->wdb) && ws_simple(s, WS_ROLLBACK) != SQLITE_OK)
            slog(s, "ROLLBACK: %s", sqlite3_errmsg(s->wdb));
        return;
    }
    pthread_mutex_lock(&s->mu);
    s->transactions++;
    s->ops_committed += n - failed;
    pthread_mutex_unlock(&s->mu);
}

static void *writer_main(void *arg)
{
    store *s = arg;
    pthread_mutex_lock(&s->mu);
    for (;;) {
        while (!s->head && !s->stopping)
            pthread_cond_wait(&s->cv_work, &s->mu);
        if (!s->head) break;                     /* stopping, queue drained */
        /* batching window: until the oldest op is batch_s old */
        struct timespec dl = to_timespec(s->head->t_enq + s->batch_s);
        while (!s->stopping && s->flush_target <= s->done_seq &&
               s->qops < s->batch_ops) {
            if (pthread_cond_timedwait(&s->cv_work, &s->mu, &dl) == ETIMEDOUT) break;
        }
        op *batch = s->head, *last = batch;
        size_t n = 1, bytes = batch->bytes;
        while (last->next && n < s->batch_ops) {
            last = last->next;
            n++;
            bytes += last->bytes;
        }
        s->head = last->next;
        if (!s->head) s->tail = NULL;
        last->next = NULL;
        s->qops -= n;
        uint64_t last_seq = last->seq;
        pthread_mutex_unlock(&s->mu);

        apply_batch(s, batch, n);
        while (batch) {
            op *next = batch->next;
            free(batch);
            batch = next;
        }

        pthread_mutex_lock(&s->mu);
        s->qbytes -= bytes;
        if (s->over_cap && s->qbytes <= s->cap / 2) s->over_cap = 0;
        s->done_seq = last_seq;
        pthread_cond_broadcast(&s->cv_done);
    }
    pthread_mutex_unlock(&s->mu);
    return NULL;
}

/* ---------------------------------------------------------------------- */
/* Enqueueing */

/* Allocates an op with tail bytes of room after the header. */
static op *op_new(op_kind kind, size_t tail, char **tailp)
{
    size_t bytes = OP_HDR + tail;
    op *o = calloc(1, bytes);
    if (!o) {
        fail(STORE_ENOMEM, "out of memory queueing a write (%zu bytes)", bytes);
        return NULL;
    }
    o->kind = kind;
    o->bytes = bytes;
    *tailp = (char *)o + OP_HDR;
    return o;
}

/* Copies n bytes at *cur, advancing it; returns the copy. */
static void *tail_put(char **cur, const void *src, size_t n)
{
    void *p = *cur;
    if (n) memcpy(p, src, n);
    *cur += n;
    return p;
}

static const char *tail_str(char **cur, const char *str)
{
    return str ? tail_put(cur, str, strlen(str) + 1) : NULL;
}

static size_t str_room(const char *str) { return str ? strlen(str) + 1 : 0; }

/* Refuses a snapshot because the queue is above its cap: counts and logs. */
static int drop_snapshot(store *s, const store_snapshot *snap, size_t qb)
{
    slog(s, "snapshot of run %" PRId64 " at step %" PRId64 " (%zu bytes) dropped:"
         " %zu bytes of writes pending, cap %zu", snap->run_id, snap->step,
         snap->size, qb, s->cap);
    return fail(STORE_EFULL, "snapshot of run %" PRId64 " at step %" PRId64
                " dropped: write queue full (%zu bytes pending, cap %zu)",
                snap->run_id, snap->step, qb, s->cap);
}

/* Appends an op to the queue.  droppable: a snapshot, refused above the
 * cap.  Takes ownership of o in every case. */
static int submit(store *s, op *o, int droppable)
{
    int log_cap = 0;
    size_t qb;
    pthread_mutex_lock(&s->mu);
    if (s->stopping) {
        pthread_mutex_unlock(&s->mu);
        free(o);
        return fail(STORE_ECLOSED, "the store is closing");
    }
    if (droppable && s->qbytes + o->bytes > s->cap) {
        s->snapshots_dropped++;
        qb = s->qbytes;
        pthread_mutex_unlock(&s->mu);
        int r = drop_snapshot(s, &o->u.snap, qb);
        free(o);
        return r;
    }
    o->seq = ++s->enq_seq;
    o->t_enq = mono_now();
    o->next = NULL;
    int was_empty = !s->head;
    if (s->tail) s->tail->next = o;
    else s->head = o;
    s->tail = o;
    s->qops++;
    s->qbytes += o->bytes;
    if (s->qbytes > s->qbytes_max) s->qbytes_max = s->qbytes;
    if (s->qbytes > s->cap && !s->over_cap) {
        s->over_cap = 1;
        log_cap = 1;
    }
    qb = s->qbytes;
    /* the writer sleeps untimed on an empty queue, timed in a batching
     * window: wake it for the first op and when a batch is full */
    if (was_empty || s->qops == s->batch_ops) pthread_cond_signal(&s->cv_work);
    pthread_mutex_unlock(&s->mu);
    if (log_cap)
        slog(s, "write queue above its cap (%zu > %zu bytes): the disk is behind;"
             " growing (only snapshots are dropped)", qb, s->cap);
    return 0;
}

int64_t store_new_run_id(store *s)
{
    pthread_mutex_lock(&s->mu);
    int64_t id = s->next_id++;
    pthread_mutex_unlock(&s->mu);
    return id;
}

int store_run_insert(store *s, const store_run *run, int64_t *id_out)
{
    if (!s || !run) return fail(STORE_EINVAL, "store_run_insert: NULL argument");
    if (run->dim < 1 || run->dim > 3)
        return fail(STORE_EINVAL, "run dim %d not in 1..3", run->dim);
    if (!method_ok(run->method))
        return fail(STORE_EINVAL, "unknown method %d", (int)run->method);
    if (!update_ok(run->update))
        return fail(STORE_EINVAL, "unknown update scheme %d", (int)run->update);
    if (!status_ok(run->status))
        return fail(STORE_EINVAL, "unknown run status %d", (int)run->status);
    if (run->case_len && !run->case_pb)
        return fail(STORE_EINVAL, "case_pb is NULL with case_len %zu", run->case_len);
    if (run->particles < 0 || run->nodes < 0 || run->steps_done < 0)
        return fail(STORE_EINVAL, "negative particles, nodes or steps_done");
    if (isnan(run->submitted_at) || run->submitted_at < 0)
        return fail(STORE_EINVAL, "bad submitted_at");

    const char *name = run->name ? run->name : "";
    const char *ver = run->server_version ? run->server_version : "";
    char *cur;
    op *o = op_new(OP_RUN_INSERT, str_room(name) + str_room(ver) +
                   str_room(run->error) + run->case_len, &cur);
    if (!o) return STORE_ENOMEM;
    store_run *r = &o->u.run;
    *r = *run;
    r->name = tail_str(&cur, name);
    r->server_version = tail_str(&cur, ver);
    r->error = tail_str(&cur, run->error);
    r->case_pb = run->case_len ? tail_put(&cur, run->case_pb, run->case_len) : NULL;
    store_sha256_hex(r->case_pb, r->case_len, r->case_hash);
    if (r->submitted_at == 0) r->submitted_at = store_time_now();

    pthread_mutex_lock(&s->mu);
    if (r->id <= 0) r->id = s->next_id++;
    else if (r->id >= s->next_id) s->next_id = r->id + 1;
    pthread_mutex_unlock(&s->mu);

    int64_t id = r->id;
    int rc = submit(s, o, 0);
    if (!rc && id_out) *id_out = id;
    return rc;
}

int store_run_set_status(store *s, int64_t id, store_status status, double at,
                         const char *error)
{
    if (!s) return fail(STORE_EINVAL, "store_run_set_status: NULL store");
    if (!status_ok(status)) return fail(STORE_EINVAL, "unknown run status %d", (int)status);
    if (isnan(at) || at < 0) return fail(STORE_EINVAL, "bad status time");
    char *cur;
    op *o = op_new(OP_RUN_STATUS, str_room(error), &cur);
    if (!o) return STORE_ENOMEM;
    o->u.st.id = id;
    o->u.st.status = status;
    o->u.st.at = at == 0 ? store_time_now() : at;
    o->u.st.error = tail_str(&cur, error);
    return submit(s, o, 0);
}

int store_run_progress(store *s, int64_t id, int64_t steps_done, double wall_s,
                       double psteps_per_s)
{
    if (!s) return fail(STORE_EINVAL, "store_run_progress: NULL store");
    if (steps_done < 0) return fail(STORE_EINVAL, "negative steps_done");
    char *cur;
    op *o = op_new(OP_RUN_PROGRESS, 0, &cur);
    if (!o) return STORE_ENOMEM;
    o->u.prog.id = id;
    o->u.prog.steps = steps_done;
    o->u.prog.wall = wall_s;
    o->u.prog.rate = psteps_per_s;
    return submit(s, o, 0);
}

int store_run_finish(store *s, int64_t id, const store_run_end *end)
{
    if (!s || !end) return fail(STORE_EINVAL, "store_run_finish: NULL argument");
    if (!status_ok(end->status) || end->status == STORE_QUEUED ||
        end->status == STORE_RUNNING)
        return fail(STORE_EINVAL, "store_run_finish: status '%s' is not a final status",
                    store_status_name(end->status));
    if (end->steps_done < 0) return fail(STORE_EINVAL, "negative steps_done");
    if (isnan(end->ended_at) || end->ended_at < 0) return fail(STORE_EINVAL, "bad ended_at");
    char *cur;
    op *o = op_new(OP_RUN_FINISH, str_room(end->error), &cur);
    if (!o) return STORE_ENOMEM;
    o->u.fin.id = id;
    o->u.fin.end = *end;
    o->u.fin.end.error = tail_str(&cur, end->error);
    if (o->u.fin.end.ended_at == 0) o->u.fin.end.ended_at = store_time_now();
    return submit(s, o, 0);
}

int store_energy_append_n(store *s, const store_energy_sample *e, size_t n)
{
    if (!s || (n && !e)) return fail(STORE_EINVAL, "store_energy_append: NULL argument");
    if (!n) return 0;
    if (n > (SIZE_MAX - OP_HDR) / sizeof *e)
        return fail(STORE_EINVAL, "store_energy_append: %zu samples", n);
    char *cur;
    op *o = op_new(OP_ENERGY, n * sizeof *e, &cur);
    if (!o) return STORE_ENOMEM;
    o->u.en.n = n;
    o->u.en.v = tail_put(&cur, e, n * sizeof *e);
    return submit(s, o, 0);
}

int store_energy_append(store *s, const store_energy_sample *e)
{
    return store_energy_append_n(s, e, 1);
}

int store_snapshot_put(store *s, const store_snapshot *snap)
{
    if (!s || !snap) return fail(STORE_EINVAL, "store_snapshot_put: NULL argument");
    if (snap->size && !snap->data)
        return fail(STORE_EINVAL, "snapshot data is NULL with size %zu", snap->size);
    if (snap->dim < 1 || snap->dim > 3)
        return fail(STORE_EINVAL, "snapshot dim %d not in 1..3", snap->dim);
    if (snap->n < 0 || snap->step < 0)
        return fail(STORE_EINVAL, "negative snapshot step or particle count");
    if (snap->size > SIZE_MAX - OP_HDR)
        return fail(STORE_EINVAL, "snapshot of %zu bytes", snap->size);
    /* refuse before copying a big blob; submit() checks again under the
     * same lock that enqueues */
    pthread_mutex_lock(&s->mu);
    size_t qb = s->qbytes;
    int full = qb + OP_HDR + snap->size > s->cap;
    if (full) s->snapshots_dropped++;
    pthread_mutex_unlock(&s->mu);
    if (full) return drop_snapshot(s, snap, qb);
    char *cur;
    op *o = op_new(OP_SNAPSHOT, snap->size, &cur);
    if (!o) return STORE_ENOMEM;
    o->u.snap = *snap;
    o->u.snap.data = snap->size ? tail_put(&cur, snap->data, snap->size) : NULL;
    return submit(s, o, 1);
}

int store_flush(store *s)
{
    if (!s) return fail(STORE_EINVAL, "store_flush: NULL store");
    pthread_mutex_lock(&s->mu);
    uint64_t target = s->enq_seq;
    if (target > s->flush_target) s->flush_target = target;
    pthread_cond_signal(&s->cv_work);
    while (s->done_seq < target)
        pthread_cond_wait(&s->cv_done, &s->mu);
    int rc = 0;
    if (s->unreported) {
        rc = fail(STORE_EWRITE, "%" PRIu64 " asynchronous write(s) failed; last: %s",
                  s->unreported, s->last_werr);
        s->unreported = 0;
    }
    pthread_mutex_unlock(&s->mu);
    return rc;
}

/* ---------------------------------------------------------------------- */
/* Reads */

#define RUN_COLS                                                              \
    "id, name, length(case_pb), case_hash, method, update_scheme, dim,"       \
    " particles, nodes, status, submitted_at, started_at, ended_at,"          \
    " steps_done, wall_s, psteps_per_s, kinetic, strain, potential,"          \
    " external_work, total, error, server_version"
#define RUN_COL_CASE 23

void store_run_clear(store_run *r)
{
    if (!r) return;
    free((void *)r->name);
    free((void *)r->case_pb);
    free((void *)r->error);
    free((void *)r->server_version);
    memset(r, 0, sizeof *r);
}

/* Fills r from the current row (columns RUN_COLS [, case_pb]). */
static int read_run_row(sqlite3 *db, sqlite3_stmt *st, store_run *r, int with_case)
{
    memset(r, 0, sizeof *r);
    r->id = sqlite3_column_int64(st, 0);
    r->case_len = (size_t)sqlite3_column_int64(st, 2);
    const unsigned char *h = sqlite3_column_text(st, 3);
    snprintf(r->case_hash, sizeof r->case_hash, "%s", h ? (const char *)h : "");
    int m = parse_name((const char *)sqlite3_column_text(st, 4), method_names, 2);
    int u = parse_name((const char *)sqlite3_column_text(st, 5), update_names, 3);
    int stt = parse_name((const char *)sqlite3_column_text(st, 9), status_names, STORE_NSTATUS);
    if (m < 0 || u < 0 || stt < 0)
        return fail(STORE_ESQL, "run %" PRId64 ": bad method, update_scheme or status value",
                    r->id);
    r->method = (store_method)m;
    r->update = (store_update)u;
    r->status = (store_status)stt;
    r->dim = sqlite3_column_int(st, 6);
    r->particles = sqlite3_column_int64(st, 7);
    r->nodes = sqlite3_column_int64(st, 8);
    r->submitted_at = col_time(st, 10);
    r->started_at = col_time(st, 11);
    r->ended_at = col_time(st, 12);
    r->steps_done = sqlite3_column_int64(st, 13);
    r->wall_s = col_real_nan(st, 14);
    r->psteps_per_s = col_real_nan(st, 15);
    r->energy.kinetic = col_real_nan(st, 16);
    r->energy.strain = col_real_nan(st, 17);
    r->energy.potential = col_real_nan(st, 18);
    r->energy.external_work = col_real_nan(st, 19);
    r->energy.total = col_real_nan(st, 20);
    int rc;
    if ((rc = col_strdup(db, st, 1, &r->name)) ||
        (rc = col_strdup(db, st, 21, &r->error)) ||
        (rc = col_strdup(db, st, 22, &r->server_version))) {
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
    return fail(STORE_ENOMEM, "out of memory reading run");
}

int store_run_get(store *s, int64_t id, store_run *out)
{
    if (!s || !out) return fail(STORE_EINVAL, "store_run_get: NULL argument");
    memset(out, 0, sizeof *out);
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    int rc = sqlite3_prepare_v2(db, "SELECT " RUN_COLS ", case_pb FROM runs WHERE id = ?1",
                                -1, &st, NULL);
    if (rc != SQLITE_OK) {
        r = sql_fail(db, rc, "reading a run");
        goto out;
    }
    rc = sqlite3_bind_int64(st, 1, id);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    if (rc == SQLITE_ROW) r = read_run_row(db, st, out, 1);
    else if (rc == SQLITE_DONE) r = fail(STORE_ENOTFOUND, "no run %" PRId64, id);
    else r = sql_fail(db, rc, "reading a run");
    rc = sqlite3_finalize(st);
    if (!r && rc != SQLITE_OK) {
        r = sql_fail(db, rc, "reading a run");
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
    if (!s || !runs || !n) return fail(STORE_EINVAL, "store_run_list: NULL argument");
    *runs = NULL;
    *n = 0;
    if (!f) f = &none;
    if (f->status_mask >> STORE_NSTATUS)
        return fail(STORE_EINVAL, "status mask 0x%x has unknown bits", f->status_mask);
    if (f->limit > INT64_MAX) return fail(STORE_EINVAL, "limit too large");

    char sql[1024];
    size_t len = (size_t)snprintf(sql, sizeof sql, "SELECT " RUN_COLS ", %s FROM runs WHERE 1",
                                  f->with_case ? "case_pb" : "NULL");
    if (f->status_mask) {
        len += (size_t)snprintf(sql + len, sizeof sql - len, " AND status IN (");
        int first = 1;
        for (int i = 0; i < STORE_NSTATUS; i++)
            if (f->status_mask & STORE_STATUS_BIT(i)) {
                len += (size_t)snprintf(sql + len, sizeof sql - len, "%s'%s'",
                                        first ? "" : ",", status_names[i]);
                first = 0;
            }
        len += (size_t)snprintf(sql + len, sizeof sql - len, ")");
    }
    if (f->before_id > 0) len += (size_t)snprintf(sql + len, sizeof sql - len, " AND id < ?1");
    len += (size_t)snprintf(sql + len, sizeof sql - len, " ORDER BY id DESC");
    if (f->limit) len += (size_t)snprintf(sql + len, sizeof sql - len, " LIMIT ?2");
    if (len >= sizeof sql) return fail(STORE_EINVAL, "run list query too long");

    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    store_run *v = NULL;
    size_t cnt = 0, capn = 0;
    int rc = sqlite3_prepare_v2(db, sql, -1, &st, NULL);
    if (rc != SQLITE_OK) {
        r = sql_fail(db, rc, "listing runs");
        goto out;
    }
    if (f->before_id > 0) rc = sqlite3_bind_int64(st, 1, f->before_id);
    if (rc == SQLITE_OK && f->limit) rc = sqlite3_bind_int64(st, 2, (sqlite3_int64)f->limit);
    if (rc != SQLITE_OK) {
        r = sql_fail(db, rc, "listing runs");
        goto out;
    }
    while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
        if (cnt == capn) {
            size_t nc = capn ? 2 * capn : 16;
            store_run *nv = realloc(v, nc * sizeof *nv);
            if (!nv) {
                r = fail(STORE_ENOMEM, "out of memory listing runs");
                goto out;
            }
            v = nv;
            capn = nc;
        }
        if ((r = read_run_row(db, st, &v[cnt], f->with_case))) goto out;
        cnt++;
    }
    if (rc != SQLITE_DONE) r = sql_fail(db, rc, "listing runs");
out:
    if (st) {
        rc = sqlite3_finalize(st);
        if (!r && rc != SQLITE_OK) r = sql_fail(db, rc, "listing runs");
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

void store_energy_series_free(store_energy_series *es)
{
    if (!es) return;
    free(es->seq);            /* the one allocation */
    memset(es, 0, sizeof *es);
}

int store_energy_read(store *s, int64_t run_id, int64_t from_seq, size_t max,
                      store_energy_series *out)
{
    if (!s || !out) return fail(STORE_EINVAL, "store_energy_read: NULL argument");
    memset(out, 0, sizeof *out);
    if (max > INT64_MAX) max = 0;
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    char *mem = NULL;
    int64_t total = 0;
    int rc;
    /* count and rows in one read transaction: the same snapshot */
    if ((r = db_exec(db, "BEGIN", "reading energy samples"))) goto out;
    rc = sqlite3_prepare_v2(db, "SELECT count(*) FROM energy WHERE run_id = ?1 AND seq >= ?2",
                            -1, &st, NULL);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 1, run_id);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 2, from_seq);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    if (rc != SQLITE_ROW) {
        r = sql_fail(db, rc, "counting energy samples");
        goto out;
    }
    total = sqlite3_column_int64(st, 0);
    rc = sqlite3_finalize(st);
    st = NULL;
    if (rc != SQLITE_OK) {
        r = sql_fail(db, rc, "counting energy samples");
        goto out;
    }
    size_t cnt = (size_t)total;
    if (max && cnt > max) cnt = max;
    if (!cnt) goto out;
    if (cnt > SIZE_MAX / (14 * sizeof(double))) {
        r = fail(STORE_ENOMEM, "%zu energy samples do not fit in memory", cnt);
        goto out;
    }
    mem = malloc(cnt * 14 * sizeof(double));
    if (!mem) {
        r = fail(STORE_ENOMEM, "out of memory reading %zu energy samples", cnt);
        goto out;
    }
    rc = sqlite3_prepare_v2(db,
        "SELECT seq, step, t, kinetic, strain, potential, external_work, total,"
        " momentum_x, momentum_y, momentum_z, mass FROM energy"
        " WHERE run_id = ?1 AND seq >= ?2 ORDER BY seq LIMIT ?3", -1, &st, NULL);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 1, run_id);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 2, from_seq);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 3, (sqlite3_int64)cnt);
    if (rc != SQLITE_OK) {
        r = sql_fail(db, rc, "reading energy samples");
        goto out;
    }
    out->seq = (int64_t *)mem;
    out->step = out->seq + cnt;
    double *d = (double *)(out->step + cnt);
    double **cols[10] = { &out->t, &out->kinetic, &out->strain, &out->potential,
                          &out->external_work, &out->total, &out->momentum_x,
                          &out->momentum_y, &out->momentum_z, &out->mass };
    for (int k = 0; k < 10; k++) *cols[k] = d + (size_t)k * cnt;
    size_t i = 0;
    while (i < cnt && (rc = sqlite3_step(st)) == SQLITE_ROW) {
        out->seq[i] = sqlite3_column_int64(st, 0);
        out->step[i] = sqlite3_column_int64(st, 1);
        for (int k = 0; k < 10; k++) (*cols[k])[i] = col_real_nan(st, 2 + k);
        i++;
    }
    if (i < cnt && rc != SQLITE_DONE) {
        r = sql_fail(db, rc, "reading energy samples");
        goto out;
    }
    out->n = i;
    mem = NULL;                  /* owned by out */
out:
    if (st) {
        rc = sqlite3_finalize(st);
        if (!r && rc != SQLITE_OK) r = sql_fail(db, rc, "reading energy samples");
    }
    if (!sqlite3_get_autocommit(db)) {
        int r2 = db_exec(db, "COMMIT", "ending the read transaction");
        if (!r) r = r2;
    }
    reader_put(s, db);
    free(mem);
    if (r) store_energy_series_free(out);
    return r;
}

int store_run_extras(store *s, int64_t run_id, store_run_extra *out)
{
    if (!s || !out) return fail(STORE_EINVAL, "store_run_extras: NULL argument");
    memset(out, 0, sizeof *out);
    out->last_seq = -1;
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    int rc;
    size_t cap = 0;
    if ((r = db_exec(db, "BEGIN", "reading a run's extras"))) goto out;
    rc = sqlite3_prepare_v2(db, "SELECT count(*), max(seq) FROM energy WHERE run_id = ?1", -1,
                            &st, NULL);
    if (rc == SQLITE_OK) rc = sqlite3_bind_int64(st, 1, run_id);
    if (rc == SQLITE_OK) rc = sqlite3_step(st);
    if (rc != SQLITE_ROW) {
        r = sql_fail(db, rc, "counting energy samples");
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
        r = sql_fail(db, rc, "listing snapshots");
        goto out;
    }
    while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
        if (out->n_snapshots == cap) {
            size_t ncap = cap ? 2 * cap : 16;
            int64_t *nb = realloc(out->snapshot_steps, ncap * sizeof *nb);
            if (!nb) {
                r = fail(STORE_ENOMEM, "out of memory listing snapshots");
                goto out;
            }
            out->snapshot_steps = nb;
            cap = ncap;
        }
        out->snapshot_steps[out->n_snapshots++] = sqlite3_column_int64(st, 0);
    }
    if (rc != SQLITE_DONE) r = sql_fail(db, rc, "listing snapshots");
out:
    if (st) sqlite3_finalize(st);
    if (!sqlite3_get_autocommit(db)) {
        int r2 = db_exec(db, "COMMIT", "ending the read transaction");
        if (!r) r = r2;
    }
    reader_put(s, db);
    if (r) store_run_extra_clear(out);
    return r;
}

void store_run_extra_clear(store_run_extra *x)
{
    if (!x) return;
    free(x->snapshot_steps);
    memset(x, 0, sizeof *x);
    x->last_seq = -1;
}

void store_snapshot_clear(store_snapshot *snap)
{
    if (!snap) return;
    free((void *)snap->data);
    memset(snap, 0, sizeof *snap);
}

int store_snapshot_get(store *s, int64_t run_id, int64_t step, store_snapshot *out)
{
    if (!s || !out) return fail(STORE_EINVAL, "store_snapshot_get: NULL argument");
    memset(out, 0, sizeof *out);
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    sqlite3_stmt *st = NULL;
    const char *sql = step >= 0
        ? "SELECT run_id, step, t, n, dim, fields, data FROM snapshots"
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
        r = step >= 0 ? fail(STORE_ENOTFOUND, "no snapshot of run %" PRId64 " at step %" PRId64,
                             run_id, step)
                      : fail(STORE_ENOTFOUND, "no snapshot of run %" PRId64, run_id);
    } else {
        r = sql_fail(db, rc, "reading a snapshot");
    }
    if (st) {
        rc = sqlite3_finalize(st);
        if (!r && rc != SQLITE_OK) r = sql_fail(db, rc, "reading a snapshot");
    }
    reader_put(s, db);
    if (r) store_snapshot_clear(out);
    return r;
}

int store_schema_version(store *s, int *version)
{
    if (!s || !version) return fail(STORE_EINVAL, "store_schema_version: NULL argument");
    sqlite3 *db;
    int r = reader_get(s, &db);
    if (r) return r;
    int64_t v = 0;
    r = db_query1(db, "PRAGMA user_version", &v, NULL, 0);
    reader_put(s, db);
    if (!r) *version = (int)v;
    return r;
}

void store_get_stats(store *s, store_stats *st)
{
    memset(st, 0, sizeof *st);
    if (!s) return;
    pthread_mutex_lock(&s->mu);
    st->ops_enqueued = s->enq_seq;
    st->ops_committed = s->ops_committed;
    st->transactions = s->transactions;
    st->write_errors = s->write_errors;
    st->snapshots_dropped = s->snapshots_dropped;
    st->queue_ops = s->qops;
    st->queue_bytes = s->qbytes;
    st->queue_bytes_max = s->qbytes_max;
    st->recovered_running = s->rec_running;
    st->recovered_queued = s->rec_queued;
    pthread_mutex_unlock(&s->mu);
}

void store_last_write_error(store *s, char *buf, size_t len)
{
    if (!buf || !len) return;
    buf[0] = 0;
    if (!s) return;
    pthread_mutex_lock(&s->mu);
    snprintf(buf, len, "%s", s->last_werr);
    pthread_mutex_unlock(&s->mu);
}

/* ---------------------------------------------------------------------- */
/* Open and close */

/* Frees everything; the writer thread must not be running. */
static void destroy(store *s)
{
    for (int i = 0; i < s->npool; i++) close_db(s, s->pool[i]);
    s->npool = 0;
    for (int i = 0; i < WS_COUNT; i++) {
        if (s->ws[i] && sqlite3_finalize(s->ws[i]) != SQLITE_OK)
            slog(s, "finalizing a statement: %s", sqlite3_errmsg(s->wdb));
        s->ws[i] = NULL;
    }
    if (s->wdb) close_db(s, s->wdb);   /* last connection: checkpoints, drops the WAL */
    s->wdb = NULL;
    lock_release(s);
    while (s->head) {
        op *o = s->head;
        s->head = o->next;
        free(o);
    }
    if (s->sync_ready) {
        pthread_mutex_destroy(&s->mu);
        pthread_mutex_destroy(&s->pool_mu);
        pthread_cond_destroy(&s->cv_work);
        pthread_cond_destroy(&s->cv_done);
    }
    free(s->path);
    free(s->lock_path);
    free(s);
}

static int init_sync(store *s)
{
    pthread_condattr_t ca;
    if (pthread_condattr_init(&ca)) return fail(STORE_ENOMEM, "pthread_condattr_init failed");
    int e = pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    if (e) {
        pthread_condattr_destroy(&ca);
        return fail(STORE_ENOMEM, "pthread_condattr_setclock: %s", strerror(e));
    }
    if (pthread_mutex_init(&s->mu, NULL)) goto f0;
    if (pthread_mutex_init(&s->pool_mu, NULL)) goto f1;
    if (pthread_cond_init(&s->cv_work, &ca)) goto f2;
    if (pthread_cond_init(&s->cv_done, &ca)) goto f3;
    pthread_condattr_destroy(&ca);
    s->sync_ready = 1;
    return 0;
f3: pthread_cond_destroy(&s->cv_work);
f2: pthread_mutex_destroy(&s->pool_mu);
f1: pthread_mutex_destroy(&s->mu);
f0: pthread_condattr_destroy(&ca);
    return fail(STORE_ENOMEM, "cannot initialise the store's mutexes");
}

static int prepare_writer(store *s)
{
    for (int i = 0; i < WS_COUNT; i++) {
        int rc = sqlite3_prepare_v3(s->wdb, writer_sql[i], -1, SQLITE_PREPARE_PERSISTENT,
                                    &s->ws[i], NULL);
        if (rc != SQLITE_OK) return sql_fail(s->wdb, rc, writer_sql[i]);
    }
    return 0;
}

int store_open(const char *path, const store_options *opt, store **out, char *err,
               size_t errlen)
{
    int r;
    store *s = NULL;
    if (err && errlen) err[0] = 0;
    if (out) *out = NULL;
    if (!path || !*path || !out) {
        r = fail(STORE_EINVAL, "store_open: no database path");
        goto fail;
    }
    if (!sqlite3_threadsafe()) {
        r = fail(STORE_ESQL, "this SQLite library is built without thread support");
        goto fail;
    }
    s = calloc(1, sizeof *s);
    if (!s) {
        r = fail(STORE_ENOMEM, "out of memory opening %s", path);
        goto fail;
    }
    s->lock_fd = -1;
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
        if (opt->log) {
            s->log = opt->log;
            s->log_ud = opt->log_ud;
        }
    }
    size_t plen = strlen(path);
    s->path = malloc(plen + 1);
    s->lock_path = malloc(plen + sizeof ".lock");
    if (!s->path || !s->lock_path) {
        r = fail(STORE_ENOMEM, "out of memory opening %s", path);
        goto fail;
    }
    memcpy(s->path, path, plen + 1);
    memcpy(s->lock_path, path, plen);
    memcpy(s->lock_path + plen, ".lock", sizeof ".lock");

    if ((r = init_sync(s)) || (r = lock_acquire(s)) || (r = open_writer(s)) ||
        (r = migrate(s)) || (r = recover(s)))
        goto fail;
    int64_t next = 1;
    if ((r = db_query1(s->wdb, "SELECT COALESCE(MAX(id), 0) + 1 FROM runs", &next, NULL, 0)))
        goto fail;
    s->next_id = next;
    if ((r = prepare_writer(s))) goto fail;
    int e = pthread_create(&s->writer, NULL, writer_main, s);
    if (e) {
        r = fail(STORE_ENOMEM, "cannot start the store writer thread: %s", strerror(e));
        goto fail;
    }
    s->writer_running = 1;
    (void)pthread_setname_np(s->writer, "mpmd-store");   /* cosmetic */
    *out = s;
    return 0;
fail:
    if (err && errlen) snprintf(err, errlen, "%s", tl_err);
    if (s) destroy(s);
    return r;
}

void store_close(store **sp)
{
    if (!sp || !*sp) return;
    store *s = *sp;
    *sp = NULL;
    if (s->writer_running) {
        pthread_mutex_lock(&s->mu);
        s->stopping = 1;                 /* the writer drains the queue first */
        pthread_cond_broadcast(&s->cv_work);
        pthread_mutex_unlock(&s->mu);
        pthread_join(s->writer, NULL);
        s->writer_running = 0;
        if (s->unreported)
            slog(s, "%" PRIu64 " asynchronous write(s) failed before close; last: %s",
                 s->unreported, s->last_werr);
    }
    destroy(s);
}
