#!/bin/bash
# Session 26 call 12 (diagnostics for the next session, not merged): shm = HEAD's climb with
# 2.5 KB more workgroup memory (does the L1 carve-out matter?); nofence = HEAD without the
# storageBarrier where a merge's info is handed over (what one device fence a merge costs).
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
W=.gpu/data/wgsl
for v in skip shm nofence; do
  echo "== $v"
  .gpu/bin/shader-stats --entry hploc_climb $W/digit_histogram.wgsl $W/centroid_bounds.wgsl $W/triangle_box.wgsl $W/ingest_decode.wgsl $W/lbvh.wgsl $W/hploc_$v.wgsl 2>&1 | grep -i -E "register|shared" | head -3
done
for round in 1 2; do
  for b in head shm nofence; do
    timeout 150 .gpu/bin/ksrt_$b bench --scenes $S --scene dragon --iterations 5 --size 64x64 --busy-gpu-ms 5 > $OUT/dragon-$b-$round.txt 2>&1
    grep -E "BLAS build|SAH|profile.*hploc" $OUT/dragon-$b-$round.txt | head -3 | cut -c1-130 | sed "s/^/[$b $round] /"
  done
done
