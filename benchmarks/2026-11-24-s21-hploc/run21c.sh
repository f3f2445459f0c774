#!/usr/bin/env bash
# Session 21, call 3: where the hploc climb's time goes (diagnostic variants, some unsafe:
# nf1 drops the task's device fence, nf3 all three, nonn pairs clusters without searching).
set -u
B=.gpu/bin/ksrt
S=.gpu/data/scenes
.gpu/bin/shader-stats --entry hploc_climb --entry lbvh_climb .gpu/v/full_base.wgsl 2>&1 | tail -8
for v in base nf1 nf3 nonn base; do
  export KSRT_DEV_HPLOC_WGSL=.gpu/v/hploc_$v.wgsl
  echo "=== $v ==="
  timeout 90 $B bench --scenes $S --scene dragon --scene apartment --iterations 5 > $OUT/$v.txt 2>&1; echo rc=$?
  grep -E "^[a-z]|peer workload|SAH|BLAS build|hploc|oracle" $OUT/$v.txt | cut -c1-130
done
