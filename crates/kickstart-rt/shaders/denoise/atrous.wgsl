// kickstart-rt denoisers, pass 2 (repeated): one edge-stopping à-trous iteration (3×3 taps
// `step` pixels apart) over the temporally accumulated signal(s).
//
// Tap weights: B-spline kernel × normal (exponent grows as roughness falls) × plane distance
// (depth edges) × luminance against the estimated noise of both pixels (SVGF-like:
// |Δl| / (σ_l·√(variance_p + variance_q)), symmetric so that a sparse signal keeps its energy) × a
// Gaussian of the pixel distance whose radius follows the signal: specular roughness, hit
// distance (contact detail keeps a small radius), the shadow's occluder distance (penumbra
// width) and the history length (converged pixels need less blur).
//
// The first iteration estimates the noise variance of the accumulated value (see
// dn_variance_estimate).
// Later iterations propagate it (Σ w² var / (Σ w)²). The last iteration (DN_LAST) writes the
// output textures instead of an intermediate buffer (dn_write_output, defined by the prelude).
//
// Cost: per tap one guide and one record read, one log2 (normal weight) and per signal one exp2:
// the plane, luminance, normal and distance weights are multiplied as one exponential, with
// their per-pixel factors (reciprocal widths, the distance term of the two tap distances)
// computed once per pixel.
//
// Composed with a record module and an output module (see denoise/common.wgsl).

#import denoise/common

