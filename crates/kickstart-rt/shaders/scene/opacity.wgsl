// Opacity micro-maps of cutout geometry (docs/ray-tracing-core.md, "Cutout geometry"): one
// component's triangles a dispatch, one invocation per word of a triangle's map. A triangle at
// level L is split into 4^L micro-triangles by a grid of N = 2^L segments per edge: row iv
// (0..N, along the barycentric v) holds 2 (N - iv) - 1 micro-triangles, the upright one of cell
// iu at 2 iu and the inverted one at 2 iu + 1; row iv starts at index iv (2N - iv). Bit m of a
// map (word m / 32, bit m % 32) is micro-triangle m's opacity at its centre. scene/traversal
// (rt_opaque_at) finds the micro-triangle of a hit's barycentrics the same way.
//
// Modes: 0 every bit opaque (a component without opacity, in a geometry with some), 1 the glTF
// MASK test of a texture channel at the interpolated coordinates (texel of mip 0, repeating),
// 2 a flag per triangle (all bits as its flag).

#import scene/ingest_decode

struct Bake {
    mode: u32,
    level: u32,
    words: u32,     // words a triangle's map takes
    out_word: u32,  // word of `maps` where triangle 0's map starts
    uv_word: u32,   // coordinates: word of `raw`, byte shift, stride, format
    uv_shift: u32,
    uv_stride: u32,
    uv_format: u32, // 0 Float32x2, 1 Float16x2, 2 Unorm16x2
    flag_word: u32, // per-triangle flags: word of `raw` holding triangle 0's
    channel: u32,
    factor: f32,
    cutoff: f32,
}

@group(0) @binding(0) var<uniform> bake: Bake;
// The component's ingestion row (its indices; positions are not read).
@group(0) @binding(1) var<storage, read> components: array<Component>;
@group(0) @binding(2) var<storage, read> raw: array<u32>;
// The triangle pool as words: the maps live in it (no binding of their own while tracing).
@group(0) @binding(3) var<storage, read_write> maps: array<u32>;
@group(0) @binding(4) var opacity_texture: texture_2d<f32>;

const BAKE_WG: u32 = 64u;

// Vertex index k of triangle j (the vertex count when the index is out of range).
fn bake_vertex(c: Component, j: u32, k: u32) -> u32 {
    return min(vertex_index(c, j, k), c.vtx_count);
}

// Texture coordinates of vertex v; non-finite ones read as 0.
fn bake_uv(c: Component, v: u32) -> vec2<f32> {
    if v >= c.vtx_count {
        return vec2<f32>(0.0);
    }
    let rel = bake.uv_shift + v * bake.uv_stride;
    var bits: vec2<u32>;
    if bake.uv_format == 0u {
        bits = vec2<u32>(load_u32(bake.uv_word, rel), load_u32(bake.uv_word, rel + 4u));
    } else if bake.uv_format == 1u {
        bits = vec2<u32>(f16_bits_to_f32(load_u16(bake.uv_word, rel)),
                         f16_bits_to_f32(load_u16(bake.uv_word, rel + 2u)));
    } else {
        let q = vec2<f32>(f32(load_u16(bake.uv_word, rel)), f32(load_u16(bake.uv_word, rel + 2u)));
        return q / 65535.0;
    }
    if (bits.x & 0x7f800000u) == 0x7f800000u || (bits.y & 0x7f800000u) == 0x7f800000u {
        return vec2<f32>(0.0);
    }
    return bitcast<vec2<f32>>(bits);
}

// The MASK test at `uv`: the texel it falls in (repeating), its channel times the factor.
fn bake_opaque(uv: vec2<f32>) -> bool {
    let size = textureDimensions(opacity_texture, 0);
    let f = uv - floor(uv);
    let texel = min(vec2<u32>(f * vec2<f32>(size)), size - vec2<u32>(1u));
    let alpha = textureLoad(opacity_texture, texel, 0)[min(bake.channel, 3u)];
    return bake.factor * alpha >= bake.cutoff;
}

@compute @workgroup_size(64)
fn opacity_bake(@builtin(workgroup_id) wid: vec3<u32>,
                @builtin(num_workgroups) nwg: vec3<u32>,
                @builtin(local_invocation_index) lid: u32) {
    let c = components[0];
    let t = (wid.y * nwg.x + wid.x) * BAKE_WG + lid;
    if t >= c.tri_count * bake.words {
        return;
    }
    let j = t / bake.words;
    let w = t % bake.words;
    let out = bake.out_word + t;
    if bake.mode == 0u {
        maps[out] = 0xffffffffu;
        return;
    }
    if bake.mode == 2u {
        maps[out] = select(0u, 0xffffffffu, raw[bake.flag_word + j] != 0u);
        return;
    }
    let uv0 = bake_uv(c, bake_vertex(c, j, 0u));
    let uv1 = bake_uv(c, bake_vertex(c, j, 1u));
    let uv2 = bake_uv(c, bake_vertex(c, j, 2u));
    let n = 1u << bake.level;
    let micro = n * n;
    // The row of micro-triangle 32 w, then step through the word's micro-triangles in order.
    var m = 32u * w;
    var row = 0u;
    while row + 1u < n && (row + 1u) * (2u * n - row - 1u) <= m {
        row += 1u;
    }
    var r = m - row * (2u * n - row);
    var bits = 0u;
    for (var b = 0u; b < 32u && m < micro; b++) {
        let iu = r / 2u;
        // Centre of the micro-triangle in grid units: upright (iu + 1/3, row + 1/3), inverted
        // (iu + 2/3, row + 2/3).
        let k = select(1.0, 2.0, (r & 1u) == 1u) / 3.0;
        let bary = (vec2<f32>(f32(iu), f32(row)) + vec2<f32>(k)) / f32(n);
        let uv = (1.0 - bary.x - bary.y) * uv0 + bary.x * uv1 + bary.y * uv2;
        if bake_opaque(uv) {
            bits |= 1u << b;
        }
        m += 1u;
        r += 1u;
        if r >= 2u * (n - row) - 1u {
            row += 1u;
            r = 0u;
        }
    }
    maps[out] = bits;
}
