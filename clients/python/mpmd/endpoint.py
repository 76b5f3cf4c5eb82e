"""The endpoint rules mpmctl follows (protocol/mpp_endpoint.c), in Python.

``is_local(ep)``: ipc://, inproc:// and tcp:// to a loopback host
(127.x.x.x, localhost, ip6-localhost, ::1).  ``derive_stream(ep)``: the
stream socket of a control endpoint, tcp port + 1 or the ipc path +
``.stream``.  ``stream_for_client(reported, control)``: the stream endpoint
a client connects to: what the daemon reports in Pong.streamEndpoint,
unless that is a loopback or wildcard tcp address (the daemon's own view,
useless from another machine), in which case it is derived from the
control endpoint the client used.
"""

_LOOPBACK = ("localhost", "ip6-localhost", "::1", "[::1]")
_WILDCARD = ("*", "[*]", "0.0.0.0", "::", "[::]")

DEFAULT_ENDPOINT = "tcp://127.0.0.1:5555"


def _tcp_host(ep):
    if not ep.startswith("tcp://"):
        return None
    rest = ep[6:]
    colon = rest.rfind(":")
    return rest[:colon] if colon >= 0 else rest


def is_local(ep):
    """True for ipc://, inproc:// and loopback tcp:// endpoints."""
    if not ep:
        return False
    if ep.startswith("ipc://") or ep.startswith("inproc://"):
        return True
    host = _tcp_host(ep)
    if host is None:
        return False
    return host.startswith("127.") or host in _LOOPBACK


def is_wildcard(ep):
    """True for a tcp:// endpoint on a wildcard address (*, 0.0.0.0, ::)."""
    host = _tcp_host(ep) if ep else None
    return host is not None and host in _WILDCARD


def derive_stream(ep):
    """The stream endpoint of control endpoint ep, or None if there is none
    (tcp: port + 1; ipc: path + '.stream')."""
    if not ep:
        return None
    if ep.startswith("ipc://"):
        return ep + ".stream"
    if not ep.startswith("tcp://"):
        return None
    colon = ep.rfind(":")
    if colon < 6:
        return None
    port = ep[colon + 1 :]
    if not port.isdigit():
        return None
    p = int(port)
    if p < 1 or p >= 65535:
        return None
    return "%s:%d" % (ep[:colon], p + 1)


def stream_for_client(reported, control):
    """The stream endpoint to subscribe to, given the daemon's report
    (Pong.streamEndpoint) and the control endpoint used; None if neither
    gives one."""
    if reported and not (
        reported.startswith("tcp://") and (is_local(reported) or is_wildcard(reported))
    ):
        return reported
    return derive_stream(control)
