/*
 * t_daemon_subs.c - a real mpmd's stream socket against hostile and
 * stalled subscribers.  A raw ZMTP peer (a unix socket speaking the
 * handshake itself, so that the test process builds no trie of its own)
 * sends one oversized subscription, or a flood of small ones; a SUB that
 * never reads watches several jobs in turn; a normal reader watches a job
 * beside a stalled one.  Each test measures the daemon's VmHWM (reset
 * before the attack through /proc/PID/clear_refs) against a stated bound,
 * the worst Ping latency of another client during the attack, and VmRSS
 * after the hostile client left against the baseline; the reader counts
 * the snapshots it gets.  Quick sizes in `make test` (daemon_subs_*), the
 * issue's full sizes under MPM_STRESS=full (rel_subs_*: a 256 MiB
 * subscription, 1,000,000 subscriptions, 16 jobs of 200 snapshots).
 */
#define _GNU_SOURCE
#include "t_daemon.h"
#include "t_daemon_util.h"
#include "t_stress.h"

#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/un.h>
#include <unistd.h>
#include <zmq.h>

/* Sanitizers carry shadow memory and ASan a quarantine of freed blocks:
 * the memory margins grow with them. */
#if defined(__SANITIZE_ADDRESS__)
#define MARGIN_MB 128L
#elif defined(__SANITIZE_THREAD__)
#define MARGIN_MB 640L
#else
#define MARGIN_MB 40L
#endif
/* What the daemon may keep, above its baseline, a second after a hostile
 * client left (the allocator's free lists; under ASan its 16 MB quarantine
 * as well, see td_start_measured()). */
#if defined(__SANITIZE_ADDRESS__)
#define AFTER_MB 64L
#elif defined(__SANITIZE_THREAD__)
#define AFTER_MB 256L
#else
#define AFTER_MB 16L
#endif
/* The worst Ping round trip (a fresh connection each) that the daemon
 * must keep to during an attack. */
#define PING_BOUND_S 1.0

/* ---- a raw ZMTP 3.0 SUB peer over the daemon's ipc stream endpoint ---- */

/* Reads exactly n bytes (5 s at most); 0 or -1. */
static int raw_read(int fd, unsigned char *buf, size_t n)
{
    while (n) {
        ssize_t r = recv(fd, buf, n, 0);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) return -1;
        buf += r;
        n -= (size_t)r;
    }
    return 0;
}

/* Connects and shakes hands as a SUB would, step by step: the greeting
 * (ZMTP 3.0, NULL), the daemon's greeting, READY (Socket-Type SUB), the
 * daemon's READY.  Returns the fd or -1. */
static int raw_sub(const td_daemon *d)
{
    struct sockaddr_un a;
    char path[400];
    snprintf(path, sizeof path, "%s/ctl.stream", d->dir);
    if (strlen(path) >= sizeof a.sun_path) return -1;
    int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) return -1;
    memset(&a, 0, sizeof a);
    a.sun_family = AF_UNIX;
    memcpy(a.sun_path, path, strlen(path) + 1);
    unsigned char greeting[64] = {0xff, 0, 0, 0, 0, 0, 0, 0, 1, 0x7f, 3, 0, 'N', 'U', 'L', 'L'};
    /* READY: command flag, 25 bytes, "\5READY", "\13Socket-Type", 3, "SUB" */
    static const unsigned char ready[27] = {4,   25,  5,   'R', 'E', 'A', 'D', 'Y', 11,
                                            'S', 'o', 'c', 'k', 'e', 't', '-', 'T', 'y',
                                            'p', 'e', 0,   0,   0,   3,   'S', 'U', 'B'};
    unsigned char in[256];
    struct timeval tv = {5, 0};
    if (connect(fd, (struct sockaddr *)&a, sizeof a) ||
        setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv) ||
        send(fd, greeting, sizeof greeting, MSG_NOSIGNAL) != (ssize_t)sizeof greeting ||
        raw_read(fd, in, 64) ||
        send(fd, ready, sizeof ready, MSG_NOSIGNAL) != (ssize_t)sizeof ready ||
        raw_read(fd, in, 2) || raw_read(fd, in + 2, in[1])) {
        close(fd);
        return -1;
    }
    return fd;
}

