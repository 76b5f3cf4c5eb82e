/*
 * store.h - the mpmd run-record store: one SQLite database file holding a
 * row per submitted run (its case as protobuf bytes, status, timings and
 * final energies), the energy samples of each run and opaque particle
 * snapshots.  Writes are asynchronous: any thread enqueues them and one
 * writer thread commits them in batches, in enqueue order.  Commits can be
 * awaited without blocking (store_ticket, store_ticket_done and a file
 * descriptor for a poll loop, store_notify_fd) or by blocking
 * (store_flush).  Reads are synchronous, thread-safe and never wait for the
 * writer (WAL mode, their own read-only connections).  One daemon per
 * database file: store_open() takes an exclusive flock() on "<path>.lock"
 * and refuses to open a file another mpmd holds.
 *
 * The API speaks mpmd's one vocabulary: run status is mpp_status
 * (protocol/include/mpp.h), method, update and transfer are the solver's
 * mpm_method, mpm_update and mpm_transfer, energy samples are
 * mpm_energy_sample (solver/include/mpm.h).
 * Callers never see SQLite types.  Every function returns 0 or a negative
 * MPM_E* code (mpm_error.h), and store_error() gives the calling thread's
 * last error (SQLite's message included):
 *   MPM_EINVAL     a bad argument (the message names it)
 *   MPM_ENOMEM     allocation failed
 *   MPM_EIO        an SQLite or file-system error; an asynchronous write
 *                  that failed (store_flush)
 *   MPM_ELOCKED    the database is in use by another mpmd
 *   MPM_ESCHEMA    not an mpmd database, or a newer schema
 *   MPM_ENOTFOUND  no such run / snapshot
 *   MPM_EFULL      a snapshot dropped: the write queue is above its cap
 *   MPM_EUNAVAIL   the store is closing
 * Strings and blobs passed in are copied; strings and blobs handed out are
 * owned by the returned struct and released by its *_clear / *_free
 * function.
 *
 * Times are unix seconds as doubles (0 = not set, stored as NULL).  Energy
 * values that are NaN are stored as NULL and read back as NaN (SQLite has
 * no NaN); -0.0 reads back as +0.0.
 */
#ifndef STORE_H
#define STORE_H

#include "mpm.h"
#include "mpm_error.h"
#include "mpp.h"

#include <stddef.h>
#include <stdint.h>

/* Latest schema version (PRAGMA user_version after store_open). */
#define STORE_SCHEMA_VERSION 9

/* Bit of a status in store_run_filter.status_mask. */
#define STORE_STATUS_BIT(st) (1u << (unsigned)(st))

/* Error texts written by crash recovery (see store_open). */
#define STORE_INTERRUPTED_RUNNING "daemon stopped before the run ended"
#define STORE_INTERRUPTED_QUEUED "daemon stopped before the run started"

/* A run record.  As input (store_run_insert) the pointers are borrowed and
 * copied; as output (store_run_get / store_run_list) they are owned by the
 * struct and freed by store_run_clear().  Field names are the schema's
 * (mpmd.RunInfo). */
