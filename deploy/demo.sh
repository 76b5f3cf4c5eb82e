#!/usr/bin/env bash
# make demo: starts mpmd on loopback with its default database (mpmd.db in
# this directory) and the web monitor mpmweb (http://127.0.0.1:8080/, or
# MPMWEB_LISTEN), submits a case that records snapshots, watches it live in
# the terminal while the monitor draws its particles, checks that the
# monitor answers, lists the runs, prints the commands to try next, and
# stops the monitor and the daemon.  If an mpmd already answers on the
# endpoint, the demo uses it and leaves it running.  The case (argument 1,
# or `make demo CASE=...`):
#   collapse  (the default) a granular column collapse, a = 2, Drucker-Prager
#             phi 30 on a rough base, 8192 particles, ~16,000 steps
#             (proto/examples/collapse2d_demo.json; 20-30 s on two cores)
#   disks     the paper's two bouncing disks, GMPM, 12,600 particles, 16,000
#             steps (proto/examples/disks2d_demo.json)
# Overrides (the test docs_demo runs this script with them): MPMD_BIN,
# MPMCTL_BIN, MPMWEB_BIN (default bin/...), MPMD_ENDPOINT, MPMD_DB,
# MPMWEB_LISTEN, DEMO_STEPS (run that many steps instead of to the case's
# end time), DEMO_PAUSE (seconds to open the page before the run, default 3),
# DEMO_LOGS (the directory of the two logs, default build); DEMO_PICTURE=FILE
# takes a PNG of the monitor showing the run at step DEMO_PICTURE_STEP (3500)
# with headless Chromium (make docs-picture).
set -euo pipefail
choice=${1:-collapse}
case "$choice" in
collapse) file=proto/examples/collapse2d_demo.json
          title="a granular column collapse, a = 2, Drucker-Prager phi 30 on a rough base (Lube et al. 2005)" ;;
disks) file=proto/examples/disks2d_demo.json
       title="the paper's two bouncing disks, GMPM (Section 5.6), finer" ;;
*) echo "demo: unknown case '$choice' (collapse or disks)" >&2; exit 2 ;;
esac
cd "$(dirname "$0")/.."
mpmd=${MPMD_BIN:-bin/mpmd}
mpmctl=${MPMCTL_BIN:-bin/mpmctl}
mpmweb=${MPMWEB_BIN:-bin/mpmweb}
export MPMD_ENDPOINT=${MPMD_ENDPOINT:-tcp://127.0.0.1:5555}
db=${MPMD_DB:-mpmd.db}
logs=${DEMO_LOGS:-build}
mkdir -p build "$logs"
log=$logs/demo-mpmd.log
weblog=$logs/demo-mpmweb.log
if [ -n "${DEMO_STEPS:-}" ]; then
    # a shorter run of the same case: its end time replaced by a step count
    [[ "$DEMO_STEPS" =~ ^[1-9][0-9]*$ ]] || { echo "demo: DEMO_STEPS must be a positive whole number" >&2; exit 2; }
    sed -E 's/"endTime": *[0-9.eE+-]+/"steps": '"$DEMO_STEPS"'/' "$file" > "$logs/demo-case.json"
    file=$logs/demo-case.json
fi
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

if "$mpmctl" ping --timeout 1 >/dev/null 2>&1; then
    echo "demo: an mpmd already answers on $MPMD_ENDPOINT; using it"
else
    echo "demo: starting mpmd on $MPMD_ENDPOINT (database $db, log $log)"
    "$mpmd" --db "$db" > "$log" 2>&1 &
    pid=$!
    for _ in $(seq 100); do
        "$mpmctl" ping --timeout 1 >/dev/null 2>&1 && break
        if ! kill -0 "$pid" 2>/dev/null; then
            pid=
            echo "demo: mpmd did not start:" >&2
            cat "$log" >&2
            exit 1
        fi
        sleep 0.2
    done
    "$mpmctl" ping
fi
listen=${MPMWEB_LISTEN:-127.0.0.1:8080}
"$mpmweb" --listen "$listen" --static clients/web/static > "$weblog" 2>&1 &
webpid=$!
for _ in $(seq 50); do
    grep -q "serving" "$weblog" 2>/dev/null && break
    if ! kill -0 "$webpid" 2>/dev/null; then
        webpid=
        echo "demo: mpmweb did not start (port taken? MPMWEB_LISTEN=127.0.0.1:PORT make demo):" >&2
        cat "$weblog" >&2
        break
    fi
    sleep 0.2
done

echo
echo "demo: $title"
id=$("$mpmctl" submit "$file" --quiet)
if [ -n "$webpid" ]; then
    echo "demo: the web monitor shows run $id at http://$listen/#run=$id (open it now:"
    echo "      the particles and the energies move as the run goes)"
    sleep "${DEMO_PAUSE:-3}"
fi
"$mpmctl" watch "$id"
echo
"$mpmctl" runs --limit 5
echo
"$mpmctl" show "$id" | grep -E '^run |status|wall|particles|snapshots'
if [ -n "$webpid" ]; then
    # the monitor answers for the run (an HTTP request through bash's /dev/tcp)
    host=${listen%:*}
    host=${host#[}
    host=${host%]}
    reply=$( { exec 3<>"/dev/tcp/$host/${listen##*:}" &&
               printf 'GET /api/run/%s HTTP/1.0\r\nHost: %s\r\n\r\n' "$id" "$listen" >&3 &&
               head -1 <&3; } 2>/dev/null) || true
    echo "demo: the web monitor's answer for run $id: ${reply%$'\r'}"
fi
if [ -n "${DEMO_PICTURE:-}" ] && [ -n "$webpid" ]; then
    # the README's picture: the recorded run at DEMO_PICTURE_STEP in
    # headless Chromium (make docs-picture)
    url="http://$listen/#run=$id&step=${DEMO_PICTURE_STEP:-3500}"
    prof=$(mktemp -d)
    chromium --headless=new --no-sandbox --disable-gpu --hide-scrollbars --no-first-run \
        --user-data-dir="$prof" --window-size=1200,820 --virtual-time-budget=15000 \
        --screenshot="$DEMO_PICTURE" "$url" > "$logs/demo-chromium.log" 2>&1 ||
        { echo "demo: chromium could not take $DEMO_PICTURE (its log: $logs/demo-chromium.log)" >&2; exit 1; }
    rm -rf "$prof"
    echo "demo: $url -> $DEMO_PICTURE"
fi
echo
echo "demo: next, the tour (README.md, \"A short tour\"), with mpmd running again:"
row() { printf '  %-36s # %s\n' "$1" "$2"; }
row "bin/mpmd &" "the same database: run $id is there"
row "bin/mpmctl show $id --case" "this run and its case"
row "bin/mpmctl export $id out/" "its snapshots for ParaView: out/*.pvd"
row "bin/mpmctl plot $id -o energy.png" "its energy curves"
row "bin/mpmweb &" "then http://$listen/#run=$id: the slider"
if [ -n "$webpid" ] && [ -t 0 ]; then
    echo
    read -r -p "demo: the run stays on http://$listen/#run=$id (slider, energy); press Enter to stop. " _ || true
fi
