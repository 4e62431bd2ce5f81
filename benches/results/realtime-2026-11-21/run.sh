#!/bin/bash
B=${RATELAB:-target/release/ratelab}
for r in 1 2 3 4 5; do
  for mode in plain fifo; do
    extra=""; [ $mode = fifo ] && extra="--rt-priority 50"
    echo "=== round $r $mode 50Hz $(date +%T) load $(cut -d' ' -f1 /proc/loadavg)"
    $B bench --hz 50 --duration 10 $extra | tail -4
    echo "=== round $r $mode 1kHz"
    $B bench --hz 1000 --duration 5 $extra | tail -4
  done
done
echo ALLDONE
