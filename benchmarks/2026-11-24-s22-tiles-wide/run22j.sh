#!/usr/bin/env bash
# Session 22, call 10: HEAD 4551eda (the slot traced once in instance_refs): bench of the apartment and the dragon (tiles), and the
# library + ray_tracing test binaries in both CI device configurations.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
t0=$(date +%s)
timeout 120 .gpu/bin/ksrt bench --scenes $S --scene apartment --scene dragon --iterations 5 --ray-order tiles --json $OUT/bench.json > $OUT/bench.txt 2>&1; echo "bench rc=$? $(( $(date +%s) - t0 ))s"
grep -E "^[a-z]|^    (primary|ao|diffuse) .*rays|peer workload|oracle|together|instances  build" $OUT/bench.txt | cut -c1-140
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 120 .gpu/bin/t_lib 2>&1 | tail -3
  CI=true timeout 120 .gpu/bin/t_rt 2>&1 | tail -3
done
