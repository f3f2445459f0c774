// Direct lighting injection (src/cache/inject.rs): the scene at group 0, the cache at group 1,
// and the depth input from one of cache/inject_depth/*, chosen by the pass. `inject`: one invocation per strided pixel finds
// the surface the pixel shows (a ray from the camera towards the depth's position, accepted
// when it hits within the tolerance of that depth) and adds the pixel's radiance to the nearest
// surfel's accumulation slot, exactly (64-bit fixed-point sums and a count). `resolve` (a second
// module) blends each slot's average into its surfel and clears the slot.

#import scene/traversal
#import cache/sample
#import gpu/uniform_branch

struct InjectParams {
    clip_to_world: mat4x4<f32>,
    eye: vec4<f32>,
    // x, y, width, height of the viewport.
    viewport: vec4<u32>,
    // Strided grid width and height, stride, 1 for orthographic.
    grid: vec4<u32>,
    // Offset inside each stride block (x, y), 1 when depth is world positions, words of the
    // surfel → slot map.
    offset: vec4<u32>,
    // NDC depth of orthographic ray origins, relative depth tolerance, average window, unused.
    f: vec4<f32>,
    // xy: the camera jitter, pixels (the depth at pixel c + jitter holds unjittered pixel c).
    jitter: vec4<f32>,
}

@group(1) @binding(2) var<storage, read_write> accum: array<atomic<u32>>;
@group(2) @binding(0) var<uniform> params: InjectParams;
@group(2) @binding(2) var light_tex: texture_2d<f32>;

// Fixed-point scale of the sums: 16 fractional bits.
const FIXED_SCALE: f32 = 65536.0;
const MAX_RADIANCE: f32 = 65504.0;

// Branches on the task's parameters go through this (gpu/uniform_branch.wgsl says why).
fn inject_branch(x: u32) -> u32 {
    return uniform_branch(x, light_tex);
}

fn unproject(ndc: vec2<f32>, z: f32) -> vec3<f32> {
    let p = params.clip_to_world * vec4<f32>(ndc, z, 1.0);
    return p.xyz / p.w;
}

fn finite_or_zero(x: f32) -> f32 {
    if (bitcast<u32>(x) & 0x7f800000u) == 0x7f800000u {
        return 0.0;
    }
    return clamp(x, 0.0, MAX_RADIANCE);
}

fn add64(w: u32, x: u32) {
    let old = atomicAdd(&accum[w], x);
    if old + x < old {
        atomicAdd(&accum[w + 1u], 1u);
    }
}

@compute @workgroup_size(RT_WORKGROUP_SIZE)
fn inject(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = (wid.y * nwg.x + wid.x) * RT_WORKGROUP_SIZE + lid;
    let gw = params.grid.x;
    let gh = params.grid.y;
    if i >= gw * gh {
        return;
    }
    let stride = params.grid.z;
    let lx = (i % gw) * stride + params.offset.x;
    let ly = (i / gw) * stride + params.offset.y;
    if lx >= params.viewport.z || ly >= params.viewport.w {
        return;
    }
    let pixel = vec2<i32>(vec2<u32>(params.viewport.x + lx, params.viewport.y + ly));
    // The ray goes through where the (jittered) depth was sampled, so that it meets the surface
    // the pixel shows even at grazing angles.
    let ndc = vec2<f32>(
        (f32(lx) + 0.5 - params.jitter.x) / f32(params.viewport.z) * 2.0 - 1.0,
        1.0 - (f32(ly) + 0.5 - params.jitter.y) / f32(params.viewport.w) * 2.0,
    );
    let d = inject_load_depth(pixel);
    var goal: vec3<f32>;
    if inject_branch(params.offset.z) == 1u {
        goal = d.xyz;
    } else {
        goal = unproject(ndc, d.x);
    }
    var origin = params.eye.xyz;
    if inject_branch(params.grid.w) == 1u {
        origin = unproject(ndc, params.f.x);
    }
    if !rt_is_finite3(goal) || !rt_is_finite3(origin) {
        return;
    }
    let dir = goal - origin;
    let tol = params.f.y;
    // Only injection targets receive lighting; another instance in front is not hit, so the hit
    // behind it fails the depth test below.
    let hit = rt_closest_hit(RtRay(origin, 0.0, dir, 1.0 + tol), 1u);
    if hit.hit == 0u || hit.t < 1.0 - tol {
        return;
    }
    let s = cache_nearest_surfel(hit.instance, hit.primitive, vec2<f32>(hit.u, hit.v));
    if s == CACHE_NO_SURFEL || s >= params.offset.w {
        return;
    }
    let c = textureLoad(light_tex, pixel, 0);
    let q = vec3<u32>(
        u32(round(finite_or_zero(c.x) * FIXED_SCALE)),
        u32(round(finite_or_zero(c.y) * FIXED_SCALE)),
        u32(round(finite_or_zero(c.z) * FIXED_SCALE)),
    );
    // The first pixel of a surfel claims its slot (slot ids are pixel ids + 1, unique).
    var slot = 0u;
    for (var tries = 0u; tries < 64u; tries++) {
        let r = atomicCompareExchangeWeak(&accum[s], 0u, i + 1u);
        if r.exchanged {
            slot = i + 1u;
            break;
        }
        if r.old_value != 0u {
            slot = r.old_value;
            break;
        }
    }
    if slot == 0u {
        return;
    }
    let w = params.offset.w + (slot - 1u) * 8u;
    add64(w, q.x);
    add64(w + 2u, q.y);
    add64(w + 4u, q.z);
    atomicAdd(&accum[w + 6u], 1u);
    atomicStore(&accum[w + 7u], s);
}
