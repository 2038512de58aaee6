#!/bin/bash
# Each run-*/run.rrd of two output trees (outputs.sh) compared: the wall-clock timelines
# (log_time, log_tick) and metrics/decision_ms dropped, both rebatched alike (rerun's chunks
# follow the wall clock's flushes), then `rerun rrd compare --unordered`.
R=${RERUN:-/work/main/.venv/bin/rerun}; T=$(mktemp -d)
for d in "$1"/run-*/; do s=$(basename "$d")
  for w in 1 2; do src=$([ $w = 1 ] && echo "$1" || echo "$2")
    $R rrd filter --drop-timeline log_time --drop-timeline log_tick --drop-entity /metrics/decision_ms "$src/$s/run.rrd" -o "$T/f$w.rrd" 2>/dev/null
    $R rrd optimize --max-rows 1000000 --max-size 1GiB "$T/f$w.rrd" -o "$T/o$w.rrd" 2>/dev/null
  done
  if $R rrd compare --unordered "$T/o1.rrd" "$T/o2.rrd" >/dev/null 2>&1; then echo "same $s/run.rrd"; else echo "DIFF $s/run.rrd"; fi
done
rm -rf "$T"
