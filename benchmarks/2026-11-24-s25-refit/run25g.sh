#!/usr/bin/env bash
# Session 25, call 7: 031dd92 (tidy: the review tidy, no behaviour change) against blk
# (45d7616), dragon alternating with --busy-gpu-ms 5; apartment tidy; tidy's library (with the
# ignored million-triangle refit) and ray_tracing tests in both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in tidy blk tidy; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$v-$t0.txt 2>&1; echo "== dragon $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS refit|profile    blas refit|oracle" $OUT/dragon-$v-$t0.txt | cut -c1-260
done
timeout 150 .gpu/bin/ksrt-tidy bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/apt-tidy.txt 2>&1; echo "== apartment tidy rc=$?"
grep -E "BLAS refit|profile    blas refit|oracle" $OUT/apt-tidy.txt | cut -c1-300
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 60 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked"
  CI=true timeout 60 .gpu/bin/t_rt 2>&1 | grep -E "test result|FAILED|panicked"
done
