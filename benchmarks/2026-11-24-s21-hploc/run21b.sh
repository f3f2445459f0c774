#!/usr/bin/env bash
# Session 21, call 2: hploc climb variants (shader swapped at run time by the uncommitted
# KSRT_DEV_HPLOC_WGSL hook): search radius 32 (built in, = whole slice), 16, 8, 4; slices of 16
# keeping 8 clusters (k8).
set -u
B=.gpu/bin/ksrt
S=.gpu/data/scenes
for v in r32 r16 r8 r4 k8 r32; do
  if [ $v = r32 ]; then unset KSRT_DEV_HPLOC_WGSL; else export KSRT_DEV_HPLOC_WGSL=.gpu/v/hploc_$v.wgsl; fi
  echo "=== $v ==="
  timeout 90 $B bench --scenes $S --scene dragon --scene apartment --iterations 5 > $OUT/$v.txt 2>&1; echo rc=$?
  grep -E "^[a-z]|DEV|peer workload|SAH|BLAS build|hploc|oracle" $OUT/$v.txt | cut -c1-160
done
