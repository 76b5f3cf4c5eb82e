/*
 * mpp_endpoint.c - the endpoint rules (see mpp_endpoint.h): one host
 * parser and one derivation, used by mpmd's --endpoint checks and by
 * mpmctl's choice of the stream to subscribe to.  The host is read the way
 * libzmq reads it (the address after the last ';', the port after the last
 * ':', IPv6 in brackets), and a bind counts as loopback only for a literal
 * loopback address or the two names mpmd itself maps to one
 * (srv_socket.c): every other spelling may mean an interface or a name.
 */
#include "mpp_endpoint.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The host of a tcp:// endpoint (*len bytes at the returned pointer; the
 * port follows the last ':'), or NULL for another transport.  A source
 * address ("SRC;HOST:PORT", libzmq's form) is skipped: the host is what
 * follows the last ';', the address libzmq binds or connects to. */
static const char *tcp_host(const char *ep, size_t *len)
{
    if (strncmp(ep, "tcp://", 6)) return NULL;
    const char *h = ep + 6, *semi = strrchr(h, ';');
    if (semi) h = semi + 1;
    const char *colon = strrchr(h, ':');
    *len = colon ? (size_t)(colon - h) : strlen(h);
    return h;
}

static int host_is(const char *h, size_t len, const char *const *names, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (strlen(names[i]) == len && !strncmp(h, names[i], len)) return 1;
    return 0;
}

/* 1 if h (len bytes) is a dotted-quad IPv4 literal in 127.0.0.0/8: four
 * decimal parts of 1 to 3 digits, each at most 255, no leading zero (the
 * spellings "127.1", "0x7f.0.0.1" or "2130706433", which libzmq's resolver
 * also takes, are not recognised: not provably loopback to this check). */
static int ipv4_loopback(const char *h, size_t len)
{
    int part = 0, val = 0, digits = 0, first = -1;
    for (size_t i = 0; i <= len; i++) {
        char c = i < len ? h[i] : '.';
        if (c >= '0' && c <= '9') {
            if (digits == 3 || (digits && val == 0)) return 0;
            val = 10 * val + (c - '0');
            digits++;
            continue;
        }
        if (c != '.' || !digits || val > 255 || part == 4) return 0;
        if (part == 0) first = val;
        part++;
        val = digits = 0;
    }
    return part == 4 && first == 127;
}

int mpp_endpoint_bind_class(const char *ep, char *why, size_t n)
{
    static const char *const names[] = {"localhost", "ip6-localhost", "::1", "[::1]"};
    static const char *const remote[] = {"ws://", "wss://", "tipc://", "vmci://"};
    static const char *const no_zmtp[] = {"pgm://", "epgm://", "norm://", "udp://"};
    char dummy[1];
    if (!why || !n) why = dummy, n = sizeof dummy;
    why[0] = 0;
    if (!ep || !*ep) {
        snprintf(why, n, "no endpoint");
        return MPP_BIND_INVALID;
    }
    if (!strncmp(ep, "ipc://", 6) || !strncmp(ep, "inproc://", 9)) return MPP_BIND_LOCAL;
    for (size_t i = 0; i < sizeof remote / sizeof remote[0]; i++)
        if (!strncmp(ep, remote[i], strlen(remote[i]))) {
            snprintf(why, n, "%.*s is reachable from other machines", (int)strlen(remote[i]) - 3,
                     remote[i]);
            return MPP_BIND_REMOTE;
        }
    for (size_t i = 0; i < sizeof no_zmtp / sizeof no_zmtp[0]; i++)
        if (!strncmp(ep, no_zmtp[i], strlen(no_zmtp[i]))) {
            snprintf(why, n,
                     "%.*s carries no ZMTP handshake, so neither CURVE nor the request "
                     "protocol: mpmd binds tcp, ipc, inproc, ws, wss, tipc or vmci",
                     (int)strlen(no_zmtp[i]) - 3, no_zmtp[i]);
            return MPP_BIND_INVALID;
        }
    if (strncmp(ep, "tcp://", 6)) {
        snprintf(why, n,
                 "unknown transport (mpmd binds tcp://, ipc://, inproc://, ws://, wss://, "
                 "tipc:// or vmci://)");
        return MPP_BIND_INVALID;
    }
    if (strchr(ep + 6, ';')) {
        snprintf(why, n,
                 "a source address (the part before ';') has no meaning for a bind: libzmq "
                 "would bind '%.64s', the part after it",
                 strrchr(ep, ';') + 1);
        return MPP_BIND_INVALID;
    }
    const char *colon = strrchr(ep + 6, ':'), *port = colon ? colon + 1 : NULL;
    size_t plen = port ? strlen(port) : 0;
    int port_ok = plen == 1 && port[0] == '*';
    if (plen >= 1 && plen <= 5 && strspn(port, "0123456789") == plen) port_ok = atol(port) <= 65535;
    if (!colon || !port_ok) {
        snprintf(why, n, "expected tcp://HOST:PORT with PORT a number from 0 to 65535 or '*'");
        return MPP_BIND_INVALID;
    }
    size_t len;
    const char *h = tcp_host(ep, &len);
    if (ipv4_loopback(h, len) || host_is(h, len, names, sizeof names / sizeof names[0]))
        return MPP_BIND_LOCAL;
    if (mpp_endpoint_is_wildcard(ep))
        snprintf(why, n, "'%.*s' binds every interface", (int)len, h);
    else
        snprintf(why, n,
                 "'%.*s' is not one of 127.x.y.z, ::1, [::1], localhost or ip6-localhost "
                 "(libzmq takes other names for interfaces such as eth0, and other numbers "
                 "for any address)",
                 (int)(len > 64 ? 64 : len), h);
    return MPP_BIND_REMOTE;
}

int mpp_endpoint_is_local(const char *ep)
{
    static const char *const loopback[] = {"localhost", "ip6-localhost", "::1", "[::1]"};
    size_t len;
    const char *h;
    if (!ep) return 0;
    if (!strncmp(ep, "ipc://", 6) || !strncmp(ep, "inproc://", 9)) return 1;
    if (!(h = tcp_host(ep, &len))) return 0;
    return ipv4_loopback(h, len) || host_is(h, len, loopback, sizeof loopback / sizeof loopback[0]);
}

int mpp_endpoint_is_wildcard(const char *ep)
{
    static const char *const any[] = {"*", "[*]", "0.0.0.0", "::", "[::]"};
    size_t len;
    const char *h = ep ? tcp_host(ep, &len) : NULL;
    return h && host_is(h, len, any, sizeof any / sizeof any[0]);
}

int mpp_stream_endpoint_derive(const char *ep, char *out, size_t n)
{
    int w;
    if (!ep) return -1;
    if (!strncmp(ep, "ipc://", 6)) {
        w = snprintf(out, n, "%s.stream", ep);
        return w > 0 && (size_t)w < n ? 0 : -1;
    }
    if (strncmp(ep, "tcp://", 6)) return -1;
    const char *colon = strrchr(ep + 6, ':');
    char *end;
    if (!colon) return -1;
    errno = 0;
    long port = strtol(colon + 1, &end, 10);
    if (errno || end == colon + 1 || *end || port < 1 || port >= 65535) return -1;
    w = snprintf(out, n, "%.*s:%ld", (int)(colon - ep), ep, port + 1);
    return w > 0 && (size_t)w < n ? 0 : -1;
}

int mpp_stream_endpoint_for_client(const char *reported, const char *control, char *out, size_t n)
{
    if (reported && *reported &&
        !(!strncmp(reported, "tcp://", 6) &&
          (mpp_endpoint_is_local(reported) || mpp_endpoint_is_wildcard(reported)))) {
        int w = snprintf(out, n, "%s", reported);
        if (w > 0 && (size_t)w < n) return 0;
    }
    return mpp_stream_endpoint_derive(control, out, n);
}
