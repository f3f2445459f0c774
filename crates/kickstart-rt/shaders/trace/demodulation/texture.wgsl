// The radiance passes' demodulation store when the task has a demodulation output (see
// trace/radiance.wgsl): output1 at binding 5 of the task's group, in the format OUTPUT1_FORMAT.

#param OUTPUT1_FORMAT

@group(2) @binding(5) var out1: texture_storage_2d<{{OUTPUT1_FORMAT}}, write>;

fn tr_store_demodulation(texel: vec2<u32>, v: vec4<f32>) {
    textureStore(out1, texel, v);
}
