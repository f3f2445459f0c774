#!/usr/bin/env bash
# Session 23, call 5: HEAD 293f4ff (refit: gather with sorted boxes, prefetched topology in the
# climb's device-scope phase): full bench of the apartment and the dragon (tiles); A/B on the dragon
# against p1r3 (dev-p1r3.patch: phase-1 rounds of 3 barriers); library + ray_tracing tests of both
# in both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
t0=$(date +%s)
timeout 150 .gpu/bin/ksrt-head bench --scenes $S --scene apartment --scene dragon --iterations 5 --ray-order tiles --json $OUT/bench.json > $OUT/bench.txt 2>&1; echo "bench rc=$? $(( $(date +%s) - t0 ))s"
grep -E "^[a-z]|BLAS|profile    blas refit|^    (primary|ao|diffuse) .*rays|peer workload|oracle|together|instances  build" $OUT/bench.txt | cut -c1-150
for v in p1r3 head p1r3 head; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles > $OUT/ab-$v-$t0.txt 2>&1; echo "== $v dragon rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS refit|profile    blas refit|instances  build|tlas build/lbvh climb|tlas refit/lbvh" $OUT/ab-$v-$t0.txt | sed 's/cache allocation[^,]*, //g' | cut -c1-130
done
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  for v in "" _p1r3; do
    echo "=== tests$v ($cfg) ==="
    CI=true timeout 120 .gpu/bin/t_lib$v 2>&1 | tail -2
    CI=true timeout 120 .gpu/bin/t_rt$v 2>&1 | tail -2
  done
done
