/*
 * store_writer.c - the store's write side (see store.h): the queue every
 * write function appends to, the one writer thread that commits it, and
 * commit tracking (store_flush, tickets, the notify fd).  The statements
 * and transactions the thread runs are store_apply.c's, the upkeep
 * store_upkeep.c's; this header tells the whole write path.
 * How it works: the notes after the includes.
 */
#include "store_internal.h"

#include "store_apply.h"
#include "store_sql.h"
#include "store_upkeep.h"
#include "store_writer.h"

#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

/*
 * Writer thread.  One thread owns the write connection.  Every write
 * function (store_run_insert, store_run_set_status, store_run_progress,
 * store_run_finish, store_energy_append, store_snapshot_put) copies its
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
 * pending, or someone waits for a commit (store_flush, store_ticket), or
 * the store is closing; then it detaches up to batch_ops ops from the head
 * and applies them in ONE transaction (BEGIN IMMEDIATE ... COMMIT) with
 * prepared statements, outside the mutex, so producers keep enqueueing
 * while it writes.  A commit in WAL mode with synchronous=NORMAL costs no
 * fsync (the WAL is synced at checkpoints), so a batch is cheap and a crash
 * of the daemon loses nothing committed (a power loss may lose the last
 * transactions).
 *
 * Ordering.  There is one queue and one writer, and ops are applied in
 * enqueue order: whatever one thread enqueues is applied in its program
 * order, and an op enqueued after another returned (in any thread) is
 * applied after it.  So a run's insert always precedes its samples, and the
 * foreign keys hold.  done_seq is the seq of the last op of the last
 * committed batch.
 *
 * Commit tracking.  store_flush() waits for done_seq >= the enq_seq it saw
 * on entry.  An event loop must not wait, so a ticket is the enqueue
 * number of the last op of a run (kept in a small hash map, s->rmap, whose
 * committed entries are dropped when it is rebuilt) or of any run; it is
 * done once done_seq reaches it.  After each batch the writer adds 1 to an
 * eventfd, which a poll loop watches to re-check its tickets.
 *
 * Errors of asynchronous writes.  An op that fails (a constraint: duplicate
 * run id, a sample for an unknown run; an update of a missing run or of one
 * that already ended - terminal statuses are final, so a late "running"
 * cannot overwrite "cancelled") is skipped - SQLite undoes only that
 * statement - and the rest of the batch commits.  If SQLite rolls back the
 * whole transaction (disk full, I/O error) the batch is lost.  BEGIN
 * failing with SQLITE_BUSY (another process writing; not another mpmd, the
 * lock prevents that) is retried.  Every failure is logged, counted
 * (store_get_stats) and reported once by the next store_flush() as
 * MPM_EIO.
 *
 * A full disk.  The writes a client is told about (a run's insert, a
 * resume) have an outcome: a lost transaction, or such a write refused,
 * is remembered as a range of enqueue numbers (s->fails, a ring of 64),
 * which store_write_result() looks up once the write is done, so the
 * daemon replies with the job id only after its row is committed.  A lost
 * transaction also marks the store degraded (store_writable() refuses new
 * work), releases the disk reserve (store_ends.c) and keeps every run end
 * in it (the end of a run the disk stopped: FAILED with the reason), in
 * memory and in a preallocated slot of the side file.  The upkeep
 * (sti_upkeep, store_upkeep.c) then writes, in one transaction, the kept ends and a crash
 * recovery the open could not write, or a probe when there is neither; it
 * runs right after a loss and every UPKEEP_S while it has work, and puts
 * the reserve back once a transaction commits.  Guarded by the
 * daemon_disk_* tests (tests/daemon/t_daemon_disk.c).
 *
 * Memory cap.  s->qbytes counts the bytes of ops not yet committed.  Above
 * queue_cap (64 MiB): snapshots (the bulky items) are dropped with a log
 * line and MPM_EFULL; every other op - energy samples, run inserts and
 * updates - is still accepted and the queue GROWS (logged once each time it
 * crosses the cap).  We chose growing over blocking the producer because
 * enqueue must never wait on disk I/O (a solver step stalled behind a slow
 * disk would distort its timings), and because those ops are small: past
 * the cap the queue grows by one queue entry (~480 bytes) per sample
 * appended alone, or about 100 bytes per sample appended in a batch, so
 * memory stays near the cap unless the disk stops for good, which the log
 * shows.
 */

