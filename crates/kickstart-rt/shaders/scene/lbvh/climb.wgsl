// Bottom-up boxes (build and refit), one invocation per leaf.
//
// WGSL promises no forward progress between workgroups and only relaxed atomics, so nothing here
// waits on another invocation. Each invocation climbs from its leaf; at every inner node the
// FIRST to arrive stops and the SECOND continues with the union of both children. The second
// must see the first's box, hence:
//   1. boxes live in `work` and are written/read with atomicStore/atomicLoad (device-coherent);
//   2. write box -> storageBarrier() -> atomicAdd(arrival) -> storageBarrier() -> read sibling.
//      storageBarrier() is an OpControlBarrier with Device memory scope and AcquireRelease |
//      UniformMemory semantics: the first one is a release fence before the arrival increment,
//      the second an acquire fence after it, so when the second arriver's atomicAdd reads the
//      first's increment, the first's box stores happen-before the second's loads.
// storageBarrier() is also a workgroup control barrier, so it must be reached in
// workgroup-uniform control flow: the climb is a loop whose trip count is uniform (it runs while
// ANY invocation of the workgroup is still climbing, read through workgroupUniformLoad), and
// each invocation carries its own `climbing` flag. Inactive invocations just pass the barriers.

#import scene/lbvh/common

var<workgroup> wg_active: atomic<u32>;
var<workgroup> wg_go: u32;

// Whether `flag` is set in any invocation of the workgroup: the same answer in all of them, so
// the climb's loops keep a uniform trip count. Every invocation must call it (it has barriers).
fn wg_any(flag: bool, lid: u32) -> bool {
    if lid == 0u {
        atomicStore(&wg_active, 0u);
    }
    workgroupBarrier();
    if flag {
        atomicAdd(&wg_active, 1u);
    }
    workgroupBarrier();
    if lid == 0u {
        wg_go = atomicLoad(&wg_active);
    }
    return workgroupUniformLoad(&wg_go) != 0u;
}

fn leaf_box(k: u32) -> Box {
    if (seg.flags & FLAG_SORTED_BOXES) != 0u {
        return prim_box(k);
    }
    return prim_box(order[seg.order_base + k]);
}

fn store_box(node: u32, b: Box) {
    let at = BOXES_AT + 6u * node;
    atomicStore(&work[seg.work_base + at], bitcast<u32>(b.lo.x));
    atomicStore(&work[seg.work_base + at + 1u], bitcast<u32>(b.lo.y));
    atomicStore(&work[seg.work_base + at + 2u], bitcast<u32>(b.lo.z));
    atomicStore(&work[seg.work_base + at + 3u], bitcast<u32>(b.hi.x));
    atomicStore(&work[seg.work_base + at + 4u], bitcast<u32>(b.hi.y));
    atomicStore(&work[seg.work_base + at + 5u], bitcast<u32>(b.hi.z));
}

fn load_box(node: u32) -> Box {
    let at = BOXES_AT + 6u * node;
    return Box(
        vec3<f32>(bitcast<f32>(atomicLoad(&work[seg.work_base + at])), bitcast<f32>(atomicLoad(&work[seg.work_base + at + 1u])),
                  bitcast<f32>(atomicLoad(&work[seg.work_base + at + 2u]))),
        vec3<f32>(bitcast<f32>(atomicLoad(&work[seg.work_base + at + 3u])),
                  bitcast<f32>(atomicLoad(&work[seg.work_base + at + 4u])),
                  bitcast<f32>(atomicLoad(&work[seg.work_base + at + 5u]))));
}

// Summary of child ref c whose box is `b`: a leaf's is computed, an inner node's was published
// by its climber (with its box, under the same release/acquire protocol).
fn child_subtree(c: u32, b: Box) -> Subtree {
    // Without collapsing no summary was published (and none is needed: nothing collapses).
    if (c & LEAF_BIT) != 0u || !collapsing() {
        return leaf_subtree(c & 0x7fffffffu, b);
    }
    return load_subtree(c);
}

// Box of child ref c (topology encoding): leaves from the input, inner nodes from `work`.
fn child_box(c: u32) -> Box {
    if (c & LEAF_BIT) != 0u {
        return leaf_box(c & 0x7fffffffu);
    }
    return load_box(c);
}

