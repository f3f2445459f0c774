#!/bin/bash
# Session 28 call 9: the world ray kept in the stack's top entries (h28sp) against HEAD's loop
# (h28), one binary (fd37358 + dev-trace-hook.diff), rays of both scenes, two rounds; and the
# apartment baked into one mesh (--flatten) with HEAD's loop; registers of both.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt-dev
D=.gpu/data
run() { local name=$1; shift; local t0=$(date +%s); timeout 150 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle" $OUT/$name.txt | cut -c1-110; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays"
for round in 1 2; do
  for v in h28 h28sp; do
    KSRT_DEV_TRACE_WGSL=$D/$v.wgsl run $v-$round $B bench $A --scene dragon --scene apartment
  done
done
run flat $B bench $A --scene apartment --flatten
for v in h28 h28sp; do .gpu/bin/shader-stats --entry main --unchecked $D/$v.wgsl 2>&1 | grep -E "Register Count|Binary Size" | sed "s/^/[$v] /"; done
