#!/usr/bin/env bash
# Session 23, call 1: climb with block-local phase from workgroup memory + refit gather with sorted
# boxes (new), the same without the phase-2 topology prefetch (nopf), against HEAD 2233727 (base).
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in base new nopf new base; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --json $OUT/dragon-$v-$t0.json > $OUT/dragon-$v-$t0.txt 2>&1; echo "== $v dragon rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS|profile    blas refit|profile    blas build|instances  build|tlas build/lbvh climb|tlas refit/lbvh|peer workload|together" $OUT/dragon-$v-$t0.txt | sed 's/cache allocation[^,]*, //g' | cut -c1-220
done
for v in new base; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene apartment --iterations 5 --ray-order tiles > $OUT/apt-$v.txt 2>&1; echo "== $v apartment rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS|profile    blas refit|peer workload|together" $OUT/apt-$v.txt | cut -c1-220
done
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib 2>&1 | tail -2
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | tail -2
done
