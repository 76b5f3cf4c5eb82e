#!/usr/bin/env bash
# compare.sh - `make bench-compare REF=<commit>`: the throughput
# of this tree's bin/mpmbench against the bench of another commit, run on
# the same machine, interleaved, on the same configurations.
#
#   bench/perf/compare.sh REF
#
# 1. REF's tree: a git worktree under build/compare/<short-sha>, its
#    bin/mpmbench built there with its own Makefile (reftree.sh).  This
#    tree's bin/mpmbench is built too.
# 2. Rounds (COMPARE_ROUNDS, default 3): each round measures the STREAM
#    triad (bin/mpmbench --triad) on the thread counts used, then every
#    configuration with REF's bench ("before") and this one ("after"), one
#    after the other, so that a drift of the machine falls on both alike.
#    Each run is one bin/mpmbench row (the median of its 3 timed runs after
#    a warm-up); the table gives the median over the rounds, and the lowest
#    and highest ratio after / before of a single round (marked ~ when they
#    straddle 1: the noise is as large as the difference).
# 3. Only options REF's bench understands are passed to it (--scene,
#    --particles, --steps, --threads, --method, --update, --csv, and
#    --transfer / a method / a scene only when its --help names them): a
#    configuration REF cannot run shows "n/a" before.  REF's bench is run
#    from REF's tree, so the rows it appends to build/bench/throughput.csv
#    land there.
#
# Environment:
#   COMPARE_ROUNDS     rounds (default 3; COMPARE_QUICK: 2)
#   COMPARE_PARTICLES  particles per configuration (default 1000000)
#   COMPARE_RUN_S      aimed seconds of one timed run at the target speeds
#                      (pb_target_rate(), bench/perf/scenes.c; default 1.0): steps = ceil(target x 10^6 x
#                      RUN_S / particles), at least 5 (2D MPM 30 steps, 2D
#                      GIMP / B-spline 12, 3D MPM 16, 3D others 5 for 10^6)
#   COMPARE_STEPS      fixed steps for every configuration instead
#   COMPARE_ARGS       the configurations, ';'-separated bin/mpmbench
#                      arguments (without --csv; --steps given there wins
#                      over the rule above, --particles over
#                      COMPARE_PARTICLES), e.g.
#                      "--scene disks2d --method mpm --threads 2"
#   COMPARE_QUICK=1    a short sanity run: disks2d and cube3d MPM USF on 2
#                      threads, 50000 particles, 5 steps, 2 rounds
#   MPMBENCH_TRIAD_MIB passed on to the triad (MiB per array)
set -euo pipefail

REF=${1:-}
if [ -z "$REF" ]; then
    echo "usage: bench/perf/compare.sh REF   (make bench-compare REF=<commit>)" >&2
    exit 2
fi
ROOT=$(git rev-parse --show-toplevel)
cd "$ROOT"
# shellcheck source=bench/perf/reftree.sh
source bench/perf/reftree.sh

# 4 runs of 10 steps of cube3d MPM USL stay short of its step 47; the
# collapse pair runs 100-step runs (timed over steps 100-400, where the
# column yields: the rule's 12 steps timed steps 12-48, which are nearly
# all elastic)
DEFAULT_ARGS=$(default_configs 10)
DEFAULT_ARGS+="--scene collapse2d --method bspline2 --update usf --threads 2 --steps 100"

ROUNDS=${COMPARE_ROUNDS:-3}
PARTICLES=${COMPARE_PARTICLES:-1000000}
RUN_S=${COMPARE_RUN_S:-1.0}
STEPS=${COMPARE_STEPS:-}
ARGS=${COMPARE_ARGS:-$DEFAULT_ARGS}
if [ -n "${COMPARE_QUICK:-}" ] && [ "${COMPARE_QUICK}" != 0 ]; then
    ROUNDS=${COMPARE_ROUNDS:-2}
    PARTICLES=${COMPARE_PARTICLES:-50000}
    STEPS=${COMPARE_STEPS:-5}
    ARGS=${COMPARE_ARGS:-"--scene disks2d --method mpm --update usf --threads 2;--scene cube3d --method mpm --update usf --threads 2"}
