// kickstart-rt traversal module: two-level BVH traversal (TLAS → instance → BLAS) with a
// watertight ray/triangle test. Every tracing pass prepends this file to its own source (WGSL has
// no include). Layouts and rules: docs/ray-tracing-core.md ("Traversal"); the CPU oracle in
// src/cpu follows the same rules, and the unit tests in src/trace compare the two. The scene
// table structs come from scene/types.
//
// Watertightness without f64: an edge function that is exactly 0 counts as inside (edge-inclusive,
// evaluated in f32 only; the CPU oracle does the same). Rounding of a product is monotonic, so a
// non-zero edge function always has the exact sign; a zero may be a rounded tiny value, and
// counting it as inside can only add hits, never open a gap. Each edge function is evaluated with
// its two endpoints in a canonical order, so the two triangles sharing an edge evaluate the same
// expression (one of them negates it): even where the compiler contracts a*b - c*d into an FMA,
// both sides round identically and their signs stay exactly opposite.

#import scene/types
#import scene/cutout_test

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

@group(0) @binding(0) var<storage, read> rt_tlas_nodes: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read> rt_instances: array<InstanceGpu>;
@group(0) @binding(2) var<storage, read> rt_geometries: array<GeometryGpu>;
@group(0) @binding(3) var<storage, read> rt_blas_nodes: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> rt_triangles: array<vec4<f32>>;

const RT_STACK_SIZE: u32 = 64u;
const RT_MAX_VISITS: u32 = 1048576u;
const RT_LEAF_BIT: u32 = 0x80000000u;
const RT_FIRST_MASK: u32 = 0x0fffffffu;
const RT_NO_INDEX: u32 = 0xffffffffu;
// Largest finite f32: stands in for ∞ (WGSL lets implementations assume no infinities).
// The largest finite f32, written exactly (a decimal literal above it is out of range for
// stricter WGSL compilers).
const RT_FLT_MAX: f32 = 0x1.fffffep+127f;
// 1 + 2γ (Ize 2013), as the CPU's slab test: widens the far distance so rounding never culls a
// box that a grazing ray touches.
const RT_FAR_WIDEN: f32 = 1.0000004;

// Traversal stack: one private array per invocation (node reference and entry distance), 64
// entries for both levels.
//
// Measured on the H100 (docs/decisions/stack-in-workgroup-memory.md): moving the shallow part
// of the stack into workgroup memory (per-lane slices of 16–24 entries) made incoherent rays
// much *slower* than this private stack; the workgroup carve-out costs occupancy and L1 for
// node fetches more than local-memory stack traffic costs. Keep the stack private unless a
// measurement says otherwise.
//
// Passes that include this module dispatch RT_WORKGROUP_SIZE invocations per workgroup.
const RT_WORKGROUP_SIZE: u32 = 64u;
// One 8-byte entry (node reference, entry distance bits): one local-memory store or load per
// push or pop instead of two.
var<private> rt_stack: array<vec2<u32>, RT_STACK_SIZE>;

// Stack entry i (< RT_STACK_SIZE): node reference and entry distance.
fn rt_stack_store(i: u32, node: u32, t: f32) {
    rt_stack[i] = vec2<u32>(node, bitcast<u32>(t));
}

struct RtStackEntry {
    node: u32,
    t: f32,
}

fn rt_stack_load(i: u32) -> RtStackEntry {
    let e = rt_stack[i];
    return RtStackEntry(e.x, bitcast<f32>(e.y));
}

fn rt_is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn rt_is_finite3(x: vec3<f32>) -> bool {
    return rt_is_finite(x.x) && rt_is_finite(x.y) && rt_is_finite(x.z);
}

// Rows × (p, w), summed left to right as the CPU oracle does (a built-in dot may sum in another
// order, which moves rays through vertices by an ulp relative to the oracle).
fn rt_transform(m: mat3x4<f32>, p: vec3<f32>, w: f32) -> vec3<f32> {
    return vec3<f32>(
        m[0].x * p.x + m[0].y * p.y + m[0].z * p.z + m[0].w * w,
        m[1].x * p.x + m[1].y * p.y + m[1].z * p.z + m[1].w * w,
        m[2].x * p.x + m[2].y * p.y + m[2].z * p.z + m[2].w * w,
    );
}

