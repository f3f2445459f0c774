#!/usr/bin/env bash
# Session 25, call 2: the range pass's variants, all with the ingestion fused into the refit:
# seq (session 24's one invocation a node walking the levels), l1 (one invocation a child, all
# levels), l2 (2 lanes a child, 16 levels each), new (f9ef781: 8 lanes, 4 levels each); dragon
# with --busy-gpu-ms 5. Then the failing ray_tracing test with its whole output.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
export KSRT_SCENES=$S
CI=true timeout 60 .gpu/bin/t_rt update_refits > $OUT/t_rt-update-refits-full.txt 2>&1; echo "== t_rt update_refits rc=$?"
grep -E "disagree|ray [0-9]|panicked|hits" $OUT/t_rt-update-refits-full.txt | head -30 | cut -c1-400
for v in seq l1 l2 new seq l1; do
  t0=$(date +%s)
  timeout 150 .gpu/bin/ksrt-$v bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 > $OUT/dragon-$v-$t0.txt 2>&1; echo "== dragon $v rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "BLAS refit|profile    blas refit|oracle" $OUT/dragon-$v-$t0.txt | cut -c1-260
done
