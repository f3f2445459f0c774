#!/usr/bin/env bash
# Session 21: the clustered (H-PLOC) fast-trace BLAS on the H100: bench, the apartment as one mesh,
# and the library + ray_tracing test binaries in both CI device configurations.
set -u
B=.gpu/bin/ksrt
S=.gpu/data/scenes
export KSRT_SCENES=$S
echo "=== bench (all scenes, TLAS) ==="
timeout 240 $B bench --scenes $S --iterations 10 --json $OUT/bench.json > $OUT/bench.txt 2>&1; echo rc=$?
grep -E "^[a-z]|peer workload|Mrays|work |SAH|BLAS|profile    blas build|oracle|instances" $OUT/bench.txt | cut -c1-400
echo "=== flatten ==="
timeout 120 $B bench --scenes $S --scene dragon --scene apartment --iterations 5 --flatten --json $OUT/flat.json > $OUT/flat.txt 2>&1; echo rc=$?
grep -E "^[a-z]|peer workload|Mrays|work |SAH|BLAS build|oracle" $OUT/flat.txt | cut -c1-300
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 150 .gpu/bin/t_lib 2>&1 | tail -4
  CI=true timeout 150 .gpu/bin/t_rt 2>&1 | tail -4
done
