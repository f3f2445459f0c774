#!/usr/bin/env bash
# Session 23, call 7: a07f3e0 (sum: 2-dispatch sort passes up to 128 blocks) against ff2114e
# (busy: the same bench option, 3-dispatch passes), dragon with --busy-gpu-ms 5 and 0, alternating;
# full bench of HEAD with --busy-gpu-ms 5 (apartment + dragon, json); library + ray_tracing tests
# of a07f3e0 in both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in sum busy sum busy; do
  for ms in 5 0; do
    t0=$(date +%s)
    timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms $ms > $OUT/$v-busy$ms-$t0.txt 2>&1; echo "== $v busy $ms rc=$? $(( $(date +%s) - t0 ))s"
    grep -E "BLAS build|BLAS refit|instances  build|tlas build/lbvh climb" $OUT/$v-busy$ms-$t0.txt | sed 's/cache allocation[^,]*, //g' | cut -c1-150
  done
done
t0=$(date +%s)
timeout 200 .gpu/bin/ksrt-sum bench --scenes $S --scene apartment --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 --json $OUT/bench.json > $OUT/bench.txt 2>&1; echo "bench rc=$? $(( $(date +%s) - t0 ))s"
grep -E "^[a-z]|BLAS|profile    blas|^    (primary|ao|diffuse) .*rays|peer workload|oracle|together|instances  build" $OUT/bench.txt | cut -c1-200
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib 2>&1 | tail -2
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | tail -2
done
