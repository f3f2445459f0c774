#!/bin/bash
# Session 29 call 6: 32-byte quantised BVH2 nodes. The BLAS pool is rewritten in place before the
# first batch (quant/dev_quantize.wgsl through KSRT_DEV_QUANT; uncommitted dev-quant-hook.diff)
# and traced by wgsl/q32.wgsl (two vec4 loads and a decode per BLAS node step), against HEAD's
# pass on the unquantised pool (d0). One binary (6e84ad0 + hook), three rounds.
cd "$(dirname "$0")/../.."
chmod +x .gpu/bin/*
S=.gpu/data/scenes
W=benchmarks/2026-11-27-s29-schedule/wgsl
run() { local name=$1; shift; local t0=$(date +%s); timeout 90 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle" $OUT/$name.txt | cut -c1-110; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays --scene dragon --scene apartment"
for round in 1 2 3; do
  KSRT_DEV_TRACE_WGSL=$W/d0.wgsl run d0-$round .gpu/bin/ksrt bench $A
  KSRT_DEV_QUANT=benchmarks/2026-11-27-s29-schedule/quant/dev_quantize.wgsl KSRT_DEV_TRACE_WGSL=$W/q32.wgsl run q32-$round .gpu/bin/ksrt bench $A
done
