#!/bin/bash
# Session 27 call 9: HEAD 1c80927 (review tidy): rays, trace tasks and the tests
# in both configurations.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
run() { local name=$1; shift; local t0=$(date +%s); timeout 150 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle|together|multi_shadow 32" $OUT/$name.txt | cut -c1-110; }
run head .gpu/bin/ksrt bench --scenes $S --scene dragon --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays,tasks
export KSRT_SCENES=$S
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg)"
  CI=true timeout 150 .gpu/bin/t_lib --include-ignored > $OUT/tlib-$cfg.txt 2>&1; echo "t_lib rc=$?"; grep -E "test result|FAILED|panicked" $OUT/tlib-$cfg.txt | head -5
  CI=true timeout 150 .gpu/bin/t_rt > $OUT/trt-$cfg.txt 2>&1; echo "t_rt rc=$?"; grep -E "test result|FAILED|panicked" $OUT/trt-$cfg.txt | head -5
done
