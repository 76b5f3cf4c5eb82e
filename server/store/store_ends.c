/*
 * store_ends.c - what keeps a full disk from losing a run's end, and the
 * disk reserve (see store_writer.c's header for when they are used).
 *
 * Kept ends.  The end of a run (OP_RUN_FINISH) whose transaction the disk
 * lost is kept in s->defer (at most DEFER_MAX) and written into a slot of
 * the side file "<db>.ends": ENDS_SLOTS slots of 512 bytes, allocated
 * (posix_fallocate) when the store opens, so that writing one needs no new
 * block of a full disk; each slot carries a checksum, a torn one is
 * ignored.  The next store_open loads them before its crash recovery, so a
 * run the disk stopped reads FAILED with its reason, not 'interrupted'.
 * Reads show the kept ends, and the runs a pending crash recovery will
 * mark, as they will be written (sti_ends_overlay).
 *
 * The reserve.  "<db>.reserve" holds reserve_bytes (1 MiB) allocated while
 * there is room.  A lost transaction releases it, and so does an open that
 * finds no room for SQLite's WAL index: its room goes to the upkeep, the
 * crash recovery and the reads.  The store takes no new work
 * (store_writable) until the writer has put it back, i.e. until the disk
 * has that much free again.  Guarded by the daemon_disk_* tests.
 */
#define _GNU_SOURCE
#include "store_internal.h"

#include "store_ends.h"
#include "store_sql.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define END_MAGIC "MPMDEND1"

/* One slot of the side file (the host's layout, as the checkpoints). */
typedef struct {
    char magic[8];
    int64_t run_id;
    int32_t status, flags; /* flags: 1 has_energy, 2 has_balance, 4 error, 8 warning */
    int64_t steps;
    double finished_at, wall_s, psteps_per_s;
    double energy[5]; /* kinetic, strain, potential, external_work, total */
    double balance_error;
    char error[296];
    char warning[104];
    uint64_t sum; /* of the bytes before it */
} end_slot;

_Static_assert(sizeof(end_slot) == 512, "a slot of the side file is 512 bytes");

static uint64_t slot_sum(const end_slot *e)
{
    const unsigned char *p = (const unsigned char *)e;
    uint64_t h = 0xcbf29ce484222325ULL;
    for (size_t i = 0; i < offsetof(end_slot, sum); i++) h = (h ^ p[i]) * 0x100000001b3ULL;
    return h;
}

/* The texts of a kept end point into itself. */
static void fix_texts(deferred_end *d, int has_error, int has_warning)
{
    d->end.error = has_error ? d->error : NULL;
    d->end.warning = has_warning ? d->warning : NULL;
}

/* Appends d to s->defer (under s->mu); -1 when full or out of memory. */
static int defer_add_locked(store *s, const deferred_end *d)
{
    if (s->ndefer >= DEFER_MAX) return -1;
    deferred_end *v = realloc(s->defer, (s->ndefer + 1) * sizeof *v);
    if (!v) return -1;
    s->defer = v;
    v[s->ndefer] = *d;
    fix_texts(&v[s->ndefer], d->end.error != NULL, d->end.warning != NULL);
    s->ndefer++;
    return 0;
}

