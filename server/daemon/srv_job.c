/*
 * srv_job.c - one job on a worker thread (srv_pool.c runs the threads):
 * the simulation built from the checked case and stepped until it ends,
 * its energy samples, progress, snapshots and end recorded in the store
 * and published as stream messages through the worker's PUSH socket,
 * every recorded byte charged to the disk budgets (srv_budget.h), and its
 * checkpoints.
 *
 * Energy samples reach the store and the stream in small batches (at most
 * ~FLUSH_S late), so a job sampling every step does not wake the other
 * threads at every step; snapshots are packed into one buffer per job and
 * handed to zmq without a copy (see publish_snapshot()).  A message the
 * main thread is too far behind to take is dropped, its seq number still
 * used, so watchers see the gap and refetch from the store.
 *
 * Checkpoints (srv_ckpt.h) are taken between two steps, when the case's
 * schedule (Case.checkpoint, else --checkpoint-every-s of wall time) says
 * so and at a shutdown: the samples held so far reach the store first,
 * then the file is written, then its record; the file goes when the run
 * ends other than INTERRUPTED.  A resumed job loads its checkpoint into a
 * fresh simulation and goes on with the next step, its samples numbered
 * after the checkpoint's, its wall time added to the run's.
 */
#include "srv_job.h"

#include "mpm.h"
#include "srv_budget.h"
#include "srv_log.h"
#include "srv_tsan.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <zmq.h>

static double mono_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

void srv_topic(uint64_t job, char *buf)
{
    snprintf(buf, SRV_TOPIC_LEN + 1, "job:%016llx:", (unsigned long long)job);
}

int srv_topic_parse(const char *buf, size_t len, uint64_t *job)
{
    if (len != SRV_TOPIC_LEN || memcmp(buf, "job:", 4) || buf[SRV_TOPIC_LEN - 1] != ':') return -1;
    uint64_t v = 0;
    for (int i = 4; i < 20; i++) {
        char c = buf[i];
        int d = c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : -1;
        if (d < 0) return -1;
        v = v << 4 | (uint64_t)d;
    }
    *job = v;
    return 0;
}

void srv_job_free(srv_job *j)
{
    if (!j) return;
    mpp_case_destroy(&j->sc);
    srv_ckpt_file_clear(&j->ck);
    free(j);
}

/* ---- the stream, from a worker ---- */

/* Energy samples are handed on in batches: each goes to the store and the
 * stream in order, but a worker taking one every step of a fast job would
 * otherwise wake the store's writer and the main thread (which relays to
 * the XPUB) at every step, and on a machine whose cores the solver keeps
 * busy each wake-up preempts the solver.  A sample is held only while the
 * next one is expected within FLUSH_S of the last hand-over, so none waits
 * much longer than FLUSH_S (progress, snapshots and the end hand the
 * batch on first: stream messages keep their seq order); the store gets a
 * batch before the stream sees any of it, so a watcher that finds a gap
 * and asks GetEnergy finds the samples there. */
#define FLUSH_S 0.1
#define FLUSH_MAX 256

typedef struct {
    mpm_energy_sample rec[FLUSH_MAX];
    uint8_t *msg[FLUSH_MAX]; /* packed StreamMsg or NULL (encoding failed) */
    size_t len[FLUSH_MAX];
    size_t n;
    double last_flush, last_sample; /* mono_now() */
} pending;

typedef struct {
    const srv_job_env *e;
    void *push;
    srv_job *j;
    char topic[SRV_TOPIC_LEN + 1];
    pending *pe;       /* NULL: every sample handed on at once */
    int64_t recorded;  /* bytes this job has recorded (charged) */
    int over;          /* a disk budget refused a write: the job ends */
    char overwhy[512]; /* why */
    int64_t ck_bytes;  /* the size of its checkpoint file on disk (charged) */
} ctx;

/* Charges n bytes the job is about to record (srv_budget.h): 0, or -1
 * when a budget refuses them: they are not to be recorded, and the job
 * ends FAILED with the reason (c->overwhy) before its next step. */
static int charge(ctx *c, int64_t n)
{
    if (!c->e->budget) return 0;
    if (c->over) return -1;
    if (!srv_budget_charge(c->e->budget, c->j->owner, &c->recorded, n, c->overwhy,
                           sizeof c->overwhy))
        return 0;
    c->over = 1;
    return -1;
}

static void refund(ctx *c, int64_t n)
{
    if (c->e->budget) srv_budget_refund(c->e->budget, c->j->owner, &c->recorded, n);
}

static void publish(ctx *c, uint8_t *buf, size_t len)
{
    if (!buf) return;
    if (zmq_send(c->push, c->topic, SRV_TOPIC_LEN, ZMQ_SNDMORE | ZMQ_DONTWAIT) < 0 ||
        zmq_send(c->push, buf, len, ZMQ_DONTWAIT) < 0) {
        if (errno != EAGAIN)
            srv_warn(c->j->id, "stream send: %s", zmq_strerror(errno));
        else
            srv_debug(c->j->id, "stream message dropped (main thread behind)");
    }
    free(buf);
}

