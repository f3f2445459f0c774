#!/bin/bash
# Session 27 call 3: trace tasks with the own SPIR-V's storage buffers unchecked (as wgpu-hal
# writes them), against the WGSL path; a 32-entry stack (s32.wgsl) against 64 for the ray batches.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt-dev
D=.gpu/data
run() { local name=$1; shift; local t0=$(date +%s); timeout 150 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle|^    (specular|diffuse|ao|shadow|multi_shadow) .* ms|together" $OUT/$name.txt | cut -c1-110; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5"
for scene in dragon apartment; do
  run $scene-head $B bench $A --scene $scene --sections rays,tasks
  KSRT_DISABLE_FEATURES=PASSTHROUGH_SHADERS run $scene-wgsl $B bench $A --scene $scene --sections tasks
  KSRT_DEV_TRACE_WGSL=$D/s32.wgsl run $scene-s32 $B bench $A --scene $scene --sections rays
done
