#!/usr/bin/env bash
# Prints docs/reliability.md's table from the "reliability: PART
# key=value ..." lines that the rel_* tests and tests/fuzz/run.sh print,
# read from the logs given (or stdin): one row per part, in the order
# fuzz, kill9, load, watchers, disk, fulldisk, hostile (the last line of a part wins).
#   reliab_table.sh LOG...
set -uo pipefail
lines=$(cat "$@" | sed -n 's/^ *reliability: //p')
echo
echo "Reliability"
echo
echo "| part | figures |"
echo "| --- | --- |"
for part in fuzz kill9 load watchers disk fulldisk hostile; do
  row=$(printf '%s\n' "$lines" | awk -v p="$part" '$1 == p' | tail -1)
  if [ -z "$row" ]; then
    echo "| $part | (not run) |"
  else
    echo "| $part | ${row#"$part" } |"
  fi
done
