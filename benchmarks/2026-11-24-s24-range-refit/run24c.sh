#!/usr/bin/env bash
# Session 24, call 3: 6bcf395 (two: the range refit in two passes) against bb8805b's code (base,
# = 1e446b2's), dragon alternating twice with --busy-gpu-ms 5, then once without it; apartment
# two once; two's library (with the ignored million-triangle range refit) + ray_tracing tests in
# both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in two base two base; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$v-$t0.txt 2>&1; echo "== dragon $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS build|BLAS refit|profile    blas refit|peer workload|oracle|instances  build" $OUT/dragon-$v-$t0.txt | cut -c1-260
done
t0=$(date +%s)
timeout 150 .gpu/bin/ksrt-two bench --scenes $S --scene dragon --iterations 5 --ray-order tiles > $OUT/dragon-two-idle.txt 2>&1; echo "== dragon two, no busy work rc=$? $(( $(date +%s) - t0 ))s"
grep -E "BLAS refit|profile    blas refit" $OUT/dragon-two-idle.txt | cut -c1-260
t0=$(date +%s)
timeout 150 .gpu/bin/ksrt-two bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/apt-two.txt 2>&1; echo "== apartment two rc=$? $(( $(date +%s) - t0 ))s"
grep -E "BLAS build|BLAS refit|profile    blas refit|peer workload|oracle" $OUT/apt-two.txt | cut -c1-260
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked|range_refit"
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | tail -2
done
