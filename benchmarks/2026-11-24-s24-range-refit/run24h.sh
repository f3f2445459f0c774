#!/usr/bin/env bash
# Session 24, call 12: faecadd (tidy: HEAD's code after the review tidy of lbvh.wgsl) against
# f4febd1 (head), dragon alternating twice with --busy-gpu-ms 5; tidy's library (with the ignored
# million-triangle range refit) + ray_tracing tests in both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in tidy head tidy head; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$v-$t0.txt 2>&1; echo "== dragon $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS build|BLAS refit|profile    blas refit|peer workload|oracle" $OUT/dragon-$v-$t0.txt | cut -c1-260
done
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked"
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | grep -E "test result|FAILED|panicked"
done
