#!/usr/bin/env bash
# Session 25, call 5: with the ingestion fused into the refit: dual (call 4) against quad (each
# child's range walked as two independent walks, the blocks' levels and the levels above, four
# walks side by side); dragon alternating twice with --busy-gpu-ms 5; apartment quad; quad's
# library (with the ignored million-triangle refit) and ray_tracing tests in both configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
for v in quad dual quad dual; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$v-$t0.txt 2>&1; echo "== dragon $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS build|BLAS refit|profile    blas refit|peer workload|oracle|100000 instances" $OUT/dragon-$v-$t0.txt | cut -c1-260
done
timeout 150 .gpu/bin/ksrt-quad bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/apt-quad.txt 2>&1; echo "== apartment quad rc=$?"
grep -E "BLAS refit|profile    blas refit|peer workload|oracle" $OUT/apt-quad.txt | cut -c1-300
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 60 .gpu/bin/t_lib --include-ignored 2>&1 | grep -E "test result|FAILED|panicked"
  CI=true timeout 60 .gpu/bin/t_rt 2>&1 | grep -E "test result|FAILED|panicked"
done
