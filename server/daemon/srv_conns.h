/*
 * srv_conns.h - the request socket's connections, counted, and the cap on
 * them (--max-connections).
 *
 * libzmq accepts every connection itself and offers no way to refuse an
 * accept, so the cap is applied at the handshake: a socket monitor reports
 * each accepted connection (ZMQ_EVENT_ACCEPTED, with its descriptor) and
 * each closed one (ZMQ_EVENT_DISCONNECTED, ZMQ_EVENT_CLOSED); the ZAP
 * handler (srv_auth.c) reads those events on its own thread, so that the
 * count includes every connection accepted before the one it is asked
 * about, and refuses the handshake of a connection past the cap, which
 * libzmq then closes.  Connections that never finish their handshake
 * count too (they hold a descriptor) and are closed by libzmq after
 * --handshake-timeout-s (ZMQ_HANDSHAKE_IVL).
 */
#ifndef SRV_CONNS_H
#define SRV_CONNS_H

#include <stddef.h>

typedef struct srv_conns srv_conns;

/* max: the cap (0: none).  The monitor's receiving end is made in zctx
 * (connected ahead of the monitor itself).  NULL, with the reason in err,
 * on failure. */
srv_conns *srv_conns_new(void *zctx, int max, char *err, size_t errlen);

/* The socket the monitor's events arrive on: the ZAP thread polls it,
 * calls srv_conns_drain() when it is readable, and closes it when it
 * ends (srv_auth_set_gate()). */
void *srv_conns_socket(srv_conns *c);

/* Starts the monitor on sock (the request socket, just bound): 0, or -1
 * with the reason in err. */
int srv_conns_watch(srv_conns *c, void *sock, char *err, size_t errlen);

/* Reads the events waiting (ZAP thread only): 0, or -1 once the context
 * is terminating. */
int srv_conns_drain(void *c);

/* 1 if one more handshake may complete (open connections, counting the
 * one asking, within the cap), else 0; *open gets the count.  ZAP thread
 * only, after srv_conns_drain(). */
int srv_conns_admit(void *c, int *open);

/* Frees c (after zmq_ctx_term: its socket was closed by the ZAP thread,
 * or here when that thread never started); nulls the pointer. */
void srv_conns_destroy(srv_conns **c);

#endif
