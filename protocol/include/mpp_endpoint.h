/*
 * mpp_endpoint.h - the endpoint rules of the mpmd protocol, one copy for
 * mpmd's configuration and for mpmctl: whether a ZeroMQ endpoint stays on
 * this machine, and the stream endpoint that goes with a control endpoint.
 * Plain C (no generated code, no ZeroMQ).
 */
#ifndef MPP_ENDPOINT_H
#define MPP_ENDPOINT_H

#include <stddef.h>

/* 1 if ep binds or connects only on this machine: ipc://, inproc://, or
 * tcp:// whose host (after a source address "SRC;", if any) is a loopback
 * literal (127.x.y.z in dotted-quad decimal, ::1 or [::1]) or localhost or
 * ip6-localhost; else 0 (a wildcard such as tcp://\*:5555 binds every
 * interface; an interface name such as lo or eth0, a DNS name or another
 * spelling of a number may mean any address). */
int mpp_endpoint_is_local(const char *ep);

/* What a bind on ep needs (mpmd's fail-closed rule, the same for both
 * sockets and for flags, environment and config file). */
enum {
    MPP_BIND_INVALID = -1, /* never bound: why says (an unknown transport, one without
                            * ZMTP such as pgm:// or udp://, a source address, a bad port) */
    MPP_BIND_LOCAL = 0,    /* provably this machine only: mpp_endpoint_is_local() */
    MPP_BIND_REMOTE = 1    /* maybe reachable from elsewhere: CURVE needed; why says why */
};

/* The class of a bind on ep, with the reason of a MPP_BIND_INVALID or
 * MPP_BIND_REMOTE in why (n bytes, may be NULL). */
int mpp_endpoint_bind_class(const char *ep, char *why, size_t n);

/* 1 if ep is tcp:// with a wildcard host (*, [*], 0.0.0.0, ::, [::]). */
int mpp_endpoint_is_wildcard(const char *ep);

/* The stream endpoint that goes with a control endpoint: tcp port + 1
 * (port 1..65534), or ipc path + ".stream", into out (n bytes).  Returns 0,
 * or -1 if ep has neither form or out is too small. */
int mpp_stream_endpoint_derive(const char *ep, char *out, size_t n);

/* The stream endpoint a client should use, given the one the daemon
 * reports (Pong.stream_endpoint; NULL or "" when unknown) and the control
 * endpoint the client reached it at: the reported one, unless it is tcp
 * with a loopback or wildcard host (which only means something on the
 * daemon's machine), or unknown; then the derivation from the control
 * endpoint.  Returns 0 or -1 (nothing usable). */
int mpp_stream_endpoint_for_client(const char *reported, const char *control, char *out, size_t n);

#endif
