/*
 * srv_socket.c - opening and binding the daemon's sockets: the fail-closed
 * check for non-loopback binds without CURVE (mpp_endpoint_bind_class(),
 * and no interface named like the loopback literal), host aliases libzmq cannot
 * bind (localhost, ip6-localhost), refusing an ipc:// endpoint a live
 * process owns, the socket options (linger, IPv6, ROUTER_MANDATORY, HWMs,
 * CURVE through srv_auth, ZMQ_MAXMSGSIZE on both sockets, ZMQ_XPUB_MANUAL)
 * and the bind itself.
 */
#include "srv_socket.h"

#include "mpp_endpoint.h"
#include "srv_log.h"
#include "srv_stream.h"

#include <errno.h>
#include <net/if.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>
#include <zmq.h>

/* 1 if a process accepts connections on the unix socket at path (a live
 * daemon owns this ipc:// endpoint), 0 if none does (no file, or a stale
 * one that a dead daemon left: zmq_bind replaces it). */
static int ipc_in_use(const char *path)
{
    struct sockaddr_un a;
    if (path[0] == '@' || strlen(path) >= sizeof a.sun_path) return 0; /* abstract: bind says */
    int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) return 0;
    memset(&a, 0, sizeof a);
    a.sun_family = AF_UNIX;
    memcpy(a.sun_path, path, strlen(path) + 1);
    int live = connect(fd, (struct sockaddr *)&a, sizeof a) == 0;
    close(fd);
    return live;
}

/* 1 if the host of tcp endpoint ep is also the name of a network
 * interface: libzmq looks a bind host up as an interface name first (an
 * interface named "127.0.0.1" would take the bind to its own address). */
static int nic_named(const char *ep)
{
    char host[IF_NAMESIZE + 1];
    if (strncmp(ep, "tcp://", 6)) return 0;
    const char *h = ep + 6, *colon = strrchr(h, ':');
    size_t len = colon ? (size_t)(colon - h) : strlen(h);
    if (len >= sizeof host) return 0; /* longer than any interface name */
    memcpy(host, h, len);
    host[len] = 0;
    return if_nametoindex(host) != 0;
}

/* The endpoint libzmq binds for ep: tcp://localhost:P becomes
 * tcp://127.0.0.1:P and tcp://ip6-localhost:P tcp://[::1]:P (libzmq takes
 * a bind host for an interface name, not a host name); *ipv6 says the host
 * is an IPv6 address (ZMQ_IPV6 needed). */
static int bind_endpoint(const char *ep, char *out, size_t n, int *ipv6)
{
    static const struct {
        const char *from, *to;
    } alias[] = {{"tcp://localhost:", "tcp://127.0.0.1:"},
                 {"tcp://ip6-localhost:", "tcp://[::1]:"}};
    *ipv6 = 0;
    for (size_t i = 0; i < sizeof alias / sizeof alias[0]; i++) {
        size_t k = strlen(alias[i].from);
        if (!strncmp(ep, alias[i].from, k)) {
            int w = snprintf(out, n, "%s%s", alias[i].to, ep + k);
            *ipv6 = alias[i].to[6] == '[';
            return w > 0 && (size_t)w < n ? 0 : -1;
        }
    }
    *ipv6 = !strncmp(ep, "tcp://[", 7) || (!strncmp(ep, "tcp://", 6) && strchr(ep + 6, ':') &&
                                           strchr(ep + 6, ':') != strrchr(ep + 6, ':'));
    int w = snprintf(out, n, "%s", ep);
    return w > 0 && (size_t)w < n ? 0 : -1;
}

