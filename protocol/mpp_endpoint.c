/*
 * mpp_endpoint.c - the endpoint rules (see mpp_endpoint.h): one host
 * parser and one derivation, used by mpmd's --endpoint checks and by
 * mpmctl's choice of the stream to subscribe to.
 */
#include "mpp_endpoint.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The host of a tcp:// endpoint (*len bytes at the returned pointer; the
 * port follows the last ':'), or NULL for another transport. */
static const char *tcp_host(const char *ep, size_t *len)
{
    if (strncmp(ep, "tcp://", 6)) return NULL;
    const char *h = ep + 6, *colon = strrchr(h, ':');
    *len = colon ? (size_t)(colon - h) : strlen(h);
    return h;
}

static int host_is(const char *h, size_t len, const char *const *names, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (strlen(names[i]) == len && !strncmp(h, names[i], len)) return 1;
    return 0;
}

int mpp_endpoint_is_local(const char *ep)
{
    static const char *const loopback[] = {"localhost", "ip6-localhost", "::1", "[::1]"};
    size_t len;
    const char *h;
    if (!ep) return 0;
    if (!strncmp(ep, "ipc://", 6) || !strncmp(ep, "inproc://", 9)) return 1;
    if (!(h = tcp_host(ep, &len))) return 0;
    if (len >= 4 && !strncmp(h, "127.", 4)) return 1;
    return host_is(h, len, loopback, sizeof loopback / sizeof loopback[0]);
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
