"""Client: the mpmd daemon from Python, over its control and stream sockets.

One Client holds one DEALER on the daemon's control socket (a ROUTER) and
exchanges ``[empty][Request]`` / ``[empty][Reply]`` frames with it, one
request at a time, each bounded by ``timeout`` seconds: no reply in time
raises MpmdError ``TIMEOUT`` (and the socket is replaced, so a late reply
cannot be taken for the next one's).  A socket monitor reports a refused
CURVE key or a failed handshake at once (``AUTH``) and a connection the
daemon closed without a reply (``DISCONNECTED``), as mpmctl does.

``watch(job)`` subscribes a SUB to the job's topic on the stream socket
(``job:%016x:``) *before* it reads the stored energy history, then merges
both by EnergySample.seq (docs/protocol.md, "Joining late"): every energy
sample is yielded exactly once, in order, however late the watcher joins
or whatever the stream drops; a job that ends while nobody hears its
Finished message is found by asking Status after a second of silence.

Endpoints and keys follow mpmctl's rules: ``endpoint`` (else
``$MPMD_ENDPOINT``, else tcp://127.0.0.1:5555); ``stream`` (else
``$MPMD_STREAM``, else the daemon's Pong.streamEndpoint or the control
endpoint's port + 1 / ipc path + ``.stream``); CURVE keys as in keys.py.
"""

import json
import os
import time
from typing import Any, Dict, Iterator, List, Optional, Union

import zmq
from google.protobuf import json_format
from google.protobuf.message import DecodeError

from . import endpoint as _ep
from . import keys as _keys
from ._pb import pb
from .errors import AUTH, DISCONNECTED, PROTOCOL, TIMEOUT, USAGE, MpmdError
from .results import (
    Energy,
    Finished,
    Progress,
    Run,
    RunList,
    Snapshot,
    Submitted,
    energy_array,
    status_name,
)

SCHEMA_VERSION = pb.SCHEMA_VERSION
SCHEMA_MINOR = getattr(pb, "SCHEMA_MINOR", 0)
DEFAULT_TIMEOUT = 10.0  # seconds, as mpmctl's --timeout
WATCH_IDLE_S = 1.0  # a watcher that hears nothing this long asks Status
WATCH_SUB_HWM = 100000  # stream messages buffered before dropping

_ENDED = ("FINISHED", "FAILED", "CANCELLED", "INTERRUPTED")

# what the socket monitor saw, worst last
_MON_NONE, _MON_DROPPED, _MON_HANDSHAKE, _MON_REFUSED = range(4)

# what a job or run may be given as
JobRef = Union[int, Submitted, Run]
CaseLike = Union[dict, str, bytes, "os.PathLike[str]", Any]


def _job_id(x: Any, what: str = "job") -> int:
    """An id from an int, a Submitted or a Run."""
    try:
        v = int(x.job_id if isinstance(x, Submitted) else x)
    except (TypeError, ValueError):
        raise MpmdError(USAGE, "%s: %r is not an id (a positive integer)" % (what, x)) from None
    if v <= 0 or v >= 1 << 64:
        raise MpmdError(USAGE, "%s: %r is not an id (a positive integer)" % (what, x))
    return v


def _run_id(x: Any, what: str = "run") -> int:
    if isinstance(x, Submitted):
        return _job_id(x.run_id, what)
    return _job_id(x, what)


def topic(job: int) -> bytes:
    """The stream topic of a job: 'job:' and its id as 16 hex digits, ':'."""
    return b"job:%016x:" % job


def _json_path(path: List[Union[str, int]]) -> str:
    """["bodies", 0, "ppc"] -> "bodies[0].ppc"."""
    out = ""
    for p in path:
        out += "[%d]" % p if isinstance(p, int) else ("." if out else "") + p
    return out


