/*
 * srv_reply.h - the daemon's replies (srv_reply.c).  Main thread only.
 */
#ifndef SRV_REPLY_H
#define SRV_REPLY_H

#include "srv_daemon_int.h"

#include <stddef.h>
#include <stdint.h>
#include <zmq.h>

/* Sends one reply (buf, len; freed; NULL: out of memory, logged) to the
 * client whose identity frame is id.  When the client's (or every
 * client's) unread replies are at their bound, the reply is dropped and a
 * short Error naming the limit goes in its place. */
void srv_send_reply(daemon_t *d, zmq_msg_t *id, uint8_t *buf, size_t len);
/* Answers with the Error reply of an mpm_error (wire code, camelCase
 * field and text from the protocol library). */
void srv_reply_mpm_error(daemon_t *d, zmq_msg_t *id, const mpm_error *e);
/* Answers with an error: code an MPM_E* code, field a path in the schema's
 * spelling ("" or NULL: none), the message without the field. */
void srv_reply_error(daemon_t *d, zmq_msg_t *id, int code, const char *field, const char *fmt, ...)
    __attribute__((format(printf, 5, 6)));
/* A request or reply of this many bytes went by: the main loop hands the
 * freed memory back for a while (srv_trim_tick, once a turn). */
void srv_trim_note(size_t bytes);
void srv_trim_tick(void);

#endif
