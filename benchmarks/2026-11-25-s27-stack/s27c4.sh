#!/bin/bash
# Session 27 call 4: builds (BLAS fast-trace / fast-build / refit, TLAS) and denoisers with and
# without wgpu's zero fill of workgroup memory (dev hook KSRT_DEV_NO_WG_ZERO: every pipeline of
# gpu/shader.rs created with zero_initialize_workgroup_memory = false).
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt-dev
run() { local name=$1; shift; local t0=$(date +%s); timeout 150 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "BLAS build|fast-build|BLAS refit|SAH|profile|instances  build|denois|temporal|atrous|ms \(" $OUT/$name.txt | grep -v "^      work" | cut -c1-150 | head -24; }
A="--scenes $S --iterations 5 --size 64x64 --busy-gpu-ms 5"
for round in 1 2; do
  run zero-$round $B bench $A --scene dragon --scene apartment --sections builds,tlas
  KSRT_DEV_NO_WG_ZERO=1 run nozero-$round $B bench $A --scene dragon --scene apartment --sections builds,tlas
done
run den-zero $B bench --denoisers --iterations 10
KSRT_DEV_NO_WG_ZERO=1 run den-nozero $B bench --denoisers --iterations 10
