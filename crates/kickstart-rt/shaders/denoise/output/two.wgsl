// The last à-trous iteration of a two-signal set: writes one output texture per signal (group 2,
// in the formats DN_OUTPUT0_FORMAT and DN_OUTPUT1_FORMAT; see denoise/common.wgsl).

#param DN_OUTPUT0_FORMAT
#param DN_OUTPUT1_FORMAT

const DN_LAST: bool = true;

@group(2) @binding(0) var dn_out0: texture_storage_2d<{{DN_OUTPUT0_FORMAT}}, write>;
@group(2) @binding(1) var dn_out1: texture_storage_2d<{{DN_OUTPUT1_FORMAT}}, write>;

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
    if s == 1u {
        textureStore(dn_out1, texel, out);
    }
}
