#!/usr/bin/env bash
# Session 23, call 6: HEAD ff2114e, the dragon bench without and with --busy-gpu-ms 5 / 20,
# alternating twice (short tasks on an idle-gapped against a busy GPU).
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
for ms in 0 5 20 0 5 20; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-busy bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms $ms --json $OUT/busy$ms-$t0.json > $OUT/busy$ms-$t0.txt 2>&1; echo "== busy $ms rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS build|BLAS refit|profile    blas refit|peer workload|together|instances  build|tlas build/lbvh climb|tlas refit/lbvh" $OUT/busy$ms-$t0.txt | sed 's/cache allocation[^,]*, //g' | cut -c1-130
done
