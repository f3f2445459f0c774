#!/usr/bin/env bash
# Session 22, call 3: a CPU-built TLAS over instance refs ("rebraiding"). ksrt = 79ad3f9 + dev-rebraid.patch:
# KSRT_DEV_REBRAID=k builds (binned SAH) a TLAS over k x instances refs (instances opened into their BLAS subtrees,
# largest world area first; k = 1: one ref per instance, i.e. only the TLAS differs), traced by rebraid.wgsl.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt
D=.gpu/data
run() { local name=$1; shift; local t0=$(date +%s); timeout 100 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "DEV|^    (primary|ao|diffuse) .*rays|peer workload|oracle|failed" $OUT/$name.txt | cut -c1-130; }
A="--scenes $S --scene apartment --iterations 5 --ray-order tiles"
run head $B bench $A
for k in 1 2 4 8 16; do KSRT_DEV_REBRAID=$k KSRT_DEV_TRACE_WGSL=$D/rebraid.wgsl run rebraid-k$k $B bench $A; done
KSRT_DEV_REBRAID=4 KSRT_DEV_TRACE_WGSL=$D/rebraid.wgsl run rebraid-dragon-k4 $B bench --scenes $S --scene dragon --iterations 5 --ray-order tiles
