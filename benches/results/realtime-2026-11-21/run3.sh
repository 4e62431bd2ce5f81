#!/bin/bash
B=${RATELAB:-target/release/ratelab}
for r in 1 2 3 4; do
  for hz in 50 1000; do
    d=10; [ $hz = 1000 ] && d=5
    echo "=== round $r plain $hz $(date +%T) load $(cut -d' ' -f1 /proc/loadavg)"
    $B bench --hz $hz --duration $d | tail -4
    echo "=== round $r fifo $hz"
    $B bench --hz $hz --duration $d --rt-priority 50 | tail -4
    echo "=== round $r fifo stagger $hz"
    $B bench --hz $hz --duration $d --rt-priority 50 --stagger | tail -4
    echo "=== round $r plain stagger $hz"
    $B bench --hz $hz --duration $d --stagger | tail -4
  done
done
echo ALLDONE
