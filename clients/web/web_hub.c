/*
 * web_hub.c - mpmweb's live side.  One thread owns the SUB socket on the
 * daemon's stream (its own zmq context; the gateway's CURVE keys) and
 * holds at most one subscription per job, however many browsers watch it.
 * Each message is decoded once: progress, energy and finished go to the
 * job's browsers as Server-Sent Events whose data is the StreamMsg as the
 * protocol's JSON mapping writes it; a snapshot is made compact once
 * (web_snap.c), kept as the job's latest, and announced by a small
 * `snapshot` event (step, t, n) after which the page fetches it.
 *
 * Every browser has its own queue of at most WEB_SSE_QUEUE events, filled
 * by this thread under one mutex and emptied by the browser's HTTP thread.
 * Nothing here waits for a browser: a new snapshot notice replaces one
 * still queued, and a full queue drops its oldest progress event (else its
 * oldest event; the page fills a gap in the energy series from
 * /api/energy).  The daemon's own stream bounds protect the job from this
 * thread in turn.
 */
#include "web.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <zmq.h>

enum { EV_OTHER = 0, EV_PROGRESS = 1, EV_SNAPSHOT = 2 };

typedef struct {
    char *text;
    size_t len;
    int kind;
} event_t;

struct web_client {
    uint64_t job;
    event_t q[WEB_SSE_QUEUE];
    size_t count, off; /* off: bytes of q[0] already sent */
    pthread_cond_t cv;
    web_client *next;
};

typedef struct {
    uint64_t job;
    int refs, subscribed;
    char *snap; /* latest snapshot, web_snap_json() text */
    size_t snap_len;
} job_t;

static struct {
    pthread_mutex_t mu;
    pthread_t thread;
    int started, stopping;
    web_ctx *w;
    web_client *clients;
    int n_clients;
    job_t jobs[WEB_MAX_SSE];
    char ep[sizeof((web_ctx *)0)->stream_ep]; /* the stream, once known */
    unsigned long long dropped;
} hub = {.mu = PTHREAD_MUTEX_INITIALIZER};

static job_t *find_job(uint64_t job)
{
    for (int i = 0; i < WEB_MAX_SSE; i++)
        if (hub.jobs[i].job == job) return &hub.jobs[i];
    return NULL;
}

/* ---- queues (hub.mu held) ---------------------------------------------- */

static void q_remove(web_client *c, size_t i)
{
    free(c->q[i].text);
    memmove(&c->q[i], &c->q[i + 1], (c->count - i - 1) * sizeof c->q[0]);
    c->count--;
}

/* Appends a copy of the event; 0 or -1 (memory).  gcc 12's analyzer loses
 * the copy once it is stored in a client reached through hub.clients and
 * reports a leak; the queue frees it (q_remove, web_hub_leave). */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wanalyzer-malloc-leak"
