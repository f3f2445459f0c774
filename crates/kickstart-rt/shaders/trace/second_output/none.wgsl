// The radiance passes' second-output store when the task has none (see trace/radiance.wgsl):
// nothing is written.

fn tr_store_second(texel: vec2<u32>, v: vec4<f32>) {}
