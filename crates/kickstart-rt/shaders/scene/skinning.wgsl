// Skinning and morph targets (crate::SkinningTask): one dispatch a batch of meshes that share
// their buffers, one invocation a vertex; each mesh has whole workgroups of its own, from its
// `first_group`. The position is the rest position plus the weighted morph deltas, then blended by
// up to four joints' matrices; a vertex whose usable weights are all zero keeps the morphed
// rest position, and a joint index past the task's matrices is ignored.
//
// Every input is read in place from the caller's buffers, bound as windows that start at a
// storage-offset-aligned byte: the word offsets below are relative to those windows, and every
// offset and stride is a whole number of words (the validation requires it).

struct Skin {
    vertex_count: u32,
    rest_word: u32,       // rest positions: first word, words between vertices
    rest_stride: u32,
    joint_word: u32,      // joint indices: first word, words between vertices, format
    joint_stride: u32,
    joint_format: u32,    // 0 Uint8x4, 1 Uint16x4, 2 Uint32x4
    weight_word: u32,     // weights: first word, words between vertices, format
    weight_stride: u32,
    weight_format: u32,   // 0 Float32x4, 1 Unorm8x4, 2 Unorm16x4
    joint_count: u32,     // 0: no skinning
    morph_word: u32,      // morph deltas: first word, words between vertices and targets
    morph_stride: u32,
    morph_target_stride: u32,
    morph_count: u32,
    morph_weight_at: u32, // index into `pose` of the first target's weight
    out_word: u32,        // output: first word, words between vertices
    out_stride: u32,
    joint_base: u32,      // index into `pose` of the task's first matrix (12 floats each)
    first_group: u32,     // the batch's first workgroup of this mesh
    _pad: u32,
}

// The batch's meshes, in the order of their workgroups.
@group(0) @binding(0) var<storage, read> skins: array<Skin>;
@group(0) @binding(1) var<storage, read> rest: array<u32>;
@group(0) @binding(2) var<storage, read> joints: array<u32>;
@group(0) @binding(3) var<storage, read> weights: array<u32>;
@group(0) @binding(4) var<storage, read> morphs: array<f32>;
// The joint matrices (three rows of four floats each) and then the morph weights.
@group(0) @binding(5) var<storage, read> pose: array<f32>;
@group(0) @binding(6) var<storage, read_write> posed: array<f32>;

const SKIN_WG: u32 = 64u;

// The mesh this invocation poses (set first by skin_vertices; the helpers read it).
var<private> skin: Skin;

// The index in `skins` of the mesh owning workgroup g: the last whose first workgroup is at or
// before it.
fn skin_of_group(g: u32) -> u32 {
    var lo = 0u;
    var hi = arrayLength(&skins);
    while hi - lo > 1u {
        let mid = (lo + hi) / 2u;
        if skins[mid].first_group <= g {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// The four joint indices of vertex v.
fn skin_joints(v: u32) -> vec4<u32> {
    let at = skin.joint_word + v * skin.joint_stride;
    if skin.joint_format == 0u {
        let w = joints[at];
        return vec4<u32>(w & 0xffu, (w >> 8u) & 0xffu, (w >> 16u) & 0xffu, w >> 24u);
    }
    if skin.joint_format == 1u {
        let lo = joints[at];
        let hi = joints[at + 1u];
        return vec4<u32>(lo & 0xffffu, lo >> 16u, hi & 0xffffu, hi >> 16u);
    }
    return vec4<u32>(joints[at], joints[at + 1u], joints[at + 2u], joints[at + 3u]);
}

// The four weights of vertex v.
fn skin_weights(v: u32) -> vec4<f32> {
    let at = skin.weight_word + v * skin.weight_stride;
    if skin.weight_format == 1u {
        return unpack4x8unorm(weights[at]);
    }
    if skin.weight_format == 2u {
        let lo = unpack2x16unorm(weights[at]);
        let hi = unpack2x16unorm(weights[at + 1u]);
        return vec4<f32>(lo, hi);
    }
    return bitcast<vec4<f32>>(vec4<u32>(
        weights[at], weights[at + 1u], weights[at + 2u], weights[at + 3u]));
}

// Joint j's matrix applied to point p.
fn skin_transform(j: u32, p: vec3<f32>) -> vec3<f32> {
    let m = (skin.joint_base + j) * 12u;
    let h = vec4<f32>(p, 1.0);
    return vec3<f32>(
        dot(vec4<f32>(pose[m], pose[m + 1u], pose[m + 2u], pose[m + 3u]), h),
        dot(vec4<f32>(pose[m + 4u], pose[m + 5u], pose[m + 6u], pose[m + 7u]), h),
        dot(vec4<f32>(pose[m + 8u], pose[m + 9u], pose[m + 10u], pose[m + 11u]), h));
}

@compute @workgroup_size(64)
fn skin_vertices(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lane: u32,
) {
    // The dispatch may be split into 2-D (crate::gpu::recorder::split_workgroups).
    let g = wid.y * nwg.x + wid.x;
    skin = skins[skin_of_group(g)];
    let v = (g - skin.first_group) * SKIN_WG + lane;
    if v >= skin.vertex_count {
        return;
    }
    let r = skin.rest_word + v * skin.rest_stride;
    var p = bitcast<vec3<f32>>(vec3<u32>(rest[r], rest[r + 1u], rest[r + 2u]));
    for (var t = 0u; t < skin.morph_count; t++) {
        let w = pose[skin.morph_weight_at + t];
        if w != 0.0 {
            let d = skin.morph_word + t * skin.morph_target_stride + v * skin.morph_stride;
            p += w * vec3<f32>(morphs[d], morphs[d + 1u], morphs[d + 2u]);
        }
    }
    if skin.joint_count > 0u {
        let js = skin_joints(v);
        let ws = skin_weights(v);
        var sum = vec3<f32>(0.0);
        var used = false;
        for (var i = 0u; i < 4u; i++) {
            if ws[i] != 0.0 && js[i] < skin.joint_count {
                sum += ws[i] * skin_transform(js[i], p);
                used = true;
            }
        }
        if used {
            p = sum;
        }
    }
    let o = skin.out_word + v * skin.out_stride;
    posed[o] = p.x;
    posed[o + 1u] = p.y;
    posed[o + 2u] = p.z;
}
