/*
 * srv_outq.h - the bytes of replies the request socket holds for clients
 * that have not read them yet, bounded per connection and in total.
 *
 * libzmq tells no one when a peer reads a reply, but it does tell when it
 * lets go of one: a reply is handed over without a copy
 * (zmq_msg_init_data) with a free function that libzmq's I/O thread calls
 * once the reply has gone into the kernel's socket buffer, or was dropped
 * with its connection.  Between the send and that call the reply's bytes
 * are charged to its connection (by routing id) and to the total; a reply
 * that would take either over its limit is not queued.  The counters are
 * atomics (the free function runs on libzmq's thread); everything else is
 * the main thread's.
 */
#ifndef SRV_OUTQ_H
#define SRV_OUTQ_H

#include <stddef.h>
#include <stdint.h>

typedef struct srv_outq srv_outq;

/* What srv_outq_send() did. */
enum {
    SRV_OUTQ_SENT = 0,
    SRV_OUTQ_CONN_FULL = 1,  /* the connection's limit: not sent */
    SRV_OUTQ_TOTAL_FULL = 2, /* the total limit: not sent */
    SRV_OUTQ_ERROR = -1      /* libzmq refused it (errno): not sent */
};

/* per_conn, total: byte limits (0: none).  NULL when out of memory. */
srv_outq *srv_outq_new(size_t per_conn, size_t total);
/* Frees q; call after zmq_ctx_term() (libzmq may still free replies
 * until then).  Nulls the pointer. */
void srv_outq_destroy(srv_outq **q);

/* Sends [id][empty][buf] on the ROUTER with ZMQ_DONTWAIT, buf (malloc'd,
 * len bytes) taken over in every case.  A reply goes out when its
 * connection's queued bytes plus len stay within the connection's limit
 * plus slack, and the total's within the total's plus slack (slack lets a
 * short error reply pass a full queue); a reply larger than the
 * connection's limit goes out alone, when nothing else is queued for that
 * connection.  Returns SRV_OUTQ_*; *queued (may be NULL) gets the bytes
 * queued for the connection (or in total, for SRV_OUTQ_TOTAL_FULL). */
int srv_outq_send(srv_outq *q, void *router, const void *id, size_t idlen, uint8_t *buf, size_t len,
                  size_t slack, size_t *queued);

#endif
