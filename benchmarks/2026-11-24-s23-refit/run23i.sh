#!/usr/bin/env bash
# Session 23, call 9: HEAD fc5ab15: full bench (apartment + dragon, tiles) with --busy-gpu-ms 5
# (json) and the dragon without it; library + ray_tracing tests in both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
t0=$(date +%s)
timeout 200 .gpu/bin/ksrt-final bench --scenes $S --scene apartment --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 --json $OUT/bench-busy5.json > $OUT/bench-busy5.txt 2>&1; echo "bench rc=$? $(( $(date +%s) - t0 ))s"
grep -E "^[a-z]|BLAS|profile    blas|^    (primary|ao|diffuse) .*rays|peer workload|oracle|together|instances  build|tlas build/" $OUT/bench-busy5.txt | cut -c1-220
t0=$(date +%s)
timeout 150 .gpu/bin/ksrt-final bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --json $OUT/dragon-busy0.json > $OUT/dragon-busy0.txt 2>&1; echo "dragon busy0 rc=$? $(( $(date +%s) - t0 ))s"
grep -E "BLAS|peer workload|instances  build" $OUT/dragon-busy0.txt | cut -c1-160
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib 2>&1 | tail -2
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | tail -2
done