def _parse_fault(value: Any, desc: Any, path: List[Union[str, int]]) -> Optional[str]:
    """The path (JSON mapping, lowerCamelCase) of the first field of a
    case-like dict that does not parse as message type desc, or None when
    none alone fails.  Protobuf's ParseError names the field only
    sometimes and never the index of a repeated message, so the dict is
    walked against the descriptors: an unknown name, a message that is not
    an object, a value that does not parse on its own."""
    from google.protobuf.descriptor import FieldDescriptor as FD

    if not isinstance(value, dict):
        return _json_path(path) if path else ""
    by_name = {}
    for f in desc.fields:
        by_name[f.json_name] = f
        by_name[f.name] = f
    for key, v in value.items():
        f = by_name.get(key)
        if f is None:
            return _json_path(path + [key])
        here = path + [f.json_name]
        repeated = f.label == FD.LABEL_REPEATED
        if repeated and not isinstance(v, list):
            if v is None:
                continue
            return _json_path(here)
        items = list(enumerate(v)) if repeated else [(None, v)]
        for i, item in items:
            at = here + [i] if i is not None else here
            if f.type == FD.TYPE_MESSAGE:
                if item is None and i is None:
                    continue
                bad = _parse_fault(item, f.message_type, at)
                if bad is not None:
                    return bad
            else:
                # the one value alone, in a message of this type
                try:
                    json_format.ParseDict({key: [item] if repeated else item}, _msg_class(desc)())
                except json_format.ParseError:
                    return _json_path(at)
    return None


def _msg_class(desc: Any) -> Any:
    """The generated class of a message descriptor of the schema."""
    from google.protobuf import message_factory

    if hasattr(message_factory, "GetMessageClass"):  # protobuf >= 4.22
        return message_factory.GetMessageClass(desc)
    return message_factory.MessageFactory(desc.file.pool).GetPrototype(desc)


def case_message(case: CaseLike) -> Any:
    """A Case message from a dict (the JSON mapping), a path to a JSON case
    file, JSON text, or a Case message (copied).  Fields the schema gives a
    default (method, update) are set explicitly, as mpmctl does, so the
    stored case means the same to every version.  A case that does not
    parse raises InvalidCaseError (code INVALID_CASE) with the field path
    of the first value at fault (e.g. ``bodies[1].ppc``; the daemon checks
    the rest)."""
    msg = pb.Case()
    parsed: Any = None
    try:
        if isinstance(case, pb.Case):
            msg.CopyFrom(case)
        elif isinstance(case, dict):
            parsed = case
            json_format.ParseDict(case, msg)
        elif isinstance(case, (str, bytes, os.PathLike)):
            text = case
            if isinstance(case, os.PathLike) or (
                isinstance(case, str) and not case.lstrip().startswith("{")
            ):
                path = os.fspath(case)
                try:
                    with open(path, "r", encoding="utf-8") as f:
                        text = f.read()
                except OSError as e:
                    raise MpmdError(USAGE, "cannot read %s: %s" % (path, e.strerror)) from None
            try:
                parsed = json.loads(text)
            except ValueError as e:
                raise MpmdError(
                    "INVALID_CASE", "the case is not JSON: %s" % e
                ) from None
            json_format.ParseDict(parsed, msg)
        else:
            raise MpmdError(
                USAGE,
                "case: expected a dict, a JSON file path or an mpmd Case message, got %s"
                % type(case).__name__,
            )
    except json_format.ParseError as e:
        where = _parse_fault(parsed, pb.Case.DESCRIPTOR, []) if parsed is not None else None
        text = str(e).split("\n")[0]
        if where:
            raise MpmdError(
                "INVALID_CASE", "%s: the case does not parse: %s" % (where, text), where
            ) from None
        raise MpmdError("INVALID_CASE", "the case does not parse: %s" % text) from None
    msg.method = msg.method  # an absent field holds the schema's default
    msg.update = msg.update
    return msg


