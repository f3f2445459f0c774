// kickstart-rt denoisers, last pass: writes one filtered signal to the task's output texture
// (its storage format replaces OUTPUT_FORMAT). Radiance: rgb and the filtered hit distance in
// alpha. Occlusion, shadow and multi-shadow: the denoised value (occlusion: normalised hit
// distance, 1 = open; shadows: visibility, 1 = lit) in every channel.
//
// Included after denoise_common.wgsl.

struct OutputParams {
    signal: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> dp: DenoiseParams;
@group(0) @binding(1) var<uniform> op: OutputParams;
@group(0) @binding(2) var<storage, read> src: array<vec4<u32>>;
@group(0) @binding(3) var dn_output: texture_storage_2d<OUTPUT_FORMAT, write>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= dp.viewport.z || gid.y >= dp.viewport.w {
        return;
    }
    let i = gid.y * dp.viewport.z + gid.x;
    let v = dn_value(src[i]);
    var out = v;
    if dn_kind(op.signal) != DN_KIND_SPECULAR && dn_kind(op.signal) != DN_KIND_DIFFUSE {
        out = vec4<f32>(v.x);
    }
    textureStore(dn_output, gid.xy + dp.viewport.xy, out);
}
