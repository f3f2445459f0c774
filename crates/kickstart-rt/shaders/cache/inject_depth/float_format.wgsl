// The injection's depth input (see cache/inject.wgsl) when the engine gives it in a float
// format: NDC depth in .x, or world positions in .xyz (RgbWorldSpace).

@group(2) @binding(1) var depth_tex: texture_2d<f32>;

fn inject_load_depth(pixel: vec2<i32>) -> vec4<f32> {
    return textureLoad(depth_tex, pixel, 0);
}
