#!/usr/bin/env bash
# Session 22, call 4: branch rebraid (TLAS over instance refs on the GPU): bench (all scenes, TLAS table) in tiles and
# rows, and the library + ray_tracing test binaries in both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt
export KSRT_SCENES=$S
t0=$(date +%s)
timeout 200 $B bench --scenes $S --iterations 10 --ray-order tiles --json $OUT/bench-tiles.json > $OUT/bench-tiles.txt 2>&1; echo "bench tiles rc=$? $(( $(date +%s) - t0 ))s"
grep -E "^[a-z]|peer workload|^    (primary|ao|diffuse) .*rays|oracle|BLAS build|instances  build|together" $OUT/bench-tiles.txt | cut -c1-160
t0=$(date +%s)
timeout 120 $B bench --scenes $S --scene dragon --scene apartment --iterations 5 --json $OUT/bench-rows.json > $OUT/bench-rows.txt 2>&1; echo "bench rows rc=$? $(( $(date +%s) - t0 ))s"
grep -E "^[a-z]|peer workload|oracle" $OUT/bench-rows.txt | cut -c1-160
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib 2>&1 | tail -3
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | tail -3
done
