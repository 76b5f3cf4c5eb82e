/*
 * srv_conns.c - counts the request socket's open connections from its
 * socket monitor, for the cap of --max-connections (see srv_conns.h).
 *
 * One byte per descriptor says it is an open connection: set on
 * ZMQ_EVENT_ACCEPTED, cleared on ZMQ_EVENT_DISCONNECTED or
 * ZMQ_EVENT_CLOSED; the count is the number set.  The events are read by
 * the ZAP thread before it answers a handshake: libzmq's I/O thread sends
 * a connection's ACCEPTED before its ZAP request, so the count seen then
 * includes every connection accepted so far.  The receiving end keeps no
 * bound on its queue (an event lost would leave the count wrong); the ZAP
 * thread reads it whenever it is readable.  Guarded by
 * daemon_conns_cap_holds.
 */
#include "srv_conns.h"

#include "srv_log.h"

#include <errno.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zmq.h>

#define MONITOR_EP "inproc://mpmd-conns"

struct srv_conns {
    int max;
    atomic_int open;
    unsigned char *fds; /* per descriptor: an open connection (ZAP thread's) */
    size_t nfds;
    void *pair; /* the monitor's receiving end */
};

srv_conns *srv_conns_new(void *zctx, int max, char *err, size_t errlen)
{
    int zero = 0;
    srv_conns *c = calloc(1, sizeof *c);
    if (!c) {
        snprintf(err, errlen, "out of memory");
        return NULL;
    }
    c->max = max;
    atomic_init(&c->open, 0);
    c->pair = zmq_socket(zctx, ZMQ_PAIR);
    if (!c->pair || zmq_setsockopt(c->pair, ZMQ_RCVHWM, &zero, sizeof zero) ||
        zmq_setsockopt(c->pair, ZMQ_LINGER, &zero, sizeof zero) ||
        zmq_connect(c->pair, MONITOR_EP)) {
        snprintf(err, errlen, "connection monitor: %s", zmq_strerror(errno));
        if (c->pair) zmq_close(c->pair);
        free(c);
        return NULL;
    }
    return c;
}

void *srv_conns_socket(srv_conns *c)
{
    return c->pair;
}

int srv_conns_watch(srv_conns *c, void *sock, char *err, size_t errlen)
{
    (void)c;
    if (zmq_socket_monitor(sock, MONITOR_EP,
                           ZMQ_EVENT_ACCEPTED | ZMQ_EVENT_DISCONNECTED | ZMQ_EVENT_CLOSED)) {
        snprintf(err, errlen, "connection monitor: %s", zmq_strerror(errno));
        return -1;
    }
    return 0;
}

/* One monitor event: the descriptor's byte, and the count, follow it. */
static void on_event(srv_conns *c, uint16_t ev, uint32_t fd)
{
    if (fd >= c->nfds) {
        if (ev != ZMQ_EVENT_ACCEPTED) return;
        size_t n = c->nfds ? c->nfds : 1024;
        while (n <= fd) n *= 2;
        unsigned char *f = realloc(c->fds, n);
        if (!f) {
            srv_warn(0, "connection count: out of memory");
            return;
        }
        memset(f + c->nfds, 0, n - c->nfds);
        c->fds = f;
        c->nfds = n;
    }
    if (ev == ZMQ_EVENT_ACCEPTED && !c->fds[fd]) {
        c->fds[fd] = 1;
        atomic_fetch_add(&c->open, 1);
    } else if (ev != ZMQ_EVENT_ACCEPTED && c->fds[fd]) {
        c->fds[fd] = 0;
        atomic_fetch_sub(&c->open, 1);
    }
}

int srv_conns_drain(void *arg)
{
    srv_conns *c = arg;
    for (;;) {
        zmq_msg_t m;
        zmq_msg_init(&m);
        if (zmq_msg_recv(&m, c->pair, ZMQ_DONTWAIT) < 0) {
            int e = errno;
            zmq_msg_close(&m);
            if (e == EINTR) continue;
            return e == EAGAIN ? 0 : -1;
        }
        /* frame 1: event (16 bits) and value (32 bits, the descriptor);
         * frame 2: the endpoint, not needed */
        int more = zmq_msg_more(&m);
        if (zmq_msg_size(&m) == 6 && more) {
            uint16_t ev;
            uint32_t fd;
            memcpy(&ev, zmq_msg_data(&m), 2);
            memcpy(&fd, (char *)zmq_msg_data(&m) + 2, 4);
            on_event(c, ev, fd);
        }
        zmq_msg_close(&m);
        while (more) {
            zmq_msg_init(&m);
            if (zmq_msg_recv(&m, c->pair, 0) < 0) {
                zmq_msg_close(&m);
                return -1;
            }
            more = zmq_msg_more(&m);
            zmq_msg_close(&m);
        }
    }
}

int srv_conns_admit(void *arg, int *open)
{
    srv_conns *c = arg;
    int n = atomic_load(&c->open);
    if (open) *open = n;
    return !c->max || n <= c->max;
}

void srv_conns_destroy(srv_conns **pc)
{
    srv_conns *c = *pc;
    if (!c) return;
    free(c->fds);
    free(c);
    *pc = NULL;
}
