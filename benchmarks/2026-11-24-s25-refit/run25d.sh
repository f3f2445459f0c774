#!/usr/bin/env bash
# Session 25, call 4: with the ingestion fused into the refit: seq (64bf396, one workgroup a
# block) against plain (pre + the range pass reading `work` through a read-only binding instead
# of atomics) and dual (plain + each node's two children walked side by side, every level's
# loads issued together); dragon alternating twice with --busy-gpu-ms 5; apartment dual; dual's
# library (with the ignored million-triangle refit) and ray_tracing tests in both configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in seq plain dual seq plain dual; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$v-$t0.txt 2>&1; echo "== dragon $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS refit|profile    blas refit|oracle" $OUT/dragon-$v-$t0.txt | cut -c1-260
done
timeout 150 .gpu/bin/ksrt-dual bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/apt-dual.txt 2>&1; echo "== apartment dual rc=$?"
grep -E "BLAS refit|profile    blas refit|oracle" $OUT/apt-dual.txt | cut -c1-300
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 60 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked"
  CI=true timeout 60 .gpu/bin/t_rt 2>&1 | grep -E "test result|FAILED|panicked"
done
