// Centroid bounds of a BVH build's primitives, shared by scene/lbvh/bounds.wgsl (the `lbvh_bounds`
// pass) and scene/prims.wgsl (the TLAS's instance-box pass merges them as it writes the boxes, so a
// TLAS build skips `lbvh_bounds`). Both must count the same primitives in the same way, hence one
// copy.
//
// Six u32 words: ~enc(min.xyz), enc(max.xyz), merged with atomicMax, so zero (a cleared buffer)
// is the identity. A primitive counts when its box (as stored in an AABB buffer) is not empty
// (no NaN lane, min.x <= max.x) and its centroid is finite. Per workgroup the words are reduced
// in workgroup memory first, then merged with one device atomic each.

// NaN by bit pattern (the compiler may assume floats are never NaN).
fn is_nan(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7fffffffu) > 0x7f800000u;
}

fn is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

// A float as a u32 that sorts like the float (negative: all bits flipped; positive: sign set).
fn enc(x: f32) -> u32 {
    let b = bitcast<u32>(x);
    return select(b | 0x80000000u, ~b, (b & 0x80000000u) != 0u);
}

fn dec(u: u32) -> f32 {
    return bitcast<f32>(select(~u, u & 0x7fffffffu, (u & 0x80000000u) != 0u));
}

// Whether a stored box is empty: min.x > max.x (the documented empty box), or any NaN lane.
// Non-short-circuit `|`: each `||` is a branch in the SPIR-V Tint emits, and with four boxes a
// level inlined into lbvh_range_refit's pyramid loop SwiftShader (Chromium's software WebGPU)
// never finished building the pipeline (its GPU process was killed after about 2 minutes);
// with `|` it builds in half a second. The six tests are cheap and have no side effects.
fn stored_box_is_empty(lo: vec3<f32>, hi: vec3<f32>) -> bool {
    let nan = is_nan(lo.x) | is_nan(lo.y) | is_nan(lo.z) | is_nan(hi.x) | is_nan(hi.y)
        | is_nan(hi.z);
    return nan | (lo.x > hi.x);
}

// Centroid without overflow for huge boxes; valid when every lane is finite.
fn box_centroid(lo: vec3<f32>, hi: vec3<f32>) -> vec3<f32> {
    return lo * 0.5 + hi * 0.5;
}

var<workgroup> wg_bounds: array<atomic<u32>, 6>;

// Zeroes the workgroup's words (invocations 0..5); a workgroupBarrier must follow.
fn wg_bounds_clear(lid: u32) {
    if lid < 6u {
        atomicStore(&wg_bounds[lid], 0u);
    }
}

// Merges the centroid of stored box (lo, hi) into the workgroup's words if it counts.
fn wg_bounds_add(lo: vec3<f32>, hi: vec3<f32>) {
    if stored_box_is_empty(lo, hi) {
        return;
    }
    let c = box_centroid(lo, hi);
    if !is_finite(c.x) || !is_finite(c.y) || !is_finite(c.z) {
        return;
    }
    atomicMax(&wg_bounds[0], ~enc(c.x));
    atomicMax(&wg_bounds[1], ~enc(c.y));
    atomicMax(&wg_bounds[2], ~enc(c.z));
    atomicMax(&wg_bounds[3], enc(c.x));
    atomicMax(&wg_bounds[4], enc(c.y));
    atomicMax(&wg_bounds[5], enc(c.z));
}

// Word `lid` (< 6) of the workgroup's reduction, 0 if nothing counted (after a barrier).
fn wg_bounds_word(lid: u32) -> u32 {
    return atomicLoad(&wg_bounds[lid]);
}
