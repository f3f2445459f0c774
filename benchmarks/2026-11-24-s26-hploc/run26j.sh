#!/bin/bash
# Session 26 call 13 (diagnostic for the next session, not merged): nosub = HEAD's climb without
# the clusters' SAH summaries in workgroup memory (384 bytes less; the trees are wrong, the
# merges the same), to see whether less workgroup memory than HEAD's speeds the climb up.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
W=.gpu/data/wgsl
for v in skip nosub; do
  echo "== $v"
  .gpu/bin/shader-stats --entry hploc_climb $W/digit_histogram.wgsl $W/centroid_bounds.wgsl $W/triangle_box.wgsl $W/ingest_decode.wgsl $W/lbvh.wgsl $W/hploc_$v.wgsl 2>&1 | grep -i -E "register|shared" | head -3
done
for round in 1 2; do
  for b in head nosub; do
    timeout 150 .gpu/bin/ksrt_$b bench --scenes $S --scene dragon --iterations 5 --size 64x64 --busy-gpu-ms 5 > $OUT/dragon-$b-$round.txt 2>&1
    grep -E "BLAS build|profile.*hploc" $OUT/dragon-$b-$round.txt | head -2 | cut -c1-110 | sed "s/^/[$b $round] /"
  done
done