fi

# ---- REF's tree and both builds ----
ref_tree bench-compare "$REF"
echo "bench-compare: building this tree's bin/mpmbench" >&2
make -j2 --no-print-directory bin/mpmbench >build/.bench-compare-build.log 2>&1 || {
    echo "bench-compare: building this tree failed; see build/.bench-compare-build.log" >&2
    tail -20 build/.bench-compare-build.log >&2
    exit 1
}
BEFORE=$ROOT/$DIR/bin/mpmbench
AFTER=$ROOT/bin/mpmbench
REF_HELP=$("$BEFORE" --help 2>&1 || true)
HEAD_DESC=$(git describe --always --dirty 2>/dev/null || echo "this tree")

# can REF's bench run these arguments?
ref_can() {
    local -a a
    local i
    read -r -a a <<<"$1"
    for ((i = 0; i < ${#a[@]}; i++)); do
        case "${a[i]}" in
        --transfer) grep -q -- "--transfer" <<<"$REF_HELP" || return 1 ;;
        --pic) grep -q -- "--pic" <<<"$REF_HELP" || return 1 ;;
        --method | --scene)
            local v=${a[i + 1]:-}
            grep -qw -- "$v" <<<"$REF_HELP" || return 1
            ;;
        esac
    done
    return 0
}

# particles for a configuration: its own --particles, else COMPARE_PARTICLES
particles_for() {
    local own
    own=$(awk '{ for (i = 1; i < NF; i++) if ($i == "--particles") print $(i + 1) }' <<<"$1")
    echo "${own:-$PARTICLES}"
}

# steps for a configuration (the target speeds, as bin/mpmbench)
steps_for() {
    local own
    own=$(awk '{ for (i = 1; i < NF; i++) if ($i == "--steps") print $(i + 1) }' <<<"$1")
    if [ -n "$own" ]; then
        echo "$own"
        return
    fi
    if [ -n "$STEPS" ]; then
        echo "$STEPS"
        return
    fi
    local cs=" $1 " dim=2 rate
    case "$cs" in *" cube3d "*) dim=3 ;; esac
    if [[ "$cs" == *" --method mpm "* || "$cs" != *" --method "* ]] && [[ "$cs" != *" collapse2d "* ]]; then
        rate=$([ $dim = 3 ] && echo 16 || echo 30)
    else
        rate=$([ $dim = 3 ] && echo 3 || echo 12)
    fi
    awk -v r="$rate" -v s="$RUN_S" -v n="$(particles_for "$1")" \
        'BEGIN { k = r * 1e6 * s / n; k = (k == int(k)) ? k : int(k) + 1; if (k < 5) k = 5; print k }'
}

