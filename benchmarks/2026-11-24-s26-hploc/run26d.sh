#!/bin/bash
# Session 26 call 4: the climb's cluster lists carry each cluster's box and summary (lists), and
# inner nodes tell left from right by their index (leftrule, on top of lists), against clean
# (050739e); driver statistics of the hploc_climb variants.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
W=.gpu/data/wgsl
for v in head pool half2 clean lists leftrule; do
  echo "== $v"
  .gpu/bin/shader-stats --entry hploc_climb $W/digit_histogram.wgsl $W/centroid_bounds.wgsl $W/triangle_box.wgsl $W/ingest_decode.wgsl $W/lbvh.wgsl $W/hploc_$v.wgsl 2>&1 | grep -i -E "register|shared|local|stack" | head -6
done > $OUT/shader-stats.txt
cat $OUT/shader-stats.txt
for round in 1 2; do
  for b in clean lists leftrule; do
    timeout 150 .gpu/bin/ksrt_$b bench --scenes $S --scene dragon --iterations 5 --size 64x64 --busy-gpu-ms 5 > $OUT/dragon-$b-$round.txt 2>&1
    grep -E "BLAS build|SAH|profile.*hploc" $OUT/dragon-$b-$round.txt | head -3 | cut -c1-130 | sed "s/^/[$b $round] /"
  done
done