void sti_ends_open(store *s)
{
    int fd = open(s->ends_path, O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    if (fd < 0) {
        sti_log(s, "cannot open %s: %s (run ends a full disk stops are kept in memory only)",
                s->ends_path, strerror(errno));
        return;
    }
    struct stat st;
    off_t want = (off_t)ENDS_SLOTS * (off_t)sizeof(end_slot);
    if (fstat(fd, &st) == 0 && st.st_size < want) {
        int e = posix_fallocate(fd, 0, want);
        if (e) {
            sti_log(s, "cannot allocate %s: %s", s->ends_path, strerror(e));
            if (fstat(fd, &st)) st.st_size = 0;
        } else {
            st.st_size = want;
        }
    }
    s->ends_fd = fd;
    s->ends_slots = (int)(st.st_size / (off_t)sizeof(end_slot));
    if (s->ends_slots > ENDS_SLOTS) s->ends_slots = ENDS_SLOTS;
    size_t loaded = 0;
    for (int i = 0; i < s->ends_slots; i++) {
        end_slot e;
        if (pread(fd, &e, sizeof e, (off_t)i * (off_t)sizeof e) != (ssize_t)sizeof e) break;
        if (memcmp(e.magic, END_MAGIC, 8) || slot_sum(&e) != e.sum) continue;
        deferred_end d;
        memset(&d, 0, sizeof d);
        d.run_id = e.run_id;
        d.slot = i;
        d.end.status = (mpp_status)e.status;
        d.end.steps = e.steps;
        d.end.finished_at = e.finished_at;
        d.end.wall_s = e.wall_s;
        d.end.psteps_per_s = e.psteps_per_s;
        d.end.has_energy = (e.flags & 1) != 0;
        d.end.energy.kinetic = e.energy[0];
        d.end.energy.strain = e.energy[1];
        d.end.energy.potential = e.energy[2];
        d.end.energy.external_work = e.energy[3];
        d.end.energy.total = e.energy[4];
        d.end.has_balance = (e.flags & 2) != 0;
        d.end.balance_error = e.balance_error;
        memcpy(d.error, e.error, sizeof d.error);
        d.error[sizeof d.error - 1] = 0;
        memcpy(d.warning, e.warning, sizeof d.warning);
        d.warning[sizeof d.warning - 1] = 0;
        d.end.error = (e.flags & 4) ? d.error : NULL;
        d.end.warning = (e.flags & 8) ? d.warning : NULL;
        if (!sti_status_ok(d.end.status) || !MPP_STATUS_ENDED(d.end.status)) continue;
        pthread_mutex_lock(&s->mu);
        int full = defer_add_locked(s, &d);
        if (!full) s->ends_used |= 1ull << i;
        pthread_mutex_unlock(&s->mu);
        if (!full) loaded++;
    }
    if (loaded)
        sti_log(s,
                "%s: %zu run end(s) a full disk kept out of the database, written now or once "
                "there is room",
                s->ends_path, loaded);
}

void sti_ends_close(store *s)
{
    if (s->ends_fd >= 0) close(s->ends_fd);
    s->ends_fd = -1;
    free(s->defer);
    s->defer = NULL;
    s->ndefer = 0;
}

void sti_ends_keep(store *s, int64_t run_id, const store_run_end *end)
{
    deferred_end d;
    memset(&d, 0, sizeof d);
    d.run_id = run_id;
    d.end = *end;
    d.slot = -1;
    snprintf(d.error, sizeof d.error, "%s", end->error ? end->error : "");
    snprintf(d.warning, sizeof d.warning, "%s", end->warning ? end->warning : "");
    fix_texts(&d, end->error != NULL, end->warning != NULL);
    /* a free slot of the side file (only this thread changes ends_used
     * after open) */
    int slot = -1;
    for (int i = 0; s->ends_fd >= 0 && i < s->ends_slots && slot < 0; i++)
        if (!(s->ends_used & (1ull << i))) slot = i;
    if (slot >= 0) {
        end_slot e;
        memset(&e, 0, sizeof e);
        memcpy(e.magic, END_MAGIC, 8);
        e.run_id = run_id;
        e.status = (int32_t)end->status;
        e.flags = (end->has_energy ? 1 : 0) | (end->has_balance ? 2 : 0) | (end->error ? 4 : 0) |
                  (end->warning ? 8 : 0);
        e.steps = end->steps;
        e.finished_at = end->finished_at;
        e.wall_s = end->wall_s;
        e.psteps_per_s = end->psteps_per_s;
        e.energy[0] = end->energy.kinetic;
        e.energy[1] = end->energy.strain;
        e.energy[2] = end->energy.potential;
        e.energy[3] = end->energy.external_work;
        e.energy[4] = end->energy.total;
        e.balance_error = end->balance_error;
        memcpy(e.error, d.error, sizeof e.error);
        memcpy(e.warning, d.warning, sizeof e.warning);
        e.sum = slot_sum(&e);
        if (pwrite(s->ends_fd, &e, sizeof e, (off_t)slot * (off_t)sizeof e) == (ssize_t)sizeof e &&
            fdatasync(s->ends_fd) == 0) {
            d.slot = slot;
        } else {
            sti_log(s, "cannot keep the end of run %" PRId64 " in %s: %s (kept in memory)", run_id,
                    s->ends_path, strerror(errno));
        }
    }
    pthread_mutex_lock(&s->mu);
    int full = defer_add_locked(s, &d);
    if (!full && d.slot >= 0) s->ends_used |= 1ull << d.slot;
    pthread_mutex_unlock(&s->mu);
    if (full) {
        sti_log(s, "the end of run %" PRId64 " (%s: %s) is lost: %d ends are kept already", run_id,
                sti_status_name(end->status), d.error, DEFER_MAX);
        if (d.slot >= 0) {
            end_slot z;
            memset(&z, 0, sizeof z);
            if (pwrite(s->ends_fd, &z, sizeof z, (off_t)d.slot * (off_t)sizeof z) < 0)
                sti_log(s, "clearing a slot of %s: %s", s->ends_path, strerror(errno));
        }
    } else {
        sti_log(s, "the end of run %" PRId64 " (%s) is kept %s until the store can write it",
                run_id, sti_status_name(end->status),
                d.slot >= 0 ? "in the side file" : "in memory");
    }
}

void sti_ends_drop(store *s, size_t n)
{
    end_slot z;
    memset(&z, 0, sizeof z);
    int cleared = 0;
    pthread_mutex_lock(&s->mu);
    if (n > s->ndefer) n = s->ndefer;
    for (size_t i = 0; i < n; i++) {
        int slot = s->defer[i].slot;
        if (slot < 0 || s->ends_fd < 0) continue;
        if (pwrite(s->ends_fd, &z, sizeof z, (off_t)slot * (off_t)sizeof z) == (ssize_t)sizeof z)
            cleared = 1;
        s->ends_used &= ~(1ull << slot);
    }
    if (n && s->ndefer > n) memmove(s->defer, s->defer + n, (s->ndefer - n) * sizeof *s->defer);
    s->ndefer -= n;
    for (size_t i = 0; i < s->ndefer; i++)
        fix_texts(&s->defer[i], s->defer[i].end.error != NULL, s->defer[i].end.warning != NULL);
    pthread_mutex_unlock(&s->mu);
    if (cleared && fdatasync(s->ends_fd))
        sti_log(s, "syncing %s: %s", s->ends_path, strerror(errno));
}

/* Replaces *p (a string owned by a run read back) with a copy of v. */
static void set_text(const char **p, const char *v)
{
    char *c = v ? strdup(v) : NULL;
    if (v && !c) return; /* out of memory: the stored text stays */
    free((void *)*p);
    *p = c;
}

void sti_ends_overlay(store *s, store_run *r)
{
    pthread_mutex_lock(&s->mu);
    const deferred_end *d = NULL;
    for (size_t i = 0; i < s->ndefer; i++)
        if (s->defer[i].run_id == r->id) d = &s->defer[i];
    if (d && !MPP_STATUS_ENDED(r->status)) {
        r->status = d->end.status;
        r->finished_at = d->end.finished_at;
        r->steps = d->end.steps;
        r->wall_s = d->end.wall_s;
        r->psteps_per_s = d->end.psteps_per_s;
        if (d->end.has_energy) {
            r->energy.kinetic = d->end.energy.kinetic;
            r->energy.strain = d->end.energy.strain;
            r->energy.potential = d->end.energy.potential;
            r->energy.external_work = d->end.energy.external_work;
            r->energy.total = d->end.energy.total;
        }
        r->has_balance = d->end.has_balance;
        r->balance_error = d->end.balance_error;
        set_text(&r->error, d->end.error);
        set_text(&r->warning, d->end.warning);
    } else if (!d && s->recovery_pending && r->id < s->recover_below &&
               (r->status == MPP_STATUS_RUNNING || r->status == MPP_STATUS_QUEUED)) {
        set_text(&r->error, r->status == MPP_STATUS_RUNNING ? STORE_INTERRUPTED_RUNNING
                                                            : STORE_INTERRUPTED_QUEUED);
        r->status = MPP_STATUS_INTERRUPTED;
    }
    pthread_mutex_unlock(&s->mu);
}

int sti_reserve_exists(store *s)
{
    struct stat st;
    int ok = s->reserve_bytes > 0 && stat(s->reserve_path, &st) == 0 && S_ISREG(st.st_mode) &&
             (long long)st.st_blocks * 512 >= s->reserve_bytes;
    pthread_mutex_lock(&s->mu);
    s->reserve_ok = ok;
    pthread_mutex_unlock(&s->mu);
    return ok;
}

int sti_reserve_make(store *s)
{
    if (s->reserve_bytes <= 0) return 0;
    int fd = open(s->reserve_path, O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    int e = fd < 0 ? errno : posix_fallocate(fd, 0, (off_t)s->reserve_bytes);
    if (e) {
        pthread_mutex_lock(&s->mu);
        snprintf(s->reserve_why, sizeof s->reserve_why, "%s", strerror(e));
        pthread_mutex_unlock(&s->mu);
        if (fd < 0) return -1;
        /* no room: nothing half-allocated stays */
        if (ftruncate(fd, 0)) {
        }
        close(fd);
        unlink(s->reserve_path);
        return -1;
    }
    close(fd);
    pthread_mutex_lock(&s->mu);
    int was = s->reserve_ok;
    s->reserve_ok = 1;
    pthread_mutex_unlock(&s->mu);
    if (!was && s->reserve_next > 0)
        sti_log(s, "the disk reserve (%lld KiB) is back in place: the store takes new work",
                s->reserve_bytes / 1024);
    return 0;
}

void sti_reserve_release(store *s, const char *why)
{
    if (s->reserve_bytes <= 0) return;
    int had = unlink(s->reserve_path) == 0;
    pthread_mutex_lock(&s->mu);
    s->reserve_ok = 0;
    pthread_mutex_unlock(&s->mu);
    s->reserve_next = sti_mono_now() + UPKEEP_S;
    if (had)
        sti_log(s,
                "released the disk reserve (%lld KiB) for the store's own writes (%s); new "
                "runs are refused until it is back",
                s->reserve_bytes / 1024, why);
}
