#!/bin/bash
# Session 29 call 7: HEAD (5e0c950; traversal unchanged since 986f09d) -- the whole bench on both
# scenes, then the ray batches beside the driver's own ray tracing (VK_KHR_ray_tracing_pipeline,
# which on the H100 runs on the SMs: no RT cores), same rays, rows order as the peer needs.
cd "$(dirname "$0")/../.."
chmod +x .gpu/bin/*
S=.gpu/data/scenes
run() { local name=$1; shift; local t0=$(date +%s); timeout 240 "$@" > $OUT/$name.txt 2>&1; echo "== $name rc=$? $(( $(date +%s) - t0 ))s"; grep -E "^    (primary|ao|diffuse) .*rays|work|peer workload|oracle|^    (specular|diffuse|ao|shadow|multi_shadow) +(1|4|32)? ?(lights)?  [0-9]|together|instances  build|^  (BLAS|fast|SAH)" $OUT/$name.txt | cut -c1-150; }
run bench .gpu/bin/ksrt bench --scenes $S --scene dragon --scene apartment --iterations 5 --ray-order tiles --busy-gpu-ms 5 --json $OUT/bench.json
run peer .gpu/bin/ksrt bench --scenes $S --scene dragon --scene apartment --iterations 5 --ray-order rows --busy-gpu-ms 5 --sections rays --peer vulkan-rt --json $OUT/peer.json
sed -n '/driver\|peer\|ratio/p' $OUT/peer.txt | head -40
