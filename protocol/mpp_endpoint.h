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
 * tcp:// with a loopback host (127.x.y.z, localhost, ip6-localhost, ::1 or
 * [::1]); else 0 (a wildcard such as tcp://\*:5555 binds every interface). */
int mpp_endpoint_is_local(const char *ep);

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
