#!/usr/bin/env bash
# Session 25, call 3: with the ingestion fused into the refit, the range pass as session 24's
# one workgroup a block (seq, 64bf396) against one packed list (pack, 5e42c4b) and the
# packed list with the gather loading each node's topology before its triangle (pre, uncommitted
# at the call); dragon alternating twice with --busy-gpu-ms 5; apartment pre; pre's library
# (with the ignored million-triangle refit) and ray_tracing tests in both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in seq pack pre seq pack pre; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$v-$t0.txt 2>&1; echo "== dragon $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS refit|profile    blas refit|oracle" $OUT/dragon-$v-$t0.txt | cut -c1-260
done
timeout 150 .gpu/bin/ksrt-pre bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/apt-pre.txt 2>&1; echo "== apartment pre rc=$?"
grep -E "BLAS refit|profile    blas refit|oracle" $OUT/apt-pre.txt | cut -c1-300
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 100 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked"
  CI=true timeout 100 .gpu/bin/t_rt > $OUT/t_rt-$cfg.txt 2>&1; grep -E "test result|FAILED|panicked" $OUT/t_rt-$cfg.txt
done
