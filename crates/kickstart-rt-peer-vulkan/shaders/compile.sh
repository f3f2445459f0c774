#!/bin/sh
# Compiles the peer's GLSL ray-tracing shaders to SPIR-V beside them. The .spv files are
# committed (the build and CI need no shader compiler); run this after editing a shader.
# Needs glslangValidator (Debian: apt-get install glslang-tools).
set -eu
cd "$(dirname "$0")"
for s in raygen.rgen closest.rchit miss.rmiss; do
    glslangValidator --target-env vulkan1.2 -o "$s.spv" "$s"
done