typedef struct {
    int64_t id;          /* job id; <= 0 on insert: allocate one */
    const char *name;    /* NULL on insert: "" */
    const void *case_pb; /* the case's protobuf bytes */
    size_t case_len;
    mpm_method method;
    mpm_update update;
    mpm_transfer transfer; /* runs stored before schema 5 read as FLIP */
    int dim;               /* 1..3 */
    int64_t particles, nodes;
    mpp_status status;
    double submitted_at; /* 0 on insert: now */
    double started_at, finished_at;
    int64_t steps;              /* steps done */
    double wall_s;              /* wall-clock seconds of the run */
    double psteps_per_s;        /* particle-steps per second */
    mpm_energy energy;          /* final energies: kinetic, strain,
                                   potential, external_work and total; NaN =
                                   not set (insert ignores them: see
                                   store_run_finish).  mass and momentum are
                                   not stored and read back as 0. */
    const char *error;          /* NULL = none */
    const char *server_version; /* NULL on insert: "" */
    /* the energy balance (schema 6; store_run_finish sets them): the run's
     * balance error at its end (has_balance 0: none recorded, as for runs
     * stored before) and the budget's warning (NULL = none) */
    int has_balance;
    double balance_error;
    const char *warning;
    /* who submitted it (schema 7): a client's CURVE public key in Z85, or
     * "local"; NULL on insert: ""; runs stored before read "" */
    const char *owner;
    /* the run's last checkpoint (schema 8; store_run_checkpoint): has_checkpoint
     * 0 = none (checkpoint_step -1); its step, simulated time, file size and
     * the seq its run's next energy sample takes; and how many times
     * store_run_resume() continued the run (insert ignores all of them) */
    int has_checkpoint;
    int64_t checkpoint_step;
    double checkpoint_t;
    int64_t checkpoint_bytes, checkpoint_seq;
    int64_t resumes;
    /* the solver's plan of the run (schema 9; store_run_plan): NULL when
     * not recorded (not started, or stored before; insert ignores it) */
    const char *plan;
} store_run;

/* A checkpoint of a run as the store records it (store_run_checkpoint,
 * store_run_resume): the step and simulated time it holds, its file's size
 * and the seq of the first energy sample after it (the samples recorded
 * then: seq 0 .. energy_seq - 1). */
typedef struct {
    int64_t step;
    double t;
    int64_t bytes;
    int64_t energy_seq;
} store_checkpoint;

/* How a run ended (store_run_finish). */
typedef struct {
    mpp_status status;  /* FINISHED, FAILED, CANCELLED or INTERRUPTED */
    double finished_at; /* 0: now */
    int64_t steps;
    double wall_s, psteps_per_s;
    int has_energy;       /* 0: leave the final energies unset */
    mpm_energy energy;    /* kinetic .. total are stored */
    const char *error;    /* NULL = none */
    int has_balance;      /* 0: leave balance_error unset */
    double balance_error; /* the run's energy balance error at its end */
    const char *warning;  /* the energy budget's warning; NULL = none */
} store_run_end;

/* A particle snapshot: data is opaque to the store (the caller's encoding of
 * n particles in dim dimensions with the fields in the `fields` mask).  As
 * input data is borrowed and copied; as output it is owned (store_snapshot_clear). */
typedef struct {
    int64_t run_id, step;
    double t;
    int64_t n;
    int dim;
    uint32_t fields;
    const void *data;
    size_t size;
} store_snapshot;

/* Filter for store_run_list.  All-zero: every run, newest first. */
typedef struct {
    unsigned status_mask; /* OR of STORE_STATUS_BIT(); 0 = any */
    size_t limit;         /* 0 = no limit */
    int64_t before_id;    /* > 0: only runs with id < before_id */
    int with_case;        /* 1: also load case_pb (else NULL; case_len
                             is set either way) */
    const char *owner;    /* non-NULL: only the runs of this owner */
} store_run_filter;

typedef void (*store_log_fn)(void *ud, const char *msg);

/* Options for store_open; NULL or zero fields take the defaults. */
typedef struct {
    double batch_ms;     /* commit at least this often while writes
                            are pending (default 50 ms) */
    size_t batch_ops;    /* ... or as soon as this many are pending;
                            also the most ops per transaction
                            (default 1024) */
    size_t queue_cap;    /* bytes of pending writes above which
                            snapshots are dropped (default 64 MiB) */
    int busy_timeout_ms; /* SQLite busy timeout (default 5000) */
    store_log_fn log;    /* log lines (default: stderr); called from
                            any thread, so it must be thread-safe */
    void *log_ud;
    long long reserve_bytes; /* the disk reserve "<db>.reserve" (default
                                1 MiB; < 0: none): see store_writable */
} store_options;

