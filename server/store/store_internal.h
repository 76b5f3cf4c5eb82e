/*
 * store_internal.h - the store's types, private to server/store/: the
 * store struct, the write-queue entry, the limits.  It declares no
 * function: each file's private header declares its own, so that the
 * files depend on each other one way (tests/include_graph.py checks it).
 * With store_sql.h, the only headers of mpmd that include sqlite3.h (and
 * only files in server/store/ include them).  From the bottom up:
 *
 *   store_sql.c     errors, logging, clocks, on-disk names, SQLite helpers
 *   store_ends.c    the side file of run ends a full disk kept out of
 *                   the database, and the disk reserve
 *   store_read.c    the pool of read connections and every read
 *   store_apply.c   the writer's statements and transactions
 *   store_upkeep.c  the upkeep: kept ends, crash recovery, the reserve
 *   store_writer.c  the write queue, the writer thread, commit tracking
 *                   (flush, tickets, the notify fd)
 *   store_open.c    open, lock, schema migrations, close
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
#define DEFAULT_RESERVE ((long long)1 << 20)
#define UPKEEP_S 1.0   /* retry interval of the upkeep while it has work */
#define FAIL_RING 64   /* failed acknowledged writes remembered (seq ranges) */
#define DEFER_MAX 1024 /* run ends kept in memory while the disk is full */
#define ENDS_SLOTS 64  /* ... and in the side file's preallocated slots */

/* ---- queue entries (store_writer.c) ---- */

typedef enum {
    OP_RUN_INSERT,
    OP_RUN_STATUS,
    OP_RUN_PROGRESS,
    OP_RUN_FINISH,
    OP_ENERGY,
    OP_SNAPSHOT,
    OP_RUN_CHECKPOINT,
    OP_RUN_RESUME,
    OP_RUN_PLAN
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
        } ck;             /* RUN_CHECKPOINT, RUN_RESUME */
        const char *plan; /* RUN_PLAN */
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
    WS_PLAN,
    WS_COUNT
};

/* Writes that failed (a transaction lost whole, or an insert / resume
 * refused), as a range of enqueue numbers with the reason: the outcome of
 * an acknowledged write (store_write_result). */
typedef struct {
    uint64_t lo, hi;
    int lost; /* 1: a transaction lost whole; 0: one write refused */
    char why[200];
} fail_range;

/* A run's end (OP_RUN_FINISH) whose transaction was lost: applied again
 * by the upkeep, shown by the reads meanwhile; slot: its slot in the side
 * file, -1 when only in memory.  error / warning point into the texts. */
typedef struct {
    int64_t run_id;
    store_run_end end;
    char error[296], warning[104];
    int slot;
} deferred_end;

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
    /* full-disk state (store_ends.c, the upkeep in store_upkeep.c), under
     * mu: the last transaction was lost (degraded, why), crash recovery
     * still to do for the runs with ids below recover_below, the run ends
     * kept (defer, ndefer, the side file ends_fd and its used slots), the
     * failed acknowledged writes (fails, a ring; fail_horizon: the highest
     * seq of a range it forgot), the disk reserve */
    int degraded;
    char degraded_why[256];
    int recovery_pending;
    int64_t recover_below;
    deferred_end *defer;
    size_t ndefer;
    int ends_fd;
    int ends_slots;     /* slots the side file has room for */
    uint64_t ends_used; /* bit i: slot i holds an end */
    char *ends_path, *reserve_path;
    long long reserve_bytes; /* 0: no reserve */
    int reserve_ok;          /* the reserve file is in place */
    char reserve_why[96];    /* why it could not be made */
    double reserve_next;     /* monotonic time of the next attempt */
    fail_range fails[FAIL_RING];
    unsigned nfails; /* ranges recorded so far (ring index = n % FAIL_RING) */
    uint64_t fail_horizon;
    uint64_t upkeep_logged; /* the log line of the last failed upkeep, hashed */
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

#endif
