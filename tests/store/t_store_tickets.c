/*
 * t_store_tickets.c - the store's commit tracking without blocking: a
 * ticket per run is done once that run's writes are committed, the notify
 * descriptor becomes readable after a commit, and many runs fit; the
 * owners' recorded bytes (store_owner_totals), a run's owner and the
 * listing by owner.
 */
#include "store.h"
#include "t.h"
#include "t_daemon.h"
#include "t_store.h"

#include <fcntl.h>
#include <poll.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* ---- commit tracking without blocking ---- */

/* 1 when fd becomes readable within ms milliseconds. */
static int readable_within(int fd, int ms)
{
    struct pollfd p = {.fd = fd, .events = POLLIN};
    return poll(&p, 1, ms) == 1 && (p.revents & POLLIN);
}

/* Waits (at most 5 s) in a poll loop on the notify fd until the ticket is
 * done, as the daemon's event loop would; 1 if it is. */
static int wait_ticket(store *s, uint64_t t)
{
    double t0 = td_now();
    while (!store_ticket_done(s, t) && td_now() - t0 < 5)
        if (readable_within(store_notify_fd(s), 1000)) store_notify_drain(s);
    return store_ticket_done(s, t);
}

TEST(store_tickets)
{
    /* nothing commits on its own for 60 s: whatever commits does so because
     * a ticket (or a flush) asked for it */
    store_options o = {.batch_ms = 60000, .log = quiet_log};
    store *s = NULL;
    CHECKF(store_open(db_path("tickets.db"), &o, &s) == 0, "%s", store_error()->message);
    int fd = store_notify_fd(s);
    CHECK(fd >= 0);
    CHECK(fcntl(fd, F_GETFL) & O_NONBLOCK);
    store_run in = sample_run("A", MPP_STATUS_RUNNING);
    int64_t a, b;
    CHECK(store_run_insert(s, &in, &a) == 0);
    in.name = "B";
    CHECK(store_run_insert(s, &in, &b) == 0);
    CHECK(store_flush(s) == 0);
    CHECK(readable_within(fd, 0)); /* the flush's commit */
    store_notify_drain(s);
    CHECK(!readable_within(fd, 0)); /* drained */
    store_notify_drain(s);          /* draining an empty fd: no-op */

    /* nothing pending: tickets are done at once */
    CHECK(store_ticket(s, a) == 0 && store_ticket_done(s, 0));
    CHECK(store_ticket(s, 0) == 0);
    CHECK(store_ticket(s, 424242) == 0);

    /* samples for A and B; A's ticket is that of A's write, and it is done
     * (and the fd readable) after a commit the ticket asked for */
    store_stats st0;
    store_get_stats(s, &st0);
    mpm_energy_sample ea = make_sample(a, 0), eb = make_sample(b, 0);
    CHECK(store_energy_append(s, a, &ea, 1) == 0);
    CHECK(store_energy_append(s, b, &eb, 1) == 0);
    uint64_t ta = store_ticket(s, a);
    CHECKF(ta == st0.ops_enqueued + 1, "ticket %llu, want %llu", (unsigned long long)ta,
           (unsigned long long)st0.ops_enqueued + 1);
    double t0 = td_now();
    CHECK(readable_within(fd, 5000));
    CHECKF(wait_ticket(s, ta), "run A's ticket not done");
    double dt = td_now() - t0;
    TLOG("run A's ticket done after %.1f ms (batching window 60 s)", 1e3 * dt);
    CHECK_LT(dt, 5.0);
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    CHECK(store_energy_read(s, a, 0, 0, &es, &nes) == 0);
    int ok = nes == 1 && sample_equals(es, 0, a, 0);
    free(es);
    CHECKF(ok, "run A's sample not readable when its ticket is done");
    store_notify_drain(s);

    /* a write for B only: A's ticket does not wait for it */
    CHECK(wait_ticket(s, store_ticket(s, b))); /* B's first sample is in */
    mpm_energy_sample eb1 = make_sample(b, 1);
    CHECK(store_energy_append(s, b, &eb1, 1) == 0);
    CHECK(store_ticket(s, a) == 0); /* A has nothing pending */
    store_stats st1;
    store_get_stats(s, &st1);
    CHECKF(st1.queue_ops == 1, "%zu writes pending, want B's", st1.queue_ops);
    CHECK(store_energy_read(s, b, 0, 0, &es, &nes) == 0);
    free(es);
    CHECKF(nes == 1, "B's second sample committed without being asked for (%zu)", nes);
    uint64_t tb = store_ticket(s, b);
    CHECK(tb == st1.ops_enqueued);
    CHECK(wait_ticket(s, tb));
    CHECK(store_energy_read(s, b, 0, 0, &es, &nes) == 0);
    ok = nes == 2 && sample_equals(es, 0, b, 0) && sample_equals(es, 1, b, 1);
    free(es);
    CHECK(ok);
    CHECK(store_ticket(s, b) == 0 && store_ticket(s, 0) == 0);

    /* any run: a ticket covers every write enqueued before it */
    CHECK(store_run_progress(s, a, 5, 1, 1) == 0);
    CHECK(store_run_progress(s, b, 6, 1, 1) == 0);
    uint64_t tall = store_ticket(s, 0);
    CHECK(tall == tb + 2);
    CHECK(wait_ticket(s, tall));
    store_run r;
    CHECK(store_run_get(s, a, &r) == 0);
    ok = r.steps == 5;
    store_run_clear(&r);
    CHECK(store_run_get(s, b, &r) == 0);
    ok = ok && r.steps == 6;
    store_run_clear(&r);
    CHECK(ok);

    /* a failed write completes its ticket too (flush reports it) */
    CHECK(store_run_progress(s, 9999, 1, 1, 1) == 0);
    uint64_t tf = store_ticket(s, 9999);
    CHECK(tf == tall + 1);
    CHECK(wait_ticket(s, tf));
    CHECK(store_flush(s) == MPM_EIO);
    store_close(&s);
}

