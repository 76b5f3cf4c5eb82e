#!/usr/bin/env bash
# inproc.sh - `make bench-inproc REF=<commit>`: this tree's
# solver against REF's in ONE process, alternated round by round, on the
# bench's own scenes.  Where make bench-compare runs two benches one after
# the other (a drift of the machine between them falls on one side),
# here both simulations are resident at once and each round runs REF then
# this tree or this tree then REF, a few hundred milliseconds apart; the
# median of the rounds' own ratios resolves differences of a few per cent
# on a machine whose speed moves by tens of per cent within the hour.
#
#   bench/perf/inproc/inproc.sh REF
#   bench/perf/inproc/inproc.sh --self-check   (make bench-build runs it)
#
# --self-check: this tree against itself, on this tree's build/rel objects
# (no worktree): the same REF side build (symbols made local, the entry
# points kept), the driver linked, and one small configuration in two
# processes; it fails unless the driver prints its row.  It tests the
# mechanism, not a speed.
#
# 1. REF's tree and its bench, as make bench-compare (../reftree.sh).
# 2. REF's side: side.c compiled against REF's headers with REF's own
#    bench/perf/scenes.c, linked (ld -r) with the objects REF's bench was
#    built from, every symbol then made local but the pbi_ref_* entry
#    points (objcopy --keep-global-symbols): REF's solver cannot bind to
#    this tree's, nor this tree's to REF's.  In build/compare/<sha>/build/inproc.
# 3. This tree's side and the driver (make inproc-objs), linked with REF's
#    object into build/compare/<sha>/build/inproc/inproc.
# 4. Each configuration: INPROC_PROCS processes one after the other, each
#    building both simulations afresh (where a process's arrays land moves
#    a build's speed for its whole life: inproc.c), a warm-up of each and
#    INPROC_ROUNDS rounds; a row of the rounds of all of them.
#
# Scenes: those of the bench's build() (disks2d, cube3d, bar1d, sparse2d-*)
# and the collapse2d pair, one scene each (collapse2d-dp, collapse2d-el;
# not in the default configurations), where a configuration's --skip K
# runs each side K steps untimed first: e.g.
#   INPROC_ARGS="--scene collapse2d-dp --method mpm --threads 1 --skip 300"
# times the flowing column's Drucker-Prager steps from step 300 on.
#
# Environment:
#   INPROC_ROUNDS     rounds per process (default 7)
#   INPROC_PROCS      processes per configuration (default 3)
#   INPROC_PARTICLES  particles (default 1000000)
#   INPROC_RUN_S      aimed seconds of one side's run in a round at the
#                     target speeds (default 0.5): steps =
#                     ceil(target x 10^6 x RUN_S / particles), at least 2
#   INPROC_ARGS       ';'-separated configurations, driver arguments
#                     (--scene --method --update --transfer --threads
#                     --skip, and --steps / --rounds to override the above
#                     for one)
set -euo pipefail

REF=${1:-}
if [ -z "$REF" ]; then
    echo "usage: bench/perf/inproc/inproc.sh REF | --self-check   (make bench-inproc REF=<commit>)" >&2
    exit 2
fi
ROOT=$(git rev-parse --show-toplevel)
cd "$ROOT"
# shellcheck source=bench/perf/reftree.sh
source bench/perf/reftree.sh

# 2 steps a run of cube3d MPM USL, 16 in a process of 7 rounds, stay short
# of its step 47; the collapse2d pair only on request (see above)
DEFAULT_ARGS=$(default_configs 2)
ARGS=${INPROC_ARGS:-$DEFAULT_ARGS}
ROUNDS=${INPROC_ROUNDS:-7}
PROCS=${INPROC_PROCS:-3}
PARTICLES=${INPROC_PARTICLES:-1000000}
RUN_S=${INPROC_RUN_S:-0.5}

# ---- the builds ----
if [ "$REF" = --self-check ]; then
    DIR=. SHORT=self
    make -j2 --no-print-directory bin/mpmbench >build/.bench-inproc-build.log 2>&1 || {
        echo "bench-inproc: building this tree failed; see build/.bench-inproc-build.log" >&2
        tail -20 build/.bench-inproc-build.log >&2
        exit 1
    }
    B=build/inproc-self
else
    ref_tree bench-inproc "$REF"
    B=$DIR/build/inproc
fi
mkdir -p "$B"
echo "bench-inproc: REF's side ($B/ref.o)" >&2
CSTD="-std=c11 -D_POSIX_C_SOURCE=200809L -D_DEFAULT_SOURCE"
# the objects REF's bench was built from, its own tests and benches aside
rm -f "$B/ref_objs.a"
find "$DIR/build/rel" -name '*.o' -not -path '*/tests/*' -not -path '*/bench/*' -print0 | xargs -0 ar rcs "$B/ref_objs.a"
# REF's scenes and headers, in its tree's layout (bench/ and solver/, or the
# older tests/perf/ and server/mpm/)
scenes=$(cd "$DIR" && pwd)/bench/perf/scenes.c
[ -f "$scenes" ] || scenes=$(cd "$DIR" && pwd)/tests/perf/scenes.c
# shellcheck disable=SC2086
cc $CSTD -O2 -g -w -DPBI_SIDE=ref -DPBI_SCENES="\"$scenes\"" \
    -I"$DIR/solver/include" -I"$DIR/solver" -I"$DIR/scenes/include" -I"$DIR/bench" \
    -I"$DIR/server/mpm" -I"$DIR/server" -I"$DIR/tools" -I"$DIR/server/tools" -I"$DIR/tests" \
    -c bench/perf/inproc/side.c -o "$B/side_ref.o"
