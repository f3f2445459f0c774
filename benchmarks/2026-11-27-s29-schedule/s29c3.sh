#!/bin/bash
# Session 29 call 3 (diagnostic): the secondary batches reordered on the CPU before tracing
# (untimed; uncommitted hook dev-sort-rays.diff, KSRT_DEV_SORT_RAYS=mode): how much faster the
# same traversal traces AO and diffuse rays in a coherent order. One binary (064bed9 + hook).
cd "$(dirname "$0")/../.."
chmod +x .gpu/bin/*
S=.gpu/data/scenes
run() { local name=$1; shift; local t0=$(date +%s); timeout 90 "$@" > /tmp/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload" /tmp/$name.txt | cut -c1-110; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays"
V="none m5 octo dirm b8 b12"
R=$(echo $V | tr ' ' '\n' | tac | tr '\n' ' ')
for v in $V; do KSRT_DEV_SORT_RAYS=$v run $v-1 .gpu/bin/ksrt bench $A --scene dragon --scene apartment; done
for v in $R; do KSRT_DEV_SORT_RAYS=$v run $v-2 .gpu/bin/ksrt bench $A --scene dragon --scene apartment; done
