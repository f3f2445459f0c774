#!/usr/bin/env bash
# Session 25, call 1: f9ef781 (new: range refit over 8 lanes a child + ingestion fused into the
# refit) against f4febd1 (head: session 24's code, = faecadd's behaviour), dragon alternating
# twice with --busy-gpu-ms 5; apartment each once; new's library (with the ignored
# million-triangle range refit) + ray_tracing tests in both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in head new head new; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$v-$t0.txt 2>&1; echo "== dragon $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS build|BLAS refit|profile    blas refit|profile    ingest|peer workload|oracle|100000 instances" $OUT/dragon-$v-$t0.txt | cut -c1-260
done
for v in head new; do
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/apt-$v.txt 2>&1; echo "== apartment $v rc=$?"
  grep -E "BLAS refit|profile    blas refit|peer workload|oracle" $OUT/apt-$v.txt | cut -c1-300
done
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked|range_refit"
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | grep -E "test result|FAILED|panicked|update_refits"
done
