#!/bin/bash
# Session 27 call 5: HEAD c18fbac (ksrt, t_lib, t_rt): the full bench (dragon, apartment, tiles,
# busy GPU) and the TLAS table on an idle GPU; the tests in both configurations; diagnostic: the
# dragon's rays with the TLAS level skipped (ksrt-dev2 + notlas.wgsl) against the same binary.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
D=.gpu/data
run() { local name=$1; shift; local t0=$(date +%s); timeout 200 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "BLAS build |fast-build |BLAS refit |SAH|^    (primary|ao|diffuse) .*rays|peer workload|oracle|together|instances  build" $OUT/$name.txt | cut -c1-120; }
run bench .gpu/bin/ksrt bench --scenes $S --scene dragon --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 --json $OUT/bench.json
run tlas-idle .gpu/bin/ksrt bench --scenes $S --iterations 5 --sections tlas
run dragon-dev-head .gpu/bin/ksrt-dev2 bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays
KSRT_DEV_TRACE_WGSL=$D/notlas.wgsl run dragon-dev-notlas .gpu/bin/ksrt-dev2 bench --scenes $S --scene dragon --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays
export KSRT_SCENES=$S
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg)"
  CI=true timeout 150 .gpu/bin/t_lib --include-ignored > $OUT/tlib-$cfg.txt 2>&1; echo "t_lib rc=$?"; grep -E "test result|FAILED|panicked" $OUT/tlib-$cfg.txt | head -5
  CI=true timeout 150 .gpu/bin/t_rt > $OUT/trt-$cfg.txt 2>&1; echo "t_rt rc=$?"; grep -E "test result|FAILED|panicked" $OUT/trt-$cfg.txt | head -5
done
