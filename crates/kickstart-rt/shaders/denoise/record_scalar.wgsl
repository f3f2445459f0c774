// kickstart-rt denoisers: the 8-byte signal record of scalar signals (occlusion, shadow,
// multi-shadow), included by every pass of those signals (see denoise/common.wgsl).
// x = value and hit distance (2×f16), y = history: second moment of the value / filter: variance
// of its noise, and the history length (2×f16). The value lies in [0, 1], so its moments and
// variance fit f16; the history length is at most 32 frames.

alias DnRecord = vec2<u32>;

// Value (repeated in rgb, so that luminance is the value) and hit distance of a record.
fn dn_value(s: DnRecord) -> vec4<f32> {
    let a = unpack2x16float(s.x);
    return vec4<f32>(a.x, a.x, a.x, a.y);
}

// Second moment (history) or noise variance (filter).
fn dn_rec_z(s: DnRecord) -> f32 {
    return unpack2x16float(s.y).x;
}

// History length, frames.
fn dn_rec_len(s: DnRecord) -> f32 {
    return unpack2x16float(s.y).y;
}

fn dn_pack_signal(value: vec4<f32>, z: f32, len: f32) -> DnRecord {
    let v = dn_sanitize(value);
    let zl = dn_sanitize(vec4<f32>(z, len, 0.0, 0.0));
    return vec2<u32>(pack2x16float(v.xw), pack2x16float(zl.xy));
}
