// The scene tables as the GPU reads them (layouts: docs/ray-tracing-core.md). Imported by every
// shader that reads the geometry or instance table, so the layout is written once.

struct GeometryGpu {
    node_base: u32,
    tri_base: u32,
    tri_count: u32,
    flags: u32,
    bounds_min: vec4<f32>,
    bounds_max: vec4<f32>,
    // Cutout geometry (docs/ray-tracing-core.md, "Cutout geometry"): x = first u32 word of its
    // opacity micro-maps in the triangle pool (0xffffffff: opaque), y = micro-map level, z = words
    // a triangle.
    opacity: vec4<u32>,
}

struct InstanceGpu {
    object_to_world: mat3x4<f32>,
    world_to_object: mat3x4<f32>,
    geometry: u32,
    mask: u32,
    flags: u32,
    pad: u32,
    pad2: vec4<u32>,
}

// Cutout geometry: GeometryGpu.opacity.x of an opaque geometry (no micro-maps).
const RT_OPAQUE_GEOMETRY: u32 = 0xffffffffu;

// The micro-triangle of a level-`level` opacity micro-map holding barycentrics `uv` (weights of
// the second and third vertex): N = 2^level segments an edge, row iv = floor(v N) from
// iv (2N - iv), the upright triangle of cell iu = floor(u N) at 2 iu, the inverted one after it
// (scene/opacity.wgsl bakes them in this order).
fn rt_micro_index(uv: vec2<f32>, level: u32) -> u32 {
    let n = 1u << level;
    let f = clamp(uv, vec2<f32>(0.0), vec2<f32>(1.0)) * f32(n);
    let iv = min(u32(f.y), n - 1u);
    let iu = min(u32(f.x), n - 1u - iv);
    let inverted = (f.x - f32(iu)) + (f.y - f32(iv)) > 1.0 && iu + iv + 1u < n;
    return iv * (2u * n - iv) + 2u * iu + select(0u, 1u, inverted);
}
