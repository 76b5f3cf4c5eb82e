"""The exceptions of the mpmd client: MpmdError(code, message, field) and a
subclass per code.

A failure in any layer - an Error reply of the daemon, no reply within the
timeout, a refused CURVE handshake, a key file that cannot be used, a case
that does not parse - raises an MpmdError.  ``code`` is the wire's
``Error.Code`` name for an error the daemon answered (``INVALID_CASE``,
``NOT_FOUND``, ``FORBIDDEN``, ...) or one of the client's own codes below;
``field`` is the offending field in the JSON mapping's lowerCamelCase
spelling (``bodies[0].sphere.radius``, ``runId``), empty when no single
field is at fault; ``message`` is the human-readable text (for a daemon
error already rendered as ``field: message``).

Each code has its class (``NotFoundError``, ``InvalidCaseError``,
``RequestTimeout``, ...; the table ``ERROR_CLASSES``), so that a caller can
catch one kind: ``MpmdError(code, ...)`` itself builds the subclass of its
code, and ``except MpmdError`` still catches them all.  A code this client
does not know (a newer daemon's) stays a plain MpmdError.
"""

from typing import Dict, Optional, Type

# Codes raised by the client itself (the daemon's codes are Error.Code names).
TIMEOUT = "TIMEOUT"  # no reply within the timeout: is mpmd running?
AUTH = "AUTH"  # the CURVE handshake failed or the key was refused
DISCONNECTED = "DISCONNECTED"  # the daemon closed the connection without a reply
PROTOCOL = "PROTOCOL"  # a reply that is not what was asked for, or undecodable
KEYS = "KEYS"  # a key file or key setting that cannot be used
USAGE = "USAGE"  # a bad argument (a case that does not parse, an id that is not one)

CLIENT_CODES = (TIMEOUT, AUTH, DISCONNECTED, PROTOCOL, KEYS, USAGE)


class MpmdError(Exception):
    """An mpmd request or client operation failed.

    Attributes:
        code: the Error.Code name the daemon answered (e.g. ``"NOT_FOUND"``)
            or a client code (``TIMEOUT``, ``AUTH``, ``DISCONNECTED``,
            ``PROTOCOL``, ``KEYS``, ``USAGE``).
        field: the offending field (lowerCamelCase path), or ``""``.
        message: the explanation.
    """

    code: str
    field: str
    message: str

    def __new__(cls, code: Optional[str] = None, message: str = "", field: str = ""):
        # MpmdError("NOT_FOUND", ...) is a NotFoundError
        if cls is MpmdError:
            cls = ERROR_CLASSES.get(code or "", MpmdError)
        return super().__new__(cls, code, message, field)

    def __init__(self, code: Optional[str] = None, message: str = "", field: str = ""):
        self.code = code or getattr(type(self), "CODE", "") or ""
        self.field = field or ""
        self.message = message or ""
        super().__init__(self.__str__())

    def __str__(self) -> str:
        text = "%s: %s" % (self.code, self.message)
        # as mpmctl prints it: the field only when the message does not
        # already start with it
        if self.field and not self.message.startswith(self.field + ":"):
            text += " (field %s)" % self.field
        return text

    def __repr__(self) -> str:
        return "%s(code=%r, field=%r, message=%r)" % (
            type(self).__name__,
            self.code,
            self.field,
            self.message,
        )

    def __reduce__(self):
        # pickles (multiprocessing) as the class of its code again
        return (MpmdError, (self.code, self.message, self.field))


def _kind(name: str, code: str, doc: str) -> Type[MpmdError]:
    return type(name, (MpmdError,), {"CODE": code, "__doc__": doc})


# One class per code: the daemon's Error.Code names, then the client's own.
InternalError = _kind("InternalError", "INTERNAL", "Server-side failure (I/O, memory, bug).")
BadRequestError = _kind("BadRequestError", "BAD_REQUEST", "The request could not be decoded.")
BadSchemaError = _kind("BadSchemaError", "BAD_SCHEMA", "The schema version is not supported.")
InvalidCaseError = _kind("InvalidCaseError", "INVALID_CASE", "The case was rejected; see field.")
NotFoundError = _kind("NotFoundError", "NOT_FOUND", "No such job, run or snapshot.")
QueueFullError = _kind("QueueFullError", "QUEUE_FULL", "Too many queued jobs; retry later.")
TooLargeError = _kind("TooLargeError", "TOO_LARGE", "Above one of the server's limits.")
ConflictError = _kind("ConflictError", "CONFLICT", "Not possible in the current state.")
UnavailableError = _kind("UnavailableError", "UNAVAILABLE", "The server is shutting down.")
ForbiddenError = _kind("ForbiddenError", "FORBIDDEN", "This key may not do that.")
RequestTimeout = _kind("RequestTimeout", TIMEOUT, "No reply (or no end of a wait) in time.")
AuthError = _kind("AuthError", AUTH, "The CURVE handshake failed or the key was refused.")
DisconnectedError = _kind("DisconnectedError", DISCONNECTED, "Closed without a reply.")
ProtocolError = _kind("ProtocolError", PROTOCOL, "A reply that is not what was asked for.")
KeysError = _kind("KeysError", KEYS, "A key file or setting that cannot be used.")
UsageError = _kind("UsageError", USAGE, "A bad argument.")

ERROR_CLASSES: Dict[str, Type[MpmdError]] = {
    c.CODE: c  # type: ignore[attr-defined]
    for c in (
        InternalError,
        BadRequestError,
        BadSchemaError,
        InvalidCaseError,
        NotFoundError,
        QueueFullError,
        TooLargeError,
        ConflictError,
        UnavailableError,
        ForbiddenError,
        RequestTimeout,
        AuthError,
        DisconnectedError,
        ProtocolError,
        KeysError,
        UsageError,
    )
}
