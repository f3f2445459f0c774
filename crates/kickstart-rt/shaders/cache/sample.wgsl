// Sampling the direct lighting cache at a hit (the contract in src/cache/mod.rs).

#import cache/layout

fn cache_surfel_rgb(s: u32) -> vec3<f32> {
    return cache_surfels[s].xyz;
}

fn cache_point_rgb(p: CachePoint) -> vec3<f32> {
    if p.a == p.b {
        return cache_surfel_rgb(p.a);
    }
    return mix(cache_surfel_rgb(p.a), cache_surfel_rgb(p.b), p.t);
}

// Cached linear radiance at the point (1-u-v)·v0 + u·v1 + v·v2 of primitive `prim` of instance
// slot `instance`: the initial tile colour where never injected, 0 for a slot with no cache.
// `bilinear` interpolates MeshColors samples (continuous across shared edges); the
// WarpedBarycentricStorage layout always reads its nearest tile.
fn cache_radiance(instance: u32, prim: u32, bary: vec2<f32>, bilinear: bool) -> vec3<f32> {
    let h = cache_header(instance);
    if (h.flags & CACHE_FLAG_VALID) == 0u || prim >= h.tri_count {
        return vec3<f32>(0.0);
    }
    if !bilinear || (h.flags & CACHE_FLAG_MESH_COLORS) == 0u {
        return cache_surfel_rgb(cache_nearest_surfel(instance, prim, bary));
    }
    let rec = h.records + prim * 8u;
    let packed = cache_meta[rec + 7u];
    let r = cache_mc_resolution(h, packed);
    let b = cache_clamp_bary(bary);
    let x = b * f32(r);
    let i1 = min(u32(floor(x.x)), r - 1u);
    let i2 = min(u32(floor(x.y)), r - 1u - i1);
    let f = clamp(x - vec2<f32>(f32(i1), f32(i2)), vec2<f32>(0.0), vec2<f32>(1.0));
    if f.x + f.y <= 1.0 || i1 + i2 + 1u >= r {
        // Upward sub-triangle (i1, i2), (i1+1, i2), (i1, i2+1).
        let w0 = max(1.0 - f.x - f.y, 0.0);
        let p0 = cache_mc_point(h, rec, packed, r, vec3<u32>(r - i1 - i2, i1, i2));
        let p1 = cache_mc_point(h, rec, packed, r, vec3<u32>(r - i1 - i2 - 1u, i1 + 1u, i2));
        let p2 = cache_mc_point(h, rec, packed, r, vec3<u32>(r - i1 - i2 - 1u, i1, i2 + 1u));
        return (cache_point_rgb(p0) * w0 + cache_point_rgb(p1) * f.x + cache_point_rgb(p2) * f.y)
            / max(w0 + f.x + f.y, 1e-6);
    }
    // Downward sub-triangle (i1+1, i2+1), (i1, i2+1), (i1+1, i2).
    let p0 = cache_mc_point(h, rec, packed, r, vec3<u32>(r - i1 - i2 - 2u, i1 + 1u, i2 + 1u));
    let p1 = cache_mc_point(h, rec, packed, r, vec3<u32>(r - i1 - i2 - 1u, i1, i2 + 1u));
    let p2 = cache_mc_point(h, rec, packed, r, vec3<u32>(r - i1 - i2 - 1u, i1 + 1u, i2));
    return cache_point_rgb(p0) * (f.x + f.y - 1.0) + cache_point_rgb(p1) * (1.0 - f.x)
        + cache_point_rgb(p2) * (1.0 - f.y);
}

// An id unique per surfel of the whole cache (CACHE_NO_SURFEL where the slot has no cache).
fn cache_tile_id(instance: u32, prim: u32, bary: vec2<f32>) -> u32 {
    return cache_nearest_surfel(instance, prim, bary);
}
