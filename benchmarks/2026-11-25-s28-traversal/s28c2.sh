#!/bin/bash
# Session 28 call 2: register-saving variants on mm (own SPIR-V path, no stack fill) against HEAD, one
# binary (4744b63 + dev-trace-hook.diff), rays only; registers and binary size of each.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt-dev
D=.gpu/data
run() { local name=$1; shift; local t0=$(date +%s); timeout 120 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle" $OUT/$name.txt | cut -c1-110; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays"
i=0; for v in mm mmsp mmuv mmspuv d0 mm; do i=$((i+1))
  KSRT_DEV_TRACE_WGSL=$D/$v.wgsl run $i-$v $B bench $A --scene dragon --scene apartment
done
for v in mm mmsp mmuv mmspuv; do .gpu/bin/shader-stats --entry main --unchecked $D/$v.wgsl 2>&1 | grep -E "Register Count|Local Memory|Binary Size" | sed "s/^/[$v] /"; done
