// The radiance passes' second-output store when the task has one (see trace/radiance.wgsl): the
// specular's demodulation factor or the diffuse's ambient occlusion, output1 at binding 5 of the
// task's group, in the format OUTPUT1_FORMAT.

#param OUTPUT1_FORMAT

@group(2) @binding(5) var out1: texture_storage_2d<{{OUTPUT1_FORMAT}}, write>;

fn tr_store_second(texel: vec2<u32>, v: vec4<f32>) {
    textureStore(out1, texel, v);
}