typedef struct {
    uint64_t ops_enqueued, ops_committed, transactions;
    uint64_t write_errors; /* failed asynchronous operations, total */
    uint64_t snapshots_dropped;
    size_t queue_ops, queue_bytes, queue_bytes_max;
    int64_t recovered_running; /* runs set 'interrupted' at open ... */
    int64_t recovered_queued;  /* ... by state they were left in */
} store_stats;

typedef struct store store;

/* ---- errors ---- */

/* The calling thread's last error from a store function (code 0 when
 * none yet); valid until the thread's next failing store call. */
const mpm_error *store_error(void);

/* ---- open / close ---- */

/* Opens (creating if needed) the database at path: takes an OS lock
 * (flock) on the database file itself, whatever path reaches it (writing
 * our pid, best effort, into "<real path>.lock"), sets WAL mode, busy_timeout and
 * foreign keys, applies the pending schema migrations in one transaction,
 * marks runs left 'running' or 'queued' by a previous daemon 'interrupted'
 * (error STORE_INTERRUPTED_RUNNING / STORE_INTERRUPTED_QUEUED, finished_at
 * left unset since the time of the stop is unknown, steps and the final
 * energies taken from the run's last energy sample when it has one), loads
 * the next run id and starts the writer thread.  opt may be NULL.
 * A full disk does not stop the open: the disk reserve is released for
 * SQLite's index of the WAL, and a crash recovery (or a kept run end,
 * store_writable) that cannot be written is retried by the writer every
 * second, the reads meanwhile showing those runs as it will write them.  On
 * failure returns a negative code and sets *out to NULL; store_error()
 * says why, e.g. "database X is in use by another mpmd (pid N)" with
 * MPM_ELOCKED. */
int store_open(const char *path, const store_options *opt, store **out);

/* Flushes every pending write, stops the writer thread, closes the
 * connections, releases the lock and sets *s to NULL.  No other thread may
 * use the store during or after the call.  NULL or *s == NULL: no-op. */
void store_close(store **s);

/* ---- commits ---- */

/* Blocks until every write enqueued (by any thread) before the call is
 * committed.  Returns 0, or MPM_EIO when some asynchronous write has failed
 * since the previous store_flush (each failure is reported once; the text
 * is in store_last_write_error()).  For tests and shutdown: an event loop
 * uses tickets instead. */
int store_flush(store *s);

/* A ticket for "every write enqueued so far for run_id" (run_id <= 0: for
 * any run).  Never blocks; asks the writer to commit those writes without
 * waiting out its batching window.  0 when nothing is pending (a ticket
 * that is done already). */
uint64_t store_ticket(store *s, int64_t run_id);
/* 1 when every write covered by the ticket is committed (or failed, see
 * store_flush), else 0.  Never blocks. */
int store_ticket_done(store *s, uint64_t ticket);
/* A file descriptor (an eventfd) that becomes readable after each commit,
 * for poll() / zmq_poll(); owned by the store.  store_notify_drain()
 * empties it (non-blocking). */
int store_notify_fd(store *s);
void store_notify_drain(store *s);

/* ---- a full disk ---- */

/* The enqueue number of the calling thread's last write (store_run_insert,
 * store_run_resume, ...): for store_write_result. */
uint64_t store_last_write(void);

/* The outcome of write seq (store_last_write()): 1 while it is pending, 0
 * once committed; MPM_EIO when it was lost (its transaction rolled back:
 * disk full, I/O error), MPM_ECONFLICT when it was refused alone (an
 * insert or a resume that failed: a duplicate id, a resume of a run no
 * longer interrupted), why (len bytes, may be NULL) saying why; MPM_ESTATE
 * when it failed
 * longer ago than the store remembers (64 failures), which a caller
 * takes as lost.  Never blocks. */
int store_write_result(store *s, uint64_t seq, char *why, size_t len);

/* 0 when the store takes new work: its last transaction committed, no
 * crash recovery or run end waits for space, and its disk reserve is in
 * place (opt.reserve_bytes free on the disk when it was made).  Else
 * MPM_EIO with the reason in why (len bytes, may be NULL), e.g. "the disk
 * is full (database or disk is full); ...".  The writer re-checks every
 * second (a probe write while nothing else is pending). */