/* Hands the held samples on: the store first, then the stream. */
static void flush_samples(ctx *c)
{
    pending *pe = c->pe;
    if (!pe) return;
    pe->last_flush = mono_now();
    if (!pe->n) return;
    int64_t bytes = (int64_t)pe->n * STORE_ENERGY_ROW_BYTES;
    if (charge(c, bytes)) {
        /* over a disk budget: neither recorded nor streamed */
        for (size_t i = 0; i < pe->n; i++) free(pe->msg[i]);
        pe->n = 0;
        return;
    }
    int rc = store_energy_append(c->e->st, (int64_t)c->j->id, pe->rec, pe->n);
    if (rc) {
        refund(c, bytes);
        srv_warn(c->j->id, "energy samples %llu..%llu not recorded: %s",
                 (unsigned long long)pe->rec[0].seq, (unsigned long long)pe->rec[pe->n - 1].seq,
                 store_error()->message);
    }
    for (size_t i = 0; i < pe->n; i++) publish(c, pe->msg[i], pe->len[i]);
    pe->n = 0;
}

static void energy_sample(ctx *c, mpm_sim *sim, mpm_energy_sample *out)
{
    srv_job *j = c->j;
    mpm_energy_sample s = {0};
    s.step = mpm_sim_steps(sim);
    s.t = mpm_sim_time(sim);
    s.dim = mpm_sim_dim(sim);
    mpm_sim_energy(sim, &s.e);
    s.seq = j->energy_seq++;
    mpm_energy_sample r = s; /* one shape to the wire and the store */
    uint8_t *buf = NULL;
    size_t len = 0;
    if (mpp_stream_energy(j->id, j->msg_seq++, &s, &buf, &len))
        srv_warn(j->id, "out of memory encoding an energy sample");
    if (out) *out = s;
    pending *pe = c->pe;
    if (!pe) {
        if (charge(c, STORE_ENERGY_ROW_BYTES)) {
            free(buf);
            return;
        }
        int rc = store_energy_append(c->e->st, (int64_t)j->id, &r, 1);
        if (rc) {
            refund(c, STORE_ENERGY_ROW_BYTES);
            srv_warn(j->id, "energy sample %llu not recorded: %s", (unsigned long long)s.seq,
                     store_error()->message);
        }
        publish(c, buf, len);
        return;
    }
    pe->rec[pe->n] = r;
    pe->msg[pe->n] = buf;
    pe->len[pe->n] = len;
    pe->n++;
    /* hold it only if the next sample (as far as the last interval
     * tells) comes before this batch is FLUSH_S old */
    double now = mono_now(), gap = now - pe->last_sample;
    pe->last_sample = now;
    if (pe->n == FLUSH_MAX || now + gap - pe->last_flush >= FLUSH_S) flush_samples(c);
}

/* A packed snapshot StreamMsg handed to zmq without a copy
 * (zmq_msg_init_data): zmq drops its reference once the message has left
 * (the XPUB keeps it until the last subscriber's pipe has sent it), from
 * whichever thread that happens on; the worker keeps one of its own and
 * packs the next snapshot into the same buffer when zmq is done with it -
 * so a watched job allocates its (tens of MB) message buffer once, not
 * twice per snapshot (protobuf buffer + zmq's copy), and faults no fresh
 * pages in while the solver waits. */
typedef struct {
    atomic_int refs;
    size_t cap;
    uint8_t data[];
} snapmsg;

static void snapmsg_unref(snapmsg *m)
{
    if (m && atomic_fetch_sub(&m->refs, 1) == 1) free(m);
}

/* Bytes of snapshot messages zmq holds, every job's (queued for some
 * watcher, or on their way to the stream socket). */
static atomic_size_t stream_held;

static void snapmsg_zmq_free(void *data, void *hint)
{
    (void)data;
    TSAN_ACQUIRE(hint);
    atomic_fetch_sub(&stream_held, ((snapmsg *)hint)->cap);
    snapmsg_unref(hint);
}

/* Snapshot message buffers a job may have at once (each held by zmq
 * until every watcher's connection has taken it, or kept for reuse). */
#define SNAP_SLOTS 256

/* Snapshot buffers are allocated on first use, once per job. */
typedef struct {
    double *x, *v, *stress, *mean, *pressure, *volume, *packed; /* pressure = -mean */
    double *plastic, *F; /* the model's fields, when the run has them */
    uint8_t *yl;         /* the solver's yield flags, and as the message's ints */
    int *yli;
    unsigned fields; /* the fields asked for that the run has */
    size_t n;
    snapmsg *msg[SNAP_SLOTS]; /* message buffers: the worker's reference */
    uint64_t dropped;         /* snapshots not streamed: over the budget */
} snapbuf;

static void snapbuf_free(snapbuf *b)
{
    free(b->x);
    free(b->v);
    free(b->stress);
    free(b->mean);
    free(b->pressure);
    free(b->volume);
    free(b->plastic);
    free(b->F);
    free(b->yl);
    free(b->yli);
    free(b->packed);
    for (int i = 0; i < SNAP_SLOTS; i++) snapmsg_unref(b->msg[i]);
    memset(b, 0, sizeof *b);
}

