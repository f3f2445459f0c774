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
@group(1) @binding(1) var<storage, read> guide: array<vec4<u32>>;
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

    let surf = gb_surface(texel);
    if !surf.valid {
        dn_write_output(0u, texel, dn_value(src0[dn_index(nearest)]));
        return;
    }
    let tol = UP_PLANE * max(dn_view_distance(surf.position), 1e-6) * (1.0 + block);
    var sum = vec4<f32>(0.0);
    var wsum = 0.0;
    var best = nearest;
    var best_match = -1.0;
    for (var k = 0; k < 4; k++) {
        let o = vec2<i32>(k & 1, k >> 1);
        let q = base + o;
        if !dn_in_grid(q) {
            continue;
        }
        let j = dn_index(vec2<u32>(q));
        let gq = dn_unpack_guide(guide[j]);
        let m = up_match(gq, surf.position, surf.normal, tol);
        let bw = select(1.0 - f.x, f.x, o.x == 1) * select(1.0 - f.y, f.y, o.y == 1);
        if gq.valid && m > best_match {
            best_match = m;
            best = vec2<u32>(q);
        }
        let w = bw * m;
        sum += w * dn_value(src0[j]);
        wsum += w;
    }
    if wsum > 1e-4 {
        dn_write_output(0u, texel, sum / wsum);
    } else {
        dn_write_output(0u, texel, dn_value(src0[dn_index(best)]));
    }
}

// Grid pixel `q` clamped into the grid.
fn dn_clamped(q: vec2<i32>) -> vec2<u32> {
    return vec2<u32>(clamp(q, vec2<i32>(0), vec2<i32>(dp.grid.xy) - vec2<i32>(1)));
}
