// Vertex pulling: application vertex/index bytes (copied raw into SDK memory) -> triangle soup
// (scene/ingest_decode decodes). Layouts: docs/ray-tracing-core.md. One
// thread per triangle over all components of a dispatch; a thread finds its component by binary
// search over the table's triangle starts, so thousands of small components cost one dispatch:
// the components of every geometry a task ingests are one table, each row naming its own
// dropped-triangle counters.

#import scene/ingest_decode

struct Params {
    tri_total: u32,       // triangles in this dispatch (all components)
    component_count: u32, // rows in `components`
    counter_base: u32,    // counters[counter_base + 0]: out-of-range index, + 1: non-finite
    pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> components: array<Component>;
@group(0) @binding(2) var<storage, read> raw: array<u32>;
@group(0) @binding(3) var<storage, read_write> out_tris: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> counters: array<atomic<u32>>;

const WG: u32 = 64u;

@compute @workgroup_size(64)
fn ingest(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let t = (wid.y * nwg.x + wid.x) * WG + lid;
    if t >= params.tri_total {
        return;
    }
    // Last component whose tri_start <= t (rows are sorted by tri_start, row 0 starts at 0).
    var lo = 0u;
    var hi = params.component_count;
    while hi - lo > 1u {
        let mid = (lo + hi) / 2u;
        if components[mid].tri_start <= t {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let c = components[lo];
    let j = t - c.tri_start;
    let tri = ingest_triangle(c, j);
    let base = 3u * (c.out_first + j);
    out_tris[base] = tri.v0;
    out_tris[base + 1u] = tri.v1;
    out_tris[base + 2u] = tri.v2;
    if tri.dropped != 0u {
        atomicAdd(&counters[params.counter_base + c.counter + tri.dropped - 1u], 1u);
    }
}
