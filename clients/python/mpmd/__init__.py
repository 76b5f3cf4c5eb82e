"""mpmd: the Python client of the mpmd Material Point Method service.

    import mpmd
    c = mpmd.Client()                                # $MPMD_ENDPOINT or tcp://127.0.0.1:5555
    job = c.submit("proto/examples/bar1d_gimp.json") # a dict, a JSON path or a Case message
    for ev in c.watch(job): print(ev)                # Energy, Progress, Snapshot ..., Finished
    e = c.energy(job)                                # NumPy structured array: e["t"], e["kinetic"]
    with mpmd.Client() as c:                         # closes its sockets at the end
        run = c.wait(c.submit(case), timeout=60)     # the finished Run (a table in Jupyter)

Client (client.py) talks to the daemon over ZeroMQ with the protobuf
classes generated from proto/mpmd.proto (``make python``); every failure
raises MpmdError (errors.py) with ``.code``, ``.field`` and ``.message``,
as the subclass of its code (NotFoundError, InvalidCaseError, ...).
The returned types are in results.py; endpoint and CURVE key rules, the same
as mpmctl's, in endpoint.py and keys.py.
"""

from .client import DEFAULT_TIMEOUT, SCHEMA_MINOR, SCHEMA_VERSION, Client, case_message, topic
from .errors import (
    ERROR_CLASSES,
    AuthError,
    BadRequestError,
    BadSchemaError,
    ConflictError,
    DisconnectedError,
    ForbiddenError,
    InternalError,
    InvalidCaseError,
    KeysError,
    MpmdError,
    NotFoundError,
    ProtocolError,
    QueueFullError,
    RequestTimeout,
    TooLargeError,
    UnavailableError,
    UsageError,
)
from .results import Energy, Finished, Progress, Run, RunList, Snapshot, Submitted, energy_array
from ._pb import pb

__all__ = [
    "Client",
    "MpmdError",
    "ERROR_CLASSES",
    "AuthError",
    "BadRequestError",
    "BadSchemaError",
    "ConflictError",
    "DisconnectedError",
    "ForbiddenError",
    "InternalError",
    "InvalidCaseError",
    "KeysError",
    "NotFoundError",
    "ProtocolError",
    "QueueFullError",
    "RequestTimeout",
    "TooLargeError",
    "UnavailableError",
    "UsageError",
    "Energy",
    "Progress",
    "Snapshot",
    "Finished",
    "Run",
    "RunList",
    "Submitted",
    "energy_array",
    "case_message",
    "topic",
    "pb",
    "DEFAULT_TIMEOUT",
    "SCHEMA_VERSION",
    "SCHEMA_MINOR",
]
