#!/bin/bash
# Session 26 call 8: ray_tracing tests of the final HEAD (the fast-build size test aiming at well-shaped triangles) in both CI
# device configurations.
cd "$(dirname "$0")/../.."
gunzip .gpu/bin/*.gz; chmod +x .gpu/bin/*
export KSRT_SCENES=.gpu/data/scenes
for cfg in full minimal; do
  if [ $cfg = minimal ]; then export KSRT_TEST_MINIMAL_DEVICE=1; fi
  echo "=== tests ($cfg) ==="
  CI=true timeout 80 .gpu/bin/t_rt 2>&1 | grep -E "test |test result|FAILED|panicked"
done
