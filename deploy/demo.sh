#!/usr/bin/env bash
# make demo: starts mpmd on loopback with its default database (mpmd.db in
# this directory) and the web monitor mpmweb (http://127.0.0.1:8080/, or
# MPMWEB_LISTEN), submits a case, watches the run live, lists the runs, and
# stops the monitor and the daemon.  If an mpmd already answers on the endpoint, the
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
weblog=build/demo-mpmweb.log
pid=
webpid=
stop() {
    if [ -n "$webpid" ]; then
        kill -TERM "$webpid" 2>/dev/null || true
        wait "$webpid" 2>/dev/null || true
        echo "demo: mpmweb stopped (its log: $weblog)"
    fi
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
listen=${MPMWEB_LISTEN:-127.0.0.1:8080}
bin/mpmweb --listen "$listen" > "$weblog" 2>&1 &
webpid=$!
for _ in $(seq 25); do
    grep -q "serving" "$weblog" 2>/dev/null && break
    if ! kill -0 "$webpid" 2>/dev/null; then
        webpid=
        echo "demo: mpmweb did not start (port taken? MPMWEB_LISTEN=127.0.0.1:PORT make demo):" >&2
        cat "$weblog" >&2
        break
    fi
    sleep 0.2
done
if [ -n "$webpid" ]; then
    echo "demo: the web monitor is at http://$listen/ (open it now to watch the run live)"
    sleep "${DEMO_PAUSE:-3}"
fi
echo
echo "demo: $title"
bin/mpmctl submit "$file" --watch
echo
bin/mpmctl runs --limit 5
if [ -n "$webpid" ] && [ -t 0 ]; then
    echo
    read -r -p "demo: the run stays on http://$listen/ (slider, energy); press Enter to stop. " _ || true
fi
