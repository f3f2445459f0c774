#!/usr/bin/env bash
# Session 22, call 5: A/B on one machine: ksrt-k8 = rebraid branch at <= 8 refs an instance (call 4's binary),
# ksrt-k16 = <= 16 refs an instance and no opening of a lone instance.
set -u
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
for round in 1 2; do
for b in k8 k16; do
  t0=$(date +%s)
  timeout 100 .gpu/bin/ksrt-$b bench --scenes $S --scene dragon --scene apartment --iterations 5 --ray-order tiles > $OUT/$b-r$round.txt 2>&1
  echo "== $b round $round rc=$? $(( $(date +%s) - t0 ))s"
  grep -E "^    (primary|ao|diffuse) .*rays|peer workload|oracle|together" $OUT/$b-r$round.txt | cut -c1-120
done
done
