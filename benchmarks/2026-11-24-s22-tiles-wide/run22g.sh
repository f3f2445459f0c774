#!/usr/bin/env bash
# Session 22, call 7: which part of the CPU ref TLAS (global opening order, binned-SAH tree) the GPU one (per-instance
# opening, LBVH) lacks. ksrt = 9520951 + dev-rebraid2.patch (KSRT_DEV_REBRAID=k: CPU-built ref TLAS in the SDK's layout;
# KSRT_DEV_REBRAID_PER: each instance opened on its own into k refs, as the GPU build).
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt
A="--scenes $S --scene apartment --iterations 5 --ray-order tiles"
run() { local name=$1; shift; local t0=$(date +%s); timeout 100 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "DEV|^    (primary|ao|diffuse) .*rays|peer workload|oracle|failed" $OUT/$name.txt | cut -c1-130; }
run gpu $B bench $A
KSRT_DEV_REBRAID=8 KSRT_DEV_REBRAID_PER=1 run cpu-per-k8 $B bench $A
KSRT_DEV_REBRAID=8 run cpu-global-k8 $B bench $A
KSRT_DEV_REBRAID=16 KSRT_DEV_REBRAID_PER=1 run cpu-per-k16 $B bench $A
run gpu-again $B bench $A