int store_writable(store *s, char *why, size_t len);

/* ---- writes (asynchronous: enqueue a copy and return) ---- */

/* Reserves a new run id: max(id) + 1 over the runs on disk at open, then
 * increasing; never reused within a database. */
int64_t store_new_run_id(store *s);
/* The id store_new_run_id() would give next (none reserved). */
int64_t store_next_run_id(store *s);

/* Enqueues a new run row.  run->id <= 0 allocates an id.  Every field but
 * energy (unset) is stored as given; the id used is written to *id_out if
 * not NULL. */
int store_run_insert(store *s, const store_run *run, int64_t *id_out);

/* Sets a run's status.  RUNNING also sets started_at = at; the terminal
 * statuses also set finished_at = at (at == 0: now).  error, if not NULL,
 * replaces the run's error text.  Like progress and finish, it applies only
 * to a run still 'queued' or 'running': a terminal status is final, and an
 * update of an ended run fails (as a write error: "run N already ended"). */
int store_run_set_status(store *s, int64_t id, mpp_status status, double at, const char *error);

/* Records the plan of a running run (schema 9; mpm_sim_plan()'s text):
 * the solver's fast paths it runs.  Like progress, only for a run not
 * ended. */
int store_run_plan(store *s, int64_t id, const char *plan);

/* Records progress: steps done, wall seconds so far, particle-steps/s. */
int store_run_progress(store *s, int64_t id, int64_t steps, double wall_s, double psteps_per_s);

/* Ends a run: terminal status, end time, final counters, energies, error.
 * An end whose transaction is lost (a full disk) is kept, in memory and in
 * the side file "<db>.ends" (64 preallocated slots), and written when
 * space returns, at the latest by the next store_open (before its crash
 * recovery); reads show it meanwhile. */
int store_run_finish(store *s, int64_t id, const store_run_end *end);

/* Records a run's last checkpoint (ck), or that it has none (ck NULL), in
 * any status: the run's checkpoint file (srv) is written before, deleted
 * after this. */
int store_run_checkpoint(store *s, int64_t id, const store_checkpoint *ck);

/* Continues an INTERRUPTED run from checkpoint ck, in one transaction: the
 * energy samples with seq >= ck->energy_seq and the snapshots past
 * ck->step are deleted (a resumed run records them again), and the run
 * becomes 'queued' again with steps = ck->step, its end time, error,
 * warning and balance cleared, the checkpoint recorded and resumes + 1.
 * Fails as a write error ("run N already ended" / not interrupted) when
 * the run is not INTERRUPTED when the write applies. */
int store_run_resume(store *s, int64_t id, const store_checkpoint *ck);

/* Appends n energy samples of run_id (one queue entry; each sample keeps
 * its seq).  Every field is stored but dim: reads give the run's dim.
 * Never dropped: when the queue is above its cap it grows instead (see
 * store_writer.c). */
int store_energy_append(store *s, int64_t run_id, const mpm_energy_sample *e, size_t n);

/* Stores a snapshot (replacing one at the same run and step).  Returns
 * MPM_EFULL, logging a line, if the pending writes would exceed the queue
 * cap: the snapshot is dropped. */
int store_snapshot_put(store *s, const store_snapshot *snap);

/* ---- reads (synchronous, from any thread; see committed data only) ---- */

/* Reads one run (with its case bytes).  MPM_ENOTFOUND if none. */
int store_run_get(store *s, int64_t id, store_run *out);
/* Frees the strings and blob of a run read back, and zeroes it. */
void store_run_clear(store_run *r);

/* Lists runs newest first (by id).  f may be NULL.  *runs is an array of
 * *n records (NULL when n is 0), released with store_run_list_free(). */
int store_run_list(store *s, const store_run_filter *f, store_run **runs, size_t *n);
void store_run_list_free(store_run *runs, size_t n);