#define OP_ALIGN 16
#define OP_HDR ((sizeof(op) + OP_ALIGN - 1) / OP_ALIGN * OP_ALIGN)
#define RMAP_MIN 64

static struct timespec to_timespec(double t)
{
    struct timespec ts;
    if (t < 0) t = 0;
    ts.tv_sec = (time_t)t;
    ts.tv_nsec = (long)((t - (double)ts.tv_sec) * 1e9);
    if (ts.tv_nsec >= 1000000000L) {
        ts.tv_sec++;
        ts.tv_nsec -= 1000000000L;
    }
    if (ts.tv_nsec < 0) ts.tv_nsec = 0;
    return ts;
}

static _Thread_local uint64_t tl_last_seq;

uint64_t store_last_write(void)
{
    return tl_last_seq;
}

void *sti_writer_main(void *arg)
{
    store *s = arg;
    double upkeep_at = 0; /* monotonic time of the next upkeep */
    pthread_mutex_lock(&s->mu);
    for (;;) {
        while (!s->head && !s->stopping) {
            if (!sti_upkeep_due_locked(s)) {
                pthread_cond_wait(&s->cv_work, &s->mu);
                continue;
            }
            if (sti_mono_now() < upkeep_at) {
                struct timespec ud = to_timespec(upkeep_at);
                pthread_cond_timedwait(&s->cv_work, &s->mu, &ud);
                continue;
            }
            pthread_mutex_unlock(&s->mu);
            sti_upkeep(s);
            upkeep_at = sti_mono_now() + UPKEEP_S;
            pthread_mutex_lock(&s->mu);
        }
        if (!s->head) break; /* stopping, queue drained */
        /* batching window: until the oldest op is batch_s old */
        struct timespec dl = to_timespec(s->head->t_enq + s->batch_s);
        while (!s->stopping && s->flush_target <= s->done_seq && s->qops < s->batch_ops) {
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

        uint64_t lost = s->batches_lost;
        sti_apply_batch(s, batch, n);
        /* right after a loss (the reserve's room is free now), and after a
         * commit while ends or a recovery wait (the disk has room again) */
        pthread_mutex_lock(&s->mu);
        int due = (s->batches_lost != lost || s->ndefer || s->recovery_pending) &&
                  sti_upkeep_due_locked(s);
        pthread_mutex_unlock(&s->mu);
        if (due && (s->batches_lost != lost || sti_mono_now() >= upkeep_at)) {
            sti_upkeep(s);
            upkeep_at = sti_mono_now() + UPKEEP_S;
        }
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
        sti_notify(s);
    }
    pthread_mutex_unlock(&s->mu);
    return NULL;
}

void sti_writer_free(store *s)
{
    sti_apply_free(s);
    while (s->head) {
        op *o = s->head;
        s->head = o->next;
        free(o);
    }
    s->tail = NULL;
    free(s->rmap);
    s->rmap = NULL;
    s->rmap_cap = s->rmap_used = 0;
}

/* ---------------------------------------------------------------------- */
/* The per-run map of last enqueue numbers (under s->mu) */

static size_t rmap_slot(const run_seq *m, size_t cap, int64_t run_id)
{
    size_t i = (size_t)(((uint64_t)run_id * 0x9e3779b97f4a7c15u) >> 20) & (cap - 1);
    while (m[i].seq && m[i].run_id != run_id) i = (i + 1) & (cap - 1);
    return i;
}

/* Rebuilds the map without its committed entries, with room for one more
 * run at a load of at most 1/4.  -1 when out of memory (map unchanged). */
static int rmap_rebuild(store *s)
{
    size_t live = 0;
    for (size_t i = 0; i < s->rmap_cap; i++)
        if (s->rmap[i].seq > s->done_seq) live++;
    size_t cap = RMAP_MIN;
    while (cap < 4 * (live + 1)) cap *= 2;
    run_seq *m = calloc(cap, sizeof *m);
    if (!m) return -1;
    for (size_t i = 0; i < s->rmap_cap; i++)
        if (s->rmap[i].seq > s->done_seq) m[rmap_slot(m, cap, s->rmap[i].run_id)] = s->rmap[i];
    free(s->rmap);
    s->rmap = m;
    s->rmap_cap = cap;
    s->rmap_used = live;
    return 0;
}

static void rmap_set(store *s, int64_t run_id, uint64_t seq)
{
    if (s->rmap_cap) {
        size_t i = rmap_slot(s->rmap, s->rmap_cap, run_id);
        if (s->rmap[i].seq) {
            s->rmap[i].seq = seq;
            return;
        }
    }
    if (2 * (s->rmap_used + 1) > s->rmap_cap && rmap_rebuild(s)) {
        s->unmapped_seq = seq; /* every ticket covers it: conservative */
        return;
    }
    size_t i = rmap_slot(s->rmap, s->rmap_cap, run_id);
    s->rmap[i].run_id = run_id;
    s->rmap[i].seq = seq;
    s->rmap_used++;
}

static uint64_t rmap_get(const store *s, int64_t run_id)
{
    if (!s->rmap_cap) return 0;
    return s->rmap[rmap_slot(s->rmap, s->rmap_cap, run_id)].seq;
}

/* ---------------------------------------------------------------------- */
/* Enqueueing */

/* Allocates an op with tail bytes of room after the header. */
static op *op_new(op_kind kind, int64_t run_id, size_t tail, char **tailp)
{
    size_t bytes = OP_HDR + tail;
    op *o = calloc(1, bytes);
    if (!o) {
        sti_fail(MPM_ENOMEM, "out of memory queueing a write (%zu bytes)", bytes);
        return NULL;
    }
    o->kind = kind;
    o->run_id = run_id;
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

static size_t str_room(const char *str)
{
    return str ? strlen(str) + 1 : 0;
}

/* Refuses a snapshot because the queue is above its cap: counts and logs. */
static int drop_snapshot(store *s, const store_snapshot *snap, size_t qb)
{
    sti_log(s,
            "snapshot of run %" PRId64 " at step %" PRId64 " (%zu bytes) dropped:"
            " %zu bytes of writes pending, cap %zu",
            snap->run_id, snap->step, snap->size, qb, s->cap);
    return sti_fail(MPM_EFULL,
                    "snapshot of run %" PRId64 " at step %" PRId64
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
        return sti_fail(MPM_EUNAVAIL, "the store is closing");
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
    tl_last_seq = o->seq;
    o->t_enq = sti_mono_now();
    o->next = NULL;
    rmap_set(s, o->run_id, o->seq);
    int was_empty = !s->head;
    if (s->tail)
        s->tail->next = o;
    else
        s->head = o;
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
        sti_log(s,
                "write queue above its cap (%zu > %zu bytes): the disk is behind;"
                " growing (only snapshots are dropped)",
                qb, s->cap);
    return 0;
}

int64_t store_new_run_id(store *s)
{
    pthread_mutex_lock(&s->mu);
    int64_t id = s->next_id++;
    pthread_mutex_unlock(&s->mu);
    return id;
}

int64_t store_next_run_id(store *s)
{
    pthread_mutex_lock(&s->mu);
    int64_t id = s->next_id;
    pthread_mutex_unlock(&s->mu);
    return id;
}

int store_run_insert(store *s, const store_run *run, int64_t *id_out)
{
    if (!s || !run) return sti_fail(MPM_EINVAL, "store_run_insert: NULL argument");
    if (run->dim < 1 || run->dim > 3)
        return sti_fail(MPM_EINVAL, "run dim %d not in 1..3", run->dim);
    if (!sti_method_ok(run->method))
        return sti_fail(MPM_EINVAL, "unknown method %d", (int)run->method);
    if (!sti_update_ok(run->update))
        return sti_fail(MPM_EINVAL, "unknown update scheme %d", (int)run->update);
    if (!sti_transfer_ok(run->transfer))
        return sti_fail(MPM_EINVAL, "unknown transfer %d", (int)run->transfer);
    if (!sti_status_ok(run->status))
        return sti_fail(MPM_EINVAL, "unknown run status %d", (int)run->status);
    if (run->case_len && !run->case_pb)
        return sti_fail(MPM_EINVAL, "case_pb is NULL with case_len %zu", run->case_len);
    if (run->particles < 0 || run->nodes < 0 || run->steps < 0)
        return sti_fail(MPM_EINVAL, "negative particles, nodes or steps");
    if (isnan(run->submitted_at) || run->submitted_at < 0)
        return sti_fail(MPM_EINVAL, "bad submitted_at");

    const char *name = run->name ? run->name : "";
    const char *ver = run->server_version ? run->server_version : "";
    const char *owner = run->owner ? run->owner : "";
    char *cur;
    op *o = op_new(OP_RUN_INSERT, 0,
                   str_room(name) + str_room(ver) + str_room(owner) + str_room(run->error) +
                       run->case_len,
                   &cur);
    if (!o) return MPM_ENOMEM;
    store_run *r = &o->u.run;
    *r = *run;
    r->name = tail_str(&cur, name);
    r->server_version = tail_str(&cur, ver);
    r->owner = tail_str(&cur, owner);
    r->error = tail_str(&cur, run->error);
    r->plan = NULL; /* recorded when the run starts (store_run_plan) */
    r->case_pb = run->case_len ? tail_put(&cur, run->case_pb, run->case_len) : NULL;
    if (r->submitted_at == 0) r->submitted_at = store_time_now();

    pthread_mutex_lock(&s->mu);
    if (r->id <= 0)
        r->id = s->next_id++;
    else if (r->id >= s->next_id)
        s->next_id = r->id + 1;
    pthread_mutex_unlock(&s->mu);

    int64_t id = o->run_id = r->id;
    int rc = submit(s, o, 0);
    if (!rc && id_out) *id_out = id;
    return rc;
}

int store_run_set_status(store *s, int64_t id, mpp_status status, double at, const char *error)
{
    if (!s) return sti_fail(MPM_EINVAL, "store_run_set_status: NULL store");
    if (!sti_status_ok(status)) return sti_fail(MPM_EINVAL, "unknown run status %d", (int)status);
    if (isnan(at) || at < 0) return sti_fail(MPM_EINVAL, "bad status time");
    char *cur;
    op *o = op_new(OP_RUN_STATUS, id, str_room(error), &cur);
    if (!o) return MPM_ENOMEM;
    o->u.st.status = status;
    o->u.st.at = at == 0 ? store_time_now() : at;
    o->u.st.error = tail_str(&cur, error);
    return submit(s, o, 0);
}

int store_run_plan(store *s, int64_t id, const char *plan)
{
    if (!s || !plan) return sti_fail(MPM_EINVAL, "store_run_plan: NULL argument");
    char *cur;
    op *o = op_new(OP_RUN_PLAN, id, str_room(plan), &cur);
    if (!o) return MPM_ENOMEM;
    o->u.plan = tail_str(&cur, plan);
    return submit(s, o, 0);
}

int store_run_progress(store *s, int64_t id, int64_t steps, double wall_s, double psteps_per_s)
{
    if (!s) return sti_fail(MPM_EINVAL, "store_run_progress: NULL store");
    if (steps < 0) return sti_fail(MPM_EINVAL, "negative steps");
    char *cur;
    op *o = op_new(OP_RUN_PROGRESS, id, 0, &cur);
    if (!o) return MPM_ENOMEM;
    o->u.prog.steps = steps;
    o->u.prog.wall = wall_s;
    o->u.prog.rate = psteps_per_s;
    return submit(s, o, 0);
}

int store_run_finish(store *s, int64_t id, const store_run_end *end)
{
    if (!s || !end) return sti_fail(MPM_EINVAL, "store_run_finish: NULL argument");
    if (!sti_status_ok(end->status) || !MPP_STATUS_ENDED(end->status))
        return sti_fail(MPM_EINVAL, "store_run_finish: status '%s' is not a final status",
                        sti_status_name(end->status));
    if (end->steps < 0) return sti_fail(MPM_EINVAL, "negative steps");
    if (isnan(end->finished_at) || end->finished_at < 0)
        return sti_fail(MPM_EINVAL, "bad finished_at");
    char *cur;
    op *o = op_new(OP_RUN_FINISH, id, str_room(end->error) + str_room(end->warning), &cur);
    if (!o) return MPM_ENOMEM;
    o->u.fin = *end;
    o->u.fin.error = tail_str(&cur, end->error);
    o->u.fin.warning = tail_str(&cur, end->warning);
    if (o->u.fin.finished_at == 0) o->u.fin.finished_at = store_time_now();
    return submit(s, o, 0);
}

static int checkpoint_op(store *s, op_kind kind, int64_t id, const store_checkpoint *ck)
{
    if (!s) return sti_fail(MPM_EINVAL, "store_run_checkpoint: NULL store");
    if (ck && (ck->step < 0 || ck->energy_seq < 0 || ck->bytes < 0))
        return sti_fail(MPM_EINVAL, "negative checkpoint step, seq or size");
    char *cur;
    op *o = op_new(kind, id, 0, &cur);
    if (!o) return MPM_ENOMEM;
    o->u.ck.has = ck != NULL;
    if (ck) o->u.ck.ck = *ck;
    return submit(s, o, 0);
}

int store_run_checkpoint(store *s, int64_t id, const store_checkpoint *ck)
{
    return checkpoint_op(s, OP_RUN_CHECKPOINT, id, ck);
}

int store_run_resume(store *s, int64_t id, const store_checkpoint *ck)
{
    if (!ck) return sti_fail(MPM_EINVAL, "store_run_resume: NULL checkpoint");
    return checkpoint_op(s, OP_RUN_RESUME, id, ck);
}

int store_energy_append(store *s, int64_t run_id, const mpm_energy_sample *e, size_t n)
{
    if (!s || (n && !e)) return sti_fail(MPM_EINVAL, "store_energy_append: NULL argument");
    if (!n) return 0;
    if (n > (SIZE_MAX - OP_HDR) / sizeof *e)
        return sti_fail(MPM_EINVAL, "store_energy_append: %zu samples", n);
    char *cur;
    op *o = op_new(OP_ENERGY, run_id, n * sizeof *e, &cur);
    if (!o) return MPM_ENOMEM;
    o->u.en.n = n;
    o->u.en.v = tail_put(&cur, e, n * sizeof *e);
    return submit(s, o, 0);
}

int store_snapshot_put(store *s, const store_snapshot *snap)
{
    if (!s || !snap) return sti_fail(MPM_EINVAL, "store_snapshot_put: NULL argument");
    if (snap->size && !snap->data)
        return sti_fail(MPM_EINVAL, "snapshot data is NULL with size %zu", snap->size);
    if (snap->dim < 1 || snap->dim > 3)
        return sti_fail(MPM_EINVAL, "snapshot dim %d not in 1..3", snap->dim);
    if (snap->n < 0 || snap->step < 0)
        return sti_fail(MPM_EINVAL, "negative snapshot step or particle count");
    if (snap->size > SIZE_MAX - OP_HDR)
        return sti_fail(MPM_EINVAL, "snapshot of %zu bytes", snap->size);
    /* refuse before copying a big blob; submit() checks again under the
     * same lock that enqueues */
    pthread_mutex_lock(&s->mu);
    size_t qb = s->qbytes;
    int full = qb + OP_HDR + snap->size > s->cap;
    if (full) s->snapshots_dropped++;
    pthread_mutex_unlock(&s->mu);
    if (full) return drop_snapshot(s, snap, qb);
    char *cur;
    op *o = op_new(OP_SNAPSHOT, snap->run_id, snap->size, &cur);
    if (!o) return MPM_ENOMEM;
    o->u.snap = *snap;
    o->u.snap.data = snap->size ? tail_put(&cur, snap->data, snap->size) : NULL;
    return submit(s, o, 1);
}

/* ---------------------------------------------------------------------- */
/* Commit tracking */

int store_flush(store *s)
{
    if (!s) return sti_fail(MPM_EINVAL, "store_flush: NULL store");
    pthread_mutex_lock(&s->mu);
    uint64_t target = s->enq_seq;
    if (target > s->flush_target) s->flush_target = target;
    pthread_cond_signal(&s->cv_work);
    while (s->done_seq < target) pthread_cond_wait(&s->cv_done, &s->mu);
    int rc = 0;
    if (s->unreported) {
        rc = sti_fail(MPM_EIO, "%" PRIu64 " asynchronous write(s) failed; last: %s", s->unreported,
                      s->last_werr);
        s->unreported = 0;
    }
    pthread_mutex_unlock(&s->mu);
    return rc;
}

uint64_t store_ticket(store *s, int64_t run_id)
{
    if (!s) return 0;
    pthread_mutex_lock(&s->mu);
    uint64_t t = run_id > 0 ? rmap_get(s, run_id) : s->enq_seq;
    if (s->unmapped_seq > t) t = s->unmapped_seq;
    if (t <= s->done_seq) {
        t = 0;
    } else if (t > s->flush_target) {
        s->flush_target = t; /* someone waits: skip the window */
        pthread_cond_signal(&s->cv_work);
    }
    pthread_mutex_unlock(&s->mu);
    return t;
}

int store_ticket_done(store *s, uint64_t ticket)
{
    if (!s || !ticket) return 1;
    pthread_mutex_lock(&s->mu);
    int done = s->done_seq >= ticket;
    pthread_mutex_unlock(&s->mu);
    return done;
}

int store_write_result(store *s, uint64_t seq, char *why, size_t len)
{
    if (why && len) why[0] = 0;
    if (!s) return sti_fail(MPM_EINVAL, "store_write_result: NULL store");
    int rc = 0;
    pthread_mutex_lock(&s->mu);
    if (seq > s->done_seq) {
        rc = 1;
    } else {
        unsigned n = s->nfails < FAIL_RING ? s->nfails : FAIL_RING;
        for (unsigned i = 0; i < n && !rc; i++) {
            const fail_range *f = &s->fails[i];
            if (seq >= f->lo && seq <= f->hi) {
                rc = f->lost ? MPM_EIO : MPM_ECONFLICT;
                if (why && len) snprintf(why, len, "%s", f->why);
            }
        }
        if (!rc && seq <= s->fail_horizon) {
            rc = MPM_ESTATE;
            if (why && len)
                snprintf(why, len, "the outcome of write %" PRIu64 " is no longer known", seq);
        }
    }
    pthread_mutex_unlock(&s->mu);
    return rc;
}

int store_writable(store *s, char *why, size_t len)
{
    if (why && len) why[0] = 0;
    if (!s) return sti_fail(MPM_EINVAL, "store_writable: NULL store");
    char b[400] = "";
    pthread_mutex_lock(&s->mu);
    if (s->recovery_pending)
        snprintf(b, sizeof b,
                 "crash recovery of the runs an earlier mpmd left cannot be written (%s)",
                 s->degraded_why);
    else if (s->degraded)
        snprintf(b, sizeof b, "its last transaction was lost (%s)", s->degraded_why);
    else if (s->ndefer)
        snprintf(b, sizeof b, "%zu run end(s) wait for room on the disk", s->ndefer);
    else if (s->reserve_bytes > 0 && !s->reserve_ok)
        snprintf(b, sizeof b, "its disk reserve of %lld KiB cannot be allocated (%s)",
                 s->reserve_bytes / 1024, s->reserve_why[0] ? s->reserve_why : "released");
    pthread_mutex_unlock(&s->mu);
    if (!b[0]) return 0;
    if (why && len) snprintf(why, len, "the run store cannot take new work: %s", b);
    return sti_fail(MPM_EIO, "the run store cannot take new work: %s", b);
}

int store_notify_fd(store *s)
{
    return s ? s->notify_fd : -1;
}

void store_notify_drain(store *s)
{
    uint64_t v;
    if (!s) return;
    /* one read empties an eventfd; EAGAIN: it was empty */
    ssize_t r = read(s->notify_fd, &v, sizeof v);
    (void)r;
}

/* ---------------------------------------------------------------------- */
/* Diagnostics */

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

uint64_t store_losses(store *s, char *why, size_t len)
{
    if (why && len) why[0] = 0;
    if (!s) return 0;
    pthread_mutex_lock(&s->mu);
    uint64_t n = s->batches_lost;
    if (why && len) snprintf(why, len, "%s", s->last_loss);
    pthread_mutex_unlock(&s->mu);
    return n;
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
