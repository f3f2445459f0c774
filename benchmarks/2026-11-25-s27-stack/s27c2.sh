#!/bin/bash
# Session 27 call 2: (a) trace tasks with and without the stack zero fill (one binary);
# (b) session 22's 8-wide compressed BLAS (dev hook: CPU conversion, wide.wgsl) now without the
# zero fill, against HEAD's BVH2; (c) the test binaries of fbdff53 on the H100, both configurations.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt-dev
D=.gpu/data
run() { local name=$1; shift; local t0=$(date +%s); timeout 150 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "DEV wide|^    (primary|ao|diffuse) .*rays|peer workload|oracle|^    (specular|diffuse|ao|shadow|multi_shadow) .* ms|together" $OUT/$name.txt | cut -c1-110; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5"
for scene in dragon apartment; do
  run $scene-head $B bench $A --scene $scene --sections rays,tasks
  KSRT_DISABLE_FEATURES=PASSTHROUGH_SHADERS run $scene-wgsl $B bench $A --scene $scene --sections tasks
done
KSRT_DEV_WIDE=1 KSRT_DEV_TRACE_WGSL=$D/wide.wgsl run dragon-wide $B bench $A --scene dragon --sections rays
run apartment-flat-head $B bench $A --scene apartment --flatten --sections rays
KSRT_DEV_WIDE=1 KSRT_DEV_TRACE_WGSL=$D/wide.wgsl run apartment-flat-wide $B bench $A --scene apartment --flatten --sections rays
export KSRT_SCENES=$S
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg)"
  CI=true timeout 150 .gpu/bin/t_lib --include-ignored > $OUT/tlib-$cfg.txt 2>&1; echo "t_lib rc=$?"; grep -E "test result|FAILED|panicked" $OUT/tlib-$cfg.txt | head -5
  CI=true timeout 150 .gpu/bin/t_rt > $OUT/trt-$cfg.txt 2>&1; echo "t_rt rc=$?"; grep -E "test result|FAILED|panicked" $OUT/trt-$cfg.txt | head -5
done
