// `ksrt quality`'s reference: adds one sample (a trace task's raw output) to a running sum.
// Mode 0: radiance, rgb summed. Mode 1: a shadow trace's hit distance, summed as visibility
// (1 where the light is visible, i.e. the distance is negative) in every channel. Mode 2: one
// value in R (AO), summed in every channel.

struct Params {
    width: u32,
    height: u32,
    mode: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var sample_tex: texture_2d<f32>;
@group(0) @binding(2) var<storage, read_write> sum: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn accumulate(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x >= params.width || id.y >= params.height {
        return;
    }
    let t = textureLoad(sample_tex, id.xy, 0);
    var v: vec4<f32>;
    if params.mode == 1u {
        let lit = select(0.0, 1.0, t.x < 0.0);
        v = vec4<f32>(lit, lit, lit, 1.0);
    } else if params.mode == 2u {
        let x = select(0.0, t.x, abs(t.x) < 1e30);
        v = vec4<f32>(x, x, x, 1.0);
    } else {
        // A NaN or infinite sample would poison thousands of others: dropped (counted as 0).
        let finite = all(abs(t.xyz) < vec3<f32>(1e30));
        v = select(vec4<f32>(0.0, 0.0, 0.0, 1.0), vec4<f32>(t.xyz, 1.0), finite);
    }
    let i = id.y * params.width + id.x;
    sum[i] = sum[i] + v;
}
