#!/bin/bash
# Session 26 call 2: the climb's neighbour search with each pair's area computed once (half),
# against pool (call 1); diagnostics r8 (half at radius 8) and nosearch (half pairing i, i^1).
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
S=.gpu/data/scenes
for round in 1 2; do
  for b in pool half r8 nosearch; do
    if [ $round = 2 ] && { [ $b = r8 ] || [ $b = nosearch ]; }; then continue; fi
    .gpu/bin/ksrt_$b bench --scenes $S --scene dragon --iterations 5 --size 640x360 --busy-gpu-ms 5 > $OUT/dragon-$b-$round.txt 2>&1
    grep -E "BLAS build|SAH" $OUT/dragon-$b-$round.txt | head -3 | sed "s/^/[$b $round] /"
  done
done
.gpu/bin/ksrt_half bench --scenes $S --scene apartment --iterations 5 --size 640x360 --busy-gpu-ms 5 > $OUT/apt-half.txt 2>&1
grep -E "BLAS build|SAH" $OUT/apt-half.txt | sed "s/^/[half apt] /"
