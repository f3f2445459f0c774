// Decoding of application vertex/index bytes (copied raw into SDK memory) into triangles: the
// component table row, the vertex fetch with its checks, and the triangle as stored. Shared by
// scene/ingest.wgsl (the ingestion pass) and scene/lbvh/range_refit.wgsl (lbvh_refit_ingest, the
// refit that decodes its triangles itself). The module that includes it declares `raw: array<u32>`
// (the bytes).
// Layouts: docs/ray-tracing-core.md.

// One component (112 bytes; mirrors `ComponentRow` in ingest.rs).
struct Component {
    tri_start: u32,     // first triangle of this component within the dispatch
    tri_count: u32,
    out_first: u32,     // triangle slot of its triangle 0 (out_base + primitive_base)
    prim_base: u32,     // primitive index of its triangle 0
    vtx_word: u32,      // word of `raw` holding the byte before which vertex 0 starts (byte offset / 4)
    vtx_shift: u32,     // byte offset % 4: positions may start at any byte
    vtx_stride: u32,
    vtx_format: u32,    // 0 Float32x3, 1 Float32x4, 2 Float16x4, 3 Snorm16x4
    vtx_count: u32,
    idx_word: u32,
    idx_shift: u32,
    idx_format: u32,    // 0 none (3 consecutive vertices), 1 u16, 2 u32
    first_index: u32,
    has_transform: u32, // 0: positions are copied bit-exactly (no arithmetic)
    counter: u32,       // its ingestion's dropped-triangle counters, after the dispatch's counter_base
    pad1: u32,
    row0: vec4<f32>,    // rows of the 3x4 affine transform
    row1: vec4<f32>,
    row2: vec4<f32>,
}

// 4 bytes at byte `rel` past word `base`, any alignment (little-endian). The second word is read
// only when the value straddles it, so an aligned value at the end of `raw` stays in bounds.
fn load_u32(base: u32, rel: u32) -> u32 {
    let w = base + (rel >> 2u);
    let sh = (rel & 3u) * 8u;
    let lo = raw[w];
    if sh == 0u {
        return lo;
    }
    return (lo >> sh) | (raw[w + 1u] << (32u - sh));
}

// 2 bytes at byte `rel` past word `base`, any alignment.
fn load_u16(base: u32, rel: u32) -> u32 {
    let w = base + (rel >> 2u);
    let sh = (rel & 3u) * 8u;
    var v = raw[w] >> sh;
    if sh == 24u {
        v = v | (raw[w + 1u] << 8u);
    }
    return v & 0xffffu;
}

// f16 bits -> f32 bits, exact, with integer operations only: no dependence on how a GPU treats
// f16 subnormals or whether unpack2x16float preserves ∞/NaN (they must reach the finite check).
fn f16_bits_to_f32(h: u32) -> u32 {
    let sign = (h & 0x8000u) << 16u;
    let e = (h >> 10u) & 0x1fu;
    let m = h & 0x3ffu;
    if e == 0x1fu {
        return sign | 0x7f800000u | (m << 13u); // ∞ / NaN stay non-finite
    }
    if e == 0u {
        if m == 0u {
            return sign;
        }
        // Subnormal m * 2^-24 is a normal f32: renormalise around its leading bit.
        let l = firstLeadingBit(m);
        return sign | ((l + 103u) << 23u) | ((m << (23u - l)) & 0x7fffffu);
    }
    return sign | ((e + 112u) << 23u) | (m << 13u);
}

// snorm16 bits -> bits of max(i / 32767, -1) correctly rounded (as the CPU's f32 division), by
// integer long division: WGSL's f32 division may be off by 2.5 ULP, and exact decoding keeps GPU
// positions identical to the CPU oracle's.
fn snorm16_bits_to_f32(h: u32) -> u32 {
    if h == 0x8000u || h == 0x8001u {
        return 0xbf800000u; // -32768 clamps to -1; -32767 is exactly -1
    }
    let neg = (h & 0x8000u) != 0u;
    let sign = select(0u, 0x80000000u, neg);
    let mag = select(h, 0x10000u - h, neg);
    if mag == 0u {
        return 0u;
    }
    if mag == 32767u {
        return sign | 0x3f800000u;
    }
    // mag / 32767 lies in [2^-p, 2^(1-p)) with p = 15 - floor(log2 mag).
    let p = 15u - firstLeadingBit(mag);
    let r0 = (mag << p) - 32767u; // fraction numerator after the leading 1 (< 32767)
    let t = r0 << 16u;
    let hi = t / 32767u;
    let lo = ((t % 32767u) << 8u) / 32767u;
    let frac24 = (hi << 8u) | lo; // 23 mantissa bits + 1 guard bit
    // The remainder is never 0 (32767 is odd), so there are no ties: round up iff the guard bit
    // is set. A carry out of the mantissa correctly bumps the exponent.
    return sign | (((127u - p) << 23u) + (frac24 >> 1u) + (frac24 & 1u));
}