/* The stream's memory bound across jobs.  A message buffer that zmq still
 * holds is queued for some watcher (the XPUB keeps a message until the last
 * subscriber's connection has written it to the kernel).  What one watcher
 * can hold is bounded on the main thread (srv_stream_relay(): about
 * --stream-buffer-mb per connection); the bytes all watchers hold together
 * are counted here (stream_held), and a snapshot that would take them
 * above --stream-total-mb is not streamed (its seq is used: watchers see
 * the gap; the record, if asked for, is stored as always).  One message of
 * each job may always be in flight, so a snapshot larger than the budget
 * still reaches a watcher that keeps up.  Buffers zmq has let go of are
 * reused (the solver faults in no fresh pages), and those beyond the one
 * kept are freed.  Returns the slot to pack into (its buffer at least need
 * bytes), or -1 to drop.  (daemon_subs_stalled_watcher_many_jobs) */
static int snap_slot(ctx *c, snapbuf *b, size_t need)
{
    size_t held = 0, budget = (size_t)c->e->cfg->stream_total_mb << 20;
    int reuse = -1, empty = -1;
    for (int i = 0; i < SNAP_SLOTS; i++) {
        snapmsg *m = b->msg[i];
        if (!m) {
            if (empty < 0) empty = i;
        } else if (atomic_load(&m->refs) != 1) {
            held += m->cap;
        } else if (reuse < 0 && m->cap >= need) {
            reuse = i;
        } else {
            /* free, but another one will do: let it go */
            snapmsg_unref(m);
            b->msg[i] = NULL;
            if (empty < 0) empty = i;
        }
    }
    if (budget && held && atomic_load(&stream_held) + need > budget) return -1;
    if (reuse >= 0) return reuse;
    if (empty < 0) return -1;
    snapmsg *m = malloc(sizeof *m + need);
    if (!m) {
        srv_warn(c->j->id, "out of memory for a snapshot message of %zu bytes", need);
        return -1;
    }
    atomic_init(&m->refs, 1);
    m->cap = need;
    b->msg[empty] = m;
    return empty;
}

/* The message buffer (slot) a snapshot with this seq (its arrays' sizes
 * as in s; their values are not read) will be packed into, or -1 when it
 * is not streamed: the stream's budget is full (logged once per job). */
static int snapshot_slot(ctx *c, snapbuf *b, const mpp_snapshot *s, uint64_t seq)
{
    size_t need = 0;
    mpp_stream_snapshot_into(c->j->id, seq, s, NULL, 0, &need); /* the size only */
    int slot = snap_slot(c, b, need);
    if (slot < 0 && !b->dropped++)
        srv_log(c->j->id,
                "snapshot at step %lld (%zu bytes) not streamed: %zu bytes of snapshots are "
                "still queued for slow watchers (--stream-total-mb %d); later ones are dropped "
                "likewise while they lag",
                (long long)s->step, need, atomic_load(&stream_held), c->e->cfg->stream_total_mb);
    return slot;
}

/* Packs a snapshot into the job's message buffer `slot` (snapshot_slot()
 * with the same seq) and sends it without a copy. */
static void publish_snapshot(ctx *c, snapbuf *b, const mpp_snapshot *s, uint64_t seq, int slot)
{
    srv_job *j = c->j;
    size_t len = 0;
    snapmsg *m = b->msg[slot];
    if (mpp_stream_snapshot_into(j->id, seq, s, m->data, m->cap, &len)) {
        srv_warn(j->id, "cannot encode a snapshot");
        return;
    }
    zmq_msg_t msg;
    atomic_fetch_add(&m->refs, 1); /* zmq's, dropped by snapmsg_zmq_free */
    atomic_fetch_add(&stream_held, m->cap);
    TSAN_RELEASE(m);
    if (zmq_msg_init_data(&msg, m->data, len, snapmsg_zmq_free, m)) {
        atomic_fetch_sub(&stream_held, m->cap);
        atomic_fetch_sub(&m->refs, 1);
        srv_warn(j->id, "stream send: %s", zmq_strerror(errno));
        return;
    }
    if (zmq_send(c->push, c->topic, SRV_TOPIC_LEN, ZMQ_SNDMORE | ZMQ_DONTWAIT) < 0 ||
        zmq_msg_send(&msg, c->push, ZMQ_DONTWAIT) < 0) {
        if (errno != EAGAIN)
            srv_warn(j->id, "stream send: %s", zmq_strerror(errno));
        else
            srv_debug(j->id, "stream message dropped (main thread behind)");
        zmq_msg_close(&msg); /* not sent: zmq_msg_send left it to us */
    }
}

