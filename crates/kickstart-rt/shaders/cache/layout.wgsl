// Direct lighting cache: addressing of one instance's surfels (layouts in src/cache/mod.rs).
// CACHE_GROUP is the bind group the includer binds the cache at; SURFEL_ACCESS is `read`, or
// `read_write` where a pass writes surfels (src/cache/mod.rs: sample_params).

#param CACHE_GROUP
#param SURFEL_ACCESS

@group({{CACHE_GROUP}}) @binding(0) var<storage, read> cache_meta: array<u32>;
@group({{CACHE_GROUP}}) @binding(1) var<storage, {{SURFEL_ACCESS}}> cache_surfels: array<vec4<f32>>;

const CACHE_FLAG_VALID: u32 = 1u;
const CACHE_FLAG_MESH_COLORS: u32 = 2u;
const CACHE_FLAG_COARSE: u32 = 4u;
const CACHE_NO_SURFEL: u32 = 0xffffffffu;

struct CacheHeader {
    records: u32,
    tri_count: u32,
    flags: u32,
    surfel_base: u32,
    vertex_count: u32,
    initial: vec3<f32>,
}

// The header of an instance slot; flags 0 where the slot has no cache.
fn cache_header(instance: u32) -> CacheHeader {
    var h = CacheHeader(0u, 0u, 0u, 0u, 0u, vec3<f32>(0.0));
    let n = arrayLength(&cache_meta);
    if instance >= cache_meta[1] {
        return h;
    }
    let o = cache_meta[0] + instance * 8u;
    if o + 8u > n {
        return h;
    }
    h.records = cache_meta[o];
    h.tri_count = cache_meta[o + 1u];
    h.flags = cache_meta[o + 2u];
    h.surfel_base = cache_meta[o + 3u];
    h.vertex_count = cache_meta[o + 4u];
    h.initial = vec3<f32>(
        bitcast<f32>(cache_meta[o + 5u]),
        bitcast<f32>(cache_meta[o + 6u]),
        bitcast<f32>(cache_meta[o + 7u]),
    );
    return h;
}

// A point of the cache: the mix of two surfels (a == b for a stored sample).
struct CachePoint {
    a: u32,
    b: u32,
    t: f32,
}

fn cache_single(s: u32) -> CachePoint {
    return CachePoint(s, s, 0.0);
}

// (u, v) clamped into the triangle.
fn cache_clamp_bary(bary: vec2<f32>) -> vec2<f32> {
    var b = clamp(bary, vec2<f32>(0.0), vec2<f32>(1.0));
    let s = b.x + b.y;
    if s > 1.0 {
        b = b / s;
    }
    return b;
}

// --- MeshColors ---------------------------------------------------------------------------------

fn cache_mc_resolution(h: CacheHeader, packed: u32) -> u32 {
    if (h.flags & CACHE_FLAG_COARSE) != 0u {
        return 1u;
    }
    return 1u << (packed & 15u);
}

fn cache_mc_vertex(h: CacheHeader, rec: u32, k: u32) -> u32 {
    return h.surfel_base + cache_meta[rec + k];
}

// Sample j (0..=e, canonical direction) of edge k of the triangle.
fn cache_mc_edge_sample(h: CacheHeader, rec: u32, k: u32, e: u32, rev: bool, j: u32) -> u32 {
    let start = select(k, (k + 1u) % 3u, rev);
    let end = select((k + 1u) % 3u, k, rev);
    if j == 0u {
        return cache_mc_vertex(h, rec, start);
    }
    if j >= e {
        return cache_mc_vertex(h, rec, end);
    }
    return h.surfel_base + h.vertex_count + cache_meta[rec + 3u + k] + (j - 1u);
}

// The point `step / r` along edge k (from the triangle's vertex k to k+1). Edge samples are stored
// at the edge's own resolution e (a power of two dividing r), so both triangles of an edge
// evaluate the same piecewise-linear function on it.
fn cache_mc_edge(h: CacheHeader, rec: u32, packed: u32, r: u32, k: u32, step: u32) -> CachePoint {
    var e = 1u << ((packed >> (4u + 4u * k)) & 15u);
    if (h.flags & CACHE_FLAG_COARSE) != 0u {
        e = 1u;
    }
    let rev = ((packed >> (16u + k)) & 1u) != 0u;
    let s = select(step, r - step, rev);
    let num = s * e;
    let j = num / r;
    let rem = num % r;
    let a = cache_mc_edge_sample(h, rec, k, e, rev, j);
    if rem == 0u {
        return cache_single(a);
    }
    let b = cache_mc_edge_sample(h, rec, k, e, rev, j + 1u);
    return CachePoint(a, b, f32(rem) / f32(r));
}

