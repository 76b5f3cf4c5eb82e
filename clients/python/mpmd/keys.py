"""CURVE keys, found as mpmctl finds them (clients/ctl/ctl_keys.c).

The server's public key and the client's secret key (its public key is
derived from it) come from, in order:

* the environment: ``MPMD_SERVER_KEY`` (a 40-character Z85 key, or a file
  holding one) and ``MPMD_CLIENT_KEY`` (the client's secret key file);
* a key directory holding ``server.pub`` and ``mpmd.key`` (what
  ``mpmctl keygen`` writes, plus the server's public key): the ``keys``
  argument (mpmctl's ``--keys DIR``), else ``$MPMD_KEYS``, else
  ``~/.config/mpmd`` when it exists and the endpoint is not loopback or
  ipc://.

With no server key the connection goes without CURVE (loopback, ipc://).
A key file's key is its first line that is not blank or a ``#`` comment (a
comment may follow the key); a secret key file must not be readable by
group or others (mode 0600).  Problems raise MpmdError with code ``KEYS``
(or ``USAGE`` for a key directory without ``server.pub``).
"""

import os
import stat

import zmq
from zmq.utils import z85

from . import endpoint as _ep
from .errors import KEYS, USAGE, MpmdError

KEY_LEN = 40


def is_key(text):
    """True if text is a 40-character Z85 key."""
    if not isinstance(text, str) or len(text) != KEY_LEN:
        return False
    try:
        return len(z85.decode(text.encode("ascii"))) == 32
    except Exception:
        return False


def read_key_file(path, secret, what):
    """The key of a key file (see the module's text); secret: refuse a file
    readable by group or others."""
    try:
        with open(path, "r", encoding="ascii", errors="replace") as f:
            if secret:
                mode = os.fstat(f.fileno()).st_mode
                if mode & 0o077:
                    raise MpmdError(
                        KEYS,
                        "%s: the secret key file %s has mode %04o: it must be 0600 or "
                        "stricter (chmod 600 %s)" % (what, path, stat.S_IMODE(mode), path),
                    )
            for line in f:
                s = line.strip()
                if not s or s.startswith("#"):
                    continue
                tok = s.split()[0]
                if not is_key(tok):
                    raise MpmdError(
                        KEYS, "%s: %s does not start with a 40-character Z85 key" % (what, path)
                    )
                return tok
    except OSError as e:
        raise MpmdError(KEYS, "%s: cannot open %s: %s" % (what, path, e.strerror)) from None
    raise MpmdError(KEYS, "%s: %s holds no key" % (what, path))


class CurveKeys:
    """A connection's CURVE keys (Z85 text): server_key, public_key,
    secret_key."""

    def __init__(self, server_key, secret_key):
        self.server_key = server_key
        self.secret_key = secret_key
        try:
            self.public_key = zmq.curve_public(secret_key.encode("ascii")).decode("ascii")
        except Exception as e:  # a libzmq without CURVE, or a bad key
            raise MpmdError(KEYS, "cannot derive the client's public key: %s" % e) from None

    def apply(self, sock):
        """Sets the CURVE options of a socket before it connects."""
        sock.curve_serverkey = self.server_key.encode("ascii")
        sock.curve_publickey = self.public_key.encode("ascii")
        sock.curve_secretkey = self.secret_key.encode("ascii")


def load(endpoint, keys=None, env=None):
    """The CurveKeys for a connection to endpoint, or None for no CURVE.

    keys: a key directory (as mpmctl --keys DIR), or a pair
    (server public key, client secret key) of Z85 strings or key files.
    env: the environment to read (default os.environ).
    """
    env = os.environ if env is None else env
    if isinstance(keys, (tuple, list)):
        if len(keys) != 2:
            raise MpmdError(USAGE, "keys: expected a directory or (server key, client secret key)")
        srv, cli = keys
        srv = srv if is_key(srv) else read_key_file(srv, False, "keys[0] (the server's public key)")
        cli = cli if is_key(cli) else read_key_file(cli, True, "keys[1] (the client's secret key)")
        return CurveKeys(srv, cli)
    keys_dir = os.fspath(keys) if keys else ""
    d = ""
    if keys_dir:
        d = keys_dir
    elif env.get("MPMD_KEYS"):
        d = env["MPMD_KEYS"]
    elif env.get("HOME") and not _ep.is_local(endpoint):
        # the default directory serves remote daemons only
        d = os.path.join(env["HOME"], ".config", "mpmd")
        if not os.path.exists(d):
            d = ""
    sp = os.path.join(d, "server.pub") if d else ""
    cp = os.path.join(d, "mpmd.key") if d else ""
    env_srv, env_cli = env.get("MPMD_SERVER_KEY", ""), env.get("MPMD_CLIENT_KEY", "")
    if env_srv:
        srv = env_srv if is_key(env_srv) else read_key_file(env_srv, False, "MPMD_SERVER_KEY")
    elif sp and os.path.exists(sp):
        srv = read_key_file(sp, False, "the server's public key")
    else:
        if keys_dir:
            raise MpmdError(
                USAGE,
                "keys %s: no server.pub there (the server's public key: mpmd logs it at start)"
                % keys_dir,
            )
        return None
    if env_cli:
        cli = read_key_file(env_cli, True, "MPMD_CLIENT_KEY")
    elif cp and os.path.exists(cp):
        cli = read_key_file(cp, True, "the client's secret key")
    else:
        raise MpmdError(
            USAGE,
            "a server key is set but no client key: set MPMD_CLIENT_KEY to your secret key "
            "file or put it in %s (mpmctl keygen makes one)" % (cp or "KEYDIR/mpmd.key"),
        )
    return CurveKeys(srv, cli)
