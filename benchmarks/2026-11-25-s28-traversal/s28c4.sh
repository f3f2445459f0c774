#!/bin/bash
# Session 28 call 4: the TLAS over refs clustered (hploc climb) against the LBVH, one binary
# (37d2799 + clustered TLAS, threshold from KSRT_DEV_TLAS_CLUSTER_MAX), apartment rays, tasks
# and builds, two rounds alternating; then the TLAS table (1k / 10k / 100k instances) with
# clustering off, at <= 1024 refs (the default), and always.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
B=.gpu/bin/ksrt-tlas
run() { local name=$1; shift; local t0=$(date +%s); timeout 150 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle|^    (specular|diffuse|ao|shadow|multi_shadow) +(1|4|32)? ?(lights)?  [0-9]|together|instances  build|TLAS build|^    profile    tlas build" $OUT/$name.txt | cut -c1-130; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays,tasks,builds --scene apartment"
for round in 1 2; do
  KSRT_DEV_TLAS_CLUSTER_MAX=1024 run clustered-$round $B bench $A
  KSRT_DEV_TLAS_CLUSTER_MAX=0 run lbvh-$round $B bench $A
done
T="--scenes $S --iterations 5 --busy-gpu-ms 5 --sections tlas"
for m in 0 1024 1000000; do KSRT_DEV_TLAS_CLUSTER_MAX=$m run tlas-$m $B bench $T; done
