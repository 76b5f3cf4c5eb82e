/*
 * srv_reply.c - the daemon's replies on the ROUTER: a reply handed to
 * libzmq without a copy, its unread bytes bounded per connection and in
 * total (srv_outq.h), a short error in its place when the bound is
 * reached; the Error replies; and handing memory back to the system after
 * large messages.  Main thread only.  Guarded by the daemon_replies_*
 * tests (tests/daemon/t_daemon_replies.c).
 */
#include "srv_reply.h"

#include "srv_log.h"
#include "srv_outq.h"

#include <errno.h>
#include <malloc.h>
#include <stdarg.h>
#include <stdio.h>
#include <zmq.h>

/* After a large request or reply, glibc keeps the freed blocks (libzmq
 * frees them on its own thread, some time later, and glibc's mmap
 * threshold rises with the sizes it has seen): the main loop hands them
 * back with malloc_trim(0) once a second for TRIM_WINDOW_S after the last
 * one.  Guarded by the "after they left" checks of t_daemon_replies.c. */
#define TRIM_BIG ((size_t)256 << 10)
#define TRIM_WINDOW_S 30.0
static double trim_until, trim_last;

void srv_trim_note(size_t bytes)
{
    if (bytes >= TRIM_BIG) trim_until = srv_wall_now() + TRIM_WINDOW_S;
}

void srv_trim_tick(void)
{
    double now = srv_wall_now();
    if (now < trim_until && now - trim_last >= 1.0) {
        malloc_trim(0);
        trim_last = now;
    }
}

/* A short error reply may pass a full reply queue by this much, so that a
 * client that reads at last learns why its big replies were not sent. */
#define REPLY_SLACK 65536

/* Logs a reply refused for a full queue: the first, then one line a second
 * with the count (a client that never reads could fill the log). */
static void log_refused(int conn, size_t len, size_t queued, int limit_mb, const char *setting)
{
    static double last;
    static unsigned long skipped;
    double now = srv_wall_now();
    if (now - last < 1.0) {
        skipped++;
        return;
    }
    srv_warn(0,
             "reply of %zu bytes not sent: %zu bytes of replies %s are unread (limit %d MiB, "
             "%s; %lu more refused in the last second)",
             len, queued, conn ? "to that connection" : "in all", limit_mb, setting, skipped);
    last = now;
    skipped = 0;
}

void srv_send_reply(daemon_t *d, zmq_msg_t *id, uint8_t *buf, size_t len)
{
    if (!buf) {
        srv_warn(0, "out of memory encoding a reply");
        return;
    }
    size_t queued = 0;
    srv_trim_note(len);
    int rc =
        srv_outq_send(d->outq, d->router, zmq_msg_data(id), zmq_msg_size(id), buf, len, 0, &queued);
    if (rc == SRV_OUTQ_SENT) return;
    if (rc == SRV_OUTQ_ERROR) {
        srv_warn(0, "reply not sent: %s", zmq_strerror(errno));
        return;
    }
    /* the queue is full: the reply is dropped and, in its place, a short
     * error names the limit (guarded by daemon_replies_unread_bounded) */
    int conn = rc == SRV_OUTQ_CONN_FULL;
    int mb = conn ? d->cfg->connection_reply_buffer_mb : d->cfg->reply_buffer_mb;
    const char *setting = conn ? "--connection-reply-buffer-mb" : "--reply-buffer-mb";
    log_refused(conn, len, queued, mb, setting);
    mpm_error e;
    mpm_fail(&e, MPM_EUNAVAIL, "",
             "reply of %zu bytes not sent: %zu bytes of replies %s are still unread (limit %d "
             "MiB, %s); read them, then ask again",
             len, queued, conn ? "to this connection" : "to all clients", mb, setting);
    uint8_t *eb = NULL;
    size_t el = 0;
    if (mpp_reply_error_from(&e, &eb, &el) || !eb) return;
    if (srv_outq_send(d->outq, d->router, zmq_msg_data(id), zmq_msg_size(id), eb, el, REPLY_SLACK,
                      NULL) == SRV_OUTQ_ERROR)
        srv_debug(0, "error reply not sent: %s", zmq_strerror(errno));
}

void srv_reply_mpm_error(daemon_t *d, zmq_msg_t *id, const mpm_error *e)
{
    uint8_t *buf = NULL;
    size_t len = 0;
    mpp_reply_error_from(e, &buf, &len);
    srv_send_reply(d, id, buf, len);
}

void srv_reply_error(daemon_t *d, zmq_msg_t *id, int code, const char *field, const char *fmt, ...)
{
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    mpm_error e;
    mpm_fail(&e, code, field, "%s", msg);
    srv_reply_mpm_error(d, id, &e);
}
