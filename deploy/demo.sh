#!/usr/bin/env bash
# make demo: starts mpmd on loopback with its default database (mpmd.db in
# this directory), submits a case, watches the run live, lists the runs,
# and stops the daemon.  If an mpmd already answers on the endpoint, the
# demo uses it and leaves it running.  The case (argument 1, or
# `make demo CASE=...`): disks (the default: the paper's fine bouncing
# disks) or collapse (the granular column collapse, a = 2, Drucker-Prager;
# proto/examples/collapse2d.json).
set -euo pipefail
choice=${1:-disks}
case "$choice" in
disks) file=proto/examples/disks2d_fine.json
       title="the paper's two bouncing disks, GMPM, 392 points per disk (Section 5.6)" ;;
collapse) file=proto/examples/collapse2d.json
          title="a granular column collapse, a = 2, Drucker-Prager phi 30 on a rough base (Lube et al. 2005)" ;;
*) echo "demo: unknown case '$choice' (disks or collapse)" >&2; exit 2 ;;
esac
cd "$(dirname "$0")/.."
export MPMD_ENDPOINT=${MPMD_ENDPOINT:-tcp://127.0.0.1:5555}
mkdir -p build
log=build/demo-mpmd.log
pid=
stop() {
    if [ -n "$pid" ]; then
        kill -TERM "$pid" 2>/dev/null || true
        wait "$pid" 2>/dev/null || true
        echo "demo: mpmd stopped (its log: $log)"
    fi
}
trap stop EXIT

if bin/mpmctl ping --timeout 1 >/dev/null 2>&1; then
    echo "demo: an mpmd already answers on $MPMD_ENDPOINT; using it"
else
    echo "demo: starting mpmd on $MPMD_ENDPOINT (database mpmd.db, log $log)"
    bin/mpmd > "$log" 2>&1 &
    pid=$!
    for _ in $(seq 50); do
        bin/mpmctl ping --timeout 1 >/dev/null 2>&1 && break
        if ! kill -0 "$pid" 2>/dev/null; then
            pid=
            echo "demo: mpmd did not start:" >&2
            cat "$log" >&2
            exit 1
        fi
        sleep 0.2
    done
    bin/mpmctl ping
fi
echo
echo "demo: $title"
bin/mpmctl submit "$file" --watch
echo
bin/mpmctl runs --limit 5
