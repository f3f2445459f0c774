// kickstart-rt denoisers, last pass of a block mode (one traced pixel per 2×2 or 4×4 block;
// see denoise/common.wgsl): writes every viewport pixel of one signal's output texture from the
// filtered grid, guided by the G-buffer.
//
// Per pixel: the four grid pixels around it (the traced pixels of this frame's blocks, bilinear
// weights), each weighted by how well its surface (the guide) matches this pixel's: normal
// similarity and distance from this pixel's tangent plane, so that a signal does not bleed
// across depth and normal edges. A traced pixel lands exactly on its grid pixel and gets its
// filtered value. Where no neighbour matches (a surface too thin for the grid to see), the
// best-matching one is used; pixels without a surface take the nearest grid pixel's value.
//
// Composed with a one-signal set's record module and denoise/output/one; the G-buffer is at
// group 0 (trace/gbuffer).

#import denoise/common
#import trace/gbuffer

@group(1) @binding(0) var<uniform> dp: DenoiseParams;
@group(1) @binding(1) var<storage, read> guide: array<vec2<u32>>;
@group(1) @binding(2) var<storage, read> src0: array<DnRecord>;

// Plane-distance tolerance, as a fraction of the view distance per viewport pixel of offset.
const UP_PLANE: f32 = 0.004;
// Normal-similarity exponent.
const UP_NORMAL_POWER: f32 = 32.0;

// Geometric match of grid pixel `g` (guide `gq`) for the surface (`pos`, `n`) at distance
// `tol` of plane tolerance; 0 for no surface.
fn up_match(gq: DnGuide, pos: vec3<f32>, n: vec3<f32>, tol: f32) -> f32 {
    if !gq.valid {
        return 0.0;
    }
    let cos_n = max(dot(n, gq.normal), 0.0);
    let plane = abs(dot(n, gq.position - pos)) / tol;
    return pow(cos_n, UP_NORMAL_POWER) * exp(-plane * plane);
}

// The weighted sums of the four taps, and the best-matching tap so far.
struct UpAcc {
    sum: vec4<f32>,
    wsum: f32,
    best: vec2<u32>,
    best_match: f32,
}

// Adds grid pixel `q` (guide `g`, record `h`, bilinear weight `bw`) for the surface `surf`; a
// pixel outside the grid is left out.
fn up_tap(acc: UpAcc, q: vec2<i32>, g: vec2<u32>, h: DnRecord, bw: f32, surf: GbSurface,
          tol: f32) -> UpAcc {
    if !dn_in_grid(q) {
        return acc;
    }
    var r = acc;
    let gq = dn_unpack_guide(g, vec2<u32>(q), false);
    let m = up_match(gq, surf.position, surf.normal, tol);
    if gq.valid && m > r.best_match {
        r.best_match = m;
        r.best = vec2<u32>(q);
    }
    let w = bw * m;
    r.sum += w * dn_value(h);
    r.wsum += w;
    return r;
}

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= dp.viewport.z || gid.y >= dp.viewport.w {
        return;
    }
    let texel = gid.xy + dp.viewport.xy;
    let block = f32(dp.grid.z);
    // Continuous grid coordinates of this pixel's centre: grid pixel g is centred on viewport
    // pixel g · block + lattice.
    let gc = (vec2<f32>(gid.xy) - vec2<f32>(dp.lattice.xy)) / block;
    let base_f = floor(gc);
    let f = gc - base_f;
    let base = vec2<i32>(base_f);
    let nearest = dn_clamped(vec2<i32>(round(gc)));

    // The four grid pixels' guides and records, loaded before the G-buffer is decoded and before
    // any is used (indices clamped into the grid; a tap outside it is left out below), so that
    // their latencies overlap: loaded in the loop that weighs them, each tap's loads waited on
    // the last tap's.
    let q0 = base;
    let q1 = base + vec2<i32>(1, 0);
    let q2 = base + vec2<i32>(0, 1);
    let q3 = base + vec2<i32>(1, 1);
    let j0 = dn_clamped_index(q0);
    let j1 = dn_clamped_index(q1);
    let j2 = dn_clamped_index(q2);
    let j3 = dn_clamped_index(q3);
    let g0 = guide[j0];
    let g1 = guide[j1];
    let g2 = guide[j2];
    let g3 = guide[j3];
    let h0 = src0[j0];
    let h1 = src0[j1];
    let h2 = src0[j2];
    let h3 = src0[j3];

    let surf = gb_surface(texel);
    if !surf.valid {
        dn_write_output(0u, texel, dn_value(src0[dn_index(nearest)]));
        return;
    }
    let tol = UP_PLANE * max(dn_view_distance(surf.position), 1e-6) * (1.0 + block);
    var acc: UpAcc;
    acc.best = nearest;
    acc.best_match = -1.0;
    acc = up_tap(acc, q0, g0, h0, (1.0 - f.x) * (1.0 - f.y), surf, tol);
    acc = up_tap(acc, q1, g1, h1, f.x * (1.0 - f.y), surf, tol);
    acc = up_tap(acc, q2, g2, h2, (1.0 - f.x) * f.y, surf, tol);
    acc = up_tap(acc, q3, g3, h3, f.x * f.y, surf, tol);
    let sum = acc.sum;
    let wsum = acc.wsum;
    let best = acc.best;
    if wsum > 1e-4 {
        dn_write_output(0u, texel, sum / wsum);
    } else {
        dn_write_output(0u, texel, dn_value(src0[dn_index(best)]));
    }
}
