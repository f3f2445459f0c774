// A uniform value made opaque to the driver before a shader branches on it, shared by every
// shader that branches on its task's parameters (trace/common.wgsl, trace/gbuffer.wgsl,
// cache/inject.wgsl).
//
// Mesa's lavapipe 22.x (Debian 12, the CI's Vulkan driver) specialises a shader whose `if`s,
// `switch`es or loop bounds depend on uniform-buffer values alone by compiling a new copy of it
// for that dispatch, at every dispatch, and frees none of them until the pipeline goes: a trace
// task then cost an LLVM compile and about 2 MB for the life of the context (`ksrt quality`'s
// reference samples reached 20 GB). XOR with a zero the driver cannot know (a texture's level
// count is below 2^16) keeps the value the same and the shader unspecialised; on a GPU it is one
// texture query.

// `x` unchanged, for a branch: `t` is any texture the caller binds.
fn uniform_branch(x: u32, t: texture_2d<f32>) -> u32 {
    return x ^ (textureNumLevels(t) >> 16u);
}
