#!/usr/bin/env bash
# Session 22, call 2: the 8-wide compressed BLAS (CPU conversion of the built tree, dev hook) traced by a nested
# wide traversal. ksrt = 79ad3f9 + dev-wide.patch (KSRT_DEV_WIDE converts every BLAS; KSRT_DEV_TRACE_WGSL swaps the
# trace-rays shader). head = no env (HEAD's traversal); wide = wide.wgsl (a node's hit triangles in an inner loop);
# wide1 = wide1.wgsl (one triangle or one node an iteration).
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt
D=.gpu/data
run() { local name=$1; shift; local t0=$(date +%s); timeout 120 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "DEV wide|^    (primary|ao|diffuse) .*rays|peer workload|oracle" $OUT/$name.txt | cut -c1-130; }
for f in d0 wide wide1; do echo "== $f"; .gpu/bin/shader-stats --unchecked $D/$f.wgsl 2>&1 | grep -iE "register count|stack size" | head -4; done
A="--scenes $S --scene dragon --scene apartment --iterations 5 --ray-order tiles"
run head-tiles $B bench $A
KSRT_DEV_WIDE=1 KSRT_DEV_TRACE_WGSL=$D/wide.wgsl run wide-tiles $B bench $A
KSRT_DEV_WIDE=1 KSRT_DEV_TRACE_WGSL=$D/wide1.wgsl run wide1-tiles $B bench $A
KSRT_DEV_WIDE=1 KSRT_DEV_TRACE_WGSL=$D/wide.wgsl run wide-flat-tiles $B bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --flatten
run head-flat-tiles $B bench --scenes $S --scene apartment --iterations 5 --ray-order tiles --flatten
