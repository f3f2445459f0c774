// The injection's depth input (see cache/inject.wgsl) when the engine gives it in a depth
// format: one value, the NDC depth, in .x.

@group(2) @binding(1) var depth_tex: texture_depth_2d;

fn inject_load_depth(pixel: vec2<i32>) -> vec4<f32> {
    return vec4<f32>(textureLoad(depth_tex, pixel, 0), 0.0, 0.0, 0.0);
}
