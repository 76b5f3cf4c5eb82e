#!/usr/bin/env bash
# Installs the Debian 12 packages mpmd needs to build, test and run, and only
# those that are missing. Safe to run again: with everything present it does
# nothing and prints nothing. Called by `make deps` (and so by `make test` and
# `make demo`); needs root (or sudo) only when something must be installed.
# `install-deps.sh bench` also installs the benchmark's plotting tool,
# `install-deps.sh plot` the same for `mpmctl plot`, and
# `install-deps.sh coverage` gcovr for `make coverage`.
set -euo pipefail

pkgs=(
  gcc make pkg-config
  libzmq3-dev          # ZeroMQ (Debian's libzmq5 has CURVE, through libsodium)
  libsqlite3-dev       # run records
  libprotobuf-c-dev    # protobuf-c runtime
  protobuf-c-compiler  # protoc-c, generates proto/*.pb-c.[ch]
  libjansson-dev       # JSON case files
  protobuf-compiler python3-protobuf  # make python; tests: Python's protobuf JSON parser reads the cases too
  python3-zmq python3-numpy python3-matplotlib  # the Python client (clients/python) and its example
  clang-format cppcheck  # make format-check, make lint (gcc's -fanalyzer comes with gcc)
  libmicrohttpd-dev    # mpmweb, the web monitor's HTTP server
  chromium             # tests: the web monitor's page in a real (headless) browser
  zlib1g-dev           # mpmctl's VTK writer (--compress)
  python3-vtk9 python3-numpy  # tests: VTK's own readers read mpmctl's .vtp/.pvd/.vti files
  groff-base           # tests: the man pages render without warnings (groff -ww)
  clang libclang-rt-14-dev llvm  # make fuzz (libFuzzer, run quick by make test); llvm-symbolizer
)
# Optional group: `install-deps.sh bench` adds what `make bench-accuracy` uses
# for its plots (gnuplot-nox), unless some gnuplot is already there;
# `install-deps.sh plot` the same for `mpmctl plot`.
if { [ "${1:-}" = bench ] || [ "${1:-}" = plot ]; } && ! command -v gnuplot >/dev/null 2>&1; then
  pkgs+=(gnuplot-nox)
fi
# Optional group: `install-deps.sh coverage` adds gcovr (make coverage).
if [ "${1:-}" = coverage ]; then
  pkgs+=(gcovr)
fi
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0

echo "install-deps: installing missing packages: ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root or sudo to apt-get install ${missing[*]}" >&2; exit 1; }
  SUDO=sudo
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install-deps: done" >&2
