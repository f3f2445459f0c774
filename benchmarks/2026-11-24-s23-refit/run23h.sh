#!/usr/bin/env bash
# Session 23, call 8: e3ed7c3 (sum2: block-major histogram, coalesced summing) against a07f3e0
# (sum) and ff2114e (busy: 3-dispatch passes), dragon with --busy-gpu-ms 5, alternating; sum2
# without it once; full bench of e3ed7c3 with --busy-gpu-ms 5; its library + ray_tracing tests in
# both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in sum2 sum busy sum2 sum busy; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/$v-busy5-$t0.txt 2>&1; echo "== $v busy 5 rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "instances  build|tlas build/radix" $OUT/$v-busy5-$t0.txt | sed 's/cache allocation[^,]*, //g' | cut -c1-200
done
t0=$(date +%s)
timeout 150 .gpu/bin/ksrt-sum2 bench --scenes $S --scene dragon --iterations 5 --ray-order tiles > $OUT/sum2-busy0-$t0.txt 2>&1; echo "== sum2 busy 0 rc=$?"
grep -E "instances  build" $OUT/sum2-busy0-$t0.txt
t0=$(date +%s)
timeout 200 .gpu/bin/ksrt-sum2 bench --scenes $S --scene apartment --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 --json $OUT/bench.json > $OUT/bench.txt 2>&1; echo "bench rc=$? $(( $(date +%s) - t0 ))s"
grep -E "^[a-z]|BLAS|profile    blas|^    (primary|ao|diffuse) .*rays|peer workload|oracle|together|instances  build" $OUT/bench.txt | cut -c1-200
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib 2>&1 | tail -2
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | tail -2
done
