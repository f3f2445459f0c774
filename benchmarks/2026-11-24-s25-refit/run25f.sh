#!/usr/bin/env bash
# Session 25, call 6: dual (05942d1: packed straddle list) against blk (dual's range pass and
# topology preload with session 24's per-block lists: no extra barrier or global atomic in the
# gather); dragon alternating twice with --busy-gpu-ms 5; apartment blk; blk's library (with the ignored million-triangle refit) and ray_tracing
# tests in both configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in blk dual blk dual; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$v-$t0.txt 2>&1; echo "== dragon $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS build|BLAS refit|profile    blas refit|peer workload|oracle|100000 instances" $OUT/dragon-$v-$t0.txt | cut -c1-260
done
timeout 150 .gpu/bin/ksrt-blk bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/apt-blk.txt 2>&1; echo "== apartment blk rc=$?"
grep -E "BLAS refit|profile    blas refit|peer workload|oracle" $OUT/apt-blk.txt | cut -c1-300
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 60 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked"
  CI=true timeout 60 .gpu/bin/t_rt 2>&1 | grep -E "test result|FAILED|panicked"
done