class Client:
    """A connection to mpmd.

    Client(endpoint=None, keys=None, timeout=10.0, stream=None)

    endpoint: the control socket (default $MPMD_ENDPOINT, else
        tcp://127.0.0.1:5555).
    keys: CURVE keys: a key directory holding server.pub and mpmd.key (as
        mpmctl --keys DIR), or a pair (server public key, client secret
        key) of Z85 strings or key files; default $MPMD_SERVER_KEY /
        $MPMD_CLIENT_KEY, $MPMD_KEYS, or ~/.config/mpmd for a remote
        endpoint; none: no CURVE (loopback, ipc://).
    timeout: seconds to wait for each reply (> 0).
    stream: the stream socket (default $MPMD_STREAM, else as the daemon
        reports it, else derived from endpoint).

    Every method raises MpmdError on failure (a subclass per code:
    NotFoundError, InvalidCaseError, RequestTimeout, ...).  A Client is for
    one thread at a time; use it as a context manager (``with Client() as
    c:``), or call close().
    """

    def __init__(
        self,
        endpoint: Optional[str] = None,
        keys: Any = None,
        timeout: float = DEFAULT_TIMEOUT,
        stream: Optional[str] = None,
    ) -> None:
        self.endpoint = endpoint or os.environ.get("MPMD_ENDPOINT") or _ep.DEFAULT_ENDPOINT
        self.stream = stream or os.environ.get("MPMD_STREAM") or None
        try:
            self.timeout = float(timeout)
        except (TypeError, ValueError):
            raise MpmdError(USAGE, "timeout: expected seconds, got %r" % (timeout,)) from None
        if not (0 < self.timeout <= 86400):
            raise MpmdError(USAGE, "timeout: expected seconds in (0, 86400], got %r" % timeout)
        self.curve = _keys.load(self.endpoint, keys)
        self._ctx = zmq.Context()
        self._dealer = None
        self._mon = None
        self._nmon = 0
        # the tests' fault injection, as mpmctl's MPMCTL_TEST_DROP_EVERY:
        # drop every Nth streamed energy sample
        self._drop_every = int(os.environ.get("MPMD_PY_TEST_DROP_EVERY", "0") or 0)

    # ---- connection ----------------------------------------------------------

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

    def close(self) -> None:
        """Closes the sockets (pending requests are dropped)."""
        self._close_dealer()
        if getattr(self, "_ctx", None) is not None:
            self._ctx.destroy(linger=0)  # also a watch's SUB left open
            self._ctx = None

    def _close_dealer(self):
        if getattr(self, "_mon", None) is not None:
            try:
                self._dealer.disable_monitor()
            except zmq.ZMQError:
                pass
            self._mon.close(0)
            self._mon = None
        if getattr(self, "_dealer", None) is not None:
            self._dealer.close(0)
            self._dealer = None

    def _socket(self, kind):
        s = self._ctx.socket(kind)
        s.linger = 0
        s.ipv6 = True
        if self.curve:
            self.curve.apply(s)
        return s

    def _open(self):
        if self._ctx is None:
            raise MpmdError(USAGE, "the client is closed")
        d = self._socket(zmq.DEALER)
        # the monitor tells of a refused key, a failed handshake and a
        # connection closed without a reply (libzmq would retry silently)
        self._nmon += 1
        addr = "inproc://mpmd-py-monitor-%x-%d" % (id(self), self._nmon)
        events = (
            zmq.EVENT_DISCONNECTED
            | zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL
            | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL
            | zmq.EVENT_HANDSHAKE_FAILED_AUTH
        )
        d.monitor(addr, events)
        mon = self._ctx.socket(zmq.PAIR)
        mon.linger = 0
        mon.connect(addr)
        try:
            d.connect(self.endpoint)
        except zmq.ZMQError as e:
            mon.close(0)
            d.close(0)
            raise MpmdError(USAGE, "cannot connect to %s: %s" % (self.endpoint, e)) from None
        self._dealer, self._mon = d, mon

    def _drain_monitor(self):
        seen = _MON_NONE
        while self._mon is not None:
            try:
                frames = self._mon.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                break
            if not frames or len(frames[0]) < 2:
                continue
            ev = int.from_bytes(frames[0][:2], "little")
            k = (
                _MON_DROPPED
                if ev == zmq.EVENT_DISCONNECTED
                else _MON_REFUSED
                if ev == zmq.EVENT_HANDSHAKE_FAILED_AUTH
                else _MON_HANDSHAKE
                if ev in (zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL, zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL)
                else _MON_NONE
            )
            seen = max(seen, k)
        return seen

    def _handshake_error(self, what):
        self._close_dealer()
        if what == _MON_REFUSED:
            msg = (
                "%s refused this client's key (public key %s): it is not in the server's "
                "--authorized-keys, or was removed from it"
                % (self.endpoint, self.curve.public_key if self.curve else "none")
            )
        elif self.curve:
            msg = (
                "the CURVE handshake with %s failed (client public key %s): is %s the "
                "server's public key (MPMD_SERVER_KEY), and does the server use CURVE?"
                % (self.endpoint, self.curve.public_key, self.curve.server_key)
            )
        else:
            msg = (
                "the handshake with %s failed: the server requires CURVE and this client has "
                "no key (set MPMD_SERVER_KEY and MPMD_CLIENT_KEY, or keys=DIR; README: "
                "Security)" % self.endpoint
            )
        return MpmdError(AUTH, msg)

    def _exchange(self, req, timeout=None):
        """Sends a Request, returns the Reply message (any body)."""
        timeout = self.timeout if timeout is None else timeout
        if self._dealer is None:
            self._open()
        req.schema_version = SCHEMA_VERSION
        data = req.SerializeToString()
        deadline = time.monotonic() + timeout
        before = self._drain_monitor()
        if before >= _MON_HANDSHAKE:
            raise self._handshake_error(before)
        try:
            self._dealer.send_multipart([b"", data], flags=zmq.NOBLOCK)
        except zmq.Again:
            # nothing connected yet: wait for the pipe within the deadline
            if not self._dealer.poll(int(timeout * 1000) + 1, zmq.POLLOUT):
                self._close_dealer()
                raise MpmdError(
                    TIMEOUT,
                    "no reply from %s within %g s (is mpmd running?)" % (self.endpoint, timeout),
                ) from None
            self._dealer.send_multipart([b"", data])
        poller = zmq.Poller()
        poller.register(self._dealer, zmq.POLLIN)
        poller.register(self._mon, zmq.POLLIN)
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                self._close_dealer()  # a late reply must not answer the next request
                raise MpmdError(
                    TIMEOUT,
                    "no reply from %s within %g s (is mpmd running?)" % (self.endpoint, timeout),
                )
            ready = dict(poller.poll(int(left * 1000) + 1))
            if self._dealer in ready:
                break
            if self._mon in ready:
                ev = self._drain_monitor()
                if ev >= _MON_HANDSHAKE:
                    raise self._handshake_error(ev)
                if ev == _MON_DROPPED:
                    self._close_dealer()
                    raise MpmdError(
                        DISCONNECTED,
                        "%s closed the connection without a reply: the request (%d bytes) may "
                        "exceed the server's limit (mpmd --max-request-bytes), or the server "
                        "stopped" % (self.endpoint, len(data)),
                    )
        frames = self._dealer.recv_multipart()
        if len(frames) != 2 or frames[0] != b"":
            raise MpmdError(
                PROTOCOL, "malformed reply from %s (%d frames)" % (self.endpoint, len(frames))
            )
        reply = pb.Reply()
        try:
            reply.ParseFromString(frames[1])
        except DecodeError as e:
            raise MpmdError(
                PROTOCOL, "undecodable reply from %s: %s" % (self.endpoint, e)
            ) from None
        return reply

    def _call(self, want, timeout=None, **body):
        """One request (body: the one field of Request to set, e.g.
        get_run={"run_id": 1}); returns the reply's `want` body or raises
        the reply's error."""
        req = pb.Request()
        ((name, fields),) = body.items()
        getattr(req, name).SetInParent()
        for k, v in fields.items():
            if v is not None:
                setattr(getattr(req, name), k, v)
        reply = self._exchange(req, timeout)
        which = reply.WhichOneof("body")
        if which == "error":
            e = reply.error
            raise MpmdError(_enum_name_code(e.code), e.message, e.field)
        if which != want:
            raise MpmdError(
                PROTOCOL,
                "unexpected reply from %s: %s instead of %s" % (self.endpoint, which, want),
            )
        return getattr(reply, want)

    # ---- requests -------------------------------------------------------------

    def ping(self) -> Dict[str, Any]:
        """Liveness: a dict with server_version, schema_version,
        schema_minor (0 from a daemon before schema 1.1) and
        stream_endpoint."""
        p = self._call("pong", ping={})
        return {
            "server_version": p.server_version,
            "schema_version": p.schema_version,
            "schema_minor": p.schema_minor,
            "stream_endpoint": p.stream_endpoint,
        }

    def version(self) -> Dict[str, Any]:
        """A dict: server_version, schema_version, schema_minor, components
        ({name: version})."""
        v = self._call("version", version={})
        return {
            "server_version": v.server_version,
            "schema_version": v.schema_version,
            "schema_minor": v.schema_minor,
            "components": {c.name: c.version for c in v.components},
        }

    def submit(self, case: CaseLike) -> Submitted:
        """Queues a case: a dict (the JSON mapping, as a case file holds it),
        a path to a JSON case file, or an mpmd Case message.  Returns a
        Submitted (job_id, run_id).  A case the daemon refuses raises
        MpmdError INVALID_CASE (or TOO_LARGE) with the field."""
        msg = case_message(case)
        req = pb.Request()
        req.submit.case.CopyFrom(msg)
        reply = self._exchange(req)
        which = reply.WhichOneof("body")
        if which == "error":
            e = reply.error
            raise MpmdError(_enum_name_code(e.code), e.message, e.field)
        if which != "submit_ok":
            raise MpmdError(PROTOCOL, "unexpected reply to submit: %s" % which)
        return Submitted(reply.submit_ok.job_id, reply.submit_ok.run_id)

    def status(self, job: JobRef) -> Run:
        """Where a job stands: its Run."""
        return Run.from_pb(self._call("run", status={"job_id": _job_id(job)}))

    def cancel(self, job: JobRef) -> Run:
        """Stops a queued or running job; returns its Run (a running job is
        still RUNNING until its next step: watch it, or poll status).
        CONFLICT if it already ended, FORBIDDEN unless this client's key
        submitted it or is an admin key."""
        return Run.from_pb(self._call("run", cancel={"job_id": _job_id(job)}))

    def run(self, run_id: JobRef, with_case: bool = False) -> Run:
        """One run record; with_case: Run.case holds the case as a dict."""
        return Run.from_pb(
            self._call(
                "run", get_run={"run_id": _run_id(run_id), "with_case": True if with_case else None}
            )
        )

    def runs(
        self,
        status: Optional[Union[str, int]] = None,
        limit: Optional[int] = None,
        before: Optional[JobRef] = None,
    ) -> RunList:
        """Run records, newest first: a RunList of Run (at most limit, the
        daemon's default 100; at most 10000), only those with status (a name
        such as "FINISHED") and, with before, only runs with a smaller id.
        RunList.next_before_run_id is set when the limit cut the listing."""
        st = None
        if status is not None:
            try:
                st = pb.RunStatus.Value(status) if isinstance(status, str) else int(status)
            except ValueError:
                raise MpmdError(
                    USAGE,
                    "status: %r is not one of %s"
                    % (status, ", ".join(pb.RunStatus.keys())),
                    "status",
                ) from None
        lst = self._call(
            "runs",
            list_runs={
                "status": st,
                "limit": limit,
                "before_run_id": _run_id(before) if before else None,
            },
        )
        out = RunList(Run.from_pb(r) for r in lst.runs)
        out.next_before_run_id = lst.next_before_run_id if lst.HasField("next_before_run_id") else None
        return out

    def energy_samples(self, run_id: JobRef, from_seq: int = 0) -> List[Any]:
        """The EnergySample messages of a run with seq >= from_seq, paging
        through GetEnergy."""
        rid = _run_id(run_id)
        out = []
        frm = from_seq
        while True:
            page = self._call("energy", get_energy={"run_id": rid, "from_seq": frm or None})
            out.extend(page.samples)
            if not page.more:
                return out
            if not page.samples or page.samples[-1].seq + 1 <= frm:
                raise MpmdError(
                    PROTOCOL,
                    "energy of run %d: the server says there is more after seq %d but sent "
                    "nothing new" % (rid, frm),
                )
            frm = page.samples[-1].seq + 1

    def energy(self, run_id: JobRef) -> Any:
        """A run's whole energy series as a NumPy structured array, one row
        per sample in seq order: seq, step, t, kinetic, strain, potential,
        external_work, total, mass, momentum (n, dim), angular_momentum
        (n, 1) in 2D / (n, 3) in 3D (absent in 1D; NaN: not recorded),
        plastic_work, damping_work, friction_work, prescribed_work,
        balance_error.  e["t"], e["momentum"][:, 0] / e["mass"], ..."""
        return energy_array(self.energy_samples(run_id))

    def snapshot(self, run_id: JobRef, step: Optional[int] = None) -> Snapshot:
        """A recorded snapshot (the latest, or the one at step) as a
        Snapshot of NumPy arrays.  NOT_FOUND (field "step") when there is
        none at that step."""
        s = self._call("snapshot", get_snapshot={"run_id": _run_id(run_id), "step": step})
        return Snapshot.from_pb(s)

    def wait(self, job: JobRef, timeout: Optional[float] = None, poll: float = 0.05) -> Run:
        """Waits for a job to end and returns its finished Run (status
        FINISHED, FAILED, CANCELLED or INTERRUPTED: a run that failed is
        returned, not raised).  Asks Status every `poll` seconds at first,
        then less often (up to 1 s).  timeout: seconds to wait at most
        (None: for ever); when it passes, RequestTimeout (code TIMEOUT,
        field "timeout") with the job still running."""
        jid = _job_id(job)
        if timeout is not None and not timeout >= 0:
            raise MpmdError(USAGE, "timeout: expected seconds >= 0, got %r" % (timeout,), "timeout")
        deadline = None if timeout is None else time.monotonic() + timeout
        delay = max(0.001, float(poll))
        while True:
            run = self.status(jid)
            if run.ended:
                return run
            if deadline is not None and time.monotonic() >= deadline:
                raise MpmdError(
                    TIMEOUT,
                    "job %d is still %s (step %d) after %g s" % (jid, run.status, run.steps, timeout),
                    "timeout",
                )
            left = delay if deadline is None else min(delay, max(0.0, deadline - time.monotonic()))
            time.sleep(left)
            delay = min(1.0, delay * 1.5)

    # ---- the stream -----------------------------------------------------------

    def stream_endpoint(self) -> str:
        """Where the job streams are published, as mpmctl decides it."""
        if self.stream:
            return self.stream
        reported = self.ping()["stream_endpoint"]
        ep = _ep.stream_for_client(reported, self.endpoint)
        if not ep:
            raise MpmdError(
                USAGE,
                "cannot derive the stream endpoint from %s; give stream=EP" % self.endpoint,
            )
        return ep

    def watch(self, job: JobRef, snapshots: bool = True) -> Iterator[Any]:
        """Follows a job to its end: a generator of events.

        Yields Energy (every sample of the run exactly once, in seq order,
        however late the watch starts: the stored history first, then the
        live stream, with any gap the stream leaves filled from the
        store), Progress and, with snapshots, Snapshot (live only: what is
        streamed while watching), and last a Finished.  A job that has
        already ended yields its history and its Finished.  Stopping the
        iteration early leaves the job running.  Raises MpmdError like any
        request (TIMEOUT when the daemon goes away)."""
        w = _Watch(self, _job_id(job), snapshots)
        try:
            yield from w.run()
        finally:
            w.close()


