// kickstart-rt traversal module, hardware backend: the same interface as scene/traversal (RtRay,
// RtHit, RtFound, rt_find, rt_found_hit, rt_trace, rt_closest_hit, rt_any_hit, rt_is_finite*,
// RT_* constants), answered by WGSL ray queries against the driver's acceleration structures.
// A pass composed for the hardware backend gets this module's text in place of
// scene/traversal's (src/scene/traversal.rs), so no pass knows which backend traces its rays.
//
// The TLAS instances carry their instance slot as custom data (the index of the instance's record
// in rt_instances, which hits report), and each BLAS holds its geometry's triangles in the order
// of the triangle pool (rt_triangles from the geometry's tri_base), so a hit's primitive index
// within the BLAS names the pool slot whose w holds the primitive index the application knows.
// Rays the software traversal treats as misses (non-finite origin or direction, a zero direction,
// a NaN or empty range) never reach the driver: their behaviour there is undefined.

enable wgpu_ray_query;

#import scene/types

struct RtRay {
    origin: vec3<f32>,
    t_min: f32,
    dir: vec3<f32>,
    t_max: f32,
}

// `hit` is 1 on a hit. A miss has t = -1, instance = primitive = 0xffffffff, hit = 0.
struct RtHit {
    t: f32,
    u: f32,
    v: f32,
    instance: u32,
    primitive: u32,
    hit: u32,
}

@group(0) @binding(0) var rt_tlas: acceleration_structure;
@group(0) @binding(1) var<storage, read> rt_instances: array<InstanceGpu>;
@group(0) @binding(2) var<storage, read> rt_geometries: array<GeometryGpu>;
@group(0) @binding(3) var<storage, read> rt_triangles: array<vec4<f32>>;

const RT_NO_INDEX: u32 = 0xffffffffu;
// The largest finite f32, written exactly: stands in for ∞.
const RT_FLT_MAX: f32 = 0x1.fffffep+127f;
// Passes that include this module dispatch RT_WORKGROUP_SIZE invocations per workgroup (the
// software module's size, so both backends share the passes' dispatch arithmetic).
const RT_WORKGROUP_SIZE: u32 = 64u;

fn rt_is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn rt_is_finite3(x: vec3<f32>) -> bool {
    return rt_is_finite(x.x) && rt_is_finite(x.y) && rt_is_finite(x.z);
}

fn rt_miss() -> RtHit {
    return RtHit(-1.0, 0.0, 0.0, RT_NO_INDEX, RT_NO_INDEX, 0u);
}

// What the query committed: distance, instance slot, triangle pool slot, and (unlike the
// software module, which recomputes them) the barycentrics the driver reported.
struct RtFound {
    t: f32,
    instance: u32,
    slot: u32,
    uv: vec2<f32>,
}

// Whether a candidate triangle of cutout geometry (the driver builds only those non-opaque) lets
// the ray stop: the bit of its opacity micro-map under the candidate's barycentrics, as the
// software traversal's rt_opaque_at.
fn rt_candidate_opaque(c: RayIntersection) -> bool {
    let g = rt_geometries[rt_instances[c.instance_custom_data].geometry];
    if g.opacity.x == RT_OPAQUE_GEOMETRY {
        return true;
    }
    let prim = bitcast<u32>(rt_triangles[(g.tri_base + c.primitive_index) * 3u].w);
    let m = rt_micro_index(c.barycentrics, g.opacity.y);
    let word = g.opacity.x + prim * g.opacity.z + m / 32u;
    let bits = bitcast<u32>(rt_triangles[word / 4u][word % 4u]);
    return ((bits >> (m % 32u)) & 1u) != 0u;
}

// The committed hit of `ray` among instances whose TLAS mask shares a bit with `mask` (hidden and
// non-participating instances are not in the TLAS); `any_hit` ends at the first hit found.
// Triangles are double-sided, as in the software traversal; those of cutout geometry are
// candidates the loop confirms by their micro-maps.
fn rt_find(ray: RtRay, mask: u32, any_hit: bool) -> RtFound {
    let miss = RtFound(-1.0, RT_NO_INDEX, 0u, vec2<f32>(0.0));
    if !rt_is_finite3(ray.origin) || !rt_is_finite3(ray.dir) || all(ray.dir == vec3<f32>(0.0)) {
        return miss;
    }
    let tmin_bits = bitcast<u32>(ray.t_min) & 0x7fffffffu;
    let tmax_bits = bitcast<u32>(ray.t_max) & 0x7fffffffu;
    if tmin_bits > 0x7f800000u || tmax_bits > 0x7f800000u || ray.t_max < ray.t_min {
        return miss;
    }
    let t_min = clamp(ray.t_min, -RT_FLT_MAX, RT_FLT_MAX);
    let t_max = clamp(ray.t_max, -RT_FLT_MAX, RT_FLT_MAX);
    if t_max < 0.0 {
        return miss;
    }
    // Ray queries take t_min >= 0. A range starting behind the origin is traced from the point
    // at t_min instead, and its distances shifted back: the same set of t, rounded once more.
    var origin = ray.origin;
    var shift = 0.0;
    if t_min < 0.0 {
        origin = ray.origin + ray.dir * t_min;
        shift = t_min;
    }
    var flags = RAY_FLAG_NONE;
    if any_hit {
        flags = flags | RAY_FLAG_TERMINATE_ON_FIRST_HIT;
    }
    var rq: ray_query;
    rayQueryInitialize(
        &rq,
        rt_tlas,
        RayDesc(flags, mask & 0xffu, t_min - shift, t_max - shift, origin, ray.dir),
    );
    // Opaque geometry commits every candidate inside the driver: without cutout geometry one
    // call runs the traversal.
    while rayQueryProceed(&rq) {
        let c = rayQueryGetCandidateIntersection(&rq);
        if c.kind == RAY_QUERY_INTERSECTION_TRIANGLE && rt_candidate_opaque(c) {
            rayQueryConfirmIntersection(&rq);
        }
    }
    let hit = rayQueryGetCommittedIntersection(&rq);
    if hit.kind != RAY_QUERY_INTERSECTION_TRIANGLE {
        return miss;
    }
    let instance = hit.instance_custom_data;
    let geometry = rt_instances[instance].geometry;
    let slot = rt_geometries[geometry].tri_base + hit.primitive_index;
    return RtFound(hit.t + shift, instance, slot, hit.barycentrics);
}

// The whole hit of what rt_find found: the primitive index from the pool slot's w.
fn rt_found_hit(ray: RtRay, f: RtFound) -> RtHit {
    if f.instance == RT_NO_INDEX {
        return rt_miss();
    }
    let prim = bitcast<u32>(rt_triangles[f.slot * 3u].w);
    return RtHit(f.t, f.uv.x, f.uv.y, f.instance, prim, 1u);
}

// The hit of `ray` among visible instances: the closest one, or with `any_hit` the first found.
fn rt_trace(ray: RtRay, mask: u32, any_hit: bool) -> RtHit {
    return rt_found_hit(ray, rt_find(ray, mask, any_hit));
}

// The closest hit of `ray` among visible instances.
fn rt_closest_hit(ray: RtRay, mask: u32) -> RtHit {
    return rt_trace(ray, mask, false);
}

// Whether anything visible is hit in [t_min, t_max].
fn rt_any_hit(ray: RtRay, mask: u32) -> bool {
    return rt_find(ray, mask, true).instance != RT_NO_INDEX;
}
