// Ray batch pass: one invocation per ray, rays from a buffer, hits to a buffer. The scene is at
// @group(0) (scene/traversal).

#import scene/traversal

struct TraceParams {
    count: u32,
    // 0: closest hit, 1: any hit.
    query: u32,
    mask: u32,
    pad: u32,
}

// GpuHit (32 bytes). A miss: t = -1, instance = primitive = 0xffffffff.
struct GpuHitOut {
    t: f32,
    u: f32,
    v: f32,
    instance: u32,
    primitive: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(1) @binding(0) var<uniform> params: TraceParams;
@group(1) @binding(1) var<storage, read> rays: array<RtRay>;
@group(1) @binding(2) var<storage, read_write> hits: array<GpuHitOut>;

// The traversal module's workgroup size (the Rust side dispatches by it).
@compute @workgroup_size(RT_WORKGROUP_SIZE)
fn main(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = (wid.y * nwg.x + wid.x) * RT_WORKGROUP_SIZE + lid;
    if i >= params.count {
        return;
    }
    let h = rt_trace(rays[i], params.mask, params.query == 1u);
    hits[i] = GpuHitOut(h.t, h.u, h.v, h.instance, h.primitive, 0u, 0u, 0u);
}