def _enum_name_code(v):
    try:
        return pb.Error.Code.Name(v)
    except ValueError:
        return str(v)


class _Watch:
    """The state of one watch (see Client.watch and ctl_watch.c)."""

    def __init__(self, client, job, snapshots):
        self.c = client
        self.job = job
        self.snapshots = snapshots
        self.next = 0  # next energy seq expected
        self.sub = None
        self.finished = None  # the Finished message's event, once seen
        self.fin_sample = None  # the final sample it carried
        self.energy_seen = 0
        self.step = 0

    def close(self):
        if self.sub is not None:
            self.sub.close(0)
            self.sub = None

    def _subscribe(self):
        ep = self.c.stream_endpoint()
        if self.c._ctx is None:
            raise MpmdError(USAGE, "the client is closed")
        s = self.c._socket(zmq.SUB)
        s.rcvhwm = WATCH_SUB_HWM
        s.setsockopt(zmq.SUBSCRIBE, topic(self.job))
        try:
            s.connect(ep)
        except zmq.ZMQError as e:
            s.close(0)
            raise MpmdError(USAGE, "cannot connect to the stream at %s: %s" % (ep, e)) from None
        self.sub = s

    def _history(self):
        """The stored samples from self.next on, as Energy events."""
        for s in self.c.energy_samples(self.job, self.next):
            if s.seq < self.next:
                continue
            self.next = s.seq + 1  # a hole in the store itself is skipped
            self.step = max(self.step, s.step)
            yield Energy.from_pb(s)

    def _finished_from_run(self, run):
        le = run.last_energy
        return Finished(
            status=run.status,
            error=run.error,
            steps=run.steps,
            t=run.t,
            wall_s=run.wall_s,
            energy=le,
            balance_error=run.balance_error,
            warning=run.warning,
            from_stream=False,
        )

    def run(self):
        self._subscribe()
        run = self.c.status(self.job)  # whether it exists, and where it stands
        ended = run.ended
        yield from self._history()
        if ended:
            yield self._finished_from_run(run)
            return
        last_msg = time.monotonic()
        while True:
            wait = WATCH_IDLE_S - (time.monotonic() - last_msg)
            if self.sub.poll(max(0, int(wait * 1000))):
                n = 0
                while n < 1000 and self.finished is None:
                    try:
                        frames = self.sub.recv_multipart(zmq.NOBLOCK)
                    except zmq.Again:
                        break
                    n += 1
                    yield from self._on_message(frames)
                last_msg = time.monotonic()
                if self.finished is not None:
                    yield from self._tail()
                    yield self.finished
                    return
                continue
            # quiet for a while: has the job ended unheard?  (and the samples
            # a silent stream did not bring: the store has them)
            run = self.c.status(self.job)
            if run.ended or run.energy_samples > self.next:
                yield from self._history()
            if run.ended:
                yield self._finished_from_run(run)
                return
            last_msg = time.monotonic()

    def _on_message(self, frames):
        if len(frames) != 2:
            return  # malformed: dropped, as mpmctl does
        m = pb.StreamMsg()
        try:
            m.ParseFromString(frames[1])
        except DecodeError:
            return
        if m.HasField("job_id") and m.job_id != self.job:
            return
        kind = m.WhichOneof("body")
        if kind == "energy":
            self.energy_seen += 1
            if self.c._drop_every and self.energy_seen % self.c._drop_every == 0:
                return  # injected loss (tests)
            s = m.energy
            if s.seq < self.next:
                return
            if s.seq > self.next:
                yield from self._history()  # the gap, from the store
                if s.seq < self.next:
                    return
            self.next = s.seq + 1
            self.step = max(self.step, s.step)
            yield Energy.from_pb(s, m.seq)
        elif kind == "progress":
            p = m.progress
            self.step = max(self.step, p.step)
            yield Progress(p.step, p.t, p.dt, p.steps_total, p.wall_s, m.seq)
        elif kind == "snapshot":
            if self.snapshots:
                try:
                    yield Snapshot.from_pb(m.snapshot, m.seq)
                except MpmdError:
                    pass  # a malformed snapshot: not shown
        elif kind == "finished":
            f = m.finished
            self.fin_sample = f.energy if f.HasField("energy") else None
            self.finished = Finished(
                status=status_name(f.status),
                error=f.error,
                steps=f.steps,
                t=f.t,
                wall_s=f.wall_s,
                energy=Energy.from_pb(f.energy, m.seq) if self.fin_sample is not None else None,
                balance_error=f.balance_error if f.HasField("balance_error") else None,
                warning=f.warning,
                stream_seq=m.seq,
            )

    def _tail(self):
        """After Finished: the samples still missing (its final sample
        completes the series when it is the next one; otherwise the store
        has the rest; a job that never ran has none)."""
        s = self.fin_sample
        if s is not None:
            if s.seq < self.next:
                return
            if s.seq == self.next:
                self.next += 1
                yield Energy.from_pb(s)
                return
        elif self.step == 0 and self.next == 0:
            return
        saved = self.c.timeout
        if self.finished.status == "INTERRUPTED":
            self.c.timeout = min(saved, 3.0)
        try:
            yield from self._history()
        except MpmdError as e:
            # a daemon that stopped (INTERRUPTED) may leave nobody to ask
            if not (e.code == TIMEOUT and self.finished.status == "INTERRUPTED"):
                raise
        finally:
            self.c.timeout = saved
