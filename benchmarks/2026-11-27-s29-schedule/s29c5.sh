#!/bin/bash
# Session 29 call 5 (diagnostic): the same traversal on a tree that fits the caches (bunny, 3.6k
# triangles) beside the dragon (871k): node fetches per second of each batch. HEAD's pass (the
# binary of call 4 without KSRT_DEV_TRACE_WGSL), two rounds.
cd "$(dirname "$0")/../.."
chmod +x .gpu/bin/*
S=.gpu/data/scenes
for round in 1 2; do
  timeout 120 .gpu/bin/ksrt bench --scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays --scene bunny --scene dragon > $OUT/bench-$round.txt 2>&1
  echo "== round $round rc=$?"; grep -E "^[a-z]+:|^    (primary|ao|diffuse) .*rays|work|peer workload" $OUT/bench-$round.txt | cut -c1-120
done
