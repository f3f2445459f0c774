#!/usr/bin/env bash
# Session 23, call 3: timing variants of the new climb: p1only (no device-scope phase; wrong
# trees), plainany (the workgroup vote with a plain store instead of a shared atomicAdd), new.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
for v in new p1only plainany new p1only plainany; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles > $OUT/dragon-$v-$t0.txt 2>&1; echo "== $v dragon rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS refit|profile    blas refit|instances  build|tlas build/lbvh climb|tlas refit/lbvh" $OUT/dragon-$v-$t0.txt | sed 's/cache allocation[^,]*, //g' | cut -c1-130
done
