#!/usr/bin/env bash
# Session 21, call 7: the refit of a clustered (fast-trace) BLAS. Binary: 6730bfa + the uncommitted
# dev-fast-trace-refit.patch (KSRT_DEV_FAST_TRACE_REFIT registers the bench's scenes with
# PreferFastTrace, so its allow_update geometry is a clustered tree). Off first, then on.
set -u
B=.gpu/bin/ksrt
S=.gpu/data/scenes
for mode in off on off on; do
  if [ $mode = on ]; then export KSRT_DEV_FAST_TRACE_REFIT=1; else unset KSRT_DEV_FAST_TRACE_REFIT; fi
  echo "=== fast-trace refit: $mode ==="
  timeout 90 $B bench --scenes $S --scene dragon --scene apartment --iterations 10 > $OUT/refit-$mode.txt 2>&1; echo rc=$?
  grep -E "^[a-z]|BLAS refit|refit/|SAH|oracle" $OUT/refit-$mode.txt | cut -c1-200
done
