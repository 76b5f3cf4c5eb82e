#!/usr/bin/env bash
# ceiling.sh - `make bench-ceiling`: the solver's ceiling on this machine.
# Rounds (CEILING_ROUNDS, default 3) of, at each size (CEILING_SIZES,
# default "10000 1000000" particles): bin/mpmbench --scene disks2d (MPM USF,
# 1 thread, the solver) and bin/mpmceiling (the same scene's step with
# nothing but its arithmetic), one after the other; then the triad on
# 2 threads.  The table gives per size the medians over the rounds, the
# ceiling over the solver, and what two threads at the ceiling's rate
# would make of the triad roof at the solver's modelled bytes per
# particle-step (a bound: two threads never run at twice one thread's rate).
set -euo pipefail
cd "$(dirname "$0")/../.."

rounds="${CEILING_ROUNDS:-3}"
sizes="${CEILING_SIZES:-10000 1000000}"
for b in bin/mpmbench bin/mpmceiling; do
  [ -x "$b" ] || { echo "ceiling.sh: $b is missing (make bench-ceiling builds it)" >&2; exit 2; }
done
case "$rounds" in '' | *[!0-9]* | 0) echo "ceiling.sh: CEILING_ROUNDS must be a whole number >= 1" >&2; exit 2 ;; esac

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

# the median of the numbers in a file, one a line
median() { sort -g "$1" | awk '{a[NR] = $1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }

echo "ceiling.sh: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//'), $(nproc) CPU(s), load $(cut -d' ' -f1-3 /proc/loadavg); $rounds rounds"
for r in $(seq 1 "$rounds"); do
  for n in $sizes; do
    row="$(bin/mpmbench --scene disks2d --method mpm --update usf --threads 1 --particles "$n" \
      --no-triad --csv 2>>"$tmp/err" | grep '^disks2d,')" || { cat "$tmp/err" >&2; exit 1; }
    echo "$row" | cut -d, -f10 >>"$tmp/solver.$n"
    echo "$row" | cut -d, -f12 >"$tmp/bytes.$n"
    echo "$row" | cut -d, -f5 >"$tmp/np.$n"
    crow="$(bin/mpmceiling --particles "$n" --csv 2>>"$tmp/err")" || { cat "$tmp/err" >&2; exit 1; }
    echo "$crow" | cut -d, -f5 >>"$tmp/ceiling.$n"
    echo "$crow" | cut -d, -f2 >"$tmp/kernels"
    echo "  round $r, $n particles: solver $(tail -1 "$tmp/solver.$n"), ceiling $(tail -1 "$tmp/ceiling.$n") M p-steps/s"
  done
  bin/mpmbench --triad --threads 2 --csv 2>>"$tmp/err" | awk -F, 'NR == 2 {print $2}' >>"$tmp/triad"
done

triad="$(median "$tmp/triad")"
echo
echo "ceiling kernels: $(cat "$tmp/kernels"); triad (2 threads, median of $rounds): $triad GB/s"
printf '%-10s %12s %12s %9s %8s %22s\n' particles "solver" "ceiling" "ceil/sol" "B/pstep" "2 x ceiling / roof"
for n in $sizes; do
  s="$(median "$tmp/solver.$n")"
  c="$(median "$tmp/ceiling.$n")"
  bytes="$(cat "$tmp/bytes.$n")"
  awk -v n="$(cat "$tmp/np.$n")" -v s="$s" -v c="$c" -v b="$bytes" -v t="$triad" \
    'BEGIN {printf "%-10s %12.2f %12.2f %8.3fx %8s %21.0f%%\n", n, s, c, c / s, b, 100 * 2 * c * 1e6 * b / (t * 1e9)}'
done
echo "(solver and ceiling: M particle-steps/s on 1 thread, median of the rounds; the last column:"
echo " two threads each at the ceiling's 1-thread rate, times the solver's modelled bytes, over the triad)"
