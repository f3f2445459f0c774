#!/usr/bin/env bash
# Session 23, call 10: 1e1e8e8 (mh: the morton pass makes the sort's first histogram, branch
# morton-histogram) against fc5ab15's code (final), dragon with --busy-gpu-ms 5, alternating twice;
# mh's library + ray_tracing tests in both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in mh final mh final; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/$v-busy5-$t0.txt 2>&1; echo "== $v busy 5 rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS build|BLAS refit|peer workload|oracle|instances  build|tlas build/" $OUT/$v-busy5-$t0.txt | sed 's/cache allocation[^,]*, //g' | cut -c1-230
done
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib 2>&1 | tail -2
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | tail -2
done
