// A staged triangle's box as the BVH builds store it, shared by scene/prims.wgsl (triangle_aabbs,
// the refit's gather) and scene/lbvh/range_refit.wgsl (lbvh_refit_gather): the same box wherever it
// is made.

// The stored empty box (documented in docs/ray-tracing-core.md).
const EMPTY_MIN: vec4<f32> = vec4<f32>(1e30, 1e30, 1e30, 0.0);
const EMPTY_MAX: vec4<f32> = vec4<f32>(-1e30, -1e30, -1e30, 0.0);

fn is_non_finite(v: vec3<f32>) -> bool {
    let bits = bitcast<vec3<u32>>(v);
    return any((bits & vec3<u32>(0x7f800000u)) == vec3<u32>(0x7f800000u));
}

struct StoredAabb {
    lo: vec4<f32>,
    hi: vec4<f32>,
}

// A staged triangle's box as stored. Dropped triangles (flag in the second vertex's w) get the
// empty box; so would a non-finite one, which ingestion never writes, rather than poisoning the
// build with NaN bounds.
fn triangle_box(v0: vec4<f32>, v1: vec4<f32>, v2: vec4<f32>) -> StoredAabb {
    let dropped = bitcast<u32>(v1.w) == 1u;
    if dropped || is_non_finite(v0.xyz) || is_non_finite(v1.xyz) || is_non_finite(v2.xyz) {
        return StoredAabb(EMPTY_MIN, EMPTY_MAX);
    }
    return StoredAabb(vec4<f32>(min(min(v0.xyz, v1.xyz), v2.xyz), 0.0),
                      vec4<f32>(max(max(v0.xyz, v1.xyz), v2.xyz), 0.0));
}