static int snapshot(ctx *c, mpm_sim *sim, snapbuf *b, int stream, int record)
{
    srv_job *j = c->j;
    flush_samples(c); /* the samples before it go out (and in) first */
    unsigned f = j->sc->snapshot_fields;
    size_t n = mpm_sim_particles(sim);
    int dim = mpm_sim_dim(sim);
    size_t per = 0;
    /* a field the run's particles lack is left out */
    if (!mpm_sim_has_field(sim, MPM_FIELD_PLASTIC_STRAIN)) f &= ~(unsigned)MPP_SNAP_PLASTIC_STRAIN;
    if (!mpm_sim_has_field(sim, MPM_FIELD_DEFORMATION_GRADIENT))
        f &= ~(unsigned)MPP_SNAP_DEFORMATION_GRADIENT;
    if (!mpm_sim_has_field(sim, MPM_FIELD_YIELDED)) f &= ~(unsigned)MPP_SNAP_YIELDED;
    size_t nF = n * (size_t)dim * (size_t)dim;
    if (!b->n) {
        b->n = n;
        b->fields = f;
        if (f & MPP_SNAP_PLASTIC_STRAIN) per += 1;
        if (f & MPP_SNAP_DEFORMATION_GRADIENT) per += (size_t)(dim * dim);
        if (f & MPP_SNAP_YIELDED) per += 1;
        if (f & MPP_SNAP_X) per += (size_t)dim;
        if (f & MPP_SNAP_V) per += (size_t)dim;
        if (f & MPP_SNAP_STRESS) per += 6;
        if (f & MPP_SNAP_PRESSURE) per += 1;
        if (f & MPP_SNAP_VOLUME) per += 1;
        if (((f & MPP_SNAP_X) && !(b->x = malloc(n * dim * sizeof(double)))) ||
            ((f & MPP_SNAP_V) && !(b->v = malloc(n * dim * sizeof(double)))) ||
            ((f & MPP_SNAP_STRESS) && !(b->stress = malloc(n * 6 * sizeof(double)))) ||
            ((f & MPP_SNAP_PRESSURE) && (!(b->mean = malloc(n * sizeof(double) + 1)) ||
                                         !(b->pressure = malloc(n * sizeof(double) + 1)))) ||
            ((f & MPP_SNAP_VOLUME) && !(b->volume = malloc(n * sizeof(double)))) ||
            ((f & MPP_SNAP_PLASTIC_STRAIN) && !(b->plastic = malloc(n * sizeof(double)))) ||
            ((f & MPP_SNAP_DEFORMATION_GRADIENT) && !(b->F = malloc(nF * sizeof(double)))) ||
            ((f & MPP_SNAP_YIELDED) &&
             (!(b->yl = malloc(n ? n : 1)) || !(b->yli = malloc(n * sizeof(int) + 1)))) ||
            (record && !(b->packed = malloc(n * per * sizeof(double) + 1)))) {
            srv_warn(j->id, "out of memory for snapshots of %zu particles; snapshots off", n);
            snapbuf_free(b);
            return -1;
        }
    }
    f = b->fields;
    mpp_snapshot s = {.step = mpm_sim_steps(sim),
                      .t = mpm_sim_time(sim),
                      .n = n,
                      .dim = dim,
                      .x = b->x,
                      .v = b->v,
                      .stress = b->stress,
                      .mean_stress = b->mean,
                      .volume = b->volume,
                      .plastic_strain = b->plastic,
                      .deformation_gradient = b->F,
                      .yielded = b->yli,
                      .pressure = b->pressure};
    /* a snapshot the stream's budget refuses is not even gathered unless
     * it is recorded: a stalled watcher costs the job nothing (the size of
     * its message depends on n and the fields only, not on the values) */
    uint64_t seq = 0;
    int slot = -1;
    if (stream) {
        seq = j->msg_seq++;
        slot = snapshot_slot(c, b, &s, seq);
        if (slot < 0 && !record) return 0;
    }
    mpm_sim_snapshot(sim, &(mpm_snapshot){.x = b->x,
                                          .v = b->v,
                                          .stress = b->stress,
                                          .mean_stress = b->mean,
                                          .volume = b->volume,
                                          .plastic_strain = b->plastic,
                                          .deformation_gradient = b->F,
                                          .yielded = b->yl});
    if (b->yl)
        for (size_t i = 0; i < n; i++) b->yli[i] = b->yl[i];
    /* the stream carries both; the store keeps the mean stress alone (its
     * layout of every release), the daemon derives the pressure on reading */
    if (b->mean) mpp_snapshot_pressure(b->mean, n, b->pressure);
    if (record && b->packed) {
        /* stored layout: the requested arrays back to back, in field-bit
         * order (the yield flags as 0.0 / 1.0) */
        size_t off = 0;
        const double *arr[7] = {b->x, b->v, b->stress, b->mean, b->volume, b->plastic, b->F};
        size_t cnt[7] = {n * dim, n * dim, n * 6, n, n, n, nF};
        for (int i = 0; i < 7; i++)
            if (arr[i]) {
                memcpy(b->packed + off, arr[i], cnt[i] * sizeof(double));
                off += cnt[i];
            }
        if (b->yl)
            for (size_t i = 0; i < n; i++) b->packed[off++] = b->yl[i] ? 1.0 : 0.0;
        store_snapshot ss = {(int64_t)j->id,      s.step, s.t, (int64_t)n, dim, f, b->packed,
                             off * sizeof(double)};
        /* over a disk budget: not recorded, and the job ends */
        int rc = charge(c, (int64_t)ss.size) ? 0 : store_snapshot_put(c->e->st, &ss);
        if (rc) {
            refund(c, (int64_t)ss.size);
            srv_warn(j->id, "snapshot at step %lld not recorded: %s", (long long)s.step,
                     store_error()->message);
        }
    }
    if (slot >= 0) publish_snapshot(c, b, &s, seq, slot);
    return 0;
}

