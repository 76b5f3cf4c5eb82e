"""The one exception of the mpmd client: MpmdError(code, field, message).

A failure in any layer - an Error reply of the daemon, no reply within the
timeout, a refused CURVE handshake, a key file that cannot be used, a case
that does not parse - raises MpmdError.  ``code`` is the wire's
``Error.Code`` name for an error the daemon answered (``INVALID_CASE``,
``NOT_FOUND``, ``FORBIDDEN``, ...) or one of the client's own codes below;
``field`` is the offending field in the JSON mapping's lowerCamelCase
spelling (``bodies[0].sphere.radius``, ``runId``), empty when no single
field is at fault; ``message`` is the human-readable text (for a daemon
error already rendered as ``field: message``).
"""

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

    def __init__(self, code, message, field=""):
        self.code = code
        self.field = field or ""
        self.message = message or ""
        super().__init__(self.__str__())

    def __str__(self):
        text = "%s: %s" % (self.code, self.message)
        # as mpmctl prints it: the field only when the message does not
        # already start with it
        if self.field and not self.message.startswith(self.field + ":"):
            text += " (field %s)" % self.field
        return text

    def __repr__(self):
        return "MpmdError(code=%r, field=%r, message=%r)" % (self.code, self.field, self.message)
