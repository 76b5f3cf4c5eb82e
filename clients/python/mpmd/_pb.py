"""Finds the protobuf classes generated from proto/mpmd.proto.

``make python`` runs ``protoc --python_out=build/python proto/mpmd.proto``;
the generated ``mpmd_pb2.py`` is never committed.  It is looked for, in
order: next to this package (an installed copy, ``make python-install``),
as a top-level module on ``sys.path`` (``PYTHONPATH=clients/python:build/python``),
and in the source tree's ``build/python`` (so ``PYTHONPATH=clients/python``
alone works in a built checkout).
"""

import importlib
import os
import sys


def _load():
    try:
        return importlib.import_module(__package__ + ".mpmd_pb2")
    except ImportError:
        pass
    try:
        return importlib.import_module("mpmd_pb2")
    except ImportError:
        pass
    here = os.path.dirname(os.path.abspath(__file__))
    gen = os.path.normpath(os.path.join(here, "..", "..", "..", "build", "python"))
    if os.path.isfile(os.path.join(gen, "mpmd_pb2.py")):
        sys.path.append(gen)
        return importlib.import_module("mpmd_pb2")
    raise ImportError(
        "mpmd: the generated module mpmd_pb2 is missing: run `make python` in the "
        "mpmd source tree (it writes build/python/mpmd_pb2.py) and put build/python "
        "on PYTHONPATH"
    )


pb = _load()
