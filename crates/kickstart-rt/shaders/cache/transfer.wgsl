// Direct light transfer (src/cache/transfer.rs). The cache is at group 0,
// its surfels writable (cache/sample). One invocation per target triangle writes every
// surfel the triangle reads with the source's interpolated radiance at the same primitive and
// barycentrics (shared samples are written by each of their triangles with the same value).

#import cache/sample

struct TransferParams {
    source: u32,
    target_slot: u32,
    tri_count: u32,
    pad: u32,
}

@group(1) @binding(0) var<uniform> params: TransferParams;

fn put(s: u32, prim: u32, bary: vec2<f32>) {
    if s < arrayLength(&cache_surfels) {
        let c = cache_radiance(params.source, prim, bary, true);
        cache_surfels[s] = vec4<f32>(c, 1.0);
    }
}

@compute @workgroup_size(64)
fn transfer(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let prim = (wid.y * nwg.x + wid.x) * 64u + lid;
    let h = cache_header(params.target_slot);
    if (h.flags & CACHE_FLAG_VALID) == 0u || prim >= h.tri_count || prim >= params.tri_count {
        return;
    }
    let rec = h.records + prim * 8u;
    if (h.flags & CACHE_FLAG_MESH_COLORS) != 0u {
        let packed = cache_meta[rec + 7u];
        let r = cache_mc_resolution(h, packed);
        for (var i2 = 0u; i2 <= r; i2++) {
            for (var i1 = 0u; i1 + i2 <= r; i1++) {
                let p = cache_mc_point(h, rec, packed, r, vec3<u32>(r - i1 - i2, i1, i2));
                if p.a == p.b {
                    put(p.a, prim, vec2<f32>(f32(i1), f32(i2)) / f32(r));
                }
            }
        }
        return;
    }
    if (h.flags & CACHE_FLAG_COARSE) != 0u {
        put(h.surfel_base + prim, prim, vec2<f32>(1.0 / 3.0));
        return;
    }
    let n = max(cache_meta[rec + 1u], 1u);
    for (var i2 = 0u; i2 < n; i2++) {
        for (var i1 = 0u; i1 + i2 < n; i1++) {
            let up = (vec2<f32>(f32(i1), f32(i2)) + vec2<f32>(1.0 / 3.0)) / f32(n);
            put(h.surfel_base + cache_meta[rec] + cache_wb_tile(up, n), prim, up);
            if i1 + i2 + 1u < n {
                let down = (vec2<f32>(f32(i1), f32(i2)) + vec2<f32>(2.0 / 3.0)) / f32(n);
                put(h.surfel_base + cache_meta[rec] + cache_wb_tile(down, n), prim, down);
            }
        }
    }
}
