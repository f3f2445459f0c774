// The last à-trous iteration of a one-signal set: writes the output texture (group 2, in the
// format DN_OUTPUT0_FORMAT; see denoise/common.wgsl).

#param DN_OUTPUT0_FORMAT

const DN_LAST: bool = true;

@group(2) @binding(0) var dn_out0: texture_storage_2d<{{DN_OUTPUT0_FORMAT}}, write>;

fn dn_write_output(s: u32, texel: vec2<u32>, v: vec4<f32>) {
    // Radiance: rgb and the filtered hit distance; occlusion and shadows: the value in every
    // channel.
    var out = v;
    if dn_kind(s) != DN_KIND_SPECULAR && dn_kind(s) != DN_KIND_DIFFUSE {
        out = vec4<f32>(v.x);
    }
    if s == 0u {
        textureStore(dn_out0, texel, out);
    }
}