int srv_socket_open(void *zctx, int type, const char *ep, const srv_config *cfg, srv_auth *auth,
                    void **out, char *err, size_t errlen)
{
    *out = NULL;
    char why[400];
    int cls = mpp_endpoint_bind_class(ep, why, sizeof why);
    if (cls == MPP_BIND_INVALID) {
        snprintf(err, errlen, "refusing to bind %s: %s", ep, why);
        return -1;
    }
    if (cls == MPP_BIND_LOCAL && nic_named(ep)) {
        snprintf(err, errlen,
                 "refusing to bind %s: a network interface has that name, and libzmq would "
                 "bind the interface's address",
                 ep);
        return -1;
    }
    if (cls != MPP_BIND_LOCAL && !srv_auth_curve(auth)) {
        if (!cfg->insecure_remote) {
            snprintf(err, errlen,
                     "refusing to bind %s: not loopback, ipc:// or inproc:// (%s), and no "
                     "CURVE (give --curve-secret and --authorized-keys, or "
                     "--insecure-allow-remote-without-auth on a trusted network)",
                     ep, why);
            return -1;
        }
        srv_warn(0,
                 "!!! binding %s on a non-loopback address WITHOUT AUTHENTICATION "
                 "(--insecure-allow-remote-without-auth): ANYONE WHO CAN REACH IT CAN "
                 "SUBMIT, CANCEL AND READ JOBS !!!",
                 ep);
    }
    char bep[300];
    int ipv6 = 0;
    if (bind_endpoint(ep, bep, sizeof bep, &ipv6)) {
        snprintf(err, errlen, "endpoint %s is too long", ep);
        return -1;
    }
    if (!strncmp(bep, "ipc://", 6) && ipc_in_use(bep + 6)) {
        snprintf(err, errlen,
                 "cannot bind %s: another process (a running mpmd?) accepts connections on "
                 "it; stop it or choose another endpoint",
                 ep);
        return -1;
    }
    void *s = zmq_socket(zctx, type);
    int zero = 0, one = 1, hwm = SRV_STREAM_HWM;
    if (!s) {
        snprintf(err, errlen, "zmq_socket: %s", zmq_strerror(errno));
        return -1;
    }
    if (zmq_setsockopt(s, ZMQ_LINGER, &zero, sizeof zero) ||
        (ipv6 && zmq_setsockopt(s, ZMQ_IPV6, &one, sizeof one)) ||
        (type == ZMQ_ROUTER && zmq_setsockopt(s, ZMQ_ROUTER_MANDATORY, &one, sizeof one)) ||
        (type == ZMQ_XPUB && zmq_setsockopt(s, ZMQ_SNDHWM, &hwm, sizeof hwm)) ||
        /* the daemon applies each subscription itself, only for one job's
         * topic (under CURVE: the job's owner or an admin), and a peer's
         * message larger than a subscription and the handshake needs
         * drops its connection unread (srv_stream.c) */
        (type == ZMQ_XPUB && zmq_setsockopt(s, ZMQ_XPUB_MANUAL, &one, sizeof one)) ||
        (type == ZMQ_XPUB &&
         zmq_setsockopt(s, ZMQ_MAXMSGSIZE, &(int64_t){SRV_STREAM_MAX_MSG}, sizeof(int64_t))) ||
        (type == ZMQ_PULL && zmq_setsockopt(s, ZMQ_RCVHWM, &hwm, sizeof hwm))) {
        snprintf(err, errlen, "setting options on %s: %s", ep, zmq_strerror(errno));
        zmq_close(s);
        return -1;
    }
    if ((type == ZMQ_ROUTER || type == ZMQ_XPUB) && srv_auth_secure(auth, s, err, errlen)) {
        zmq_close(s);
        return -1;
    }
    if (type == ZMQ_ROUTER) {
        /* libzmq drops the connection of a peer whose message is above
         * this as soon as its size is read, before any of it is allocated:
         * a request over --max-request-bytes is never held whole.  The
         * margin lets a request slightly over the limit get a TOO_LARGE
         * reply instead (the frame sizes a client can be told about). */
        int64_t cap = (int64_t)cfg->max_request_bytes + SRV_REQUEST_MARGIN;
        /* Each connection's pipe holds two requests the daemon has not
         * read yet (with one, libzmq 4.3 loses CURVE connections:
         * daemon_replies_curve_pipelined), and its engine one more while
         * it arrives: at most three per connection (the bound
         * --max-connections x 3 x --max-request-bytes, docs/manual.md).
         * An unauthenticated handshake holds its descriptor
         * --handshake-timeout-s at most.  With a connection cap its
         * handshakes (NULL ones too) go to the ZAP handler in a domain of
         * their own, and the handler refuses those past the cap
         * (srv_conns.h).  Guarded by
         * daemon_replies_large_requests_bounded, daemon_conns_cap_holds. */
        int rcvhwm = 2, ivl = cfg->handshake_timeout_s * 1000;
        if (zmq_setsockopt(s, ZMQ_MAXMSGSIZE, &cap, sizeof cap) ||
            zmq_setsockopt(s, ZMQ_RCVHWM, &rcvhwm, sizeof rcvhwm) ||
            zmq_setsockopt(s, ZMQ_HANDSHAKE_IVL, &ivl, sizeof ivl) ||
            (cfg->max_connections && srv_auth_zap_domain(s))) {
            snprintf(err, errlen, "request socket options: %s", zmq_strerror(errno));
            zmq_close(s);
            return -1;
        }
    }
    if (zmq_bind(s, bep)) {
        snprintf(err, errlen, "cannot bind %s: %s", ep, zmq_strerror(errno));
        zmq_close(s);
        return -1;
    }
    *out = s;
    return 0;
}
