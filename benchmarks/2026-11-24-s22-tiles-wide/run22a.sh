#!/usr/bin/env bash
# Session 22, call 1. ksrt = 79ad3f9 (tiled trace tasks, --ray-order); ksrt-base = de81a47 (before);
# ksrt-var = 79ad3f9 + dev-trace-override.patch (KSRT_DEV_TRACE_WGSL), dmt.wgsl = diagnostic Moller-Trumbore triangle test.
set -u
S=.gpu/data/scenes
B=.gpu/bin
nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm --format=csv > $OUT/gpu.txt 2>&1
run() { local name=$1; shift; local t0=$(date +%s); timeout 150 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; }
run new-tiles $B/ksrt bench --scenes $S --scene dragon --scene apartment --iterations 5 --ray-order tiles --json $OUT/new-tiles.json
run new-rows  $B/ksrt bench --scenes $S --scene dragon --scene apartment --iterations 5 --json $OUT/new-rows.json
run base-rows $B/ksrt-base bench --scenes $S --scene dragon --scene apartment --iterations 5 --json $OUT/base-rows.json
KSRT_DEV_TRACE_WGSL=.gpu/data/dmt.wgsl run var-dmt-tiles $B/ksrt-var bench --scenes $S --scene dragon --scene apartment --iterations 5 --ray-order tiles
for f in new-tiles new-rows base-rows var-dmt-tiles; do echo "== $f"; grep -E "peer workload|^    (primary|ao|diffuse) .*rays|^    (specular|diffuse|ao|shadow) .* ms|together" $OUT/$f.txt | cut -c1-120; done
export KSRT_SCENES=$S
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests trace::tasks ($cfg) ==="
  CI=true timeout 100 $B/t_lib trace::tasks 2>&1 | tail -3
done
