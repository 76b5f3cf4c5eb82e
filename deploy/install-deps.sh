#!/usr/bin/env bash
# Installs the Debian 12 packages of one group, and only those that are
# missing; with everything present it does nothing and prints nothing.
# Needs root (or sudo) only when something must be installed, and says what
# it installs before it does.  The groups (each includes the one above it):
#   demo   what `make demo`, `make` and the README's tour need: the compiler,
#          the libraries mpmd, mpmctl and mpmweb link, protoc for the Python
#          client's classes, gnuplot for `mpmctl plot`   (make demo)
#   test   the test tools: the Python client's modules, VTK's readers,
#          headless Chromium, groff, clang for the fuzzers, clang-format and
#          cppcheck   (make test, make deps, make lint, make tsan, ...)
#   bench  demo's packages: the benchmarks build with them and plot with
#          its gnuplot   (make bench, bench-accuracy, bench-build, ...)
#   plot   gnuplot alone (mpmctl plot)
#   coverage  test's packages and gcovr   (make coverage)
# `install-deps.sh --list GROUP` prints a group's packages and exits.
set -euo pipefail

demo=(
  gcc make pkg-config
  libzmq3-dev          # ZeroMQ (Debian's libzmq5 has CURVE, through libsodium)
  libsqlite3-dev       # run records
  libprotobuf-c-dev    # protobuf-c runtime
  protobuf-c-compiler  # protoc-c, generates proto/*.pb-c.[ch]
  protobuf-compiler    # protoc: make python (the Python client's classes; part of make)
  libjansson-dev       # JSON case files
  libmicrohttpd-dev    # mpmweb, the web monitor's HTTP server
  zlib1g-dev           # mpmctl's VTK writer (--compress)
  libhdf5-dev          # mpmctl export --format hdf5 (Debian's serial libhdf5)
  gnuplot-nox          # mpmctl plot (the README's tour)
)
test=(
  python3-protobuf python3-zmq python3-numpy python3-matplotlib  # the Python client, its example and tests
  clang-format cppcheck  # make format-check, make lint (gcc's -fanalyzer comes with gcc)
  chromium             # tests: the web monitor's page in a real (headless) browser
  python3-vtk9         # tests: VTK's own readers read mpmctl's .vtp/.pvd/.vti files
  python3-h5py         # tests: h5py reads the HDF5 export back
  python3-venv python3-setuptools python3-wheel  # tests: pip installs clients/python into a venv
  groff-base           # tests: the man pages render without warnings (groff -ww)
  clang libclang-rt-14-dev llvm  # make fuzz (libFuzzer, run quick by make test); llvm-symbolizer
)

list=0
if [ "${1:-}" = --list ]; then
  list=1
  shift
fi
group=${1:-test}
case "$group" in
demo | bench) pkgs=("${demo[@]}") ;;
test) pkgs=("${demo[@]}" "${test[@]}") ;;
coverage) pkgs=("${demo[@]}" "${test[@]}" gcovr) ;;
plot) pkgs=(gnuplot-nox) ;;
*) echo "install-deps: unknown group '$group' (demo, test, bench, plot or coverage)" >&2; exit 2 ;;
esac
if [ $list = 1 ]; then
  echo "${pkgs[*]}"
  exit 0
fi
# some gnuplot (gnuplot-qt, gnuplot-x11) already there serves as well
if command -v gnuplot >/dev/null 2>&1; then
  keep=()
  for p in "${pkgs[@]}"; do [ "$p" = gnuplot-nox ] || keep+=("$p"); done
  pkgs=("${keep[@]}")
fi

missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0

echo "install-deps: the '$group' group needs ${#missing[@]} Debian package(s) that are missing;" >&2
echo "install-deps: installing (apt-get install --no-install-recommends, with their dependencies):" >&2
echo "install-deps:   ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root or sudo to apt-get install ${missing[*]}" >&2; exit 1; }
  SUDO=sudo
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install-deps: done" >&2
