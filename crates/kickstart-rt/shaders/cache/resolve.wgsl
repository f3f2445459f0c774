// Blends each injection slot's exact average into its surfel (src/cache/inject.rs): the first
// injection replaces the initial colour, later ones form a running average over about
// `average_window` tasks: value += (average − value) / min(n + 1, window), n = tasks merged.

struct ResolveParams {
    slots: u32,
    map_words: u32,
    window: f32,
    pad: u32,
}

@group(0) @binding(0) var<storage, read_write> surfels: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read_write> accum: array<u32>;
@group(0) @binding(2) var<uniform> params: ResolveParams;

@compute @workgroup_size(64)
fn resolve(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = (wid.y * nwg.x + wid.x) * 64u + lid;
    if i >= params.slots {
        return;
    }
    let w = params.map_words + i * 8u;
    let count = accum[w + 6u];
    if count == 0u {
        return;
    }
    let s = accum[w + 7u];
    let n = f32(count);
    let sum = vec3<f32>(
        f32(accum[w + 1u]) * 65536.0 + f32(accum[w]) / 65536.0,
        f32(accum[w + 3u]) * 65536.0 + f32(accum[w + 2u]) / 65536.0,
        f32(accum[w + 5u]) * 65536.0 + f32(accum[w + 4u]) / 65536.0,
    );
    let average = sum / n;
    if s < arrayLength(&surfels) {
        let old = surfels[s];
        var value = average;
        if old.w >= 1.0 {
            let weight = 1.0 / min(old.w + 1.0, max(params.window, 1.0));
            value = old.xyz + (average - old.xyz) * weight;
        }
        surfels[s] = vec4<f32>(value, min(old.w + 1.0, 16777216.0));
        accum[s] = 0u;
    }
    for (var k = 0u; k < 8u; k++) {
        accum[w + k] = 0u;
    }
}
