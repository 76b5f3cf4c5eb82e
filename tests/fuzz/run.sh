#!/usr/bin/env bash
# Runs the libFuzzer targets of tests/fuzz/ (built by `make fuzz-build` into
# build/fuzz) and prints a table: target, executions, exec/s, coverage
# edges, crashes.  Each target starts from its corpus tests/fuzz/corpus/T/
# (every file run first) and mutates for RUNS executions at most, or CAP
# seconds; new inputs go to build/fuzz/work/T/, never into the kept corpus.
# A crash, a leak, a timeout, an out-of-memory or any sanitizer report
# leaves its reproducer in build/fuzz/artifacts/T/ and fails the run.  The
# last line, "reliability: fuzz ...", feeds docs/reliability.md's table.
#   run.sh RUNS CAP TARGET...
set -uo pipefail
cd "$(dirname "$0")/../.."
runs=$1 cap=$2
shift 2
fz=build/fuzz
total=0 crashes=0 rows=()
for t in "$@"; do
  bin=$fz/fuzz_$t corpus=tests/fuzz/corpus/$t work=$fz/work/$t art=$fz/artifacts/$t log=$fz/$t.log
  mkdir -p "$work" "$art" "$corpus"
  rm -f "$art"/*
  dict=()
  [ -f tests/fuzz/$t.dict ] && dict=(-dict=tests/fuzz/$t.dict)
  # -timeout: an input taking 20 s is a hang; -rss_limit_mb: so is 2 GB
  t0=$(date +%s.%N)
  "$bin" -runs="$runs" -max_total_time="$cap" -timeout=20 -rss_limit_mb=2048 \
    -print_final_stats=1 -artifact_prefix="$art/" "${dict[@]}" "$work" "$corpus" >"$log" 2>&1
  rc=$?
  secs=$(echo "$(date +%s.%N) $t0" | awk '{print $1 - $2}')
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  speed=$(echo "${execs:-0} $secs" | awk '{printf "%.0f", ($2 > 0 ? $1 / $2 : 0)}')
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
  found=$(find "$art" -type f | wc -l)
  san=$(grep -c 'ERROR: AddressSanitizer\|ERROR: LeakSanitizer\|runtime error:\|ERROR: libFuzzer' "$log")
  bad=$found
  [ "$bad" = 0 ] && { [ "$rc" != 0 ] || [ "$san" != 0 ]; } && bad=1
  total=$((total + ${execs:-0}))
  crashes=$((crashes + bad))
  rows+=("$(printf '%-8s %12s %9s %7s %8s' "$t" "${execs:-?}" "${speed:-?}" "${cov:-?}" "$bad")")
  if [ "$bad" != 0 ]; then
    echo "fuzz: $t: exit $rc, $found reproducer(s) in $art, log $log:" >&2
    grep -A30 'ERROR:\|runtime error:\|==ERROR\|deadly signal' "$log" | head -60 >&2
  fi
done
printf '%-8s %12s %9s %7s %8s\n' target executions exec/s edges crashes
printf '%s\n' "${rows[@]}"
printf '%-8s %12s\n' total "$total"
echo "reliability: fuzz targets=$# executions=$total crashes=$crashes"
[ "$crashes" = 0 ]