// SAH summary of a subtree: its cost (area-weighted, not normalised), primitive count and first
// sorted position, whether it is cheaper as a single leaf, and whether its leaves are the sorted
// positions [first, first + count) (only then can it be one leaf).
struct Subtree {
    cost: f32,
    count: u32,
    first: u32,
    collapsed: bool,
    contiguous: bool,
}

// The count word of a summary as stored: count and the two flags.
fn subtree_word(s: Subtree) -> u32 {
    return s.count | select(0u, COLLAPSED_BIT, s.collapsed) | select(SCATTERED_BIT, 0u, s.contiguous);
}

fn subtree_from(cost: u32, word: u32, first: u32) -> Subtree {
    return Subtree(bitcast<f32>(cost), word & COUNT_MASK, first, (word & COLLAPSED_BIT) != 0u,
                   (word & SCATTERED_BIT) == 0u);
}

// Surface area, 0 for an empty box, capped at BIG so sums of costs stay comparable (a non-finite
// value may be assumed away by the compiler).
fn area(b: Box) -> f32 {
    let d = max(b.hi - b.lo, vec3<f32>(0.0));
    return min(2.0 * (d.x * d.y + d.y * d.z + d.z * d.x), BIG);
}

fn leaf_subtree(k: u32, b: Box) -> Subtree {
    return Subtree(area(b) * SAH_INTERSECTION, 1u, k, false, true);
}

// The optimal cost of an inner node over children `l` and `r` (box `b`): split, or one leaf when
// collapsing is on, the leaf fits and it is no more expensive.
fn join_subtrees(b: Box, l: Subtree, r: Subtree) -> Subtree {
    let a = area(b);
    let count = l.count + r.count;
    let split = min(a * SAH_TRAVERSAL + l.cost + r.cost, BIG);
    let as_leaf = min(a * f32(count) * SAH_INTERSECTION, BIG);
    let contiguous = l.contiguous && r.contiguous
        && (l.first + l.count == r.first || r.first + r.count == l.first);
    let collapse = collapsing() && contiguous && count <= seg.max_leaf && as_leaf <= split;
    return Subtree(select(split, as_leaf, collapse), count, min(l.first, r.first), collapse,
                   contiguous);
}

// Whether this dispatch may collapse subtrees (uniform). Builds and refits that may not skip the
// summaries' stores and loads, which would otherwise add 3 words per inner node to the climb's
// device traffic for nothing.
fn collapsing() -> bool {
    return (seg.flags & FLAG_PRIMITIVE_REFS) == 0u && seg.max_leaf > 1u;
}

fn subtree_at(node: u32) -> u32 {
    let n = seg.count;
    return BOXES_AT + 7u * (n - 1u) + 3u * node;
}

fn store_subtree(node: u32, s: Subtree) {
    let at = subtree_at(node);
    atomicStore(&work[seg.work_base + at], bitcast<u32>(s.cost));
    atomicStore(&work[seg.work_base + at + 1u], subtree_word(s));
    atomicStore(&work[seg.work_base + at + 2u], s.first);
}

fn load_subtree(node: u32) -> Subtree {
    let at = subtree_at(node);
    return subtree_from(atomicLoad(&work[seg.work_base + at]), atomicLoad(&work[seg.work_base + at + 1u]),
                        atomicLoad(&work[seg.work_base + at + 2u]));
}

// The ref a node stores for child `c` (topology encoding) with summary `s`: a collapsed inner
// child becomes a leaf of its whole range (count - 1 in bits 28..30).
fn child_ref(c: u32, s: Subtree) -> u32 {
    if (c & LEAF_BIT) == 0u && s.collapsed {
        return LEAF_BIT | ((s.count - 1u) << 28u) | s.first;
    }
    return out_ref(c);
}

// Parent ref (index | PARENT_LOCAL_BIT) of a node in topology encoding (n >= 2).
fn parent_ref(node: u32) -> u32 {
    let n = seg.count;
    if (node & LEAF_BIT) != 0u {
        return topology[seg.topo_base + 3u * (n - 1u) + (node & 0x7fffffffu)];
    }
    return topology[seg.topo_base + 2u * (n - 1u) + node];
}

