// The radiance passes' demodulation store when the task has no demodulation output (see
// trace/radiance.wgsl): nothing is written.

fn tr_store_demodulation(texel: vec2<u32>, v: vec4<f32>) {}
