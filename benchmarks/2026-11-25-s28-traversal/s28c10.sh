#!/bin/bash
# Session 28 call 10 (diagnostic): refs shared by world-box area (ksrt-area: fd37358 +
# dev-area-share hack; KSRT_DEV_AREA=1: a stride of 8192 / slots refs, each instance opened into
# its area's share of 2048, at most the stride; without it: the share capped at 2048 / slots)
# against c9b4451 (ksrt), apartment rays and tasks, two rounds alternating.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
run() { local name=$1; shift; local t0=$(date +%s); timeout 150 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle|together|multi_shadow 32" $OUT/$name.txt | cut -c1-110; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays,tasks --scene apartment"
for round in 1 2; do
  run head-$round .gpu/bin/ksrt bench $A
  KSRT_DEV_AREA=1 run area-$round .gpu/bin/ksrt-area bench $A
  run areacap-$round .gpu/bin/ksrt-area bench $A
done
