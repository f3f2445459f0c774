#!/usr/bin/env bash
# Session 20: what a better tree buys the BVH2 traversal on the H100 (dev hook swaps the BLAS).
set -u
B=.gpu/bin/ksrt
S=.gpu/data/scenes
echo "=== base (instanced apartment) ==="
$B bench --scenes $S --scene dragon --scene apartment --iterations 5 --json $OUT/base.json > $OUT/base.txt 2>&1; echo rc=$?
grep -E "^[a-z]|peer workload|Mrays|work |SAH" $OUT/base.txt
echo "=== flatten, our GPU tree, tree work ==="
$B bench --scenes $S --scene dragon --scene apartment --iterations 5 --flatten --tree-work --json $OUT/flat-gpu.json > $OUT/flat-gpu.txt 2>&1; echo rc=$?
grep -E "^[a-z]|peer workload|Mrays|work |SAH|tree|obvhs|binned" $OUT/flat-gpu.txt
for t in binned medium very_slow; do
  echo "=== flatten, tree $t ==="
  KSRT_DEV_TREE=$t $B bench --scenes $S --scene dragon --scene apartment --iterations 5 --flatten --json $OUT/flat-$t.json > $OUT/flat-$t.txt 2>&1; echo rc=$?
  grep -E "^[a-z]|DEV|peer workload|Mrays|work |oracle" $OUT/flat-$t.txt
done