/* Sends all n bytes; 0, or -1 when the daemon dropped the connection. */
static int raw_send(int fd, const void *buf, size_t n)
{
    const char *p = buf;
    while (n) {
        ssize_t w = send(fd, p, n, MSG_NOSIGNAL);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return -1;
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

/* ---- the attacks ---- */

typedef struct {
    long base_kb, peak_kb, after_kb; /* VmRSS before, VmHWM during, VmRSS after */
    double ping_worst;
    long pings, lost;
} attack_fig;

/* What the attack did to the daemon: the baseline before, the peak and
 * the pings during run(), the memory a second after the client left. */
static int measure(td_daemon *d, int (*run)(td_daemon *, long), long size, attack_fig *f)
{
    pinger p;
    td_msleep(300);
    f->base_kb = proc_kb(d->pid, "VmRSS:");
    if (reset_hwm(d->pid)) TLOG("cannot reset VmHWM: the peak is since the start");
    if (pinger_start(&p, d, 1)) return -1;
    int rc = run(d, size);
    td_msleep(500); /* what the daemon still does with what it read */
    pinger_stop(&p);
    f->peak_kb = proc_kb(d->pid, "VmHWM:");
    td_msleep(1000);
    f->after_kb = proc_kb(d->pid, "VmRSS:");
    f->ping_worst = p.max_s;
    f->pings = p.pings;
    f->lost = p.lost;
    return rc;
}

/* One subscription of `size` bytes (a 1 and size - 1 bytes of topic). */
static int oversized(td_daemon *d, long size)
{
    int fd = raw_sub(d);
    if (fd < 0) return -1;
    unsigned char hdr[9] = {2}; /* a long frame */
    for (int i = 0; i < 8; i++) hdr[1 + i] = (unsigned char)((uint64_t)size >> (56 - 8 * i));
    size_t chunk = 1 << 20;
    char *buf = malloc(chunk);
    if (!buf) {
        close(fd);
        return -1;
    }
    for (size_t i = 0; i < chunk; i++) buf[i] = (char)('a' + i % 26);
    buf[0] = 1;
    long sent = 0;
    if (!raw_send(fd, hdr, sizeof hdr))
        while (sent < size) {
            size_t k = size - sent < (long)chunk ? (size_t)(size - sent) : chunk;
            if (raw_send(fd, buf, k)) break;
            buf[0] = 'x';
            sent += (long)k;
        }
    TLOG("sent %ld of the %ld-byte subscription before the daemon dropped the connection", sent,
         size);
    free(buf);
    td_msleep(200);
    close(fd);
    return 0;
}

/* n subscriptions to distinct job topics, reconnecting when the daemon
 * drops the connection, for 60 s at most. */
static int flood(td_daemon *d, long n)
{
    long sent = 0, drops = 0;
    double end = td_now() + 60;
    int fd = raw_sub(d);
    char frames[64 * 24];
    while (fd >= 0 && sent < n && td_now() < end) {
        int k = 0;
        for (; k < 64 && sent + k < n; k++) {
            char *f = frames + 24 * k;
            f[0] = 0;  /* short frame */
            f[1] = 22; /* 1 + the topic */
            f[2] = 1;
            snprintf(f + 3, 22, "job:%016llx", (unsigned long long)(sent + k));
            f[23] = ':';
        }
        if (raw_send(fd, frames, (size_t)k * 24)) {
            close(fd);
            drops++;
            fd = -1;
            while (fd < 0 && td_now() < end) {
                td_msleep(100); /* a SUB's reconnect interval */
                fd = raw_sub(d);
            }
            continue;
        }
        sent += k;
    }
    TLOG("sent %ld subscriptions; the daemon dropped the connection %ld times", sent, drops);
    td_msleep(300);
    if (fd >= 0) close(fd);
    return 0;
}

static void report(const char *what, const attack_fig *f, long bound_kb, long after_bound_kb)
{
    TLOG("%s: mpmd VmRSS %.1f MB before, VmHWM %.1f MB during (bound %.1f), VmRSS %.1f MB a "
         "second after the client left (bound %.1f); Ping worst %.3f s of %ld (%ld lost)",
         what, f->base_kb / 1024.0, f->peak_kb / 1024.0, bound_kb / 1024.0, f->after_kb / 1024.0,
         after_bound_kb / 1024.0, f->ping_worst, f->pings, f->lost);
    printf("reliability: subs %s base_mb=%.0f peak_mb=%.0f after_mb=%.0f ping_worst_s=%.3f\n", what,
           f->base_kb / 1024.0, f->peak_kb / 1024.0, f->after_kb / 1024.0, f->ping_worst);
    if (!(f->peak_kb > 0 && f->peak_kb <= bound_kb))
        t_fail(__FILE__, __LINE__, "%s: mpmd VmHWM %ld kB above the bound %ld kB", what, f->peak_kb,
               bound_kb);
    if (!(f->after_kb > 0 && f->after_kb <= after_bound_kb))
        t_fail(__FILE__, __LINE__, "%s: mpmd VmRSS %ld kB after the client left (bound %ld kB)",
               what, f->after_kb, after_bound_kb);
    if (f->ping_worst > PING_BOUND_S || f->lost || f->pings < 5)
        t_fail(__FILE__, __LINE__, "%s: Ping worst %.3f s (bound %.1f s), %ld of %ld lost", what,
               f->ping_worst, PING_BOUND_S, f->lost, f->pings);
}

/* The stream socket takes no message larger than a subscription and the
 * handshake need (512 bytes): libzmq drops the connection as soon as it
 * reads the size.  Unbounded, 8 MiB took mpmd to 793 MB for good and
 * 256 MiB to 8.8 GB. */
static void oversized_test(const char *name, long size)
{
    const char *extra[] = {"--verbose", NULL};
    char dir[300];
    td_daemon d;
    attack_fig f;
    snprintf(dir, sizeof dir, "%s/%s", t_tmpdir(), name);
    if (td_start_measured(&d, dir, extra)) return;
    CHECK(measure(&d, oversized, size, &f) == 0);
    char what[64];
    snprintf(what, sizeof what, "one %ld MiB subscription", size >> 20);
    report(what, &f, f.base_kb + MARGIN_MB * 1024, f.base_kb + AFTER_MB * 1024);
    CHECKF(ping_ok(&d), "no Pong after the attack");
}

DTEST(daemon_subs_oversized)
{
    oversized_test("oversized", 8L << 20);
}

DTEST(rel_subs_oversized)
{
    oversized_test("rel_oversized", t_stress_full() ? 256L << 20 : 8L << 20);
}

/* Many small subscriptions: the daemon applies those it accepts (one job's
 * topic, at most --stream-subscribe-ahead past the newest job), logs the
 * refusals a few a second, and past --stream-max-subscriptions (what the
 * peers hold in libzmq's own trie) drops the stream connections.
 * Unbounded, 1,000,000 took +226 MB and stalled the loop 2.5 s. */
static void flood_test(const char *name, long n)
{
    const char *extra[] = {"--verbose", NULL};
    char dir[300];
    td_daemon d;
    attack_fig f;
    snprintf(dir, sizeof dir, "%s/%s", t_tmpdir(), name);
    if (td_start_measured(&d, dir, extra)) return;
    double t0 = td_now();
    CHECK(measure(&d, flood, n, &f) == 0);
    double secs = td_now() - t0;
    char what[64];
    snprintf(what, sizeof what, "%ld subscriptions", n);
    report(what, &f, f.base_kb + MARGIN_MB * 1024, f.base_kb + AFTER_MB * 1024);
    CHECKF(ping_ok(&d), "no Pong after the attack");
    /* the refusals: a few lines a second, not one each */
    size_t len = 0, lines = 0, watched = 0;
    char *log = td_slurp(d.log, &len);
    for (const char *p = log; p && (p = strstr(p, "not applied")); p++) lines++;
    for (const char *p = log; p && (p = strstr(p, "stream watched")); p++) watched++;
    free(log);
    TLOG("%zu jobs watched; %zu log lines of refusals in %.1f s", watched, lines, secs);
    CHECKF(lines <= (size_t)(10 * secs) + 10, "%zu log lines of refused subscriptions in %.1f s",
           lines, secs);
}

DTEST(daemon_subs_flood)
{
    flood_test("flood", 1000);
}

DTEST(rel_subs_flood)
{
    flood_test("rel_flood", t_stress_full() ? 1000000 : 20000);
}

/* ---- stalled watchers ---- */

/* A SUB on the daemon's stream subscribed to jobs first..last, receiving
 * at most one message into its queue and a 4 KB socket buffer. */
static void *stalled_sub(void *zctx, const td_daemon *d, unsigned long long first,
                         unsigned long long last)
{
    void *sub = subscribe(zctx, d, first, 1);
    for (unsigned long long j = first + 1; sub && j <= last; j++) {
        char topic[32];
        snprintf(topic, sizeof topic, "job:%016llx:", j);
        if (zmq_setsockopt(sub, ZMQ_SUBSCRIBE, topic, strlen(topic))) {
            t_fail(__FILE__, __LINE__, "subscribe %s: %s", topic, zmq_strerror(errno));
            zmq_close(sub);
            return NULL;
        }
    }
    return sub;
}

static int submit(td_daemon *d, const char *path, unsigned long long want)
{
    td_out o;
    int ok = td_ctl(d, 30, &o, "submit", path, NULL) == 0 && !o.status && job_of(o.out) == want;
    if (!ok) t_fail(__FILE__, __LINE__, "submit %llu: %s%s", want, o.out, o.err);
    td_out_free(&o);
    return ok ? 0 : -1;
}

/* One watcher that never reads, subscribed to several jobs run one after
 * another: the daemon holds about --stream-buffer-mb for it across them
 * all, not as much again for each job, and lets it go when it leaves.
 * Unbounded per watcher, 16 jobs took +62 MB each, 1,025 MB, and 1,003 MB
 * stayed after the watcher left. */
static void many_jobs_test(const char *name, int jobs, long long steps)
{
    const char *extra[] = {"--workers", "1", "--verbose", NULL};
    const long stream_mb = 64; /* the default --stream-buffer-mb */
    char dir[300], path[400];
    td_daemon d;
    void *zctx = NULL, *sub = NULL;
    snprintf(dir, sizeof dir, "%s/%s", t_tmpdir(), name);
    if (td_start_measured(&d, dir, extra)) return;
    CHECK(write_case(snap_case(name, steps), dir, "snap.json", path, sizeof path) == 0);
    /* job 1 unwatched: the baseline of a job's own memory */
    double wall;
    long hwm0, hwm = 0, worst = 0;
    if (submit(&d, path, 1) || td_job_peak(&d, 1, &wall, &hwm0)) return;
    td_msleep(300);
    long rss0 = proc_kb(d.pid, "VmRSS:");
    zctx = zmq_ctx_new();
    CHECK(zctx);
    sub = stalled_sub(zctx, &d, 2, 1 + (unsigned long long)jobs);
    if (!sub || wait_watched(&d, 2, 20)) {
        t_fail(__FILE__, __LINE__, "job 2's stream never watched");
        goto out;
    }
    for (int k = 0; k < jobs; k++) {
        if (submit(&d, path, 2 + (unsigned long long)k) ||
            td_job_peak(&d, 2 + (unsigned long long)k, &wall, &hwm))
            goto out;
        if (hwm > worst) worst = hwm;
        if (k == 0 || k == jobs - 1)
            TLOG("after job %d of %d (%lld snapshots of 5.5 MB each): mpmd VmHWM %.1f MB, VmRSS "
                 "%.1f MB",
                 k + 1, jobs, steps, hwm / 1024.0, proc_kb(d.pid, "VmRSS:") / 1024.0);
    }
    zmq_close(sub);
    sub = NULL;
    td_msleep(1000);
    long after = proc_kb(d.pid, "VmRSS:");
    long bound = hwm0 + (stream_mb + MARGIN_MB) * 1024, after_bound = rss0 + (AFTER_MB + 8) * 1024;
    TLOG("one stalled watcher over %d jobs: mpmd VmHWM %.1f MB (one job unwatched: %.1f; bound "
         "%.1f), VmRSS %.1f MB after it left (%.1f before it came; bound %.1f)",
         jobs, worst / 1024.0, hwm0 / 1024.0, bound / 1024.0, after / 1024.0, rss0 / 1024.0,
         after_bound / 1024.0);
    printf("reliability: subs stalled_jobs jobs=%d hwm0_mb=%.0f peak_mb=%.0f after_mb=%.0f\n", jobs,
           hwm0 / 1024.0, worst / 1024.0, after / 1024.0);
    if (worst > bound)
        t_fail(__FILE__, __LINE__, "mpmd VmHWM %ld kB with a stalled watcher (bound %ld kB)", worst,
               bound);
    if (after > after_bound)
        t_fail(__FILE__, __LINE__, "mpmd VmRSS %ld kB after the watcher left (bound %ld kB)", after,
               after_bound);
    CHECKF(ping_ok(&d), "no Pong after the watcher");
out:
    if (sub) zmq_close(sub);
    if (zctx) zmq_ctx_term(zctx);
}

DTEST(daemon_subs_stalled_watcher_many_jobs)
{
    many_jobs_test("stalled_jobs", 4, 40);
}

DTEST(rel_subs_stalled_watcher_many_jobs)
{
    int full = t_stress_full();
    many_jobs_test("rel_stalled_jobs", full ? 16 : 4, full ? 200 : 40);
}

/* Reads the reader's stream until it is quiet for 2 s: the snapshots
 * (messages above 1 MB) it got. */
static long read_snapshots(void *reader, double timeout)
{
    long snaps = 0;
    double end = td_now() + timeout;
    zmq_pollitem_t it = {reader, 0, ZMQ_POLLIN, 0};
    while (td_now() < end && zmq_poll(&it, 1, 2000) == 1) {
        zmq_msg_t part[2];
        int n = td_recv_parts(reader, part, 2);
        snaps += n == 2 && zmq_msg_size(&part[1]) > 1000000;
        for (int i = 0; i < n && i < 2; i++) zmq_msg_close(&part[i]);
        if (!n) break;
    }
    return snaps;
}

/* A reader that keeps up gets its job's snapshots whether or not another
 * watcher of the same job stalls: the stall costs the stalled one alone.
 * Unbounded per watcher, the reader got 17 of 200. */
static void beside_test(const char *name, long long steps)
{
    const char *extra[] = {"--workers", "1", "--verbose", NULL};
    char dir[300], path[400];
    td_daemon d;
    void *zctx = NULL, *stalled = NULL, *reader = NULL;
    long got[2] = {0, 0};
    snprintf(dir, sizeof dir, "%s/%s", t_tmpdir(), name);
    if (td_start_measured(&d, dir, extra)) return;
    /* a snapshot every 4 steps of a slower job: 5.5 MB at a pace a
     * reader on a loaded machine keeps up with */
    json_t *c = snap_case(name, steps * 4);
    CHECK(c);
    set_output(c, "snapshotEvery", json_integer(4));
    CHECK(write_case(c, dir, "snap.json", path, sizeof path) == 0);
    zctx = zmq_ctx_new();
    CHECK(zctx);
    for (unsigned long long job = 1; job <= 2; job++) {
        if (job == 2) {
            stalled = stalled_sub(zctx, &d, 2, 2);
            if (!stalled || wait_watched(&d, 2, 20)) goto out;
        }
        reader = subscribe(zctx, &d, job, 100000);
        if (!reader) goto out;
        td_msleep(300); /* the subscription takes effect */
        if (submit(&d, path, job)) goto out;
        got[job - 1] = read_snapshots(reader, 120);
        zmq_close(reader);
        reader = NULL;
        char st[32];
        if (td_wait_status(&d, job, "FINISHED", 60, st, sizeof st)) goto out;
    }
    TLOG("a reader got %ld of %lld snapshots alone, %ld beside a stalled watcher", got[0], steps,
         got[1]);
    printf("reliability: subs beside steps=%lld alone=%ld beside=%ld\n", steps, got[0], got[1]);
    /* the reader alone is the reference: a loaded machine may make it miss
     * some; beside the stalled watcher it misses at most 2 more */
    CHECKF(got[0] >= steps / 2, "the reader alone got %ld of %lld snapshots", got[0], steps);
    CHECKF(got[1] >= got[0] - 2,
           "beside a stalled watcher the reader got %ld snapshots (%ld alone)", got[1], got[0]);
out:
    if (reader) zmq_close(reader);
    if (stalled) zmq_close(stalled);
    if (zctx) zmq_ctx_term(zctx);
}

DTEST(daemon_subs_reader_beside_stalled)
{
    beside_test("beside", 50);
}

DTEST(rel_subs_reader_beside_stalled)
{
    beside_test("rel_beside", t_stress_full() ? 200 : 50);
}

/* A subscription to a job id far past the newest is not applied (nor
 * remembered): a watcher cannot reserve the next thousands of ids; one a
 * few ids ahead is, and its job is streamed from its first step. */
DTEST(daemon_subs_ahead)
{
    const char *extra[] = {"--verbose", "--stream-subscribe-ahead", "4", NULL};
    char dir[300];
    td_daemon d;
    snprintf(dir, sizeof dir, "%s/ahead", t_tmpdir());
    if (td_start_measured(&d, dir, extra)) return;
    void *zctx = zmq_ctx_new();
    CHECK(zctx);
    void *near = subscribe(zctx, &d, 3, 1000), *far = near ? subscribe(zctx, &d, 5, 1000) : NULL;
    int ok = far && wait_watched(&d, 3, 20) == 0;
    size_t len = 0;
    td_msleep(300);
    char *log = td_slurp(d.log, &len);
    int far_refused = log && strstr(log, "job 5: stream subscription by local not applied") &&
                      strstr(log, "--stream-subscribe-ahead");
    int far_watched = log && strstr(log, "job 5: stream watched");
    free(log);
    if (near) zmq_close(near);
    if (far) zmq_close(far);
    zmq_ctx_term(zctx);
    CHECKF(ok, "the subscription 2 ids ahead was not applied");
    CHECKF(far_refused && !far_watched, "the subscription 4 ids ahead was applied");
}
