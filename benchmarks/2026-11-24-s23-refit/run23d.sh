#!/usr/bin/env bash
# Session 23, call 4: A/B of the climb entry for max_leaf 1 (new: lbvh_climb_boxes; oldclimb: the
# same build with lbvh_climb for every climb), both with the refit's sorted boxes; dragon then
# apartment, alternating.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
for v in new oldclimb new oldclimb new oldclimb; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles > $OUT/dragon-$v-$t0.txt 2>&1; echo "== $v dragon rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS refit|profile    blas refit|instances  build|tlas build/lbvh climb|tlas refit/lbvh" $OUT/dragon-$v-$t0.txt | sed 's/cache allocation[^,]*, //g' | cut -c1-130
done
for v in new oldclimb; do
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene apartment --iterations 5 --ray-order tiles > $OUT/apt-$v.txt 2>&1; echo "== $v apartment rc=$?"
  grep -E "BLAS refit|profile    blas refit" $OUT/apt-$v.txt | cut -c1-160
done