fn bits_non_finite(bits: vec3<u32>) -> bool {
    return any((bits & vec3<u32>(0x7f800000u)) == vec3<u32>(0x7f800000u));
}

// Position bits of vertex `v` of component `c`.
fn load_position(c: Component, v: u32) -> vec3<u32> {
    let rel = c.vtx_shift + v * c.vtx_stride;
    if c.vtx_format <= 1u {
        return vec3<u32>(load_u32(c.vtx_word, rel), load_u32(c.vtx_word, rel + 4u), load_u32(c.vtx_word, rel + 8u));
    }
    let xy = load_u32(c.vtx_word, rel);
    let z = load_u16(c.vtx_word, rel + 4u); // w is ignored: not read
    if c.vtx_format == 2u {
        return vec3<u32>(f16_bits_to_f32(xy & 0xffffu), f16_bits_to_f32(xy >> 16u), f16_bits_to_f32(z));
    }
    return vec3<u32>(snorm16_bits_to_f32(xy & 0xffffu), snorm16_bits_to_f32(xy >> 16u), snorm16_bits_to_f32(z));
}

const OK: u32 = 0u;
const BAD_INDEX: u32 = 1u;
const NON_FINITE: u32 = 2u;

struct Vertex {
    pos: vec3<f32>,
    status: u32,
}

// The vertex index of vertex k of triangle j of component c (not range-checked).
fn vertex_index(c: Component, j: u32, k: u32) -> u32 {
    let n = c.first_index + 3u * j + k;
    if c.idx_format == 1u {
        return load_u16(c.idx_word, c.idx_shift + n * 2u);
    } else if c.idx_format == 2u {
        return load_u32(c.idx_word, c.idx_shift + n * 4u);
    }
    return n;
}

// Vertex k of triangle j of component c: index fetch, range check, decode, transform, checks.
fn fetch_vertex(c: Component, j: u32, k: u32) -> Vertex {
    let v = vertex_index(c, j, k);
    if v >= c.vtx_count {
        return Vertex(vec3<f32>(0.0), BAD_INDEX);
    }
    let bits = load_position(c, v);
    // Checked on bits before any arithmetic: WGSL may assume floats are finite.
    if bits_non_finite(bits) {
        return Vertex(vec3<f32>(0.0), NON_FINITE);
    }
    var p = bitcast<vec3<f32>>(bits);
    if c.has_transform != 0u {
        let h = vec4<f32>(p, 1.0);
        p = vec3<f32>(dot(c.row0, h), dot(c.row1, h), dot(c.row2, h));
        // A finite transform can still overflow a finite position to ∞.
        if bits_non_finite(bitcast<vec3<u32>>(p)) {
            return Vertex(vec3<f32>(0.0), NON_FINITE);
        }
    }
    return Vertex(p, OK);
}

// Triangle j of component c as the triangle soup stores it (3 vec4: positions, the primitive
// index in the first w) and why it was dropped: 0 kept, else 1 + its counter (0: an index out of
// range, 1: a non-finite position). A dropped triangle has zero positions and 1 in the second
// vertex's w; an out-of-range index takes precedence (its position could not be decoded at all).
struct Ingested {
    v0: vec4<f32>,
    v1: vec4<f32>,
    v2: vec4<f32>,
    dropped: u32,
}

fn ingest_triangle(c: Component, j: u32) -> Ingested {
    let a = fetch_vertex(c, j, 0u);
    let b = fetch_vertex(c, j, 1u);
    let d = fetch_vertex(c, j, 2u);
    let prim = bitcast<f32>(c.prim_base + j);
    if max(max(a.status, b.status), d.status) == OK {
        return Ingested(vec4<f32>(a.pos, prim), vec4<f32>(b.pos, 0.0), vec4<f32>(d.pos, 0.0), 0u);
    }
    let counter = select(1u, 0u, ((a.status | b.status | d.status) & BAD_INDEX) != 0u);
    return Ingested(vec4<f32>(0.0, 0.0, 0.0, prim), vec4<f32>(0.0, 0.0, 0.0, bitcast<f32>(1u)),
                    vec4<f32>(0.0), 1u + counter);
}
