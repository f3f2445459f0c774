#!/bin/bash
# Session 26 call 3: half2 (each pair's area once, conflict-free layout), wg64 (two 32-lane slices
# a workgroup), diagnostics nowrite (no output node writes in the rounds) and nostore (no box /
# summary stores in the rounds; repeated builds reuse the previous build's identical words).
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
for round in 1 2; do
  for b in pool half2 wg64 nowrite nostore; do
    if [ $round = 2 ] && { [ $b = nowrite ] || [ $b = nostore ]; }; then continue; fi
    timeout 150 .gpu/bin/ksrt_$b bench --scenes $S --scene dragon --iterations 5 --size 64x64 --busy-gpu-ms 5 > $OUT/dragon-$b-$round.txt 2>&1
    grep -E "BLAS build|SAH|profile.*hploc" $OUT/dragon-$b-$round.txt | head -3 | cut -c1-160 | sed "s/^/[$b $round] /"
  done
done