// One invocation's climb: its current node (topology encoding: leaf bit + sorted position, or
// inner index), that subtree's box and SAH summary, and the node's parent ref (meaningful while
// climbing: the root is never the current node then).
struct Climber {
    node: u32,
    bx: Box,
    sub: Subtree,
    pref: u32,
    climbing: bool,
}

// The sibling of the climber's node under a parent whose children are `lc`, `rc`.
fn sibling(c: Climber, lc: u32, rc: u32) -> u32 {
    return select(lc, rc, lc == c.node);
}

// The second arriver at `parent` (children `lc`, `rc`, parent ref `up`) joins its subtree with
// the sibling's (box `sb`, summary `ss`), writes the parent's node and moves up to it, or stops
// at the root. Every phase of the climb ends a step this way; they differ in where the sibling
// and the topology come from.
fn climb_up(c: ptr<function, Climber>, parent: u32, lc: u32, rc: u32, sb: Box, ss: Subtree,
            up: u32) {
    var lb = sb;
    var ls = ss;
    var rb = (*c).bx;
    var rs = (*c).sub;
    if lc == (*c).node {
        lb = (*c).bx;
        ls = (*c).sub;
        rb = sb;
        rs = ss;
    }
    write_node(parent, lb, child_ref(lc, ls), rb, child_ref(rc, rs));
    (*c).bx = union_box(lb, rb);
    (*c).sub = join_subtrees((*c).bx, ls, rs);
    (*c).node = parent;
    if parent == 0u {
        write_bounds((*c).bx);
        (*c).climbing = false;
    } else {
        (*c).pref = up;
    }
}

// Phase 1 of the climb: per block-local inner node (slot = index - block start, < WG, since a
// Karras node's index is one end of its leaf range), its box (6 words) and SAH summary
// (3 words), and its arrival counter.
var<workgroup> wg_boxes: array<f32, 1536>;
var<workgroup> wg_subtrees: array<u32, 768>;
var<workgroup> wg_arrival: array<atomic<u32>, 256>;

fn wg_store(slot: u32, b: Box, s: Subtree) {
    let at = 6u * slot;
    wg_boxes[at] = b.lo.x;
    wg_boxes[at + 1u] = b.lo.y;
    wg_boxes[at + 2u] = b.lo.z;
    wg_boxes[at + 3u] = b.hi.x;
    wg_boxes[at + 4u] = b.hi.y;
    wg_boxes[at + 5u] = b.hi.z;
    if collapsing() {
        wg_subtrees[3u * slot] = bitcast<u32>(s.cost);
        wg_subtrees[3u * slot + 1u] = subtree_word(s);
        wg_subtrees[3u * slot + 2u] = s.first;
    }
}

// Box of child ref c of a block-local node: a leaf's from the input, an inner node's from
// workgroup memory.
fn wg_child_box(c: u32, block: u32) -> Box {
    if (c & LEAF_BIT) != 0u {
        return leaf_box(c & 0x7fffffffu);
    }
    let at = 6u * (c - block);
    return Box(vec3<f32>(wg_boxes[at], wg_boxes[at + 1u], wg_boxes[at + 2u]),
               vec3<f32>(wg_boxes[at + 3u], wg_boxes[at + 4u], wg_boxes[at + 5u]));
}

fn wg_child_subtree(c: u32, b: Box, block: u32) -> Subtree {
    if (c & LEAF_BIT) != 0u || !collapsing() {
        return leaf_subtree(c & 0x7fffffffu, b);
    }
    let at = 3u * (c - block);
    return subtree_from(wg_subtrees[at], wg_subtrees[at + 1u], wg_subtrees[at + 2u]);
}