OUT=$(mktemp -d "${TMPDIR:-/tmp}/bench-compare.XXXXXX")
trap 'rm -rf "$OUT"' EXIT
RES=$OUT/rows.tsv   # side cfg scene threads particles rate model_bytes round
TRI=$OUT/triad.tsv  # threads gbs
: >"$RES"
: >"$TRI"
CPU=$(awk -F': *' '/^model name/ { print $2; exit }' /proc/cpuinfo)
IFS=';' read -r -a CFGS <<<"$ARGS"
THREADS=$(for c in "${CFGS[@]}"; do
    read -r -a a <<<"$c"
    t=2
    for ((i = 0; i < ${#a[@]}; i++)); do [ "${a[i]}" = --threads ] && t=${a[i + 1]}; done
    echo "$t"
done | sort -un)

# one bench run; its CSV rows go to $RES tagged with side and configuration
run_one() { # side cfg-index bench args...
    local side=$1 k=$2 bin=$3
    shift 3
    local csv rc=0
    if [ "$side" = before ]; then
        csv=$(cd "$DIR" && "$bin" "$@" --csv 2>"$OUT/err") || rc=$?
    else
        csv=$("$bin" "$@" --no-triad --csv 2>"$OUT/err") || rc=$?
    fi
    if [ $rc -ne 0 ]; then
        echo "bench-compare: $side ($*) failed:" >&2
        grep -v "^mpmbench: .*CPU(s) online" "$OUT/err" | tail -2 >&2
        # a failed run: a "fail" sample under the configuration's scene
        local -a a
        local i sc='?' xf=''
        read -r -a a <<<"$*"
        for ((i = 0; i < ${#a[@]}; i++)); do
            [ "${a[i]}" = --scene ] && sc=${a[i + 1]}
            [ "${a[i]}" = --transfer ] && [ "${a[i + 1]}" = apic ] && xf=+apic
        done
        [ "$sc" = collapse2d ] && sc=collapse2d-el
        printf '%s\t%s\t%s\t?\t?\tfail\t\t%s\n' "$side" "$k" "$sc$xf" "$ROUND" >>"$RES"
        return 0
    fi
    awk -F, -v side="$side" -v k="$k" -v rd="$ROUND" '
        NR == 1 { for (i = 1; i <= NF; i++) col[$i] = i; next }
        $1 != "scene" {
            mb = ("model_bytes_per_pstep" in col) ? $(col["model_bytes_per_pstep"]) : ""
            printf "%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n", side, k, $(col["scene"]), $(col["threads"]),
                $(col["particles"]), $(col["mpsteps_per_s"]), mb, rd
        }' <<<"$csv" >>"$RES"
}

NC=${#CFGS[@]}
echo "bench-compare: $SHORT (before) against $HEAD_DESC (after): $NC configurations, $ROUNDS rounds, ~$PARTICLES particles" >&2
T0=$(date +%s)
for ((r = 1; r <= ROUNDS; r++)); do
    ROUND=$r
    for t in $THREADS; do
        "$AFTER" --triad --threads "$t" --csv 2>/dev/null | awk -F, 'NR > 1 { print $1 "\t" $2 }' >>"$TRI" || true
    done
    for ((k = 0; k < NC; k++)); do
        c=${CFGS[k]}
        s=$(steps_for "$c")
        n=$(particles_for "$c")
        echo "  round $r/$ROUNDS, $((k + 1))/$NC: $c (steps $s, particles $n) [$(($(date +%s) - T0)) s]" >&2
        c=$(awk '{ for (i = 1; i <= NF; i++) if ($i == "--steps" || $i == "--particles") i++; else printf "%s ", $i }' <<<"$c")
        if ref_can "$c"; then
            run_one before "$k" "$BEFORE" $c --particles "$n" --steps "$s"
        fi
        run_one after "$k" "$AFTER" $c --particles "$n" --steps "$s"
    done
done

# ---- the table ----
echo
echo "bench-compare: before = $SHORT's bench, after = $HEAD_DESC; $CPU; $(date -u '+%Y-%m-%d %H:%M UTC')"
awk -F'\t' '
    function median(list,   n, v, i, j, x) {
        n = split(list, v, " ")
        for (i = 2; i <= n; i++) { x = v[i] + 0; for (j = i - 1; j >= 1 && v[j] + 0 > x; j--) v[j + 1] = v[j]; v[j + 1] = x }
        if (n == 0) return 0
        return n % 2 ? v[(n + 1) / 2] : (v[n / 2] + v[n / 2 + 1]) / 2
    }
    { tg[$1] = tg[$1] " " $2 }
    END {
        for (t in tg) printf "STREAM triad, %s thread%s: %.2f GB/s (median over %d round(s) of the median of 7 passes)\n", t, (t > 1 ? "s" : ""), median(tg[t]), split(tg[t], dummy, " ")
    }' "$TRI" | sort
echo "Mp-steps/s: the median over the rounds of each run's median of 3 timed runs; ratio = after / before;"
echo "roof: after's modelled particle bytes (B/pstep) x Mp-steps/s over the triad of its thread count;"
echo "*: some rounds failed (the median is of the others); failed: every round failed (see above)."
echo "rounds: the lowest and highest of the rounds' own ratios (after / before within one round);"
echo "  ~: they straddle 1.00, so this machine's noise is as large as the difference."
awk -F'\t' -v args="$ARGS" -v tri="$TRI" '
    function median(list,   n, v, i, j, x) {
        n = split(list, v, " ")
        for (i = 2; i <= n; i++) { x = v[i] + 0; for (j = i - 1; j >= 1 && v[j] + 0 > x; j--) v[j + 1] = v[j]; v[j + 1] = x }
        if (n == 0) return 0
        return n % 2 ? v[(n + 1) / 2] : (v[n / 2] + v[n / 2 + 1]) / 2
    }
    function show(side, key,   r, f) {
        r = median(rate[side, key]); f = fails[side, key] + 0
        if (r <= 0) return (((side, key) in rate) || f) ? (f ? "failed" : "n/a") : "n/a"
        return sprintf("%.3f%s", r, f ? "*" : "")
    }
    function opt(c, name,   a, n, i) {
        n = split(c, a, " ")
        for (i = 1; i < n; i++) if (a[i] == name) return a[i + 1]
        return ""
    }
    BEGIN {
        nc = split(args, cfg, ";")
        while ((getline line < tri) > 0) { split(line, f, "\t"); tg[f[1]] = tg[f[1]] " " f[2] }
        for (t in tg) triad[t] = median(tg[t])
    }
    {
        key = $2 SUBSEP $3
        if (!(key in seen)) { seen[key] = 1; order[++nk] = key }
        if ($6 == "fail") { fails[$1, key]++; if (!(key in thr)) { thr[key] = "?"; np[key] = "?" } }
        else {
            rate[$1, key] = rate[$1, key] " " $6; thr[key] = $4; np[key] = $5
            one[$1, key, $8] = $6
            if ($1 == "after" && (("before", key, $8) in one)) {
                q = $6 / one["before", key, $8]
                if (!(key in qlo) || q < qlo[key]) qlo[key] = q
                if (!(key in qhi) || q > qhi[key]) qhi[key] = q
            }
        }
        if ($1 == "after" && $7 != "") mb[key] = $7
    }
    END {
        printf "%-15s %-8s %-4s %-4s %3s %9s %8s %8s %6s %12s %7s %6s\n", "scene", "method", "upd",
            "xfer", "thr", "particles", "before", "after", "ratio", "rounds", "B/pstep", "roof"
        for (i = 1; i <= nk; i++) {
            split(order[i], kk, SUBSEP)
            c = cfg[kk[1] + 1]; sc = kk[2]; sub(/\+apic$/, "", sc)
            m = opt(c, "--method"); u = opt(c, "--update"); x = opt(c, "--transfer")
            if (m == "") m = sc ~ /^collapse2d/ ? "bspline2" : "mpm"  # each scene default
            if (u == "") u = "usf"; if (x == "") x = "flip"
            b = ((("before", order[i]) in rate)) ? median(rate["before", order[i]]) : -1
            a = ((("after", order[i]) in rate)) ? median(rate["after", order[i]]) : -1
            bs = show("before", order[i]); as = show("after", order[i])
            rs = (a > 0 && b > 0) ? sprintf("%.2fx", a / b) : "-"
            t = thr[order[i]]; if (t == "?") t = opt(c, "--threads")
            ms = (order[i] in mb) ? mb[order[i]] : ""
            fs = (ms != "" && a > 0 && (t in triad) && triad[t] > 0) ? sprintf("%.0f%%", 100 * a * ms / 1e3 / triad[t]) : "-"
            qs = (order[i] in qlo) ? sprintf("%.2f-%.2f%s", qlo[order[i]], qhi[order[i]],
                                             qlo[order[i]] < 1 && qhi[order[i]] > 1 ? "~" : "") : "-"
            printf "%-15s %-8s %-4s %-4s %3s %9s %8s %8s %6s %12s %7s %6s\n", sc, toupper(m), toupper(u),
                toupper(x), t, np[order[i]], bs, as, rs, qs, ms == "" ? "-" : ms, fs
        }
    }' "$RES"
echo "bench-compare: $(($(date +%s) - T0)) s of runs"
