#!/bin/bash
# Session 29 call 2 (diagnostic): what the BVH2 loop's time is sensitive to. HEAD's loop (d0)
# against d0 + 2 or 4 extra vec4 loads of the same node per BLAS node step (ld2, ld4), + 32
# dependent FMAs per BLAS node step (alu), + one extra stack load per pop (stk); every extra
# is made opaque by params.pad (0 at run time) and leaves the results unchanged. One binary
# (064bed9), rays of both scenes, two rounds (the second reversed).
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
W=benchmarks/2026-11-27-s29-schedule/wgsl
run() { local name=$1; shift; local t0=$(date +%s); timeout 90 "$@" > /tmp/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle" /tmp/$name.txt | cut -c1-110; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays"
V="d0 ld2 ld4 alu stk"
R=$(echo $V | tr ' ' '\n' | tac | tr '\n' ' ')
for v in $V; do KSRT_DEV_TRACE_WGSL=$W/$v.wgsl run $v-1 .gpu/bin/ksrt bench $A --scene dragon --scene apartment; done
for v in $R; do KSRT_DEV_TRACE_WGSL=$W/$v.wgsl run $v-2 .gpu/bin/ksrt bench $A --scene dragon --scene apartment; done
for v in $V; do .gpu/bin/shader-stats --entry main --unchecked $W/$v.wgsl 2>&1 | grep -E "Register Count|Binary Size|rror" | sed "s/^/[$v] /"; done
