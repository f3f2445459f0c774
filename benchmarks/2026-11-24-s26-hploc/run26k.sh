#!/bin/bash
# Session 26 call 14: HEAD a6f23c6 (review tidy, no behaviour change) on the dragon, and its
# library and ray_tracing tests in both CI device configurations.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
timeout 110 .gpu/bin/ksrt bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-tidy.txt 2>&1; echo "rc=$?"
grep -E "BLAS build|fast-build|BLAS refit|SAH|peer workload|oracle" $OUT/dragon-tidy.txt | cut -c1-200
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 80 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked"
  CI=true timeout 80 .gpu/bin/t_rt 2>&1 | grep -E "test result|FAILED|panicked"
done
