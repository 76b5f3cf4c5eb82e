/*
 * srv_outq.c - replies handed to libzmq without a copy, their bytes charged
 * to their connection until libzmq frees them (see srv_outq.h).
 *
 * Each connection with bytes queued has a `conn` (routing id, atomic byte
 * count, atomic reference count) in a small array searched by routing id.
 * Every reply in flight holds a reference, the array another; the main
 * thread drops the array's reference of a connection whose count fell to
 * zero when it next adds a connection, and whichever side lets go last
 * frees it.  Guarded by daemon_replies_unread_bounded.
 */
#include "srv_outq.h"

#include "srv_grow.h"
#include "srv_tsan.h"

#include <errno.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <zmq.h>

#define ID_MAX 256 /* a routing id is at most 255 bytes */

typedef struct conn {
    atomic_size_t bytes;
    atomic_int refs;
    size_t idlen;
    unsigned char id[ID_MAX];
} conn;

struct srv_outq {
    size_t per_conn, total_max;
    atomic_size_t total;
    conn **c; /* the main thread's */
    size_t n, cap;
};

/* One reply in libzmq's hands. */
typedef struct {
    srv_outq *q;
    conn *c;
    size_t len;
} held;

static void conn_unref(conn *c)
{
    if (atomic_fetch_sub(&c->refs, 1) == 1) free(c);
}

/* libzmq's free function, on its I/O thread (or in zmq_msg_close). */
static void release(void *data, void *hint)
{
    held *h = hint;
    TSAN_ACQUIRE(h);
    free(data);
    atomic_fetch_sub(&h->c->bytes, h->len);
    atomic_fetch_sub(&h->q->total, h->len);
    conn_unref(h->c);
    free(h);
}

srv_outq *srv_outq_new(size_t per_conn, size_t total)
{
    srv_outq *q = calloc(1, sizeof *q);
    if (!q) return NULL;
    q->per_conn = per_conn;
    q->total_max = total;
    atomic_init(&q->total, 0);
    return q;
}

void srv_outq_destroy(srv_outq **pq)
{
    srv_outq *q = *pq;
    if (!q) return;
    for (size_t i = 0; i < q->n; i++) conn_unref(q->c[i]);
    free(q->c);
    free(q);
    *pq = NULL;
}

/* The connection of routing id (added, after dropping the idle ones, when
 * absent); NULL when out of memory. */
static conn *find(srv_outq *q, const void *id, size_t idlen)
{
    for (size_t i = 0; i < q->n; i++)
        if (q->c[i]->idlen == idlen && !memcmp(q->c[i]->id, id, idlen)) return q->c[i];
    size_t k = 0;
    for (size_t i = 0; i < q->n; i++) {
        if (atomic_load(&q->c[i]->bytes) == 0)
            conn_unref(q->c[i]);
        else
            q->c[k++] = q->c[i];
    }
    q->n = k;
    conn **nc = srv_grow(q->c, &q->cap, q->n + 1, sizeof *nc, 0);
    if (!nc) return NULL;
    q->c = nc;
    conn *c = malloc(sizeof *c);
    if (!c) return NULL;
    atomic_init(&c->bytes, 0);
    atomic_init(&c->refs, 1);
    c->idlen = idlen;
    memcpy(c->id, id, idlen);
    q->c[q->n++] = c;
    return c;
}

int srv_outq_send(srv_outq *q, void *router, const void *id, size_t idlen, uint8_t *buf, size_t len,
                  size_t slack, size_t *queued)
{
    size_t dummy;
    if (!queued) queued = &dummy;
    *queued = 0;
    if (idlen == 0 || idlen >= ID_MAX) {
        free(buf);
        errno = EINVAL;
        return SRV_OUTQ_ERROR;
    }
    conn *c = find(q, id, idlen);
    held *h = c ? malloc(sizeof *h) : NULL;
    if (!h) {
        free(buf);
        errno = ENOMEM;
        return SRV_OUTQ_ERROR;
    }
    size_t mine = atomic_load(&c->bytes), all = atomic_load(&q->total);
    if (q->per_conn && mine && mine + len > q->per_conn + slack) {
        *queued = mine;
        free(h);
        free(buf);
        return SRV_OUTQ_CONN_FULL;
    }
    if (q->total_max && all && all + len > q->total_max + slack) {
        *queued = all;
        free(h);
        free(buf);
        return SRV_OUTQ_TOTAL_FULL;
    }
    h->q = q;
    h->c = c;
    h->len = len;
    atomic_fetch_add(&c->refs, 1);
    atomic_fetch_add(&c->bytes, len);
    atomic_fetch_add(&q->total, len);
    zmq_msg_t m;
    TSAN_RELEASE(h);
    if (zmq_msg_init_data(&m, buf, len, release, h)) {
        /* not taken: undo by hand */
        atomic_fetch_sub(&c->bytes, len);
        atomic_fetch_sub(&q->total, len);
        conn_unref(c);
        free(h);
        free(buf);
        return SRV_OUTQ_ERROR;
    }
    if (zmq_send(router, id, idlen, ZMQ_SNDMORE | ZMQ_DONTWAIT) < 0 ||
        zmq_send(router, "", 0, ZMQ_SNDMORE | ZMQ_DONTWAIT) < 0 ||
        zmq_msg_send(&m, router, ZMQ_DONTWAIT) < 0) {
        int e = errno;
        zmq_msg_close(&m); /* calls release() */
        errno = e;
        return SRV_OUTQ_ERROR;
    }
    *queued = mine + len;
    return SRV_OUTQ_SENT;
}
