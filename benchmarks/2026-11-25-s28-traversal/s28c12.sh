#!/bin/bash
# Session 28 call 12: the review tidy 986f09d (MAX_REFS written into the shader from Rust) -- the whole bench on both scenes, the
# idle TLAS table, its library and ray_tracing tests in both CI configurations.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
run() { local name=$1; shift; local t0=$(date +%s); timeout 200 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle|^    (specular|diffuse|ao|shadow|multi_shadow) +(1|4|32)? ?(lights)?  [0-9]|together|instances  build|^  (BLAS|fast|SAH)" $OUT/$name.txt | cut -c1-130; }
run bench .gpu/bin/ksrt bench --scenes $S --scene dragon --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 --json $OUT/bench.json
run tlas-idle .gpu/bin/ksrt bench --scenes $S --iterations 5 --sections tlas
export CI=true
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  timeout 200 .gpu/bin/t_lib --include-ignored > $OUT/tlib-$cfg.txt 2>&1; echo "== tlib $cfg rc=$?"; tail -2 $OUT/tlib-$cfg.txt
  timeout 200 .gpu/bin/t_rt > $OUT/trt-$cfg.txt 2>&1; echo "== trt $cfg rc=$?"; tail -2 $OUT/trt-$cfg.txt
done
