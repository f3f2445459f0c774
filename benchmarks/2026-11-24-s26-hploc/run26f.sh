#!/bin/bash
# Session 26 call 6: HEAD cf9c3d5 (climb in workgroups of 32 from the merging nodes; fast-build
# BLAS by the range refit's passes) against base (5f83a2e + the bench's fast-build line), dragon
# and apartment at 1920x1080 in tiles; HEAD's library (with the ignored tests) and ray_tracing
# tests in both CI device configurations.
set -u
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for sc in dragon apartment; do
  for b in head base; do
    t0=$(date +%s)
    timeout 110 .gpu/bin/ksrt_$b bench --scenes $S --scene $sc --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/$sc-$b.txt 2>&1; echo "== $sc $b rc=$? $(( $(date +%s) - t0 ))s"
    grep -E "BLAS build|fast-build|BLAS refit|SAH|peer workload|oracle|Mrays/s" $OUT/$sc-$b.txt | head -12 | cut -c1-200
  done
done
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 80 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked"
  CI=true timeout 80 .gpu/bin/t_rt 2>&1 | grep -E "test result|FAILED|panicked"
done