/* A snapshot where the schedule puts one: streamed if someone watches,
 * recorded if the case asks.  Returns 0 once snapshots failed for good
 * (out of memory: none after), else 1. */
static int snapshot_due(ctx *c, mpm_sim *sim, snapbuf *b)
{
    int watched = atomic_load_explicit(&c->j->watched, memory_order_relaxed);
    int record = c->j->sc->record_snapshots;
    if (!watched && !record) return 1;
    return snapshot(c, sim, b, watched, record) == 0;
}

static void progress(ctx *c, mpm_sim *sim, double wall)
{
    srv_job *j = c->j;
    int64_t k = mpm_sim_steps(sim);
    double t = mpm_sim_time(sim), dt = mpm_sim_dt(sim);
    /* steps still to go, in floating point first (end_time / dt may
     * exceed any integer: the step limit stops such a run, not this) */
    double left = j->sc->has_end_time && dt > 0 ? ceil((j->sc->end_time - t) / dt - 0.5) : 0;
    if (!(left < 9e18 - (double)k)) left = 9e18 - (double)k;
    int64_t total =
        j->sc->has_end_time ? k + (int64_t)(left > 0 ? left : 0) : (int64_t)j->sc->steps;
    flush_samples(c);
    pthread_mutex_lock(c->e->mu);
    j->steps = k;
    j->steps_total = total;
    j->t = t;
    j->wall_s = wall;
    pthread_mutex_unlock(c->e->mu);
    store_run_progress(c->e->st, (int64_t)j->id, k, wall,
                       wall > 0 ? (double)k * (double)mpm_sim_particles(sim) / wall : 0);
    mpp_progress pr = {k, total, t, dt, wall};
    uint8_t *buf = NULL;
    size_t len = 0;
    if (mpp_stream_progress(j->id, j->msg_seq++, &pr, &buf, &len))
        srv_warn(j->id, "out of memory encoding progress");
    publish(c, buf, len);
}

/* Records the end and publishes Finished. */
static void finish(ctx *c, int status, const char *error, int64_t steps, double t, double wall,
                   size_t particles, const mpm_energy_sample *last, const double *balance,
                   const char *warning)
{
    srv_job *j = c->j;
    flush_samples(c);
    store_run_end end = {0};
    end.status = (mpp_status)status;
    end.steps = steps;
    end.wall_s = wall;
    end.psteps_per_s = wall > 0 ? (double)steps * (double)particles / wall : 0;
    end.error = error;
    if (last) {
        end.has_energy = 1;
        end.energy = last->e;
    }
    end.has_balance = balance != NULL;
    end.balance_error = balance ? *balance : 0;
    end.warning = warning;
    int rc = store_run_finish(c->e->st, (int64_t)j->id, &end);
    if (rc) srv_warn(j->id, "end of run not recorded: %s", store_error()->message);
    mpp_finished f = {status, error, steps, t, wall, last, balance != NULL, end.balance_error,
                      warning};
    uint8_t *buf = NULL;
    size_t len = 0;
    if (mpp_stream_finished(j->id, j->msg_seq++, &f, &buf, &len))
        srv_warn(j->id, "out of memory encoding the end of the stream");
    publish(c, buf, len);
    srv_log(j->id, "%s after %lld steps, t = %g, %.3f s%s%s%s%s", mpp_status_name(status),
            (long long)steps, t, wall, error ? ": " : "", error ? error : "",
            warning ? "; warning: " : "", warning ? warning : "");
}

/* Saves a checkpoint of the job's run (see the header); on
 * success *ck_step is its step.  0, or the srv_ckpt_write() code (warned). */
