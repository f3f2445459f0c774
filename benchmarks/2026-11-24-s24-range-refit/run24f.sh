#!/usr/bin/env bash
# Session 24, call 6: one (91a7611's code + each in-block node makes its own box once and takes
# its children's from workgroup memory) against atom (91a7611, HEAD's GPU code), and two
# timing-only variants of one: nolist (no straddling-node list: wrong trees) and noupper (no
# atomicMax into the upper pyramid: wrong trees); dragon with --busy-gpu-ms 5; apartment one and
# atom; one's library (with the ignored million-triangle range refit) + ray_tracing tests in both
# CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in one atom nolist noupper one atom; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$v-$t0.txt 2>&1; echo "== dragon $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS refit|profile    blas refit|oracle" $OUT/dragon-$v-$t0.txt | cut -c1-260
done
for v in one atom; do
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/apt-$v.txt 2>&1; echo "== apartment $v rc=$?"
  grep -E "BLAS refit|profile    blas refit|oracle" $OUT/apt-$v.txt | cut -c1-260
done
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked|range_refit"
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | tail -2
done
