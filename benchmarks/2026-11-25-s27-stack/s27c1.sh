#!/bin/bash
# Session 27 call 1: the traversal stack without its zero fill (own SPIR-V through
# PASSTHROUGH_SHADERS) against the WGSL path (KSRT_DISABLE_FEATURES=PASSTHROUGH_SHADERS), one binary;
# then whether Nsight Compute reads counters of a Vulkan dispatch.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt
nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm --format=csv > $OUT/gpu.txt 2>&1
run() { local name=$1; shift; local t0=$(date +%s); timeout 200 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle|^    (specular|diffuse|ao|shadow) .* ms|together|SPIR-V" $OUT/$name.txt | cut -c1-120; }
for scene in dragon apartment; do
  run $scene-new $B bench --scenes $S --scene $scene --iterations 5 --ray-order tiles --busy-gpu-ms 5 --json $OUT/$scene-new.json
  KSRT_DISABLE_FEATURES=PASSTHROUGH_SHADERS run $scene-wgsl $B bench --scenes $S --scene $scene --iterations 5 --ray-order tiles --busy-gpu-ms 5 --json $OUT/$scene-wgsl.json
done
echo "=== ncu"
which ncu; ncu --version 2>&1 | tail -2
timeout 100 ncu --target-processes all --metrics smsp__inst_executed.sum,gpu__time_duration.sum --launch-count 2 $B bench --scenes $S --scene bunny --iterations 1 --size 64x64 > $OUT/ncu.txt 2>&1
echo "ncu rc=$?"; grep -v "^    \|^$" $OUT/ncu.txt | head -20; grep -E "inst_executed|time_duration|==PROF==|==ERROR==|==WARNING==" $OUT/ncu.txt | head -20