static int take_checkpoint(ctx *c, mpm_sim *sim, srv_ckpt_buf *b, int64_t *ck_step)
{
    srv_job *j = c->j;
    double t0 = mono_now();
    /* every sample and snapshot before it committed first: a resume finds
     * the run's record complete up to the checkpoint, whenever the daemon
     * dies (a failed write shows in store_losses(), which ends the run) */
    flush_samples(c);
    store_flush(c->e->st);
    /* the disk budgets count the file at its size while it exists, and
     * the new one beside the old until the rename replaces it (guarded by
     * daemon_disk_checkpoint_budget) */
    int64_t need = (int64_t)(mpm_sim_checkpoint_size(sim) + SRV_CKPT_HEADER);
    if (charge(c, need)) {
        char why[sizeof c->overwhy + 96];
        snprintf(why, sizeof why, "checkpoint at step %lld (%lld bytes) not written: %s",
                 (long long)mpm_sim_steps(sim), (long long)need, c->overwhy);
        memcpy(c->overwhy, why, sizeof c->overwhy - 1);
        c->overwhy[sizeof c->overwhy - 1] = 0;
        srv_warn(j->id, "%s", why);
        return MPM_ETOOBIG;
    }
    store_checkpoint rec;
    char err[1600];
    int rc = srv_ckpt_write(c->e->cfg->db, (int64_t)j->id, sim, (int64_t)j->energy_seq, b, &rec,
                            err, sizeof err);
    if (rc) {
        refund(c, need);
        srv_warn(j->id, "checkpoint at step %lld not saved: %s", (long long)mpm_sim_steps(sim),
                 err);
        return rc;
    }
    refund(c, c->ck_bytes); /* the previous file is gone */
    c->ck_bytes = need;
    *ck_step = rec.step;
    if (store_run_checkpoint(c->e->st, (int64_t)j->id, &rec))
        srv_warn(j->id, "checkpoint at step %lld not recorded: %s", (long long)rec.step,
                 store_error()->message);
    srv_debug(j->id, "checkpoint at step %lld: %lld bytes in %.3f s", (long long)rec.step,
              (long long)rec.bytes, mono_now() - t0);
    return 0;
}

/* Loads a resumed job's checkpoint into sim; 0, or -1 after ending the
 * job INTERRUPTED again (its checkpoint kept) with the reason. */
static int resume_load(ctx *c, mpm_sim *sim)
{
    srv_job *j = c->j;
    mpm_error me;
    if (mpm_sim_checkpoint_load(sim, j->ck.blob, j->ck.blob_len, &me) == 0) {
        j->energy_seq = (uint64_t)j->ck.rec.energy_seq;
        /* its file is on disk, counted by the owner's and the server's
         * budgets already: the job's own count takes it too */
        c->ck_bytes = j->ck.rec.bytes;
        c->recorded += c->ck_bytes;
        srv_log(j->id, "resumed from its checkpoint at step %lld, t = %g",
                (long long)j->ck.rec.step, j->ck.rec.t);
        srv_ckpt_file_clear(&j->ck); /* the blob is in sim now */
        return 0;
    }
    char text[700], why[800];
    mpm_error_text(&me, MPM_FIELD_PROTO, text, sizeof text);
    snprintf(why, sizeof why, "checkpoint at step %lld not loadable: %s", (long long)j->ck.rec.step,
             text);
    finish(c, MPP_STATUS_INTERRUPTED, why, j->ck.rec.step, j->ck.rec.t, j->prior_wall, 0,
           j->last.step >= 0 ? &j->last : NULL, NULL, NULL);
    return -1;
}

