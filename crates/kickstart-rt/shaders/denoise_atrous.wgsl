// kickstart-rt denoisers, pass 2 (repeated): one edge-stopping à-trous iteration (3×3 taps
// `step` pixels apart) over the temporally accumulated signal(s).
//
// Tap weights: B-spline kernel × normal (exponent grows as roughness falls) × plane distance
// (depth edges) × luminance against the estimated noise (SVGF: |Δl| / (σ_l·√variance)) × a
// Gaussian of the pixel distance whose radius follows the signal: specular roughness, hit
// distance (contact detail keeps a small radius), the shadow's occluder distance (penumbra
// width) and the history length (converged pixels need less blur).
//
// The first iteration estimates the noise variance of the accumulated value (see
// dn_variance_estimate).
// Later iterations propagate it (Σ w² var / (Σ w)²).
//
// Included after denoise_common.wgsl.

struct AtrousParams {
    step: u32,
    first: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> dp: DenoiseParams;
@group(0) @binding(1) var<uniform> ap: AtrousParams;

@group(1) @binding(0) var<storage, read> guide: array<vec4<u32>>;
@group(1) @binding(1) var<storage, read> src0: array<vec4<u32>>;
@group(1) @binding(2) var<storage, read> src1: array<vec4<u32>>;
@group(1) @binding(3) var<storage, read_write> dst0: array<vec4<u32>>;
@group(1) @binding(4) var<storage, read_write> dst1: array<vec4<u32>>;

// Luminance edge-stopping strength, in standard deviations of the noise.
const SIGMA_L: f32 = 4.0;

fn dn_src(s: u32, i: u32) -> vec4<u32> {
    if s == 0u {
        return src0[i];
    }
    return src1[i];
}

fn dn_dst(s: u32, i: u32, v: vec4<u32>) {
    if s == 0u {
        dst0[i] = v;
    } else {
        dst1[i] = v;
    }
}

// Noise variance of the accumulated value at pixel `p` (first iteration): the temporal estimate
// (second moment − mean², / history length), averaged over the 3×3 neighbours of the same
// surface since one pixel's few samples make a noisy estimate, blended from the 3×3 spatial
// variance of the values over the first 8 frames (the temporal estimate needs a few frames).
fn dn_variance_estimate(s: u32, p: vec2<i32>, centre: DnGuide, dist: f32) -> f32 {
    var m1 = 0.0;
    var m2 = 0.0;
    var temporal = 0.0;
    var len = 0.0;
    var cnt = 0.0;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let q = p + vec2<i32>(dx, dy);
            if q.x < 0 || q.y < 0 || q.x >= i32(dp.viewport.z) || q.y >= i32(dp.viewport.w) {
                continue;
            }
            let j = u32(q.y) * dp.viewport.z + u32(q.x);
            let g = dn_unpack_guide(guide[j]);
            if !g.valid || abs(dot(centre.normal, g.position - centre.position)) > 0.02 * dist {
                continue;
            }
            let h = dn_src(s, j);
            let l = dn_luminance(dn_value(h).xyz);
            let n = max(bitcast<f32>(h.w), 1.0);
            m1 += l;
            m2 += l * l;
            temporal += max(bitcast<f32>(h.z) - l * l, 0.0) / n;
            len += n;
            cnt += 1.0;
        }
    }
    let k = max(cnt, 1.0);
    m1 /= k;
    let spatial = max(m2 / k - m1 * m1, 0.0);
    let t = clamp((len / k - 1.0) / 7.0, 0.0, 1.0);
    return mix(spatial, temporal / k, t);
}