TEST(store_tickets_many_runs)
{
    /* more runs than the ticket map's first size: it is rebuilt, and every
     * run's ticket stays that of its last write */
    store_options o = {.batch_ms = 60000, .log = quiet_log};
    store *s = NULL;
    CHECKF(store_open(db_path("tickets2.db"), &o, &s) == 0, "%s", store_error()->message);
    enum { NRUNS = 300 };
    int64_t ids[NRUNS];
    store_stats st0;
    store_get_stats(s, &st0);
    for (int i = 0; i < NRUNS; i++) {
        store_run in = sample_run("many", MPP_STATUS_QUEUED);
        CHECK(store_run_insert(s, &in, &ids[i]) == 0);
    }
    /* a second write for the even runs, after all the inserts */
    for (int i = 0; i < NRUNS; i += 2) CHECK(store_run_progress(s, ids[i], i, 1, 1) == 0);
    store_stats st1;
    store_get_stats(s, &st1);
    CHECK(st1.queue_ops == NRUNS + NRUNS / 2); /* nothing committed yet */
    /* run_ticket(i): insert i is op base + i + 1, progress of 2k op base + NRUNS + k + 1 */
    uint64_t base = st0.ops_enqueued;
    int pending = 0;
    for (int i = NRUNS - 1; i >= 0; i--) {
        uint64_t want = i % 2 ? base + (uint64_t)i + 1 : base + NRUNS + (uint64_t)i / 2 + 1;
        uint64_t t = store_ticket(s, ids[i]);
        /* an earlier ticket may have had it committed already */
        if (t != 0 && t != want)
            CHECKF(0, "run %d: ticket %llu, want %llu", i, (unsigned long long)t,
                   (unsigned long long)want);
        pending += t != 0;
    }
    TLOG("%d of %d tickets taken while their writes were pending", pending, NRUNS);
    CHECK(pending > 0); /* the first at least: nothing had committed */
    CHECK(store_flush(s) == 0);
    for (int i = 0; i < NRUNS; i++) CHECK(store_ticket(s, ids[i]) == 0);
    /* after the commits, the map is rebuilt without them */
    for (int i = 0; i < NRUNS; i++) CHECK(store_run_progress(s, ids[i], 1000 + i, 1, 1) == 0);
    uint64_t last = store_ticket(s, ids[NRUNS - 1]);
    CHECK(last == st1.ops_enqueued + NRUNS);
    CHECK(store_flush(s) == 0);
    CHECK(store_ticket_done(s, last));
    store_close(&s);
}