void srv_job_run(const srv_job_env *e, void *push, srv_job *j)
{
    ctx c = {e, push, j, "", NULL, 0, 0, "", 0};
    srv_topic(j->id, c.topic);
    mpp_case *sc = j->sc;
    const srv_config *cfg = e->cfg;
    /* a resumed run's wall time adds up */
    double start = srv_wall_now(), t0 = mono_now() - j->prior_wall;
    store_run_set_status(e->st, (int64_t)j->id, MPP_STATUS_RUNNING, start, NULL);
    int threads = sc->c.threads > 0 && sc->c.threads < cfg->solver_threads ? sc->c.threads
                                                                           : cfg->solver_threads;
    sc->c.threads = threads;
    if (cfg->portable_kernels) sc->c.kernels = MPM_KERNELS_PORTABLE;
    char err[512];
    mpm_error me;
    /* the case passed the codec's check (sc->info); threads is checked again */
    mpm_sim *sim = mpm_sim_new(&sc->c, &sc->info, &me);
    if (!sim) {
        finish(&c, MPP_STATUS_FAILED, mpm_error_text(&me, MPM_FIELD_PROTO, err, sizeof err), 0, 0,
               0, 0, NULL, NULL, NULL);
        return;
    }
    size_t n = mpm_sim_particles(sim);
    pthread_mutex_lock(e->mu);
    j->started_at = start;
    j->particles = n;
    j->nodes = mpm_sim_nodes(sim);
    pthread_mutex_unlock(e->mu);
    srv_log(j->id, "running: %zu particles, %zu nodes, %d thread%s", n, mpm_sim_nodes(sim), threads,
            threads > 1 ? "s" : "");
    char plan[MPM_PLAN_LEN];
    mpm_sim_plan(sim, plan, sizeof plan);
    /* the fast paths the job runs (mpm_sim_plan()), logged and stored with
     * the run (RunInfo.plan); a plan the store could not queue is only
     * logged */
    srv_log(j->id, "plan: %s", plan);
    if (store_run_plan(e->st, (int64_t)j->id, plan))
        srv_warn(j->id, "plan not recorded: %s", store_error()->message);

    mpm_energy_sample last;
    snapbuf sb = {0};
    /* without it (out of memory) samples go out one by one */
    c.pe = sc->energy_every ? calloc(1, sizeof *c.pe) : NULL;
    if (c.pe) c.pe->last_flush = c.pe->last_sample = mono_now();
    /* checkpoints: the case's schedule, else the server's default */
    unsigned ck_steps = sc->has_checkpoint ? sc->checkpoint_every_steps : 0;
    double ck_wall = sc->has_checkpoint ? sc->checkpoint_every_wall_s : cfg->checkpoint_every_s;
    int ck_on = ck_steps || ck_wall > 0;
    int64_t ck_step = j->resume ? j->ck.rec.step : -1; /* the last one's */
    srv_ckpt_buf ckb = {0};
    if (j->resume && resume_load(&c, sim)) {
        free(c.pe);
        mpm_sim_destroy(&sim);
        return;
    }
    double ck_last = mono_now(), ck_cost = 0; /* the last one's duration */
    int snaps_ok = 1, status = MPP_STATUS_FINISHED;
    char why[512] = "", loss[400];
    /* writes the store loses whole (a full disk) end the run: its record
     * would be missing its samples, and nobody would know */
    uint64_t lost0 = store_losses(e->st, NULL, 0);
    if (j->resume)
        last = j->last; /* the step-0 sample and those up to the checkpoint are stored */
    else
        energy_sample(&c, sim, &last);
    unsigned every = sc->energy_every, severy = sc->snapshot_every;
    /* a run that takes snapshots has one of its initial state and one of
     * its end (below), whatever the spacing: the first and last frames of
     * an export (guarded by ctl_compressed_outputs); taking one reads
     * the particles only, so the energy series keeps its bits */
    if (severy && !j->resume) snaps_ok = snapshot_due(&c, sim, &sb);
    progress(&c, sim, j->prior_wall);
    double next_progress = j->prior_wall + 0.2;
    for (;;) {
        int cancel = atomic_load_explicit(&j->cancel, memory_order_relaxed);
        if (cancel) {
            /* a shutdown keeps what the run has done for a resume */
            if (cancel == SRV_JOB_CANCEL_SHUTDOWN && ck_on && ck_step != mpm_sim_steps(sim))
                take_checkpoint(&c, sim, &ckb, &ck_step);
            status = cancel == SRV_JOB_CANCEL_USER ? MPP_STATUS_CANCELLED : MPP_STATUS_INTERRUPTED;
            snprintf(why, sizeof why, "%s at step %ld",
                     cancel == SRV_JOB_CANCEL_USER ? "cancelled by a client"
                                                   : "daemon shutting down",
                     mpm_sim_steps(sim));
            break;
        }
        if (c.over) {
            status = MPP_STATUS_FAILED;
            snprintf(why, sizeof why, "%s", c.overwhy);
            break;
        }
        int64_t k = mpm_sim_steps(sim);
        if (sc->has_end_time ? mpm_sim_time(sim) >= sc->end_time - 0.5 * mpm_sim_dt(sim)
                             : k >= (int64_t)sc->steps)
            break;
        if (k >= cfg->max_steps) {
            status = MPP_STATUS_FAILED;
            snprintf(why, sizeof why, "step limit %lld of this server reached (--max-steps)",
                     cfg->max_steps);
            break;
        }
        /* a step ending on a sample point sums the energies in its own
         * passes: energy_sample() then costs no pass of its own */
        if (every && (k + 1) % every == 0) mpm_sim_want_energy(sim);
        if (mpm_sim_step(sim)) {
            status = MPP_STATUS_FAILED;
            mpm_error_text(mpm_sim_error(sim), MPM_FIELD_PROTO, why, sizeof why);
            break;
        }
        k++;
        if (every && k % every == 0) energy_sample(&c, sim, &last);
        if (severy && snaps_ok && k % severy == 0) snaps_ok = snapshot_due(&c, sim, &sb);
        /* the checkpoints take at most --checkpoint-share of the job's
         * wall time: one comes at least (1 - share) / share times the
         * last one's duration after it, whatever the schedule asks
         * (guarded by daemon_disk_checkpoint_budget) */
        if (ck_on &&
            ((ck_steps && k % ck_steps == 0) || (ck_wall > 0 && mono_now() - ck_last >= ck_wall)) &&
            mono_now() - ck_last >= ck_cost * (1 - cfg->checkpoint_share) / cfg->checkpoint_share &&
            !(sc->has_end_time ? mpm_sim_time(sim) >= sc->end_time - 0.5 * mpm_sim_dt(sim)
                               : k >= (int64_t)sc->steps)) {
            /* (none after the last step: the run ends there.)  The solver
             * or memory refusing is for good; a file error may pass */
            double ck_t0 = mono_now();
            int rc = take_checkpoint(&c, sim, &ckb, &ck_step);
            if (rc && rc != MPM_EIO) ck_on = 0;
            ck_last = mono_now();
            ck_cost = ck_last - ck_t0;
        }
        if ((k & 31) == 0) {
            double w = mono_now() - t0;
            if (w >= next_progress) {
                progress(&c, sim, w);
                next_progress = w + 0.2;
                if (store_losses(e->st, loss, sizeof loss) > lost0) {
                    status = MPP_STATUS_FAILED;
                    snprintf(why, sizeof why, "%s: %s", SRV_STORE_LOST, loss);
                    break;
                }
            }
            if (cfg->max_wall_s > 0 && w > cfg->max_wall_s) {
                status = MPP_STATUS_FAILED;
                snprintf(why, sizeof why,
                         "wall-time limit %g s of this server reached "
                         "(--max-wall-s)",
                         cfg->max_wall_s);
                break;
            }
        }
    }
    double wall = mono_now() - t0;
    /* the divergence guard once more before a run is called finished: a
     * blow-up in the last steps must not be recorded as a result */
    if (status == MPP_STATUS_FINISHED && mpm_sim_check(sim)) {
        status = MPP_STATUS_FAILED;
        mpm_error_text(mpm_sim_error(sim), MPM_FIELD_PROTO, why, sizeof why);
    }
    /* (without waiting for the last commit: a loss in the run's last batch
     * shows in the log and at the next start, not here) */
    if (status == MPP_STATUS_FINISHED && store_losses(e->st, loss, sizeof loss) > lost0) {
        status = MPP_STATUS_FAILED;
        snprintf(why, sizeof why, "%s: %s", SRV_STORE_LOST, loss);
    }
    if (last.step != mpm_sim_steps(sim) && status != MPP_STATUS_FAILED)
        energy_sample(&c, sim, &last);
    else if (status == MPP_STATUS_FAILED && last.step != mpm_sim_steps(sim)) {
        /* a diverged state has no meaningful energies; keep the last good one */
    }
    /* the end's snapshot, unless the last step took one (not of a failed
     * run: its state may be the blow-up; nor of an interrupted one: its
     * resume goes on from the checkpoint) */
    if (severy && snaps_ok && mpm_sim_steps(sim) % severy != 0 &&
        (status == MPP_STATUS_FINISHED || status == MPP_STATUS_CANCELLED))
        snapshot_due(&c, sim, &sb);
    /* the last samples may pass a disk budget: then the run is not whole */
    flush_samples(&c);
    if (c.over && status == MPP_STATUS_FINISHED) {
        status = MPP_STATUS_FAILED;
        snprintf(why, sizeof why, "%s", c.overwhy);
    }
    /* the energy budget, on the balance error of the run's last sample (the
     * final one): a warning recorded with the run, or FAILED if the case
     * asks (Case.fail_on_budget) */
    double balance;
    char warn[512] = "";
    int over = mpm_sim_budget(sim, &balance, NULL, warn, sizeof warn);
    if (over && status == MPP_STATUS_FINISHED && sc->c.fail_on_budget) {
        status = MPP_STATUS_FAILED;
        snprintf(why, sizeof why, "%s", warn);
        warn[0] = 0;
    }
    progress(&c, sim, wall);
    if (!strncmp(why, SRV_STORE_LOST, strlen(SRV_STORE_LOST))) {
        pthread_mutex_lock(e->mu);
        srv_job_lost *l = e->lost;
        unsigned i = l->n++ % SRV_JOB_LOST_MAX;
        l->v[i].id = j->id;
        l->v[i].steps = mpm_sim_steps(sim);
        l->v[i].t = mpm_sim_time(sim);
        l->v[i].wall_s = wall;
        pthread_mutex_unlock(e->mu);
    }
    /* and the solver's own warnings (mpm_sim_warnings()), after it */
    char swarn[600], allwarn[sizeof warn + sizeof swarn + 2];
    int sw = mpm_sim_warnings(sim, swarn, sizeof swarn);
    snprintf(allwarn, sizeof allwarn, "%s%s%s", over ? warn : "", over && warn[0] && sw ? "; " : "",
             sw ? swarn : "");
    finish(&c, status, why[0] ? why : NULL, mpm_sim_steps(sim), mpm_sim_time(sim), wall, n, &last,
           &balance, allwarn[0] ? allwarn : NULL);
    /* only an interrupted run may be resumed: any other end drops its
     * checkpoint (a run that never took one touches nothing) */
    if (status != MPP_STATUS_INTERRUPTED && ck_step >= 0) {
        if (srv_ckpt_remove(cfg->db, (int64_t)j->id))
            srv_warn(j->id, "its checkpoint file not removed: %s", strerror(errno));
        else
            refund(&c, c.ck_bytes);
        if (store_run_checkpoint(e->st, (int64_t)j->id, NULL))
            srv_warn(j->id, "checkpoint removal not recorded: %s", store_error()->message);
    }
    free(ckb.buf);
    if (sb.dropped)
        srv_log(j->id, "%llu snapshot(s) not streamed: watchers lagged (--stream-total-mb %d)",
                (unsigned long long)sb.dropped, cfg->stream_total_mb);
    snapbuf_free(&sb);
    free(c.pe); /* empty: finish() handed everything on */
    mpm_sim_destroy(&sim);
}