@compute @workgroup_size(256)
fn lbvh_climb(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
              @builtin(num_workgroups) nwg: vec3<u32>) {
    seg = params;
    let n = params.count;
    let k = linear_id(lid, wid, nwg);
    // Fewer than two primitives: no inner nodes. (`n` is uniform, so this return keeps the rest
    // in uniform control flow.)
    if n < 2u {
        write_tiny_root(k);
        return;
    }
    var c = leaf_climber(k);

    // Phase 1, in workgroup memory: the nodes whose leaves all lie in this workgroup's block
    // (PARENT_LOCAL_BIT) have both children's climbers here, so their arrivals and boxes need
    // only workgroup barriers, not the device-scope fences of phase 2. Most inner nodes are
    // such nodes; a node straddling a block boundary is the exception (a node of s leaves
    // straddles one with probability about s / WG).
    let block = k - lid;
    atomicStore(&wg_arrival[lid], 0u);
    loop {
        let local = c.climbing && (c.pref & PARENT_LOCAL_BIT) != 0u;
        // Its first barrier also orders the arrival counters' clearing before their first use.
        if !wg_any(local, lid) {
            break;
        }
        let parent = c.pref & PARENT_INDEX_MASK;
        if local {
            if (c.node & LEAF_BIT) == 0u {
                wg_store(c.node - block, c.bx, c.sub);
            }
            // First to arrive: the sibling's climber (in this workgroup) takes over.
            c.climbing = atomicAdd(&wg_arrival[parent - block], 1u) != 0u;
        }
        // The first arriver's stores above happen-before the second's loads below, whichever
        // round the second arrives in.
        workgroupBarrier();
        if local && c.climbing {
            let lc = topology[seg.topo_base + 2u * parent];
            let rc = topology[seg.topo_base + 2u * parent + 1u];
            let sib = sibling(c, lc, rc);
            let sb = wg_child_box(sib, block);
            climb_up(&c, parent, lc, rc, sb, wg_child_subtree(sib, sb, block),
                     parent_ref(parent));
        }
    }

    climb_across(&c, lid);
}

// The whole BVH of fewer than two primitives: one invocation writes the fixed-shape root.
fn write_tiny_root(k: u32) {
    let n = seg.count;
    if k == 0u {
        let none = empty_box();
        var l = none;
        var lref = LEAF_BIT;
        if n == 1u {
            l = leaf_box(0u);
            lref = out_ref(LEAF_BIT);
        }
        write_node(0u, l, lref, none, LEAF_BIT);
        write_bounds(l);
    }
}

// The climber of leaf k (not climbing when k is past the primitives).
fn leaf_climber(k: u32) -> Climber {
    var c: Climber;
    c.climbing = k < seg.count;
    c.node = LEAF_BIT | k;
    c.bx = empty_box();
    c.pref = NO_PARENT;
    if c.climbing {
        c.bx = leaf_box(k);
        c.pref = parent_ref(c.node);
    }
    c.sub = leaf_subtree(k, c.bx);
    return c;
}

// The climb's device-scope phase: every climber left has a parent that straddles blocks (and so
// has every ancestor of it), or the topology has no block structure at all (a clustered tree's
// refit). Every invocation of the workgroup must call it (it has barriers).
fn climb_across(c: ptr<function, Climber>, lid: u32) {
    let arrival_at = BOXES_AT + 6u * (seg.count - 1u);
    loop {
        // Uniform trip count: continue while anyone in the workgroup is still climbing.
        if !wg_any((*c).climbing, lid) {
            break;
        }

        let parent = (*c).pref & PARENT_INDEX_MASK;
        // The parent's topology does not depend on who arrives second: loaded before the
        // fences, its latency overlaps theirs instead of following them.
        var lc = 0u;
        var rc = 0u;
        var up = NO_PARENT;
        if (*c).climbing {
            lc = topology[seg.topo_base + 2u * parent];
            rc = topology[seg.topo_base + 2u * parent + 1u];
            up = parent_ref(parent);
        }
        if (*c).climbing && ((*c).node & LEAF_BIT) == 0u {
            // Inner boxes are published for the sibling's climber (leaves are re-read from the
            // input instead).
            store_box((*c).node, (*c).bx);
            if collapsing() {
                store_subtree((*c).node, (*c).sub);
            }
        }
        // Release: the box above before the arrival below.
        storageBarrier();
        if (*c).climbing {
            let before = atomicAdd(&work[seg.work_base + arrival_at + parent], 1u);
            // First to arrive: the sibling's box may not exist yet; its climber takes over.
            (*c).climbing = before != 0u;
        }
        // Acquire: the sibling's box (stored before its arrival) is visible below.
        storageBarrier();
        if (*c).climbing {
            let sib = sibling(*c, lc, rc);
            let sb = child_box(sib);
            climb_up(c, parent, lc, rc, sb, child_subtree(sib, sb), up);
        }
    }
}
