#!/bin/bash
# Session 28 call 11: fab904f (ksrt: rt_edges shared, no behaviour change) against c9b4451
# (ksrt-c9b), rays and trace tasks of both scenes, two rounds alternating; fab904f's library and
# ray_tracing tests in both CI configurations.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz 2>/dev/null; chmod +x .gpu/bin/*
S=.gpu/data/scenes
run() { local name=$1; shift; local t0=$(date +%s); timeout 150 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "peer workload|oracle|together" $OUT/$name.txt | cut -c1-110; }
A="--scenes $S --iterations 5 --ray-order tiles --busy-gpu-ms 5 --sections rays,tasks --scene dragon --scene apartment"
for round in 1 2; do
  run new-$round .gpu/bin/ksrt bench $A
  run old-$round .gpu/bin/ksrt-c9b bench $A
done
export CI=true
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  timeout 200 .gpu/bin/t_lib --include-ignored > $OUT/tlib-$cfg.txt 2>&1; echo "== tlib $cfg rc=$?"; tail -2 $OUT/tlib-$cfg.txt
  timeout 200 .gpu/bin/t_rt > $OUT/trt-$cfg.txt 2>&1; echo "== trt $cfg rc=$?"; tail -2 $OUT/trt-$cfg.txt
done
