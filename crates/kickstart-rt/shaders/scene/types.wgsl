// The scene tables as the GPU reads them (layouts: docs/ray-tracing-core.md). Imported by every
// shader that reads the geometry or instance table, so the layout is written once.

struct GeometryGpu {
    node_base: u32,
    tri_base: u32,
    tri_count: u32,
    flags: u32,
    bounds_min: vec4<f32>,
    bounds_max: vec4<f32>,
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
