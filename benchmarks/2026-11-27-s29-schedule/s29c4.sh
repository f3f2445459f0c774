#!/bin/bash
# Session 29 call 4: dynamic ray fetch in the ray batch pass (wgsl/f*.wgsl from fetch/gen.py:
# a subgroup refills its finished invocations from a shared counter once NUM/DEN of them are
# idle) against HEAD's pass (d0). One binary (064bed9 + dev-fetch-hook: the io layout's counter
# binding and KSRT_DEV_TRACE_WGSL), rays of both scenes, two rounds (the second reversed).
cd "$(dirname "$0")/../.."
chmod +x .gpu/bin/*
S=.gpu/data/scenes
W=benchmarks/2026-11-27-s29-schedule/wgsl
run() { local name=$1; shift; local t0=$(date +%s); timeout 90 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle" $OUT/$name.txt | cut -c1-110; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays"
V="d0 f12 f14 f34 f18 f11"
R=$(echo $V | tr ' ' '\n' | tac | tr '\n' ' ')
for v in $V; do KSRT_DEV_TRACE_WGSL=$W/$v.wgsl run $v-1 .gpu/bin/ksrt bench $A --scene dragon --scene apartment; done
for v in $R; do KSRT_DEV_TRACE_WGSL=$W/$v.wgsl run $v-2 .gpu/bin/ksrt bench $A --scene dragon --scene apartment; done
for v in d0 f12; do .gpu/bin/shader-stats --entry main --unchecked $W/$v.wgsl 2>&1 | grep -E "Register Count|Binary Size|rror" | sed "s/^/[$v] /"; done
