/*
 * srv_socket.h - the daemon's sockets, opened and bound (srv_socket.c).
 */
#ifndef SRV_SOCKET_H
#define SRV_SOCKET_H

#include <stddef.h>

#include "srv_auth.h"
#include "srv_config.h"

/* What a request may exceed --max-request-bytes by and still be read (and
 * answered TOO_LARGE); above it libzmq drops the connection unread. */
#define SRV_REQUEST_MARGIN 65536

/* Opens a socket of `type` on zctx and binds it to ep.  A ROUTER or XPUB
 * gets CURVE from auth (NULL or no secret: none); a ROUTER also gets
 * ZMQ_MAXMSGSIZE = cfg->max_request_bytes + SRV_REQUEST_MARGIN.  A
 * non-loopback ep without CURVE is refused unless
 * cfg->insecure_remote; an ipc:// path another process accepts
 * connections on is refused.  Returns 0 with *out set, or -1 with the
 * reason in err (*out NULL). */
int srv_socket_open(void *zctx, int type, const char *ep, const srv_config *cfg, srv_auth *auth,
                    void **out, char *err, size_t errlen);

#endif