struct AtrousParams {
    step: u32,
    first: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> dp: DenoiseParams;
@group(0) @binding(1) var<uniform> ap: AtrousParams;

@group(1) @binding(0) var<storage, read> guide: array<vec2<u32>>;
@group(1) @binding(1) var<storage, read> src0: array<DnRecord>;
@group(1) @binding(2) var<storage, read> src1: array<DnRecord>;
@group(1) @binding(3) var<storage, read_write> dst0: array<DnRecord>;
@group(1) @binding(4) var<storage, read_write> dst1: array<DnRecord>;

// Luminance edge-stopping strength, in standard deviations of the noise.
const SIGMA_L: f32 = 4.0;

fn dn_src(s: u32, i: u32) -> DnRecord {
    if s == 0u {
        return src0[i];
    }
    return src1[i];
}

fn dn_dst(s: u32, i: u32, v: DnRecord) {
    if s == 0u {
        dst0[i] = v;
    } else {
        dst1[i] = v;
    }
}

// Moments of the first iteration's noise estimate (see dn_variance_estimate), summed over the
// 3×3 neighbours of the same surface.
struct DnMoments {
    m1: f32,
    m2: f32,
    temporal: f32,
    len: f32,
    cnt: f32,
}

// Adds the neighbour `q` (guide `g`, record `h`) to the moments of the centre at `pos` (normal
// `n`, camera distance `dist`) when it lies on the centre's surface. Only the neighbour's
// position is taken from its guide: no normal is decoded.
fn dn_moments_add(m: DnMoments, q: vec2<i32>, g: vec2<u32>, h: DnRecord, pos: vec3<f32>,
                  n: vec3<f32>, dist: f32) -> DnMoments {
    if !dn_in_grid(q) || !dn_guide_valid(g) {
        return m;
    }
    let gpos = dn_guide_position(vec2<u32>(q), bitcast<f32>(g.x), false);
    if abs(dot(n, gpos - pos)) > 0.02 * dist {
        return m;
    }
    let l = dn_luminance(dn_value(h).xyz);
    let len = max(dn_rec_len(h), 1.0);
    var r = m;
    r.m1 += l;
    r.m2 += l * l;
    r.temporal += max(dn_rec_z(h) - l * l, 0.0) / len;
    r.len += len;
    r.cnt += 1.0;
    return r;
}

// Noise variance of the accumulated value (first iteration) from the moments `m` of the 3×3
// neighbours of the same surface: the temporal estimate (second moment − mean², / history
// length), averaged over them since one pixel's few samples make a noisy estimate, blended from
// their spatial variance over the first 8 frames (the temporal estimate needs a few frames;
// not for shadows, see below). The first iteration's taps are those neighbours (step 1), so
// the estimate reads no memory of its own.
fn dn_variance_estimate(s: u32, m: DnMoments) -> f32 {
    let k = max(m.cnt, 1.0);
    let mean = m.m1 / k;
    let spatial = max(m.m2 / k - mean * mean, 0.0);
    var t = clamp((m.len / k - 1.0) / 7.0, 0.0, 1.0);
    if dn_kind(s) >= DN_KIND_SHADOW {
        // A shadow's spatial spread is mostly its edges, not noise: a small light's visibility
        // is exact at one sample per pixel, and blurring it by its 3×3 spread would soften
        // every hard edge. Only the temporal spread (a penumbra's samples disagree over
        // frames) counts as noise.
        t = 1.0;
    }
    return mix(spatial, m.temporal / k, t);
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

// Per-pixel constants of the tap weights (see main).
struct DnCentre {
    p: vec2<i32>,
    position: vec3<f32>,
    normal: vec3<f32>,
    z_edge: f32,
    z_corner: f32,
    r_edge: f32,
    r_corner: f32,
    n_exp: f32,
    lum: f32,
    variance: f32,
    // The centre's variance plus the luminance weight's floor (see dn_tap).
    var_floor: f32,
}

// Weighted sums of the taps.
struct DnAcc {
    sum: vec4<f32>,
    wsum: f32,
    vsum: f32,
}

// Index of the tap `o` (in steps) of grid pixel `p`, clamped into the grid (taps outside are
// dropped by dn_tap).
fn dn_tap_index(p: vec2<i32>, o: vec2<i32>, step: i32) -> u32 {
    let q = clamp(p + o * step, vec2<i32>(0), vec2<i32>(dp.grid.xy) - vec2<i32>(1));
    return dn_index(vec2<u32>(q));
}

// Adds the tap `o` (guide `g`, record `h`) of the centre `c`.
fn dn_tap(acc: DnAcc, c: DnCentre, o: vec2<i32>, step: i32, g: vec2<u32>, h: DnRecord) -> DnAcc {
    let q = c.p + o * step;
    if !dn_in_grid(q) {
        return acc;
    }
    let gq = dn_unpack_guide(g, vec2<u32>(q), false);
    if !gq.valid {
        return acc;
    }
    let cos_n = dot(c.normal, gq.normal);
    if cos_n <= 0.0 {
        return acc; // pow(0, e) = 0
    }
    let corner = o.x != 0 && o.y != 0;
    // B-spline kernel (0.25, 0.5, 0.25)²: an edge tap 0.125, a corner 0.0625.
    let kernel = select(0.125, 0.0625, corner);
    let plane = abs(dot(c.normal, gq.position - c.position));
    let v = dn_value(h);
    let lum = dn_luminance(v.xyz);
    // The tap's own noise variance: the propagated one, or in the first iteration its temporal
    // estimate (second moment − mean², over the history length; the centre's 3×3 average would
    // let the dark pixels around a rare bright one refuse it again).
    var var_q = dn_rec_z(h);
    if ap.first != 0u {
        var_q = max(var_q - lum * lum, 0.0) / max(dn_rec_len(h), 1.0);
    }
    // The luminance weight exp(-|Δl| / (σ_l √(var_p + var_q + floor²))) is symmetric in the
    // noise of both values: a rare bright sample and its dark neighbours take from each other
    // alike, so a sparse signal's energy spreads instead of staying in the few pixels that
    // caught it (a weight of the centre's noise alone lets every dark pixel refuse the bright
    // one, and the energy is lost). One inverseSqrt per tap.
    let l_fac = (LOG2E / SIGMA_L) * inverseSqrt(c.var_floor + var_q);
    let dl = abs(lum - c.lum);
    let e = -plane * select(c.z_edge, c.z_corner, corner) + c.n_exp * log2(cos_n) - dl * l_fac
        + select(c.r_edge, c.r_corner, corner);
    let w = kernel * exp2(e);
    var r = acc;
    r.sum += w * v;
    r.wsum += w;
    r.vsum += w * w * select(var_q, c.variance, ap.first != 0u);
    return r;
}

// log2(e): exp(x) = exp2(x · LOG2E).
const LOG2E: f32 = 1.4426950408889634;

// Stores the filtered record of signal `s`: to the next intermediate, or (last iteration) to the
// output texture.
fn dn_emit(s: u32, i: u32, p: vec2<u32>, value: vec4<f32>, z: f32, len: f32) {
    if DN_LAST {
        dn_write_output(s, dn_texel(p), value);
    } else {
        dn_dst(s, i, dn_pack_signal(value, z, len));
    }
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= dp.grid.x || gid.y >= dp.grid.y {
        return;
    }
    let p = vec2<i32>(gid.xy);
    let i = dn_index(gid.xy);
    let gp = dn_unpack_guide(guide[i], gid.xy, false);
    if !gp.valid {
        // No surface: the accumulated input passes through.
        for (var s = 0u; s < DN_SIGNALS; s++) {
            let h = dn_src(s, i);
            dn_emit(s, i, gid.xy, dn_value(h), 0.0, dn_rec_len(h));
        }
        return;
    }
    let dist = max(dn_view_distance(gp.position), 1e-6);
    let step = i32(ap.step);
    // Tap distances in viewport pixels (a grid pixel spans a block in a block mode), which the
    // radii and the plane tolerance are in.
    let stepf = f32(ap.step * dp.grid.z);
    // Tap distances of the 3×3 pattern: edge and corner.
    let d_edge = stepf;
    let d_corner = stepf * 1.4142135;
    // Plane weight exp(-plane / (dist · 0.004 · (1 + d))), as log2 factors per tap distance.
    let z_edge = LOG2E / (dist * 0.004 * (1.0 + d_edge));
    let z_corner = LOG2E / (dist * 0.004 * (1.0 + d_corner));

    // The eight taps, written out: every guide and record load is issued before any is used
    // (no arrays, which would live in local memory), so that their latencies overlap. One
    // signal per dispatch (SpecularAndDiffuse runs a chain per signal): the records are
    // signal 0's.
    let j0 = dn_tap_index(p, vec2<i32>(-1, -1), step);
    let j1 = dn_tap_index(p, vec2<i32>(0, -1), step);
    let j2 = dn_tap_index(p, vec2<i32>(1, -1), step);
    let j3 = dn_tap_index(p, vec2<i32>(-1, 0), step);
    let j4 = dn_tap_index(p, vec2<i32>(1, 0), step);
    let j5 = dn_tap_index(p, vec2<i32>(-1, 1), step);
    let j6 = dn_tap_index(p, vec2<i32>(0, 1), step);
    let j7 = dn_tap_index(p, vec2<i32>(1, 1), step);
    let g0 = guide[j0];
    let g1 = guide[j1];
    let g2 = guide[j2];
    let g3 = guide[j3];
    let g4 = guide[j4];
    let g5 = guide[j5];
    let g6 = guide[j6];
    let g7 = guide[j7];
    let h0 = src0[j0];
    let h1 = src0[j1];
    let h2 = src0[j2];
    let h3 = src0[j3];
    let h4 = src0[j4];
    let h5 = src0[j5];
    let h6 = src0[j6];
    let h7 = src0[j7];
    let hc = src0[i];

    let centre = dn_value(hc);
    let len_c = dn_rec_len(hc);
    var var_c = dn_rec_z(hc);
    if ap.first != 0u {
        // Step 1: the taps are the 3×3 neighbourhood the noise estimate averages over.
        var m: DnMoments;
        m = dn_moments_add(m, p, guide[i], hc, gp.position, gp.normal, dist);
        m = dn_moments_add(m, p + vec2<i32>(-1, -1), g0, h0, gp.position, gp.normal, dist);
        m = dn_moments_add(m, p + vec2<i32>(0, -1), g1, h1, gp.position, gp.normal, dist);
        m = dn_moments_add(m, p + vec2<i32>(1, -1), g2, h2, gp.position, gp.normal, dist);
        m = dn_moments_add(m, p + vec2<i32>(-1, 0), g3, h3, gp.position, gp.normal, dist);
        m = dn_moments_add(m, p + vec2<i32>(1, 0), g4, h4, gp.position, gp.normal, dist);
        m = dn_moments_add(m, p + vec2<i32>(-1, 1), g5, h5, gp.position, gp.normal, dist);
        m = dn_moments_add(m, p + vec2<i32>(0, 1), g6, h6, gp.position, gp.normal, dist);
        m = dn_moments_add(m, p + vec2<i32>(1, 1), g7, h7, gp.position, gp.normal, dist);
        var_c = dn_variance_estimate(0u, m);
    }
    let lum_c = dn_luminance(centre.xyz);
    let radius = dn_radius(0u, centre, len_c, gp.roughness, dist);
    let r2 = LOG2E / (2.0 * radius * radius);
    var n_exp = 64.0;
    if dn_kind(0u) == DN_KIND_SPECULAR {
        n_exp = mix(256.0, 32.0, gp.roughness);
    }

    var c: DnCentre;
    c.p = p;
    c.position = gp.position;
    c.normal = gp.normal;
    c.z_edge = z_edge;
    c.z_corner = z_corner;
    // log2 of the distance weight exp(-d² / (2 r²)) at an edge and a corner tap.
    c.r_edge = -d_edge * d_edge * r2;
    c.r_corner = -d_corner * d_corner * r2;
    c.n_exp = n_exp;
    c.lum = lum_c;
    c.variance = var_c;
    // The floor keeps the weight finite at zero noise: (1e-4 + 1 % of the luminance) / σ_l,
    // squared, as a variance.
    let floor = (1e-4 + 0.01 * abs(lum_c)) / SIGMA_L;
    c.var_floor = var_c + floor * floor;
    // The centre tap: kernel weight 0.5 × 0.5, every other factor 1.
    var acc: DnAcc;
    acc.sum = 0.25 * centre;
    acc.wsum = 0.25;
    acc.vsum = 0.0625 * var_c;
    acc = dn_tap(acc, c, vec2<i32>(-1, -1), step, g0, h0);
    acc = dn_tap(acc, c, vec2<i32>(0, -1), step, g1, h1);
    acc = dn_tap(acc, c, vec2<i32>(1, -1), step, g2, h2);
    acc = dn_tap(acc, c, vec2<i32>(-1, 0), step, g3, h3);
    acc = dn_tap(acc, c, vec2<i32>(1, 0), step, g4, h4);
    acc = dn_tap(acc, c, vec2<i32>(-1, 1), step, g5, h5);
    acc = dn_tap(acc, c, vec2<i32>(0, 1), step, g6, h6);
    acc = dn_tap(acc, c, vec2<i32>(1, 1), step, g7, h7);
    let ws = max(acc.wsum, 1e-8);
    dn_emit(0u, i, gid.xy, acc.sum / ws, acc.vsum / (ws * ws), len_c);
}
