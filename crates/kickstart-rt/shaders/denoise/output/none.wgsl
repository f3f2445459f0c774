// A denoise pass that writes no output texture (the temporal pass and every à-trous iteration
// but the last; see denoise/common.wgsl).

const DN_LAST: bool = false;

fn dn_write_output(s: u32, texel: vec2<u32>, v: vec4<f32>) {}
