#!/bin/bash
B=${RATELAB:-target/release/ratelab}
for r in 1 2 3 4 5 6; do
  echo "=== round $r fifo stagger $(date +%T) load $(cut -d' ' -f1 /proc/loadavg)"
  $B bench --hz 50,1000 --duration 10 --rt-priority 50 --stagger | tail -8
  echo "=== round $r plain stagger"
  $B bench --hz 50,1000 --duration 10 --stagger | tail -8
done
echo ALLDONE
