/*
 * srv_stream.c - the stream socket (XPUB) against what its peers can make
 * the daemon hold.  libzmq keeps every subscription a peer sends in a trie
 * of about one node per byte, and every message queued for a peer until
 * that peer reads it; neither has a bound of its own.  Here: the socket is
 * in ZMQ_XPUB_MANUAL mode, so only the job topics the daemon accepts reach
 * the trie that routes messages (libzmq still keeps each peer's raw
 * subscriptions, to report them when it leaves, so those are counted and
 * capped too); ZMQ_MAXMSGSIZE (srv_socket.c) bounds each one; refusals are
 * logged at most once a second with a count; and the relay of the
 * workers' messages weighs each large message in the per-connection
 * high-water mark, so that one watcher that stops reading holds at most
 * --stream-buffer-mb across all its jobs while the others are served.
 * Guarded by tests/daemon/t_daemon_subs.c.
 */
#include "srv_stream.h"

#include "srv_pool.h"

#include "srv_log.h"

#include <errno.h>
#include <malloc.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
#include <zmq.h>

/* Subscription messages read per call: a flood of them never holds the
 * loop away from the request socket for long. */
#define XPUB_BUDGET 1000
/* How long a reset of the socket waits for libzmq to report the
 * connections it dropped (their subscriptions, without a key). */
#define RESET_DRAIN_MS 50
/* Subscriptions' worth the peers give up before the allocator is asked to
 * return free pages to the system. */
#define TRIM_UNITS 1024

/* A job somebody subscribed to: the subscriptions applied, and those
 * refused (libzmq reports the end of both alike when a peer leaves). */
typedef struct {
    uint64_t job;
    uint32_t applied, refused;
} sjob;

struct srv_stream {
    const srv_config *cfg;
    sjob *jobs; /* cfg->stream_max_subscriptions of them at most */
    size_t njobs, cap;
    size_t applied;      /* subscriptions applied (in the routing trie) */
    uint64_t raw;        /* what the peers hold in libzmq, in topic-sized units */
    double log_at;       /* when the second of the refusals logged began */
    int logged;          /* refusals logged in that second */
    unsigned long quiet; /* refusals not logged since */
    uint64_t resets;
    uint64_t freed; /* units given up by peers since the last trim */
};

static double mono_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

srv_stream *srv_stream_new(const srv_config *cfg)
{
    srv_stream *s = calloc(1, sizeof *s);
    if (!s) return NULL;
    s->cfg = cfg;
    s->cap = (size_t)cfg->stream_max_subscriptions;
    s->jobs = calloc(s->cap, sizeof *s->jobs);
    if (!s->jobs) {
        free(s);
        return NULL;
    }
    s->log_at = -1e9;
    return s;
}

void srv_stream_destroy(srv_stream **p)
{
    if (!p || !*p) return;
    free((*p)->jobs);
    free(*p);
    *p = NULL;
}

static sjob *find_job(const srv_stream *s, uint64_t job)
{
    for (size_t i = 0; i < s->njobs; i++)
        if (s->jobs[i].job == job) return &s->jobs[i];
    return NULL;
}

int srv_stream_watched(const srv_stream *s, uint64_t job)
{
    const sjob *e = s ? find_job(s, job) : NULL;
    return e && e->applied > 0;
}

static sjob *get_job(srv_stream *s, uint64_t job)
{
    sjob *e = find_job(s, job);
    if (e || s->njobs == s->cap) return e;
    e = &s->jobs[s->njobs++];
    memset(e, 0, sizeof *e);
    e->job = job;
    return e;
}

static void put_job(srv_stream *s, sjob *e)
{
    if (e->applied || e->refused) return;
    *e = s->jobs[--s->njobs];
}

/* Refusals logged one by one in a second, at most; the others are
 * counted and their number logged when the second is over. */
#define LOG_BURST 5

/* Logs the count of refusals left unlogged once their second is over. */
static void refusals_flush(srv_stream *s, double now)
{
    if (!s->quiet || now - s->log_at < 1.0) return;
    srv_warn(0, "%lu more stream subscriptions not applied in %.1f s (not logged one by one)",
             s->quiet, now - s->log_at);
    s->quiet = 0;
}

