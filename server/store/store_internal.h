/*
 * store_internal.h - what the store's three files share, private to
 * server/store/: the store struct, the write-queue entry, the SQLite
 * helpers, error and log functions, the on-disk names of the enums.  The
 * only header of mpmd that includes sqlite3.h (and only files in
 * server/store/ include it).
 *
 *   store_open.c    open, lock, schema migrations, crash recovery, close;
 *                   errors, logging, the SQLite helpers
 *   store_writer.c  the write queue, the writer thread, commit tracking
 *                   (flush, tickets, the notify fd)
 *   store_read.c    the pool of read connections and every read
 *
 * Internal functions are prefixed sti_.
 */
#ifndef STORE_INTERNAL_H
#define STORE_INTERNAL_H

#include "store.h"

#include <pthread.h>
#include <sqlite3.h>

#define STORE_APP_ID 0x6d706d64 /* "mpmd" in PRAGMA application_id */
#define DEFAULT_BATCH_MS 50.0
#define DEFAULT_BATCH_OPS 1024
#define DEFAULT_QUEUE_CAP ((size_t)64 << 20)
#define DEFAULT_BUSY_MS 5000
#define READER_POOL_MAX 8 /* idle read connections kept */
#define BEGIN_RETRIES 3

/* ---- queue entries (store_writer.c) ---- */

typedef enum {
    OP_RUN_INSERT,
    OP_RUN_STATUS,
    OP_RUN_PROGRESS,
    OP_RUN_FINISH,
    OP_ENERGY,
    OP_SNAPSHOT,
    OP_RUN_CHECKPOINT,
    OP_RUN_RESUME
} op_kind;

typedef struct op {
    struct op *next;
    op_kind kind;
    int64_t run_id; /* the run it writes (commit tracking) */
    uint64_t seq;   /* enqueue number */
    double t_enq;   /* monotonic time of enqueue */
    size_t bytes;   /* size of this allocation (queue accounting) */
    union {
        store_run run; /* RUN_INSERT */
        struct {
            mpp_status status;
            double at;
            const char *error;
        } st; /* RUN_STATUS */
        struct {
            int64_t steps;
            double wall, rate;
        } prog;
        store_run_end fin; /* RUN_FINISH */
        struct {
            size_t n;
            mpm_energy_sample *v;
        } en;                /* ENERGY */
        store_snapshot snap; /* SNAPSHOT */
        struct {
            int has;
            store_checkpoint ck;
        } ck; /* RUN_CHECKPOINT, RUN_RESUME */
    } u;
    /* copies of strings / blobs / samples follow, at OP_HDR */
} op;

/* Prepared statements of the writer connection. */
enum {
    WS_BEGIN,
    WS_COMMIT,
    WS_ROLLBACK,
    WS_INS_RUN,
    WS_UPD_STATUS,
    WS_UPD_PROGRESS,
    WS_FINISH,
    WS_INS_ENERGY,
    WS_PUT_SNAP,
    WS_GET_STATUS,
    WS_CHECKPOINT,
    WS_RESUME_RUN,
    WS_RESUME_ENERGY,
    WS_RESUME_SNAPS,
    WS_COUNT
};

/* The last enqueue number of a run's writes (commit tracking); seq 0 marks
 * an empty slot. */
typedef struct {
    int64_t run_id;
    uint64_t seq;
} run_seq;

struct store {
    char *path;
    char *lock_path; /* realpath(path).lock: flock()ed, the holder's pid in it */
    int lock_fd;     /* the lock file */
    int notify_fd;   /* eventfd, written after each commit */

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
    pthread_cond_t cv_work; /* writer waits: work, flush, stop */
    pthread_cond_t cv_done; /* flushers wait: done_seq advanced */
    int sync_ready;
    pthread_t writer;
    int writer_running;
    op *head, *tail;
    size_t qops;   /* ops in the queue (not yet taken) */
    size_t qbytes; /* bytes of ops not yet committed */
    size_t qbytes_max;
    uint64_t enq_seq, done_seq, flush_target;
    int stopping;
    int over_cap; /* logged that the queue passed the cap */
    int64_t next_id;
    uint64_t ops_committed, transactions, write_errors, unreported;
    uint64_t batches_lost; /* transactions lost whole (disk full, I/O error) */
    char last_loss[512];   /* why the last one was */
    uint64_t snapshots_dropped;
    char last_werr[512];
    int64_t rec_running, rec_queued;
    /* per-run last enqueue numbers (open addressing, rebuilt without the
     * committed entries when half full) */
    run_seq *rmap;
    size_t rmap_cap, rmap_used;
    uint64_t unmapped_seq; /* an op whose run could not be recorded:
                              every ticket covers it */

    /* idle read connections, under pool_mu */
    pthread_mutex_t pool_mu;
    sqlite3 *pool[READER_POOL_MAX];
    int npool;
};

/* ---- on-disk names (store_open.c) ---- */

/* status_names[st - MPP_STATUS_MIN] for an mpp_status st. */
#define STORE_NSTATUS (MPP_STATUS_MAX - MPP_STATUS_MIN + 1)
extern const char *const sti_status_names[STORE_NSTATUS];
#define STORE_NMETHOD 5
extern const char *const sti_method_names[STORE_NMETHOD];
extern const char *const sti_update_names[3];
#define STORE_NTRANSFER 2
extern const char *const sti_transfer_names[STORE_NTRANSFER];
int sti_status_ok(mpp_status st);
int sti_method_ok(mpm_method m);
int sti_update_ok(mpm_update u);
int sti_transfer_ok(mpm_transfer t);
const char *sti_status_name(mpp_status st); /* "queued", ...; "?" */
/* Index of name in names[0..n), or -1. */
int sti_parse_name(const char *name, const char *const *names, int n);

/* ---- errors, logging, time (store_open.c) ---- */

/* Sets the calling thread's error to code with the message; returns code. */
int sti_fail(int code, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* MPM_EIO with "what: sqlite message" (MPM_ENOMEM for SQLITE_NOMEM). */
int sti_sql_fail(sqlite3 *db, int rc, const char *what);
/* The thread's error value, to save and restore around a cleanup. */
mpm_error *sti_error(void);
void sti_log(store *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
double sti_mono_now(void);

/* ---- SQLite helpers (store_open.c) ---- */

/* Runs one or more statements with no results. */
int sti_exec(sqlite3 *db, const char *sql, const char *what);
/* Runs a query returning one integer (or text into txt if not NULL). */
int sti_query1(sqlite3 *db, const char *sql, int64_t *v, char *txt, size_t txtlen);
/* Extended result codes, busy timeout, foreign keys. */
int sti_conn_setup(sqlite3 *db, int busy_ms);
void sti_close_db(store *s, sqlite3 *db);

/* ---- writer (store_writer.c) ---- */

/* Prepares the writer's statements on s->wdb. */
int sti_writer_prepare(store *s);
/* The writer thread's body (arg: the store). */
void *sti_writer_main(void *arg);
/* Finalizes the statements, frees the queue and the run map. */
void sti_writer_free(store *s);

/* ---- readers (store_read.c) ---- */

/* Closes the idle read connections. */
void sti_readers_close(store *s);

#endif