// Component k (0, 1 or 2) of v: exactly the value v[k], without a dynamic index. A runtime
// vector index gets a bounds clamp from naga and may be lowered through a scratch copy of the
// vector; it ran three times per vertex, nine per triangle. Two selects per component cost a few
// ALU ops and yield the same bits, so the shear (and watertightness: every vertex still goes
// through one deterministic formula) is unchanged.
fn rt_component(v: vec3<f32>, k: u32) -> f32 {
    return select(select(v.x, v.y, k == 1u), v.z, k == 2u);
}

// A ray prepared for one space (world for the TLAS, an instance's object space for its BLAS).
struct RtSpace {
    origin: vec3<f32>,
    // Reciprocal direction; 0 on flat axes (never used there).
    inv_dir: vec3<f32>,
    // Axes where the direction is 0 (or so small that its reciprocal overflows): the CPU gets
    // ±∞ × 0 = NaN or ±∞ there, i.e. the axis only decides whether the origin is inside the slab.
    flat_axis: vec3<bool>,
    // Any flat axis: the box test takes its general path (rare: axis-aligned rays).
    any_flat: bool,
    // Watertight test: axis permutation (kx, ky, kz) and shear (Sx, Sy, Sz).
    k: vec3<u32>,
    s: vec3<f32>,
}

fn rt_space(origin: vec3<f32>, dir: vec3<f32>) -> RtSpace {
    var sp: RtSpace;
    sp.origin = origin;
    let zero = dir == vec3<f32>(0.0);
    let inv = vec3<f32>(1.0) / select(dir, vec3<f32>(1.0), zero);
    let overflow = vec3<bool>(!rt_is_finite(inv.x), !rt_is_finite(inv.y), !rt_is_finite(inv.z));
    // A reciprocal flushed to 0 (a huge direction component) is flat too: the fast box test
    // needs a non-zero reciprocal to tell an empty box from a point.
    sp.flat_axis = zero | overflow | (inv == vec3<f32>(0.0));
    sp.any_flat = any(sp.flat_axis);
    sp.inv_dir = select(inv, vec3<f32>(0.0), sp.flat_axis);
    // Same axis choice as the CPU (strict comparisons, ties to the later axis).
    let a = abs(dir);
    var kz = 2u;
    if a.x > a.y {
        if a.x > a.z {
            kz = 0u;
        }
    } else if a.y > a.z {
        kz = 1u;
    }
    var kx = (kz + 1u) % 3u;
    var ky = (kx + 1u) % 3u;
    // Keep the winding: swap when the dominant component is negative.
    let dz = rt_component(dir, kz);
    if dz < 0.0 {
        let tmp = kx;
        kx = ky;
        ky = tmp;
    }
    sp.k = vec3<u32>(kx, ky, kz);
    sp.s = vec3<f32>(rt_component(dir, kx) / dz, rt_component(dir, ky) / dz, 1.0 / dz);
    return sp;
}

struct RtBoxHit {
    near: f32,
    hit: bool,
}

// Slab test against [bmin, bmax] within [t_min, t_max]; empty boxes (min > max) are missed.
fn rt_box(bmin: vec3<f32>, bmax: vec3<f32>, sp: RtSpace, t_min: f32, t_max: f32) -> RtBoxHit {
    if !sp.any_flat {
        // No flat axis (nearly every ray): the general path below without its flat-axis and
        // empty-box logic, the same distances bit for bit. Empty boxes are stored as (+1e30,
        // -1e30) on every axis (docs/ray-tracing-core.md), so one comparison on x rejects them.
        // min/max of both planes rather than picking the entry plane by the direction's sign:
        // the same values (rounding is monotonic and no reciprocal is 0 here), six selects fewer
        // a box (measured faster on the H100; see docs/decisions/slab-test.md).
        let t0 = (bmin - sp.origin) * sp.inv_dir;
        let t1 = (bmax - sp.origin) * sp.inv_dir;
        let tn = min(t0, t1);
        let tf = max(t0, t1);
        let near = max(t_min, max(tn.x, max(tn.y, tn.z)));
        let far = min(t_max, min(tf.x, min(tf.y, tf.z)));
        return RtBoxHit(near, near <= far * RT_FAR_WIDEN && bmin.x <= bmax.x);
    }
    var r: RtBoxHit;
    r.near = t_min;
    r.hit = false;
    if any(bmin > bmax) {
        return r;
    }
    let inside = (sp.origin >= bmin) & (sp.origin <= bmax);
    if any(sp.flat_axis & !inside) {
        return r;
    }
    let t0 = (bmin - sp.origin) * sp.inv_dir;
    let t1 = (bmax - sp.origin) * sp.inv_dir;
    // A flat axis with the origin inside its slab does not constrain the interval (the CPU's
    // NaN → ∓∞ rule).
    let lo = select(min(t0, t1), vec3<f32>(-RT_FLT_MAX), sp.flat_axis);
    let hi = select(max(t0, t1), vec3<f32>(RT_FLT_MAX), sp.flat_axis);
    let near = max(t_min, max(lo.x, max(lo.y, lo.z)));
    let far = min(t_max, min(hi.x, min(hi.y, hi.z)));
    r.near = near;
    r.hit = near <= far * RT_FAR_WIDEN;
    return r;
}