/* Reads the energy samples of a run with seq >= from_seq, at most max of
 * them (0: all), in seq order, into *out: a malloc'd array of *n samples
 * (free() it; NULL when there are none, which is not an error).  Each
 * sample's dim is its run's.  A value stored as NULL reads back as NaN: the
 * angular momentum of samples written before schema version 3 is NaN (not
 * recorded), all three components. */
int store_energy_read(store *s, int64_t run_id, int64_t from_seq, size_t max,
                      mpm_energy_sample **out, size_t *n);

/* A run's energy-sample count, the seq of its last sample (-1: none) and
 * the steps of its stored snapshots (ascending). */
typedef struct {
    int64_t energy_count, last_seq;
    int64_t *snapshot_steps;
    size_t n_snapshots;
} store_run_extra;

/* Fills *out (free it with store_run_extra_clear()); 0 or a negative
 * code. */
int store_run_extras(store *s, int64_t run_id, store_run_extra *out);
void store_run_extra_clear(store_run_extra *x);

/* Bytes the committed records of one owner's runs take (schema 7): their
 * snapshots' data, plus STORE_ENERGY_ROW_BYTES per energy sample, plus the
 * size of each run's recorded checkpoint file; into *bytes.  0 or a
 * negative code. */
#define STORE_ENERGY_ROW_BYTES 168 /* 21 columns of 8 bytes */
int store_owner_bytes(store *s, const char *owner, int64_t *bytes);

/* The same figure for every owner at once (one query, for a daemon's
 * start): *rows gets *n entries (NULL when there are no runs), released
 * with store_owner_totals_free(); their sum is the database's recorded
 * total.  0 or a negative code. */
typedef struct {
    const char *owner; /* "" for runs stored before schema 7 (NULL: none) */
    int64_t bytes;
} store_owner_total;
int store_owner_totals(store *s, store_owner_total **rows, size_t *n);

/* The owner of run id into buf (len bytes; "" for runs stored before
 * schema 7), without reading the rest of the run.  MPM_ENOTFOUND if
 * none. */
int store_run_owner(store *s, int64_t id, char *buf, size_t len);
void store_owner_totals_free(store_owner_total *rows, size_t n);

/* Reads the snapshot of a run at step (step < 0: the one with the highest
 * step).  MPM_ENOTFOUND if none. */
int store_snapshot_get(store *s, int64_t run_id, int64_t step, store_snapshot *out);
void store_snapshot_clear(store_snapshot *snap);

/* The database's schema version (PRAGMA user_version). */
int store_schema_version(store *s, int *version);

/* ---- diagnostics and helpers ---- */

void store_get_stats(store *s, store_stats *st);
/* Transactions the writer lost whole since the store opened (disk full,
 * I/O error: every write in them is lost), with the reason of the last
 * one in why (len bytes; "" if none; why may be NULL). */
uint64_t store_losses(store *s, char *why, size_t len);
/* Copies the text of the last failed asynchronous write ("" if none). */
void store_last_write_error(store *s, char *buf, size_t len);

/* The SQLite library version in use, e.g. "3.40.1". */
const char *store_sqlite_version(void);

/* Unix time now, in seconds. */
double store_time_now(void);

/* Runs SQL statements on the database file at path with a connection of
 * its own: no lock, no migration, no store.  For tests that build a
 * database by hand (an old schema) and inspect one; never on a file a
 * store has open.  result, if not NULL, gets the first column of the last
 * row a statement returned (unchanged if none). */
int store_exec_raw(const char *path, const char *sql, int64_t *result);

/* PRAGMA integrity_check on the database file at path, with a connection
 * of its own (as store_exec_raw; a daemon may have it open, from another
 * process).  *ok = 1 when SQLite answers "ok"; report (len bytes, may be
 * NULL) gets what it said, rows joined with "; ", truncated to fit.
 * Returns 0 when the check ran, MPM_EIO when the file cannot be opened or
 * read (*ok = 0). */
int store_integrity_check(const char *path, int *ok, char *report, size_t len);

#endif