ld -r -o "$B/ref_all.o" "$B/side_ref.o" "$B/ref_objs.a"
printf 'pbi_ref_%s\n' open run particles steps close >"$B/keep.txt"
objcopy --keep-global-symbols="$B/keep.txt" "$B/ref_all.o" "$B/ref.o"
left=$(nm -u "$B/ref.o" | awk '{ print $2 }' | grep -E '^(mpm_|pb_|ref_)' || true)
if [ -n "$left" ]; then
    echo "bench-inproc: REF's side still needs: $left" >&2
    exit 1
fi
echo "bench-inproc: this tree's side and the driver" >&2
make -j2 --no-print-directory inproc-objs >build/.bench-inproc-build.log 2>&1 || {
    echo "bench-inproc: building this tree failed; see build/.bench-inproc-build.log" >&2
    tail -20 build/.bench-inproc-build.log >&2
    exit 1
}
cc -O2 -g -o "$B/inproc" build/rel/bench/perf/inproc/inproc.o build/rel/bench/perf/inproc/side.o \
    build/rel/bench/perf/triad.o "$B/ref.o" build/rel/libscenes.a build/rel/libmpm.a -lm -lpthread

if [ "$REF" = --self-check ]; then
    row=$("$B/inproc" --scene disks2d --particles 4000 --steps 3 --rounds 3 --procs 2 --threads 2 --csv)
    echo "bench-inproc --self-check: $row" >&2
    # scene,method,update,transfer,threads,particles,steps,rounds,... : 6 rounds of 2 processes
    awk -F, '$1 == "disks2d" && $6 > 3000 && $8 == 6 && $11 > 0 { ok = 1 } END { exit !ok }' <<<"$row" || {
        echo "bench-inproc --self-check: FAILED (no row of 6 rounds)" >&2
        exit 1
    }
    # the collapse (its own case builder) after skipped steps: 3 rounds of 1 process
    row=$("$B/inproc" --scene collapse2d-dp --particles 4000 --skip 5 --steps 2 --rounds 3 --procs 1 --threads 1 --csv)
    echo "bench-inproc --self-check: $row" >&2
    awk -F, '$1 == "collapse2d-dp" && $6 > 3000 && $8 == 3 && $11 > 0 { ok = 1 } END { exit !ok }' <<<"$row" || {
        echo "bench-inproc --self-check: FAILED (no collapse2d-dp row of 3 rounds)" >&2
        exit 1
    }
    echo "bench-inproc --self-check: ok" >&2
    exit 0
fi

# steps for a configuration (the target speeds, as make bench-compare)
steps_for() {
    local cs=" $1 " dim=2 rate
    case "$cs" in *" cube3d "*) dim=3 ;; *" bar1d "*) dim=1 ;; esac
    if [[ "$cs" == *" --method mpm "* || "$cs" != *" --method "* ]]; then
        rate=$([ $dim = 3 ] && echo 16 || echo 30)
    else
        rate=$([ $dim = 3 ] && echo 3 || echo 12)
    fi
    awk -v r="$rate" -v s="$RUN_S" -v n="$PARTICLES" \
        'BEGIN { k = r * 1e6 * s / n; k = (k == int(k)) ? k : int(k) + 1; if (k < 2) k = 2; print k }'
}

HEAD_DESC=$(git describe --always --dirty 2>/dev/null || echo "this tree")
CPU=$(awk -F': *' '/^model name/ { print $2; exit }' /proc/cpuinfo)
IFS=';' read -r -a CFGS <<<"$ARGS"
NC=${#CFGS[@]}
echo "bench-inproc: $SHORT (ref) against $HEAD_DESC (new) in one process: $NC configurations, $PROCS processes x $ROUNDS rounds, ~$PARTICLES particles" >&2
T0=$(date +%s)
OUT=$(mktemp)
trap 'rm -f "$OUT"' EXIT
fails=0
for ((k = 0; k < NC; k++)); do
    c=${CFGS[k]}
    [ -z "${c// /}" ] && continue
    extra=()
    [[ " $c " == *" --steps "* ]] || extra+=(--steps "$(steps_for "$c")")
    [[ " $c " == *" --rounds "* ]] || extra+=(--rounds "$ROUNDS")
    [[ " $c " == *" --procs "* ]] || extra+=(--procs "$PROCS")
    echo "  $((k + 1))/$NC: $c ${extra[*]} [$(($(date +%s) - T0)) s]" >&2
    rc=0
    # shellcheck disable=SC2086 # the configuration's words are the driver's arguments
    "$B/inproc" $c "${extra[@]}" --particles "$PARTICLES" >>"$OUT" || rc=$?
    if [ $rc = 3 ]; then
        echo "(n/a: $SHORT has no such configuration) $c" >>"$OUT"
    elif [ $rc != 0 ]; then
        echo "bench-inproc: failed: $c" >&2
        echo "(failed) $c" >>"$OUT"
        fails=$((fails + 1))
    fi
done
echo
echo "bench-inproc: ref = $SHORT, new = $HEAD_DESC, alternated in one process; $CPU; $(date -u '+%Y-%m-%d %H:%M UTC')"
echo "Mp-steps/s: each side's median over the rounds; new/ref: the median of the rounds' own ratios,"
echo "q1-q3 and min-max their quartiles and extremes; new>ref: the rounds in which this tree was faster;"
echo "per process: each process's median ratio @ the STREAM triad (GB/s) measured before and after its"
echo "rounds (an older build's speed can shift for a process's whole life; see inproc.c)."
"$B/inproc" --header-only
cat "$OUT"
echo "bench-inproc: $(($(date +%s) - T0)) s of runs"
[ $fails = 0 ]