#endif
static int q_push(web_client *c, const char *text, size_t len, int kind)
{
    size_t first = c->off ? 1 : 0; /* q[0] is being sent: keep it */
    if (kind == EV_SNAPSHOT) {
        for (size_t i = first; i < c->count; i++)
            if (c->q[i].kind == EV_SNAPSHOT) {
                q_remove(c, i);
                hub.dropped++;
                break;
            }
    }
    if (c->count == WEB_SSE_QUEUE) {
        size_t victim = first;
        for (size_t i = first; i < c->count; i++)
            if (c->q[i].kind == EV_PROGRESS) {
                victim = i;
                break;
            }
        q_remove(c, victim);
        hub.dropped++;
    }
    char *t = malloc(len + 1);
    if (!t) return -1;
    memcpy(t, text, len);
    t[len] = 0;
    event_t *e = &c->q[c->count++];
    e->text = t;
    e->len = len;
    e->kind = kind;
    pthread_cond_signal(&c->cv);
    return 0;
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

static void fan_out(uint64_t job, const char *text, size_t len, int kind)
{
    for (web_client *c = hub.clients; c; c = c->next)
        if (c->job == job && q_push(c, text, len, kind))
            fprintf(stderr, "mpmweb: out of memory: an event for job %llu dropped\n",
                    (unsigned long long)job);
}

/* ---- the stream thread ------------------------------------------------------ */

/* One [topic][StreamMsg] message from the daemon. */
static void on_message(const void *data, size_t size)
{
    mpp_stream m;
    mpm_error e;
    char *json = NULL, *ev = NULL, *snap = NULL;
    size_t snap_len = 0;
    if (mpp_stream_decode(data, size, 0, &m, &e) || !m.has_job_id) {
        mpp_stream_clear(&m);
        return;
    }
    uint64_t job = m.job_id;
    int kind = m.kind == MPP_STREAM_PROGRESS   ? EV_PROGRESS
               : m.kind == MPP_STREAM_SNAPSHOT ? EV_SNAPSHOT
                                               : EV_OTHER;
    const char *name = m.kind == MPP_STREAM_PROGRESS   ? "progress"
                       : m.kind == MPP_STREAM_ENERGY   ? "energy"
                       : m.kind == MPP_STREAM_SNAPSHOT ? "snapshot"
                       : m.kind == MPP_STREAM_FINISHED ? "finished"
                                                       : NULL;
    if (!name) {
        mpp_stream_clear(&m);
        return;
    }
    if (kind == EV_SNAPSHOT) {
        char head[192];
        if (web_snap_json(&m.snapshot, &snap, &snap_len)) {
            mpp_stream_clear(&m);
            return;
        }
        snprintf(head, sizeof head, "{\"step\":%lld,\"t\":%.9g,\"n\":%zu}",
                 (long long)m.snapshot.step, m.snapshot.t, m.snapshot.n);
        json = strdup(head);
    } else if (mpp_msg_bytes_to_json(MPP_MSG_STREAM, data, size, 0, 0, &json, &e)) {
        json = NULL;
    }
    mpp_stream_clear(&m);
    size_t n = json ? strlen(json) + strlen(name) + 32 : 0;
    if (json && (ev = malloc(n))) {
        int k = snprintf(ev, n, "event: %s\ndata: %s\n\n", name, json);
        pthread_mutex_lock(&hub.mu);
        job_t *j = find_job(job);
        if (j && j->refs > 0) {
            if (snap) {
                free(j->snap);
                j->snap = snap;
                j->snap_len = snap_len;
                snap = NULL;
            }
            fan_out(job, ev, (size_t)k, kind);
        }
        pthread_mutex_unlock(&hub.mu);
    }
    free(ev);
    free(json);
    free(snap);
}

/* Receives one multipart message (dropping malformed ones). */
static void recv_one(void *sub)
{
    zmq_msg_t topic, body;
    int more = 0;
    size_t ml = sizeof more;
    if (zmq_msg_init(&topic) || zmq_msg_init(&body)) return;
    if (zmq_msg_recv(&topic, sub, ZMQ_DONTWAIT) < 0) goto out;
    if (zmq_getsockopt(sub, ZMQ_RCVMORE, &more, &ml) || !more) goto out;
    if (zmq_msg_recv(&body, sub, 0) < 0) goto out;
    if (zmq_getsockopt(sub, ZMQ_RCVMORE, &more, &ml)) more = 0;
    if (more) {
        ctl_drain_more(sub);
        goto out;
    }
    on_message(zmq_msg_data(&body), zmq_msg_size(&body));
out:
    zmq_msg_close(&topic);
    zmq_msg_close(&body);
}

/* Subscribes to the jobs that gained a browser and unsubscribes from those
 * that lost their last one (hub.mu held). */
static void sync_subscriptions(void *sub)
{
    for (int i = 0; i < WEB_MAX_SSE; i++) {
        job_t *j = &hub.jobs[i];
        char topic[32];
        if (!j->job) continue;
        snprintf(topic, sizeof topic, "job:%016llx:", (unsigned long long)j->job);
        if (j->refs > 0 && !j->subscribed) {
            if (zmq_setsockopt(sub, ZMQ_SUBSCRIBE, topic, strlen(topic)) == 0)
                j->subscribed = 1;
            else
                fprintf(stderr, "mpmweb: subscribe %s: %s\n", topic, zmq_strerror(errno));
        } else if (j->refs == 0) {
            if (j->subscribed) zmq_setsockopt(sub, ZMQ_UNSUBSCRIBE, topic, strlen(topic));
            free(j->snap);
            memset(j, 0, sizeof *j);
        }
    }
}

static void *hub_main(void *arg)
{
    (void)arg;
    void *ctx = zmq_ctx_new(), *sub = NULL;
    int linger = 0, hwm = 10000, one = 1;
    if (!ctx) {
        fprintf(stderr, "mpmweb: zmq_ctx_new: %s\n", zmq_strerror(errno));
        return NULL;
    }
    for (;;) {
        char ep[sizeof hub.ep];
        pthread_mutex_lock(&hub.mu);
        int stop = hub.stopping;
        memcpy(ep, hub.ep, sizeof ep);
        pthread_mutex_unlock(&hub.mu);
        if (stop) break;
        if (!sub) {
            /* the endpoint is known once a browser's stream asked for it */
            if (!ep[0]) {
                struct timespec ts = {0, 100000000};
                nanosleep(&ts, NULL);
                continue;
            }
            sub = zmq_socket(ctx, ZMQ_SUB);
            if (!sub || zmq_setsockopt(sub, ZMQ_LINGER, &linger, sizeof linger) ||
                zmq_setsockopt(sub, ZMQ_RCVHWM, &hwm, sizeof hwm) ||
                zmq_setsockopt(sub, ZMQ_IPV6, &one, sizeof one) ||
                ctl_conn_secure(&hub.w->conn, sub) || zmq_connect(sub, ep)) {
                fprintf(stderr, "mpmweb: cannot connect to the stream at %s: %s\n", ep,
                        zmq_strerror(errno));
                if (sub) zmq_close(sub);
                sub = NULL;
                break;
            }
        }
        pthread_mutex_lock(&hub.mu);
        sync_subscriptions(sub);
        pthread_mutex_unlock(&hub.mu);
        zmq_pollitem_t it = {sub, 0, ZMQ_POLLIN, 0};
        int rc = zmq_poll(&it, 1, 100);
        if (rc < 0 && errno != EINTR) {
            fprintf(stderr, "mpmweb: zmq_poll: %s\n", zmq_strerror(errno));
            break;
        }
        for (int k = 0; rc > 0 && k < 1000; k++) {
            zmq_pollitem_t it2 = {sub, 0, ZMQ_POLLIN, 0};
            recv_one(sub);
            if (zmq_poll(&it2, 1, 0) <= 0) break;
        }
    }
    if (sub) zmq_close(sub);
    while (zmq_ctx_term(ctx) && errno == EINTR) {
    }
    return NULL;
}

int web_hub_start(web_ctx *w)
{
    hub.w = w;
    if (pthread_create(&hub.thread, NULL, hub_main, NULL)) {
        fprintf(stderr, "mpmweb: cannot start the stream thread\n");
        return CTL_ESYS;
    }
    hub.started = 1;
    return 0;
}

void web_hub_stop(void)
{
    pthread_mutex_lock(&hub.mu);
    hub.stopping = 1;
    for (web_client *c = hub.clients; c; c = c->next) pthread_cond_broadcast(&c->cv);
    pthread_mutex_unlock(&hub.mu);
    if (hub.started) pthread_join(hub.thread, NULL);
    hub.started = 0;
}

web_client *web_hub_join(uint64_t job, const char *first)
{
    web_client *c = calloc(1, sizeof *c);
    if (!c) return NULL;
    pthread_mutex_lock(&hub.mu);
    job_t *j = find_job(job);
    if (!j) j = find_job(0);
    if (hub.n_clients >= WEB_MAX_SSE || !j || hub.stopping) {
        pthread_mutex_unlock(&hub.mu);
        free(c);
        return NULL;
    }
    if (pthread_cond_init(&c->cv, NULL)) {
        pthread_mutex_unlock(&hub.mu);
        free(c);
        return NULL;
    }
    /* the caller asked web_stream_endpoint() first, under the gateway's
     * mutex: the endpoint is set and never changes */
    if (!hub.ep[0] && hub.w && hub.w->has_stream)
        snprintf(hub.ep, sizeof hub.ep, "%s", hub.w->stream_ep);
    j->job = job;
    j->refs++;
    c->job = job;
    c->next = hub.clients;
    hub.clients = c;
    hub.n_clients++;
    if (first) q_push(c, first, strlen(first), EV_OTHER);
    pthread_mutex_unlock(&hub.mu);
    return c;
}

void web_hub_push_front(web_client *c, const char *event, size_t len)
{
    char *t = malloc(len + 1);
    if (!t) return;
    memcpy(t, event, len);
    t[len] = 0;
    pthread_mutex_lock(&hub.mu);
    if (c->count == WEB_SSE_QUEUE) {
        q_remove(c, c->count - 1);
        hub.dropped++;
    }
    size_t at = c->off ? 1 : 0;
    memmove(&c->q[at + 1], &c->q[at], (c->count - at) * sizeof c->q[0]);
    c->q[at].text = t;
    c->q[at].len = len;
    c->q[at].kind = EV_OTHER;
    c->count++;
    pthread_cond_signal(&c->cv);
    pthread_mutex_unlock(&hub.mu);
}

long web_hub_read(web_client *c, char *buf, size_t max)
{
    static const char keep[] = ": keep-alive\n\n";
    long n;
    pthread_mutex_lock(&hub.mu);
    if (!c->count && !hub.stopping) {
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        ts.tv_sec += 10;
        while (!c->count && !hub.stopping)
            if (pthread_cond_timedwait(&c->cv, &hub.mu, &ts) == ETIMEDOUT) break;
    }
    if (hub.stopping) {
        n = -1;
    } else if (!c->count) {
        n = (long)(sizeof keep - 1 < max ? sizeof keep - 1 : max);
        memcpy(buf, keep, (size_t)n);
    } else {
        event_t *e = &c->q[0];
        size_t k = e->len - c->off;
        if (k > max) k = max;
        memcpy(buf, e->text + c->off, k);
        c->off += k;
        if (c->off == e->len) {
            c->off = 0;
            q_remove(c, 0);
        }
        n = (long)k;
    }
    pthread_mutex_unlock(&hub.mu);
    return n;
}

void web_hub_leave(web_client *c)
{
    if (!c) return;
    pthread_mutex_lock(&hub.mu);
    for (web_client **p = &hub.clients; *p; p = &(*p)->next)
        if (*p == c) {
            *p = c->next;
            hub.n_clients--;
            break;
        }
    job_t *j = find_job(c->job);
    if (j && j->refs > 0) j->refs--;
    while (c->count) q_remove(c, c->count - 1);
    pthread_mutex_unlock(&hub.mu);
    pthread_cond_destroy(&c->cv);
    free(c);
}

int web_hub_latest(uint64_t job, char **out, size_t *len)
{
    int rc = CTL_EPROTO;
    *out = NULL;
    *len = 0;
    pthread_mutex_lock(&hub.mu);
    job_t *j = find_job(job);
    if (j && j->snap) {
        *out = malloc(j->snap_len + 1);
        if (*out) {
            memcpy(*out, j->snap, j->snap_len + 1);
            *len = j->snap_len;
            rc = 0;
        } else {
            rc = CTL_ESYS;
        }
    }
    pthread_mutex_unlock(&hub.mu);
    return rc;
}

unsigned long long web_hub_dropped(void)
{
    pthread_mutex_lock(&hub.mu);
    unsigned long long d = hub.dropped;
    pthread_mutex_unlock(&hub.mu);
    return d;
}
