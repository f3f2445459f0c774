#!/bin/bash
# Session 29 call 1: triangle scheduling variants of the traversal loop (wgsl/*.wgsl, through the
# uncommitted KSRT_DEV_TRACE_WGSL hook), one binary (064bed9 + the previous try's uncommitted
# loop), rays of both scenes, two rounds (the second in reverse order); registers of each.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
W=benchmarks/2026-11-27-s29-schedule/wgsl
run() { local name=$1; shift; local t0=$(date +%s); timeout 90 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle" $OUT/$name.txt | cut -c1-110; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays"
V="d0 now sg12 sg14 sg34 sg11 spec11 spec12"
R=$(echo $V | tr ' ' '\n' | tac | tr '\n' ' ')
for v in $V; do KSRT_DEV_TRACE_WGSL=$W/$v.wgsl run $v-1 .gpu/bin/ksrt bench $A --scene dragon --scene apartment; done
for v in $R; do KSRT_DEV_TRACE_WGSL=$W/$v.wgsl run $v-2 .gpu/bin/ksrt bench $A --scene dragon --scene apartment; done
for v in $V; do .gpu/bin/shader-stats --entry main --unchecked $W/$v.wgsl 2>&1 | grep -E "Register Count|Binary Size|rror" | sed "s/^/[$v] /"; done
