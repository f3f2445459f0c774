// Ray batch pass with dynamic ray fetch: each invocation takes rays from a shared counter; when
// at least RT_REFILL_NUM / RT_REFILL_DEN of a subgroup's invocations have finished their ray,
// those write their hits and take new rays together, so a subgroup does not wait for its
// longest ray with most lanes idle.

struct TraceParams {
    count: u32,
    query: u32,
    mask: u32,
    pad: u32,
}

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
@group(1) @binding(3) var<storage, read_write> fetch_next: atomic<u32>;

const RT_REFILL_NUM: u32 = RT_REFILL_NUM_V;
const RT_REFILL_DEN: u32 = RT_REFILL_DEN_V;

fn rt_ballot_count(b: vec4<u32>) -> u32 {
    return countOneBits(b.x) + countOneBits(b.y) + countOneBits(b.z) + countOneBits(b.w);
}

// Set bits of b below bit `lane`.
fn rt_ballot_rank(b: vec4<u32>, lane: u32) -> u32 {
    let word = lane / 32u;
    let part = (1u << (lane % 32u)) - 1u;
    let below = vec4<u32>(
        select(select(0u, part, word == 0u), 0xffffffffu, word > 0u),
        select(select(0u, part, word == 1u), 0xffffffffu, word > 1u),
        select(select(0u, part, word == 2u), 0xffffffffu, word > 2u),
        select(0u, part, word == 3u),
    );
    return rt_ballot_count(b & below);
}

@compute @workgroup_size(RT_WORKGROUP_SIZE)
fn main(@builtin(subgroup_invocation_id) lane: u32) {
    let any_hit = params.query == 1u;
    let mask = params.mask;
    let ref_table = (arrayLength(&rt_tlas_nodes) / 5u) * 4u;
    var idx = RT_NO_INDEX;
    var done = true;
    var ray: RtRay;
    var t_min = 0.0;
    var t_max = 0.0;
    var space: RtSpace;
    var sp = 0u;
    var blas_sp = RT_STACK_SIZE + 1u;
    var node_base = 0u;
    var tri_base = 0u;
    var cur_inst = 0u;
    var best_inst = RT_NO_INDEX;
    var best_slot = 0u;
    var visits = 0u;
    loop {
        let idle = subgroupBallot(done);
        let lanes = subgroupBallot(true);
        let n_idle = rt_ballot_count(idle);
        if n_idle * RT_REFILL_DEN >= rt_ballot_count(lanes) * RT_REFILL_NUM {
            var base = 0u;
            // The first active invocation takes the rays of all; subgroupBroadcastFirst reads it.
            if rt_ballot_rank(lanes, lane) == 0u {
                base = atomicAdd(&fetch_next, n_idle);
            }
            base = subgroupBroadcastFirst(base);
            if done {
                if idx != RT_NO_INDEX {
                    var found = RtFound(-1.0, RT_NO_INDEX, 0u);
                    if best_inst != RT_NO_INDEX {
                        found = RtFound(t_max, best_inst, best_slot);
                    }
                    let h = rt_found_hit(ray, found);
                    hits[idx] = GpuHitOut(h.t, h.u, h.v, h.instance, h.primitive, 0u, 0u, 0u);
                }
                idx = base + rt_ballot_rank(idle, lane);
                if idx >= params.count {
                    break;
                }
                ray = rays[idx];
                best_inst = RT_NO_INDEX;
                best_slot = 0u;
                // rt_find's checks: a ray that fails them is a miss (done stays true).
                let tmin_bits = bitcast<u32>(ray.t_min) & 0x7fffffffu;
                let tmax_bits = bitcast<u32>(ray.t_max) & 0x7fffffffu;
                if rt_is_finite3(ray.origin) && rt_is_finite3(ray.dir) && !all(ray.dir == vec3<f32>(0.0))
                    && tmin_bits <= 0x7f800000u && tmax_bits <= 0x7f800000u && ray.t_max >= ray.t_min {
                    t_min = clamp(ray.t_min, -RT_FLT_MAX, RT_FLT_MAX);
                    t_max = clamp(ray.t_max, -RT_FLT_MAX, RT_FLT_MAX);
                    space = rt_space(ray.origin, ray.dir);
                    rt_stack_store(0u, 0u, t_min);
                    sp = 1u;
                    blas_sp = RT_STACK_SIZE + 1u;
                    node_base = 0u;
                    tri_base = 0u;
                    cur_inst = 0u;
                    visits = 0u;
                    done = false;
                }
            }
        }
        if done {
            continue;
        }
        if sp == 0u || visits >= RT_MAX_VISITS {
            done = true;
            continue;
        }
    // BODY
    }
}
