#!/bin/bash
# Session 26 call 5: climbers start at the merging nodes (skip: no climb through the levels of
# at most 16 leaves), on top of lists; against clean (050739e) and lists.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
for round in 1 2; do
  for b in clean lists skip; do
    timeout 150 .gpu/bin/ksrt_$b bench --scenes $S --scene dragon --iterations 5 --size 64x64 --busy-gpu-ms 5 > $OUT/dragon-$b-$round.txt 2>&1
    grep -E "BLAS build|SAH|profile.*hploc" $OUT/dragon-$b-$round.txt | head -3 | cut -c1-130 | sed "s/^/[$b $round] /"
  done
done
for b in clean skip; do
  timeout 200 .gpu/bin/ksrt_$b bench --scenes $S --scene apartment --iterations 5 --size 64x64 --busy-gpu-ms 5 > $OUT/apt-$b.txt 2>&1
  grep -E "BLAS build|SAH" $OUT/apt-$b.txt | head -3 | cut -c1-130 | sed "s/^/[$b apt] /"
done