// A vertex relative to the ray origin, permuted and sheared: (x, y) in the ray's 2-D frame, z
// scaled by Sz. One function for every vertex, so a vertex shared by two triangles gets the same
// bits in both.
fn rt_shear(p: vec3<f32>, sp: RtSpace) -> vec3<f32> {
    let d = p - sp.origin;
    let dz = rt_component(d, sp.k.z);
    return vec3<f32>(
        rt_component(d, sp.k.x) - sp.s.x * dz,
        rt_component(d, sp.k.y) - sp.s.y * dz,
        sp.s.z * dz,
    );
}

// Edge function of the edge p → q: q.x * p.y - q.y * p.x (the CPU's U = cx*by - cy*bx for b → c),
// evaluated with the endpoints in a canonical order (see the header comment).
//
// Coincident endpoints give exactly 0 (mathematically x*y - y*x). Written out, a compiler that
// fuses the multiply-add (NVIDIA's does) returns the rounding error of x*y instead, the same
// non-zero value on all three edges of a point-like triangle: a zero-area triangle would then be
// "hit" by any ray reaching its box (seen on the H100 with a ray aimed at such a vertex). With
// two coincident vertices the other two edges are exact negatives (canonical order), so the
// determinant is exactly 0 and the triangle is never hit, as on the CPU.
fn rt_edge(p: vec2<f32>, q: vec2<f32>) -> f32 {
    if all(p == q) {
        return 0.0;
    }
    let swap = q.x < p.x || (q.x == p.x && q.y < p.y);
    let a = select(p, q, swap);
    let b = select(q, p, swap);
    let f = b.x * a.y - b.y * a.x;
    return select(f, -f, swap);
}

struct RtTriHit {
    t: f32,
    u: f32,
    v: f32,
    hit: bool,
}

// The triangle (a, b, c) in the ray's sheared frame: the edge functions u, v, w (of the edges
// opposite a, b and c) and the vertices' scaled z. One function for the test and for the
// barycentrics after the loop, so both evaluate the same expressions.
struct RtEdges {
    uvw: vec3<f32>,
    z: vec3<f32>,
}

