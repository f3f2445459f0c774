#!/bin/bash
# Session 26 call 1: hploc climb in 32-lane workgroups (wg32), and with a deterministic slot pool
# instead of the global node counter (pool); base = HEAD 5f83a2e + the bench's fast-build line.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
for round in 1 2; do
  for b in base wg32 pool; do
    .gpu/bin/ksrt_$b bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$b-$round.txt 2>&1
    grep -E "BLAS build|fast-build|profile|SAH|peer workload" $OUT/dragon-$b-$round.txt | head -8 | sed "s/^/[$b $round] /"
  done
done
for b in base pool; do
  .gpu/bin/ksrt_$b bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/apt-$b.txt 2>&1
  grep -E "BLAS build|fast-build|SAH|peer workload" $OUT/apt-$b.txt | sed "s/^/[$b apt] /"
done