/* A refused subscription: logged, or counted past LOG_BURST a second. */
static void refused(srv_stream *s, uint64_t job, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static void refused(srv_stream *s, uint64_t job, const char *fmt, ...)
{
    double now = mono_s();
    refusals_flush(s, now);
    if (now - s->log_at >= 1.0) {
        s->log_at = now;
        s->logged = 0;
    }
    if (s->logged >= LOG_BURST) {
        s->quiet++;
        return;
    }
    s->logged++;
    char msg[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    srv_warn(job, "%s", msg);
}

/* The units a subscription of n topic bytes takes in libzmq's trie of the
 * peers' subscriptions: one per job topic's length begun. */
static uint64_t units(size_t n)
{
    return n ? (n + SRV_TOPIC_LEN - 1) / SRV_TOPIC_LEN : 1;
}

/* The ballast topic of a job: '!' + its topic.  No watcher subscribes to
 * it (SUB sockets drop a message no subscription of theirs matches), but
 * the daemon applies it for every connection whose subscription to the
 * job it applies (srv_stream_relay()). */
static void ballast_topic(const char *topic, char *out)
{
    out[0] = '!';
    memcpy(out + 1, topic, SRV_TOPIC_LEN);
}

static void sub_apply(daemon_t *d, int on, const char *topic)
{
    char bt[SRV_TOPIC_LEN + 1];
    ballast_topic(topic, bt);
    int opt = on ? ZMQ_SUBSCRIBE : ZMQ_UNSUBSCRIBE;
    if (zmq_setsockopt(d->xpub, opt, topic, SRV_TOPIC_LEN) ||
        zmq_setsockopt(d->xpub, opt, bt, sizeof bt))
        srv_warn(0, "stream: %s: %s", on ? "ZMQ_SUBSCRIBE" : "ZMQ_UNSUBSCRIBE",
                 zmq_strerror(errno));
}

/* A subscription from a connected peer (uid: its key, or "local"): applied
 * to that connection (the last one the XPUB read from) when it is one
 * job's topic that the peer may watch and the cap leaves room. */
static void subscribe(daemon_t *d, const char *b, size_t n, int is_job, uint64_t job,
                      const char *uid)
{
    srv_stream *s = d->stream;
    if (!is_job) {
        refused(s, 0,
                "stream subscription to a %zu-byte prefix by %s not applied: only one job's "
                "topic can be watched",
                n - 1, uid);
        return;
    }
    sjob *e = get_job(s, job);
    if (e) e->refused++; /* until applied */
    if (srv_auth_curve(d->auth)) {
        char who[OWNER_SIZE];
        if (srv_pool_job_owner(d->pool, d->st, job, who, sizeof who)) {
            refused(s, job, "stream subscription by %s not applied: no such job", uid);
            return;
        }
        if (strcmp(who, uid) && !srv_auth_is_admin(d->auth, uid)) {
            refused(s, job, "stream subscription by %s refused: the job is %s's", uid, who);
            return;
        }
    } else {
        int64_t next = store_next_run_id(d->st);
        if (job >= (uint64_t)next + (uint64_t)d->cfg->stream_subscribe_ahead) {
            refused(s, job,
                    "stream subscription by %s not applied: the newest job is %lld, and a "
                    "watcher may subscribe %d ids past it (--stream-subscribe-ahead)",
                    uid, (long long)next - 1, d->cfg->stream_subscribe_ahead);
            return;
        }
    }
    if (!e || s->applied >= s->cap) {
        refused(s, job,
                "stream subscription by %s not applied: %zu subscriptions applied "
                "(--stream-max-subscriptions %d)",
                uid, s->applied, d->cfg->stream_max_subscriptions);
        return;
    }
    sub_apply(d, 1, b + 1);
    e->refused--;
    e->applied++;
    s->applied++;
    if (e->applied == 1) {
        srv_debug(job, "stream watched");
        srv_pool_watch(d->pool, job, 1);
    }
}

/* An unsubscription: from a connected peer (live: applied to its
 * connection), or one libzmq reports for a peer that left.  Which of the
 * job's subscriptions it ends is not known, so a refused one is counted
 * off first: a job stays watched rather than losing a watcher. */
static void unsubscribe(daemon_t *d, const char *b, int is_job, uint64_t job, int live)
{
    srv_stream *s = d->stream;
    if (!is_job) return;
    if (live) sub_apply(d, 0, b + 1);
    sjob *e = find_job(s, job);
    if (!e) return;
    if (e->refused)
        e->refused--;
    else if (e->applied) {
        e->applied--;
        s->applied--;
        if (!e->applied) {
            srv_debug(job, "stream no longer watched");
            srv_pool_watch(d->pool, job, 0);
        }
    }
    put_job(s, e);
}

/* Past --stream-max-subscriptions: libzmq cannot be told to drop one
 * connection, or to hold fewer subscriptions for it, so the daemon drops
 * them all (unbinding the endpoint ends its connections) and binds again
 * at once.  Watchers' SUB sockets reconnect and subscribe again by
 * themselves and see a gap in seq; a peer that floods again is dropped
 * again. */
static void reset(daemon_t *d)
{
    srv_stream *s = d->stream;
    char ep[512];
    size_t len = sizeof ep;
    s->resets++;
    srv_warn(0,
             "stream: the peers hold %llu subscriptions' worth (--stream-max-subscriptions %d): "
             "dropping every stream connection (reset %llu); watchers reconnect",
             (unsigned long long)s->raw, d->cfg->stream_max_subscriptions,
             (unsigned long long)s->resets);
    if (zmq_getsockopt(d->xpub, ZMQ_LAST_ENDPOINT, ep, &len) || zmq_unbind(d->xpub, ep)) {
        srv_warn(0, "stream: cannot unbind: %s", zmq_strerror(errno));
        return;
    }
    /* the connections' subscriptions come back as unsubscriptions: they
     * belong to the connections just dropped */
    double end = mono_s() + RESET_DRAIN_MS / 1000.0;
    while (mono_s() < end) {
        zmq_pollitem_t it = {d->xpub, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&it, 1, 5) <= 0) continue;
        zmq_msg_t m;
        zmq_msg_init(&m);
        while (zmq_msg_recv(&m, d->xpub, ZMQ_DONTWAIT) >= 0) {
        }
        zmq_msg_close(&m);
    }
    for (size_t i = 0; i < s->njobs; i++)
        if (s->jobs[i].applied) srv_pool_watch(d->pool, s->jobs[i].job, 0);
    s->njobs = 0;
    s->applied = 0;
    s->raw = 0;
    int rc = -1;
    for (int tries = 0; tries < 200 && (rc = zmq_bind(d->xpub, ep)) && errno == EADDRINUSE; tries++)
        usleep(5000); /* the old listener closes on an I/O thread */
    if (rc) srv_error(0, "stream: cannot bind %s again: %s", ep, zmq_strerror(errno));
}

void srv_stream_on_xpub(daemon_t *d)
{
    srv_stream *s = d->stream;
    refusals_flush(s, mono_s());
    for (int k = 0; k < XPUB_BUDGET; k++) {
        zmq_msg_t m;
        zmq_msg_init(&m);
        if (zmq_msg_recv(&m, d->xpub, ZMQ_DONTWAIT) < 0) {
            zmq_msg_close(&m);
            break;
        }
        const char *b = zmq_msg_data(&m);
        size_t n = zmq_msg_size(&m);
        /* a connected peer's message has its connection's properties; the
         * unsubscriptions libzmq makes for a peer that left have none */
        const char *type = zmq_msg_gets(&m, "Socket-Type");
        const char *uid = zmq_msg_gets(&m, "User-Id");
        int keyed = uid && *uid;
        if (!keyed) uid = SRV_OWNER_LOCAL;
        uint64_t job = 0;
        int is_job = n == SRV_TOPIC_LEN + 1 && srv_topic_parse(b + 1, SRV_TOPIC_LEN, &job) == 0;
        if (n >= 1 && b[0] == 1) {
            s->raw += units(n - 1);
            /* noted so that a revoked key's connection is closed; a
             * subscription of a key no longer listed is not applied
             * (daemon_revoke_open_connections) */
            if (keyed) srv_auth_note_peer(d->auth, &m, uid);
            if (type && (!keyed || srv_auth_key_ok(d->auth, uid)))
                subscribe(d, b, n, is_job, job, uid);
        } else if (n >= 1 && b[0] == 0) {
            uint64_t u = units(n - 1);
            s->raw = s->raw > u ? s->raw - u : 0;
            s->freed += u;
            unsubscribe(d, b, is_job, job, type != NULL);
        }
        zmq_msg_close(&m);
        if (s->raw > (uint64_t)d->cfg->stream_max_subscriptions) {
            reset(d);
            s->freed = TRIM_UNITS;
            break;
        }
    }
    /* libzmq frees a leaving peer's trie node by node, and the allocator
     * keeps the small blocks: give the pages back
     * (daemon_subs_flood's memory after the client left) */
    if (s->freed >= TRIM_UNITS) {
        s->freed = 0;
        malloc_trim(0);
    }
}

void srv_stream_relay(daemon_t *d, long budget)
{
    size_t unit = 0;
    if (d->cfg->stream_buffer_mb > 0)
        unit = ((size_t)d->cfg->stream_buffer_mb << 20) / SRV_STREAM_HWM;
    char topic[SRV_TOPIC_LEN] = {0};
    int first = 1;
    for (long k = 0; !budget || k < budget; k++) {
        zmq_msg_t m;
        zmq_msg_init(&m);
        if (zmq_msg_recv(&m, d->pull, ZMQ_DONTWAIT) < 0) {
            zmq_msg_close(&m);
            if (errno != EAGAIN) srv_warn(0, "stream relay: %s", zmq_strerror(errno));
            return;
        }
        int more = zmq_msg_more(&m);
        size_t size = zmq_msg_size(&m);
        if (first && size == SRV_TOPIC_LEN) memcpy(topic, zmq_msg_data(&m), SRV_TOPIC_LEN);
        int was_first = first;
        first = !more;
        /* an XPUB drops for a connection at its high-water mark, and for
         * that connection only: a slow watcher never slows anyone */
        if (zmq_msg_send(&m, d->xpub, (more ? ZMQ_SNDMORE : 0) | ZMQ_DONTWAIT) < 0) {
            zmq_msg_close(&m);
            continue;
        }
        /* The weight of a large message.  The high-water mark counts
         * messages, not bytes, and a message stays queued for a
         * connection until it has been written out, so a watcher that
         * stops reading would keep SRV_STREAM_HWM snapshots.  After each
         * message of `size` bytes, size / unit empty messages go to the
         * job's ballast topic, which the daemon applied with each of the
         * job's subscriptions: each takes a place in the queue of every
         * connection that watches the job and is dropped, unread, by its
         * SUB socket.  A connection's queue is full once it holds about
         * --stream-buffer-mb of messages, whatever their jobs, and the
         * XPUB drops further messages for that connection alone.
         * (daemon_subs_stalled_watcher_many_jobs,
         * daemon_subs_reader_beside_stalled) */
        if (!more && !was_first && unit && size >= unit && topic[0]) {
            char bt[SRV_TOPIC_LEN + 1];
            ballast_topic(topic, bt);
            size_t w = size / unit;
            if (w > SRV_STREAM_HWM) w = SRV_STREAM_HWM;
            for (size_t i = 0; i < w; i++)
                if (zmq_send(d->xpub, bt, sizeof bt, ZMQ_DONTWAIT) < 0) break;
        }
    }
}

void srv_stream_publish(void *arg, uint64_t job, uint8_t *msg, size_t len)
{
    daemon_t *d = arg;
    char topic[SRV_TOPIC_LEN + 1];
    srv_topic(job, topic);
    if (msg && (zmq_send(d->xpub, topic, SRV_TOPIC_LEN, ZMQ_SNDMORE | ZMQ_DONTWAIT) < 0 ||
                zmq_send(d->xpub, msg, len, ZMQ_DONTWAIT) < 0))
        srv_warn(job, "stream message not published: %s", zmq_strerror(errno));
    free(msg);
}