fn rt_edges(sp: RtSpace, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> RtEdges {
    let pa = rt_shear(a, sp);
    let pb = rt_shear(b, sp);
    let pc = rt_shear(c, sp);
    let uvw = vec3<f32>(rt_edge(pb.xy, pc.xy), rt_edge(pc.xy, pa.xy), rt_edge(pa.xy, pb.xy));
    return RtEdges(uvw, vec3<f32>(pa.z, pb.z, pc.z));
}

// Watertight ray/triangle test (Woop, Benthin & Wald 2013), both windings, edge-inclusive,
// t in [t_min, t_max] inclusive. u, v: weights of the second and third vertex.
fn rt_triangle(sp: RtSpace, t_min: f32, t_max: f32, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> RtTriHit {
    var r: RtTriHit;
    r.hit = false;
    r.t = 0.0;
    r.u = 0.0;
    r.v = 0.0;
    let e = rt_edges(sp, a, b, c);
    let u = e.uvw.x;
    let v = e.uvw.y;
    let w = e.uvw.z;
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return r;
    }
    let det = u + v + w;
    if det == 0.0 || !rt_is_finite(det) {
        return r;
    }
    let t_scaled = u * e.z.x + v * e.z.y + w * e.z.z;
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    if !rt_is_finite(t) || t < t_min || t > t_max {
        return r;
    }
    r.t = t;
    r.u = v * inv;
    r.v = w * inv;
    r.hit = true;
    return r;
}

// Whether the micro-map of cutout geometry lets a hit at the triangle (a, b, c) of primitive
// `prim` count: the bit of the micro-triangle under its barycentrics. `first` is the geometry's
// first map word in the triangle pool (GeometryGpu.opacity.x); its level is read from the
// geometry of instance `inst` (only cutout geometry gets here).
fn rt_opaque_at(sp: RtSpace, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>, prim: u32, first: u32,
                inst: u32) -> bool {
    let o = rt_geometries[rt_instances[inst].geometry].opacity;
    let m = rt_micro_index(rt_barycentrics(sp, a, b, c), o.y);
    let word = first + prim * o.z + m / 32u;
    let bits = bitcast<u32>(rt_triangles[word / 4u][word % 4u]);
    return ((bits >> (m % 32u)) & 1u) != 0u;
}

// u, v of rt_triangle's hit, without its tests: after the loop the triangle is known to be hit,
// and a test repeated in another place of the program could round differently where the compiler
// fuses multiply-adds differently.
fn rt_barycentrics(sp: RtSpace, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> vec2<f32> {
    let e = rt_edges(sp, a, b, c).uvw;
    let inv = 1.0 / (e.x + e.y + e.z);
    return vec2<f32>(e.y * inv, e.z * inv);
}

fn rt_miss() -> RtHit {
    return RtHit(-1.0, 0.0, 0.0, RT_NO_INDEX, RT_NO_INDEX, 0u);
}

// What the traversal loop keeps of the best hit: its distance, instance slot and triangle slot
// (the triangle's index in rt_triangles, not its primitive index). A miss has instance
// RT_NO_INDEX and t = -1. Barycentrics and the primitive index are derived after the loop
// (rt_found_hit), only for callers that want them: two fewer values live through every
// iteration (measured faster on the H100; see docs/decisions/traversal-loop-state.md).
struct RtFound {
    t: f32,
    instance: u32,
    slot: u32,
}

// Traverses TLAS and BLASes with one stack. Entries at stack index >= `blas_sp` belong to the
// BLAS of the instance being traversed; popping an entry below it means that BLAS is done. Each
// entry keeps the entry distance of its box, so subtrees behind a closer hit are skipped.
// `any_hit` returns at the first hit found.
fn rt_find(ray: RtRay, mask: u32, any_hit: bool) -> RtFound {
    let miss = RtFound(-1.0, RT_NO_INDEX, 0u);
    if !rt_is_finite3(ray.origin) || !rt_is_finite3(ray.dir) || all(ray.dir == vec3<f32>(0.0)) {
        return miss;
    }
    // NaN range: nothing is in it (as on the CPU, where every comparison with NaN fails).
    let tmin_bits = bitcast<u32>(ray.t_min) & 0x7fffffffu;
    let tmax_bits = bitcast<u32>(ray.t_max) & 0x7fffffffu;
    if tmin_bits > 0x7f800000u || tmax_bits > 0x7f800000u {
        return miss;
    }
    // ±∞ become ±FLT_MAX: the same set of finite t.
    let t_min = clamp(ray.t_min, -RT_FLT_MAX, RT_FLT_MAX);
    var t_max = clamp(ray.t_max, -RT_FLT_MAX, RT_FLT_MAX);
    if ray.t_max < ray.t_min {
        return miss;
    }
    var best_inst = RT_NO_INDEX;
    var best_slot = 0u;
    // The space of the level being traversed: the world's for the TLAS, the instance's for its
    // BLAS. The world space is not kept aside while a BLAS is traversed but recomputed (same
    // function, same bits) when the BLAS is left: less live state per iteration (measured faster
    // on the H100; see docs/decisions/traversal-loop-state.md).
    var space = rt_space(ray.origin, ray.dir);
    // TLAS leaves name instance refs; their table follows the node slots (C node slots of 4
    // vec4, then C entries of 1: see instance_refs in scene/prims.wgsl).
    let ref_table = (arrayLength(&rt_tlas_nodes) / 5u) * 4u;
    rt_stack_store(0u, 0u, t_min);
    var sp = 1u;
    var blas_sp = RT_STACK_SIZE + 1u;
    var node_base = 0u;
    var tri_base = 0u;
    var cur_inst = 0u;
    // The current BLAS's first opacity map word (RT_OPAQUE_GEOMETRY: opaque, tested for free).
    // Never read where RT_CUTOUTS is false (a scene without cutout geometry).
    var cur_opacity = RT_OPAQUE_GEOMETRY;
    var visits = 0u;
    while sp > 0u && visits < RT_MAX_VISITS {
        visits += 1u;
        sp -= 1u;
        let popped = rt_stack_load(sp);
        let entry = popped.node;
        let entry_t = popped.t;
        let in_blas = sp >= blas_sp;
        if !in_blas && blas_sp <= RT_STACK_SIZE {
            // Back in the TLAS.
            blas_sp = RT_STACK_SIZE + 1u;
            space = rt_space(ray.origin, ray.dir);
        }
        // Pushed before a closer hit was found: the box test would now fail.
        if entry_t > t_max * RT_FAR_WIDEN {
            continue;
        }
        if (entry & RT_LEAF_BIT) != 0u {
            let first = entry & RT_FIRST_MASK;
            let count = ((entry >> 28u) & 7u) + 1u;
            // One item per iteration; the rest of the leaf goes back on top of the stack.
            // - BLAS leaf: one triangle now, the rest popped next. When the invocations of a
            //   subgroup diverge between leaves and inner nodes, each iteration then costs one
            //   node step plus one triangle test, not a node step plus the longest leaf's
            //   triangles (measured faster on the H100; see
            //   docs/decisions/leaf-triangles.md). The rest is pushed with t_min, so it is never
            //   culled: every triangle of a leaf is tested, as before.
            // - TLAS leaf of several instance refs: the first is entered now; the rest lies below
            //   that BLAS's entries, so it comes after this BLAS is done, culled by the leaf's
            //   entry distance like any other entry.
            if count > 1u && sp < RT_STACK_SIZE {
                let rest = RT_LEAF_BIT | ((count - 2u) << 28u) | (first + 1u);
                rt_stack_store(sp, rest, select(entry_t, t_min, in_blas));
                sp += 1u;
            }
            if in_blas {
                let slot = tri_base + first;
                let v0 = rt_triangles[slot * 3u];
                let v1 = rt_triangles[slot * 3u + 1u];
                let v2 = rt_triangles[slot * 3u + 2u];
                var h = rt_triangle(space, t_min, t_max, v0.xyz, v1.xyz, v2.xyz);
                if RT_CUTOUTS && h.hit && cur_opacity != RT_OPAQUE_GEOMETRY {
                    h.hit = rt_opaque_at(space, v0.xyz, v1.xyz, v2.xyz, bitcast<u32>(v0.w),
                                         cur_opacity, cur_inst);
                }
                if h.hit {
                    // Once a hit is kept, t_max is its distance (the triangle test never
                    // returns t > t_max). Tie rule: equal t → lowest instance, then lowest
                    // primitive index (the kept triangle's read again: ties are rare).
                    var better = best_inst == RT_NO_INDEX || h.t < t_max;
                    if !better && h.t == t_max {
                        let prim = bitcast<u32>(v0.w);
                        let best_prim = bitcast<u32>(rt_triangles[best_slot * 3u].w);
                        better = cur_inst < best_inst
                            || (cur_inst == best_inst && prim < best_prim);
                    }
                    if better {
                        best_inst = cur_inst;
                        best_slot = slot;
                        t_max = h.t;
                        if any_hit {
                            break;
                        }
                    }
                }
            } else {
                // A ref: (instance slot, entry into its BLAS: the root, or the subtree the TLAS
                // build opened the instance into, the BLAS build's stamp).
                let r = bitcast<vec3<u32>>(rt_tlas_nodes[ref_table + first].xyz);
                let inst = rt_instances[r.x];
                if (inst.mask & mask) == 0u || (inst.flags & 1u) == 0u {
                    continue;
                }
                let geo = rt_geometries[inst.geometry];
                if (geo.flags & 1u) == 0u || sp >= RT_STACK_SIZE {
                    continue;
                }
                // No renormalisation: t means the same in object and world space.
                let m = inst.world_to_object;
                space = rt_space(
                    rt_transform(m, ray.origin, 1.0),
                    rt_transform(m, ray.dir, 0.0),
                );
                node_base = geo.node_base;
                tri_base = geo.tri_base;
                cur_inst = r.x;
                if RT_CUTOUTS {
                    cur_opacity = geo.opacity.x;
                }
                blas_sp = sp;
                // A ref made for another build of this BLAS (TLAS update deferred past a rebuild)
                // is entered at the root: complete, never another build's node indices.
                let entry = select(0u, r.y, (geo.flags >> 8u) == r.z);
                rt_stack_store(sp, entry, entry_t);
                sp += 1u;
            }
            continue;
        }
        var n0: vec4<f32>;
        var n1: vec4<f32>;
        var n2: vec4<f32>;
        var n3: vec4<f32>;
        if in_blas {
            let base = (node_base + entry) * 4u;
            n0 = rt_blas_nodes[base];
            n1 = rt_blas_nodes[base + 1u];
            n2 = rt_blas_nodes[base + 2u];
            n3 = rt_blas_nodes[base + 3u];
        } else {
            let base = entry * 4u;
            n0 = rt_tlas_nodes[base];
            n1 = rt_tlas_nodes[base + 1u];
            n2 = rt_tlas_nodes[base + 2u];
            n3 = rt_tlas_nodes[base + 3u];
        }
        let hl = rt_box(n0.xyz, n1.xyz, space, t_min, t_max);
        let hr = rt_box(n2.xyz, n3.xyz, space, t_min, t_max);
        let lref = bitcast<u32>(n0.w);
        let rref = bitcast<u32>(n1.w);
        // Push the farther child first so the nearer one is visited next. When the stack is
        // full the farther child is dropped (it cannot happen for trees of depth < 32 per level).
        if hl.hit && hr.hit {
            var near_ref = lref;
            var near_t = hl.near;
            var far_ref = rref;
            var far_t = hr.near;
            if hr.near < hl.near {
                near_ref = rref;
                near_t = hr.near;
                far_ref = lref;
                far_t = hl.near;
            }
            if sp + 1u < RT_STACK_SIZE {
                rt_stack_store(sp, far_ref, far_t);
                sp += 1u;
            }
            if sp < RT_STACK_SIZE {
                rt_stack_store(sp, near_ref, near_t);
                sp += 1u;
            }
        } else if (hl.hit || hr.hit) && sp < RT_STACK_SIZE {
            rt_stack_store(sp, select(rref, lref, hl.hit), select(hr.near, hl.near, hl.hit));
            sp += 1u;
        }
    }
    if best_inst == RT_NO_INDEX {
        return miss;
    }
    return RtFound(t_max, best_inst, best_slot);
}

// The whole hit of what rt_find found with `ray`: the triangle test runs again in the hit
// instance's space, computed by the same functions from the same values as in the loop, for
// the barycentrics; the distance is the loop's.
fn rt_found_hit(ray: RtRay, f: RtFound) -> RtHit {
    if f.instance == RT_NO_INDEX {
        return rt_miss();
    }
    let m = rt_instances[f.instance].world_to_object;
    let space = rt_space(rt_transform(m, ray.origin, 1.0), rt_transform(m, ray.dir, 0.0));
    let v0 = rt_triangles[f.slot * 3u];
    let v1 = rt_triangles[f.slot * 3u + 1u];
    let v2 = rt_triangles[f.slot * 3u + 2u];
    let uv = rt_barycentrics(space, v0.xyz, v1.xyz, v2.xyz);
    return RtHit(f.t, uv.x, uv.y, f.instance, bitcast<u32>(v0.w), 1u);
}

// The hit of `ray` among visible instances ((instance.mask & mask) != 0, flags bit 0): the
// closest one, or with `any_hit` the first found.
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
