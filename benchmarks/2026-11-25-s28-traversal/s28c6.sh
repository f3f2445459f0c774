#!/bin/bash
# Session 28 call 6: a TLAS ref budget of 2048 (up to 32 refs an instance, clustered up to 2048
# refs) against 1024 / 16 (bb5150d), one binary (bb5150d + KSRT_DEV_REF_BUDGET / _MAX_REFS),
# apartment rays and tasks, two rounds alternating; the TLAS table for both.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt-budget
run() { local name=$1; shift; local t0=$(date +%s); timeout 150 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle|^    (specular|diffuse|ao|shadow|multi_shadow) +(1|4|32)? ?(lights)?  [0-9]|together|instances  build" $OUT/$name.txt | cut -c1-130; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays,tasks --scene apartment"
for round in 1 2; do
  KSRT_DEV_REF_BUDGET=2048 KSRT_DEV_MAX_REFS=32 run b2048-$round $B bench $A
  KSRT_DEV_REF_BUDGET=1024 KSRT_DEV_MAX_REFS=16 run b1024-$round $B bench $A
done
T="--scenes $S --scene dragon --iterations 5 --busy-gpu-ms 5 --sections tlas"
KSRT_DEV_REF_BUDGET=2048 KSRT_DEV_MAX_REFS=32 run tlas-b2048 $B bench $T
KSRT_DEV_REF_BUDGET=1024 KSRT_DEV_MAX_REFS=16 run tlas-b1024 $B bench $T
