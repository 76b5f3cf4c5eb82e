"""setup.py - the build step pyproject.toml cannot say: the protobuf module
mpmd_pb2 is generated from the tree's proto/mpmd.proto by protoc into the
built package (never kept in the source), and the version is read from
protocol/include/mpp.h (MPP_VERSION), the one place it is written.  Outside an
mpmd tree (no ../../proto/mpmd.proto), an mpmd/mpmd_pb2.py already in the
package directory is used as it is.  Guarded by python_client_pip, which
installs the package into a virtual environment and uses it.
"""

import os
import re
import shutil
import subprocess
import tempfile

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = os.path.dirname(os.path.abspath(__file__))
TREE = os.path.normpath(os.path.join(HERE, "..", ".."))
PROTO_DIR = os.path.join(TREE, "proto")
MPP_H = os.path.join(TREE, "protocol", "include", "mpp.h")


def version():
    try:
        with open(MPP_H, encoding="utf-8") as f:
            m = re.search(r'#define MPP_VERSION "([^"]+)"', f.read())
    except OSError:
        m = None
    return m.group(1) if m else "0+unknown"


def generate(dest):
    """Writes dest/mpmd_pb2.py from proto/mpmd.proto with protoc."""
    proto = os.path.join(PROTO_DIR, "mpmd.proto")
    shipped = os.path.join(HERE, "mpmd", "mpmd_pb2.py")
    if not os.path.isfile(proto):
        if os.path.isfile(shipped):
            shutil.copy(shipped, os.path.join(dest, "mpmd_pb2.py"))
            return
        raise SystemExit(
            "mpmd: %s is missing: install from clients/python of an mpmd source tree" % proto
        )
    protoc = shutil.which("protoc")
    if not protoc:
        raise SystemExit(
            "mpmd: generating mpmd_pb2 needs protoc: install the Debian package "
            "protobuf-compiler (apt-get install protobuf-compiler)"
        )
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(
            [protoc, "--proto_path=" + PROTO_DIR, "--python_out=" + tmp, proto], check=True
        )
        shutil.copy(os.path.join(tmp, "mpmd_pb2.py"), os.path.join(dest, "mpmd_pb2.py"))


class BuildPy(build_py):
    def run(self):
        super().run()
        dest = os.path.join(self.build_lib, "mpmd")
        os.makedirs(dest, exist_ok=True)
        generate(dest)


setup(version=version(), cmdclass={"build_py": BuildPy})