// Grid point (i0, i1, i2), i0 + i1 + i2 = r, of the triangle's resolution-r grid.
fn cache_mc_point(h: CacheHeader, rec: u32, packed: u32, r: u32, i: vec3<u32>) -> CachePoint {
    if i.x == r {
        return cache_single(cache_mc_vertex(h, rec, 0u));
    }
    if i.y == r {
        return cache_single(cache_mc_vertex(h, rec, 1u));
    }
    if i.z == r {
        return cache_single(cache_mc_vertex(h, rec, 2u));
    }
    if i.z == 0u {
        return cache_mc_edge(h, rec, packed, r, 0u, i.y);
    }
    if i.x == 0u {
        return cache_mc_edge(h, rec, packed, r, 1u, i.z);
    }
    if i.y == 0u {
        return cache_mc_edge(h, rec, packed, r, 2u, i.x);
    }
    // Interior: rows of constant i2 (1..r-2), i1 from 1 in each row.
    let row = i.z - 1u;
    let offset = row * (r - 1u) - (row * (row + 1u)) / 2u;
    return cache_single(h.surfel_base + h.vertex_count + cache_meta[rec + 6u] + offset + (i.y - 1u));
}

// The nearest grid point of barycentrics (u, v) at resolution r: floors, then the remaining
// steps go to the components with the largest fractions.
fn cache_nearest_grid(bary: vec2<f32>, r: u32) -> vec3<u32> {
    let b = cache_clamp_bary(bary);
    let x = vec3<f32>(max(1.0 - b.x - b.y, 0.0), b.x, b.y) * f32(r);
    let f = floor(x);
    var i = min(vec3<u32>(f), vec3<u32>(r));
    var fr = x - f;
    var sum = i.x + i.y + i.z;
    for (var n = 0u; n < 3u && sum < r; n++) {
        if fr.x >= fr.y && fr.x >= fr.z {
            i.x += 1u;
            fr.x = -1.0;
        } else if fr.y >= fr.z {
            i.y += 1u;
            fr.y = -1.0;
        } else {
            i.z += 1u;
            fr.z = -1.0;
        }
        sum += 1u;
    }
    for (var n = 0u; n < 3u && sum > r; n++) {
        if i.x >= i.y && i.x >= i.z {
            i.x -= 1u;
        } else if i.y >= i.z {
            i.y -= 1u;
        } else {
            i.z -= 1u;
        }
        sum -= 1u;
    }
    return i;
}

// --- WarpedBarycentricStorage --------------------------------------------------------------------

// The tile of (u, v) in a triangle of n×n tiles (rows of constant v; up and down triangles
// alternate along a row).
fn cache_wb_tile(bary: vec2<f32>, n: u32) -> u32 {
    let b = cache_clamp_bary(bary);
    let x = b * f32(n);
    let i1 = min(u32(floor(x.x)), n - 1u);
    let i2 = min(u32(floor(x.y)), n - 1u - i1);
    let f = x - vec2<f32>(f32(i1), f32(i2));
    var down = 0u;
    if f.x + f.y > 1.0 && i1 + i2 + 1u < n {
        down = 1u;
    }
    return 2u * n * i2 - i2 * i2 + 2u * i1 + down;
}

// --- Both layouts --------------------------------------------------------------------------------

// The surfel nearest to a surface point, or CACHE_NO_SURFEL.
fn cache_nearest_surfel(instance: u32, prim: u32, bary: vec2<f32>) -> u32 {
    let h = cache_header(instance);
    if (h.flags & CACHE_FLAG_VALID) == 0u || prim >= h.tri_count {
        return CACHE_NO_SURFEL;
    }
    let rec = h.records + prim * 8u;
    if (h.flags & CACHE_FLAG_MESH_COLORS) != 0u {
        let packed = cache_meta[rec + 7u];
        let r = cache_mc_resolution(h, packed);
        let p = cache_mc_point(h, rec, packed, r, cache_nearest_grid(bary, r));
        return select(p.a, p.b, p.t >= 0.5);
    }
    if (h.flags & CACHE_FLAG_COARSE) != 0u {
        return h.surfel_base + prim;
    }
    let n = max(cache_meta[rec + 1u], 1u);
    return h.surfel_base + cache_meta[rec] + cache_wb_tile(bary, n);
}
