#!/usr/bin/env bash
# Session 22, call 8: A/B on one machine: ksrt-per = 0afe3a8 (each instance opened on its own into <= 8 refs);
# ksrt-area = working tree after 0b03290 (8 refs a slot on average shared by world-box area, <= 1024/slots each).
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
for round in 1 2; do
for b in per area; do
  t0=$(date +%s)
  timeout 100 .gpu/bin/ksrt-$b bench --scenes $S --scene apartment --scene dragon --iterations 5 --ray-order tiles > $OUT/$b-r$round.txt 2>&1
  echo "== $b round $round rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle|together|instances  build" $OUT/$b-r$round.txt | cut -c1-120
done
done
