#!/usr/bin/env bash
# Session 24, call 5: a50c986 (final: HEAD's code), dragon twice with --busy-gpu-ms 5, apartment
# once with it, then the default bench of both scenes (no busy work, tiles) to JSON; the library
# (with the ignored million-triangle range refit) + ray_tracing tests in both CI device
# configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for sc in dragon dragon apartment; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-final bench --scenes $S --scene $sc --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/$sc-final-busy5-$t0.txt 2>&1; echo "== $sc final busy 5 rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS refit|profile    blas refit|peer workload|oracle" $OUT/$sc-final-busy5-$t0.txt | cut -c1-260
done
t0=$(date +%s)
timeout 240 .gpu/bin/ksrt-final bench --scenes $S --iterations 5 --ray-order tiles --json $OUT/bench-final.json > $OUT/bench-final.txt 2>&1; echo "== full bench rc=$? $(( $(date +%s) - t0 ))s"
grep -E "^[a-z]+:|BLAS build|BLAS refit|profile    blas refit|SAH|primary  |ao  |diffuse  |peer workload|oracle|instances  build" $OUT/bench-final.txt | cut -c1-200
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked|range_refit"
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | tail -2
done