// Radius (pixels) of the distance falloff for signal `s` at a pixel.
fn dn_radius(s: u32, value: vec4<f32>, len: f32, roughness: f32, dist: f32) -> f32 {
    // Converged pixels need less blur; not shadows, whose penumbrae are smooth by nature.
    let converged = clamp(len / dp.max_history, 0.0, 1.0);
    var r = dp.base_radius;
    if dn_kind(s) < DN_KIND_SHADOW {
        r *= mix(1.0, 0.35, converged);
    }
    let hit = clamp(value.w / max(0.2 * dist, 1e-6), 0.2, 1.0);
    switch dn_kind(s) {
        case DN_KIND_SPECULAR: {
            r *= clamp(roughness * 2.0, 0.05, 1.0) * hit;
        }
        case DN_KIND_DIFFUSE: {
            r *= hit;
        }
        case DN_KIND_OCCLUSION: {
            r *= 0.3 + 0.7 * clamp(value.w, 0.0, 1.0);
        }
        default: {
            r *= clamp(0.3 + value.w / max(0.05 * dist, 1e-6), 0.3, 1.0);
        }
    }
    return max(r, 0.5);
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= dp.viewport.z || gid.y >= dp.viewport.w {
        return;
    }
    let p = vec2<i32>(gid.xy);
    let i = gid.y * dp.viewport.z + gid.x;
    let gp = dn_unpack_guide(guide[i]);
    if !gp.valid {
        for (var s = 0u; s < dp.signal_count; s++) {
            let h = dn_src(s, i);
            dn_dst(s, i, vec4<u32>(h.xy, bitcast<u32>(0.0), h.w));
        }
        return;
    }
    let dist = max(dn_view_distance(gp.position), 1e-6);
    let step = i32(ap.step);

    var centre: array<vec4<f32>, 2>;
    var var_c = array<f32, 2>(0.0, 0.0);
    var lum_c = array<f32, 2>(0.0, 0.0);
    var radius = array<f32, 2>(1.0, 1.0);
    var len_c = array<f32, 2>(0.0, 0.0);
    var n_exp = array<f32, 2>(64.0, 64.0);
    for (var s = 0u; s < dp.signal_count; s++) {
        let h = dn_src(s, i);
        centre[s] = dn_value(h);
        len_c[s] = bitcast<f32>(h.w);
        if ap.first != 0u {
            var_c[s] = dn_variance_estimate(s, p, gp, dist);
        } else {
            var_c[s] = bitcast<f32>(h.z);
        }
        lum_c[s] = dn_luminance(centre[s].xyz);
        radius[s] = dn_radius(s, centre[s], len_c[s], gp.roughness, dist);
        if dn_kind(s) == DN_KIND_SPECULAR {
            n_exp[s] = mix(256.0, 32.0, gp.roughness);
        }
    }

    var sum: array<vec4<f32>, 2>;
    var wsum = array<f32, 2>(0.0, 0.0);
    var vsum = array<f32, 2>(0.0, 0.0);
    let kernel = array<f32, 3>(0.25, 0.5, 0.25);
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let q = p + vec2<i32>(dx, dy) * step;
            if q.x < 0 || q.y < 0 || q.x >= i32(dp.viewport.z) || q.y >= i32(dp.viewport.w) {
                continue;
            }
            let j = u32(q.y) * dp.viewport.z + u32(q.x);
            let gq = dn_unpack_guide(guide[j]);
            if !gq.valid {
                continue;
            }
            let d_px = length(vec2<f32>(q - p));
            let plane = abs(dot(gp.normal, gq.position - gp.position));
            let w_z = exp(-plane / (dist * 0.004 * (1.0 + d_px)));
            let cos_n = max(dot(gp.normal, gq.normal), 0.0);
            let w_geo = kernel[dx + 1] * kernel[dy + 1] * w_z;
            for (var s = 0u; s < dp.signal_count; s++) {
                let h = dn_src(s, j);
                let v = dn_value(h);
                var var_q = var_c[s];
                if ap.first == 0u {
                    var_q = bitcast<f32>(h.z);
                }
                let dl = abs(dn_luminance(v.xyz) - lum_c[s]);
                let w_l = exp(-dl / (SIGMA_L * sqrt(var_c[s]) + 1e-4 + 0.01 * abs(lum_c[s])));
                let w_n = pow(cos_n, n_exp[s]);
                let w_r = exp(-d_px * d_px / (2.0 * radius[s] * radius[s]));
                var w = w_geo * w_n * w_l * w_r;
                if j == i {
                    w = w_geo;
                }
                sum[s] += w * v;
                wsum[s] += w;
                vsum[s] += w * w * var_q;
            }
        }
    }
    for (var s = 0u; s < dp.signal_count; s++) {
        let ws = max(wsum[s], 1e-8);
        dn_dst(s, i, dn_pack_signal(sum[s] / ws, vsum[s] / (ws * ws), len_c[s]));
    }
}