/* ---- the owners' recorded bytes (the daemon's disk budgets) ---- */

/* store_owner_totals: one row per owner, each the same figure as
 * store_owner_bytes (snapshot bytes + STORE_ENERGY_ROW_BYTES per sample),
 * runs without records counted 0; the listing's owner filter. */
TEST(store_owner_totals)
{
    store *s = NULL;
    store_options o = {.log = quiet_log};
    CHECKF(store_open(db_path("owners.db"), &o, &s) == 0, "%s", store_error()->message);
    static const char *const owners[3] = {"alice", "bob", "carol"};
    int64_t id[4];
    for (int k = 0; k < 4; k++) {
        store_run in = sample_run("owned", MPP_STATUS_RUNNING);
        in.owner = owners[k == 3 ? 0 : k]; /* alice has two runs */
        CHECK(store_run_insert(s, &in, &id[k]) == 0);
    }
    /* alice: 1000 + 24 bytes and 3 samples; bob: 5 samples; carol: none */
    static unsigned char blob[1000];
    store_snapshot a = {
        .run_id = id[0], .step = 1, .n = 1, .dim = 1, .fields = 1, .data = blob, .size = 1000};
    store_snapshot b = {
        .run_id = id[3], .step = 1, .n = 1, .dim = 1, .fields = 1, .data = blob, .size = 24};
    CHECK(store_snapshot_put(s, &a) == 0 && store_snapshot_put(s, &b) == 0);
    mpm_energy_sample e[5];
    memset(e, 0, sizeof e);
    for (int i = 0; i < 5; i++) e[i].seq = (uint64_t)i, e[i].dim = 1;
    CHECK(store_energy_append(s, id[0], e, 2) == 0 && store_energy_append(s, id[3], e, 1) == 0);
    CHECK(store_energy_append(s, id[1], e, 5) == 0);
    CHECK(store_flush(s) == 0);
    store_owner_total *rows = NULL;
    size_t n = 0;
    CHECK(store_owner_totals(s, &rows, &n) == 0);
    int64_t want[3] = {1024 + 3 * STORE_ENERGY_ROW_BYTES, 5 * STORE_ENERGY_ROW_BYTES, 0};
    int ok = n == 3;
    for (size_t i = 0; ok && i < n; i++) {
        int k = !strcmp(rows[i].owner, "alice") ? 0 : !strcmp(rows[i].owner, "bob") ? 1 : 2;
        int64_t one = -1;
        ok = rows[i].bytes == want[k] && store_owner_bytes(s, rows[i].owner, &one) == 0 &&
             one == want[k];
        TLOG("%s: %lld bytes (store_owner_bytes %lld)", rows[i].owner, (long long)rows[i].bytes,
             (long long)one);
    }
    store_owner_totals_free(rows, n);
    CHECKF(ok, "the owners' totals differ from what was recorded");
    store_run_filter f = {.owner = "alice"};
    store_run *runs = NULL;
    CHECK(store_run_list(s, &f, &runs, &n) == 0);
    ok = n == 2 && runs[0].id == id[3] && runs[1].id == id[0];
    store_run_list_free(runs, n);
    CHECKF(ok, "the owner filter listed %zu runs", n);
    char who[48];
    CHECK(store_run_owner(s, id[1], who, sizeof who) == 0 && !strcmp(who, "bob"));
    CHECK(store_run_owner(s, 999, who, sizeof who) == MPM_ENOTFOUND);
    store_close(&s);
}
