#!/usr/bin/env bash
# Session 24, call 1: f60f11f (new: the range refit) against bb8805b's code (base, = 1e446b2's),
# dragon alternating twice with --busy-gpu-ms 5, apartment once each; new's library +
# ray_tracing tests in both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in new base new base; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$v-$t0.txt 2>&1; echo "== dragon $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS build|BLAS refit|profile    blas refit|peer workload|oracle|instances  build|tlas build/" $OUT/dragon-$v-$t0.txt | sed 's/cache allocation[^,]*, //g' | cut -c1-260
done
for v in new base; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/apt-$v.txt 2>&1; echo "== apartment $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS build|BLAS refit|profile    blas refit|peer workload|oracle" $OUT/apt-$v.txt | cut -c1-260
done
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib 2>&1 | tail -2
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | tail -2
done
