#!/bin/bash
B=${RATELAB:-target/release/ratelab}
for r in 1 2 3 4 5; do
  echo "=== round $r plain 50Hz $(date +%T) load $(cut -d' ' -f1 /proc/loadavg)"
  $B bench --hz 50 --duration 10 | tail -4
  echo "=== round $r fifo 50Hz"
  $B bench --hz 50 --duration 10 --rt-priority 50 | tail -4
  echo "=== round $r fifo margin1000 50Hz"
  $B bench --hz 50 --duration 10 --rt-priority 50 --spin-margin-us 1000 | tail -4
  echo "=== round $r plain 1kHz"
  $B bench --hz 1000 --duration 5 | tail -4
  echo "=== round $r fifo 1kHz"
  $B bench --hz 1000 --duration 5 --rt-priority 50 | tail -4
done
echo ALLDONE
