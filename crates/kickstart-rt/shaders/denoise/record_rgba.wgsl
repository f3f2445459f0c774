// kickstart-rt denoisers: the 16-byte signal record of radiance (specular, diffuse), included by
// every pass of those signals (see denoise/common.wgsl). x = rg (2×f16), y = b and the hit
// distance (2×f16), z = history: second moment of luminance (f32; HDR luminance squared does
// not fit f16) / filter: variance of the value's noise (f32), w = history length (f32).

alias DnRecord = vec4<u32>;

// Value (rgb, hit distance) of a record.
fn dn_value(s: DnRecord) -> vec4<f32> {
    return vec4<f32>(unpack2x16float(s.x), unpack2x16float(s.y));
}

// Second moment (history) or noise variance (filter).
fn dn_rec_z(s: DnRecord) -> f32 {
    return bitcast<f32>(s.z);
}

// History length, frames.
fn dn_rec_len(s: DnRecord) -> f32 {
    return bitcast<f32>(s.w);
}

fn dn_pack_signal(value: vec4<f32>, z: f32, len: f32) -> DnRecord {
    let v = dn_sanitize(value);
    return vec4<u32>(pack2x16float(v.xy), pack2x16float(v.zw), bitcast<u32>(z), bitcast<u32>(len));
}
