// Clustered BVH build over the LBVH's Morton order: locally-ordered clustering (PLOC, Meister &
// Bittner 2018) done hierarchically while climbing the Karras tree, after H-PLOC (Benthin et al.
// 2024). Imports scene/lbvh/climb (its boxes, SAH summaries, node writer and workgroup vote);
// driven by src/scene/lbvh/mod.rs, which documents the pass order.
//
// Entry point (32 invocations, one per Karras inner node; the Karras hierarchy of lbvh_hierarchy
// is bound at `topology`, base 0, with its range ends):
//   hploc_climb  climbs the Karras tree bottom-up like lbvh_climb (the second arriver at a node
//                goes on), from the nodes that merge: a node's clusters are its leaves while it
//                covers at most HP_KEEP of them; at every node covering more, and at the root,
//                the clusters of its two children (at most 2 HP_KEEP) are merged by PLOC in
//                workgroup memory until HP_KEEP remain (one at the root), one node at a time, by
//                all 32 invocations.
//                Each merge makes one node of the output tree, written in the final node format
//                (boxes, SAH leaf collapsing) and, in `topo_out`, in the topology format of
//                scene/lbvh/common.wgsl (so lbvh_climb refits it).
//
// Why 32 invocations: a merge needs at most 32 lanes, and the climbers of a workgroup step
// through every merge's barriers together. In workgroups of 256 (eight merges side by side),
// every merge waited for the other seven slices' rounds, and the upper levels, with one climber
// left, held 256 lanes; with 32 the climb measured faster on the H100, and faster than two
// slices of 32 a workgroup (docs/decisions/hploc-climb.md). Starting the climbers at the
// merging nodes instead of the leaves (no exchange through device memory on the levels of at
// most HP_KEEP leaves) saves more.
//
// Why clusters: a Karras node splits at the highest differing Morton bit, wherever the geometry
// is; PLOC pairs each cluster with the one whose union box is smallest among its neighbours in
// Morton order, so boxes hug the geometry (SAH cost and node visits per ray drop, most on
// scenes whose parts are far apart in Morton order, like architecture).
//
// `work` layout (u32 words, all accessed atomically; n primitives):
//   [0, 6)                        centroid bounds (lbvh_bounds)
//   [8, 8 + 6 (n-1))              cluster lists' boxes: list slot K's at 8 + 6 K
//   [8 + 6 (n-1), 8 + 7 (n-1))    per Karras node P: the first arriver's far range end + 1
//                                 (cleared before the climb; 0 = nobody arrived yet)
//   [8 + 7 (n-1), 8 + 10 (n-1))   cluster lists' SAH summaries (as lbvh_climb's), by list slot
//   [8 + 10 (n-1), 8 + 11 (n-1))  per Karras node P covering > HP_KEEP leaves: its cluster count
//   [8 + 11 (n-1), 8 + 12 (n-1) + 1)
//                                 cluster lists: such a node's clusters from its first sorted
//                                 position (output node index, or LEAF_BIT | sorted position);
//                                 slots above n - 2 are never used (a listed node covers more
//                                 than HP_KEEP leaves, the root one cluster at slot 0)
//   [8 + 12 (n-1) + 1, 8 + 13 (n-1) + 2)
//                                 free-slot lists: such a node's unused output slots (one fewer
//                                 than its clusters) from its first sorted position
//
// Output node slots: the Karras subtree over sorted leaves [lo, hi] holds hi - lo inner nodes,
// whose indices are a set S of hi - lo numbers in [lo, hi] (the node's own index is lo or hi; a
// left child [lo, s] has index s and S = [lo + 1, s], a right child [s + 1, hi] has index s + 1
// and S = [s + 1, hi - 1]). Its c clusters took hi - lo + 1 - c merges, so c - 1 slots of S stay
// free. A merge at node P uses its children's free slots, then P's own index: cl - 1 + cr - 1 +
// 1 slots for the cl + cr - cp merges it makes (cp >= 1 clusters stay), and leaves cp - 1 free
// for its parent. Every slot is used once; the root (index 0, one cluster) uses all of its
// pool, its own index last, so its last merge, the tree's root, is node 0, where traversal
// starts. Merges take slots in the order of their lanes, so the tree is the same on every
// build of the same input (no global counter; its contention cost nothing measurable).

#import scene/lbvh/climb

// Invocations of the climb: the most clusters one merge holds.
const HP_WG: u32 = 32u;
// Clusters kept by a node that covers more leaves than this.
const HP_KEEP: u32 = 16u;
// Neighbour search radius in cluster order (about the Morton order of the clusters' leaves).
// A smaller radius builds faster in workgroups of 256 but leaves a worse tree (the apartment
// baked into one mesh traced measurably slower at 8 than at 32); a fast-trace build spends the
// time. In workgroups of 32 a smaller radius saves almost nothing (measured on the H100; see
// docs/decisions/hploc-climb.md).
const HP_RADIUS: u32 = 16u;
const HP_NONE: u32 = 0xFFFFFFFFu;

// The merge running now: its parameters (HP_INFO words), the owner of its node, the cluster
// count and goal, the lanes merging this round and those whose clusters survive it (one bit
// each), and the first pool slot this round's merges take.
const HP_INFO: u32 = 6u;
var<workgroup> hp_owner: atomic<u32>;
var<workgroup> hp_info: array<u32, HP_INFO>;
var<workgroup> hp_count: u32;
var<workgroup> hp_goal: u32;
var<workgroup> hp_merges: atomic<u32>;
var<workgroup> hp_kept: atomic<u32>;
var<workgroup> hp_base: u32;
var<workgroup> hp_segment: u32;
// The output slots the merge may use (see the layout notes).
var<workgroup> hp_pool: array<u32, HP_WG>;
// Per lane: the cluster it holds (ref, box, SAH summary) and its nearest neighbour.
var<workgroup> hp_ref: array<u32, HP_WG>;
var<workgroup> hp_box: array<f32, 192>;
var<workgroup> hp_sub: array<u32, 96>;
var<workgroup> hp_nn: array<u32, HP_WG>;

// Whether the merge still has more clusters than its goal (uniform; one barrier). Reads what
// lane 0 stored before the caller's last barrier.
fn hp_merging(lane: u32) -> bool {
    if lane == 0u {
        wg_go = select(0u, 1u, hp_count > hp_goal);
    }
    return workgroupUniformLoad(&wg_go) != 0u;
}

fn hp_xchg_at() -> u32 {
    return BOXES_AT + 6u * (seg.count - 1u);
}

fn hp_counts_at() -> u32 {
    return BOXES_AT + 10u * (seg.count - 1u);
}

fn hp_lists_at() -> u32 {
    return BOXES_AT + 11u * (seg.count - 1u);
}

fn hp_free_at() -> u32 {
    return BOXES_AT + 12u * (seg.count - 1u) + 1u;
}

// Karras parent of inner node `node` (the hierarchy is at base 0 of `topology`).
fn hp_karras_parent(node: u32) -> u32 {
    return topology[seg.karras_base + 2u * (seg.count - 1u) + node] & PARENT_INDEX_MASK;
}

// The other end of inner Karras node `node`'s leaf range (it starts or ends at its index), as
// lbvh_hierarchy stored it (range_ends_at, here at base 0).
fn hp_range_end(node: u32) -> u32 {
    return topology[seg.karras_base + 4u * seg.count - 3u + node];
}

// Leaves covered by Karras child `r` (topology encoding).
fn hp_child_size(r: u32) -> u32 {
    if (r & LEAF_BIT) != 0u {
        return 1u;
    }
    let end = hp_range_end(r);
    return max(end, r) - min(end, r) + 1u;
}

// A cluster as one lane holds it.
struct Cluster {
    r: u32,
    bx: Box,
    sub: Subtree,
}

// The cluster at sorted position `k` of a child's range: the leaf itself where the child covers
// at most HP_KEEP leaves, else the child's list entry (ref, box and summary side by side, so
// all three loads are in flight together).
fn hp_load(k: u32, listed: bool) -> Cluster {
    if listed {
        return Cluster(atomicLoad(&work[seg.work_base + hp_lists_at() + k]), load_box(k), load_subtree(k));
    }
    let b = leaf_box(k);
    return Cluster(LEAF_BIT | k, b, leaf_subtree(k, b));
}

fn hp_put(li: u32, c: Cluster) {
    hp_ref[li] = c.r;
    let at = 6u * li;
    hp_box[at] = c.bx.lo.x;
    hp_box[at + 1u] = c.bx.lo.y;
    hp_box[at + 2u] = c.bx.lo.z;
    hp_box[at + 3u] = c.bx.hi.x;
    hp_box[at + 4u] = c.bx.hi.y;
    hp_box[at + 5u] = c.bx.hi.z;
    hp_sub[3u * li] = bitcast<u32>(c.sub.cost);
    hp_sub[3u * li + 1u] = subtree_word(c.sub);
    hp_sub[3u * li + 2u] = c.sub.first;
}

fn hp_box_at(li: u32) -> Box {
    let at = 6u * li;
    return Box(vec3<f32>(hp_box[at], hp_box[at + 1u], hp_box[at + 2u]),
               vec3<f32>(hp_box[at + 3u], hp_box[at + 4u], hp_box[at + 5u]));
}

fn hp_get(li: u32) -> Cluster {
    return Cluster(hp_ref[li], hp_box_at(li),
                   subtree_from(hp_sub[3u * li], hp_sub[3u * li + 1u], hp_sub[3u * li + 2u]));
}

// Surface area for the neighbour search: extents clamped to 1e18 so the result is always finite
// (never inf, never inf * 0 = NaN): the comparisons below must be a total order for every round
// to merge (see hp_tie_before).
fn hp_area(b: Box) -> f32 {
    let d = clamp(b.hi - b.lo, vec3<f32>(0.0), vec3<f32>(1e18));
    return 2.0 * (d.x * d.y + d.y * d.z + d.z * d.x);
}

// Whether candidate `m` ranks before `best` as lane j's neighbour when their merged areas are
// equal. The order is a function of the pair alone (so the pair with the smallest key overall is
// always mutual: every round merges at least once), and prefers the partner j ^ 1, then the
// nearest index: identical boxes then merge in balanced pairs, not in a chain.
fn hp_tie_before(j: u32, m: u32, best: u32) -> bool {
    let pm = select(1u, 0u, m == (j ^ 1u));
    let pb = select(1u, 0u, best == (j ^ 1u));
    if pm != pb {
        return pm < pb;
    }
    let dm = select(j - m, m - j, m > j);
    let db = select(j - best, best - j, best > j);
    if dm != db {
        return dm < db;
    }
    return min(j, m) < min(j, best);
}

// The output-topology parent slot of child ref `r`.
fn hp_parent_slot(r: u32) -> u32 {
    let n = seg.count;
    if (r & LEAF_BIT) != 0u {
        return seg.topo_base + 3u * (n - 1u) + (r & 0x7fffffffu);
    }
    return seg.topo_base + 2u * (n - 1u) + r;
}

// One climber: its Karras node (topology encoding), the node's leaf range [lo, hi], and the split
// of that range between its children (the last leaf of the left child).
struct HpClimber {
    node: u32,
    lo: u32,
    hi: u32,
    split: u32,
    climbing: bool,
    // The node's clusters must be merged (it covers more than HP_KEEP leaves, or is the root).
    pending: bool,
}

@compute @workgroup_size(32)
fn hploc_climb(@builtin(local_invocation_index) lane: u32, @builtin(workgroup_id) wid: vec3<u32>,
               @builtin(num_workgroups) nwg: vec3<u32>) {
    // The build of the batch this workgroup's leaves belong to (builds start at multiples of WG,
    // so at multiples of HP_WG), read through workgroup memory so that `n` is uniform.
    let first = (wid.y * nwg.x + wid.x) * HP_WG;
    if lane == 0u {
        hp_segment = segment_at(first);
    }
    let s = workgroupUniformLoad(&hp_segment);
    seg = segs[s];
    let n = segs[s].count;
    let k = first - seg.key_base + lane;
    // Below two primitives there are no inner nodes: the root alone (a batch's tiny builds;
    // a single build of one primitive runs lbvh_climb instead).
    if n < 2u {
        write_tiny_root(k);
        return;
    }
    let xchg = hp_xchg_at();
    let counts = hp_counts_at();
    let lists = hp_lists_at();
    let free = hp_free_at();

    // Climbers start at the nodes that merge (more than HP_KEEP leaves, or the root), one
    // invocation per Karras inner node: below them there is nothing to do (a node of at most
    // HP_KEEP leaves keeps them as its clusters). A node whose children are both that small
    // starts at once; one with a single small child lets that child arrive for it here, so the
    // other child's climber, arriving second, goes on (or this invocation, if it arrives
    // second).
    var c: HpClimber;
    c.climbing = false;
    c.pending = false;
    if k + 1u < n {
        let end = hp_range_end(k);
        c.node = k;
        c.lo = min(k, end);
        c.hi = max(k, end);
        let size = c.hi - c.lo + 1u;
        if size > HP_KEEP || size == n {
            let l = topology[seg.karras_base + 2u * k];
            c.split = l & 0x7fffffffu;
            let small_l = hp_child_size(l) <= HP_KEEP;
            let small_r = hp_child_size(topology[seg.karras_base + 2u * k + 1u]) <= HP_KEEP;
            c.climbing = small_l && small_r;
            if small_l != small_r {
                let before = atomicExchange(&work[seg.work_base + xchg + k], select(c.hi, c.lo, small_l) + 1u);
                c.climbing = before != 0u;
            }
            c.pending = c.climbing;
        }
    }
    // Acquire: a climber that arrived second sees the other child's clusters below.
    storageBarrier();

    loop {
        // The merges of this step, one node at a time.
        loop {
            if lane == 0u {
                atomicStore(&hp_owner, HP_NONE);
            }
            workgroupBarrier();
            if c.pending {
                atomicMin(&hp_owner, lane);
            }
            workgroupBarrier();
            if lane == 0u {
                wg_go = atomicLoad(&hp_owner);
            }
            let owner = workgroupUniformLoad(&wg_go);
            if owner == HP_NONE {
                break;
            }
            if owner == lane {
                // Cluster counts of the two children: a child covering at most HP_KEEP leaves
                // has them as its clusters; a larger one stored its count (it is an inner Karras
                // node: the left child's index is the split, the right one's the split + 1).
                let lsize = c.split - c.lo + 1u;
                let rsize = c.hi - c.split;
                hp_info[0] = c.lo;
                hp_info[1] = c.split;
                hp_info[2] = select(lsize, atomicLoad(&work[seg.work_base + counts + c.split]), lsize > HP_KEEP);
                hp_info[3] = select(rsize, atomicLoad(&work[seg.work_base + counts + c.split + 1u]), rsize > HP_KEEP);
                hp_info[4] = select(0u, 1u, lsize > HP_KEEP) | select(0u, 2u, rsize > HP_KEEP)
                    | select(0u, 4u, c.hi - c.lo + 1u == n);
                hp_info[5] = c.node;
                c.pending = false;
            }
            // Workgroup memory (the info) and storage (the lists the owner's acquire made
            // visible) both hand over to the other lanes here.
            workgroupBarrier();
            storageBarrier();
            let lo = hp_info[0];
            let split = hp_info[1];
            let lcount = hp_info[2];
            let rcount = hp_info[3];
            let flags = hp_info[4];
            let node = hp_info[5];
            let root = (flags & 4u) != 0u;
            let total = lcount + rcount;
            var mine_c: Cluster;
            if lane < total {
                let left = lane < lcount;
                mine_c = hp_load(select(split + 1u + lane - lcount, lo + lane, left),
                                 (flags & select(2u, 1u, left)) != 0u);
                hp_put(lane, mine_c);
            }
            if lane + 1u < total {
                // The pool: the children's free slots (a small child's are its whole index
                // set), then the node's own index (see the layout notes).
                var slot = node;
                if lane + 1u < lcount {
                    slot = select(lo + 1u + lane, atomicLoad(&work[seg.work_base + free + lo + lane]),
                                  (flags & 1u) != 0u);
                } else if lane + 2u < total {
                    let j = lane + 1u - lcount;
                    slot = select(split + 1u + j, atomicLoad(&work[seg.work_base + free + split + 1u + j]),
                                  (flags & 2u) != 0u);
                }
                hp_pool[lane] = slot;
            }
            if lane == 0u {
                hp_count = total;
                hp_goal = select(HP_KEEP, 1u, root);
                hp_base = 0u;
                atomicStore(&hp_merges, 0u);
            }
            workgroupBarrier();

            // PLOC rounds: nearest neighbours, mutual pairs merge, survivors close ranks. Every
            // round merges at least once (see hp_tie_before), so HP_WG rounds always suffice.
            for (var round = 0u; round < HP_WG; round++) {
                if !hp_merging(lane) {
                    break;
                }
                let count = hp_count;
                let holds = lane < count;
                if lane == 0u {
                    atomicStore(&hp_kept, 0u);
                }
                if holds {
                    mine_c = hp_get(lane);
                    var best = HP_NONE;
                    var best_area = 0.0;
                    let m_end = min(count, lane + HP_RADIUS + 1u);
                    for (var m = select(0u, lane - HP_RADIUS, lane > HP_RADIUS); m < m_end; m++) {
                        if m == lane {
                            continue;
                        }
                        let a = hp_area(union_box(mine_c.bx, hp_box_at(m)));
                        if best == HP_NONE || a < best_area
                            || (a == best_area && hp_tie_before(lane, m, best)) {
                            best = m;
                            best_area = a;
                        }
                    }
                    hp_nn[lane] = best;
                }
                workgroupBarrier();
                var partner = HP_NONE;
                var keep = holds;
                if holds {
                    let m = hp_nn[lane];
                    if hp_nn[m] == lane {
                        if lane < m {
                            partner = m;
                            atomicOr(&hp_merges, 1u << lane);
                        } else {
                            keep = false;
                        }
                    }
                }
                if keep {
                    atomicOr(&hp_kept, 1u << lane);
                }
                workgroupBarrier();
                let mergers = atomicLoad(&hp_merges);
                if partner != HP_NONE {
                    // Slots in the order of the merging lanes: the build is deterministic.
                    let o = hp_get(partner);
                    let x = hp_pool[hp_base + countOneBits(mergers & ((1u << lane) - 1u))];
                    let b = union_box(mine_c.bx, o.bx);
                    let s = join_subtrees(b, mine_c.sub, o.sub);
                    write_node(x, mine_c.bx, child_ref(mine_c.r, mine_c.sub), o.bx,
                               child_ref(o.r, o.sub));
                    topo_out[seg.topo_base + 2u * x] = mine_c.r;
                    topo_out[seg.topo_base + 2u * x + 1u] = o.r;
                    topo_out[hp_parent_slot(mine_c.r)] = x;
                    topo_out[hp_parent_slot(o.r)] = x;
                    mine_c = Cluster(x, b, s);
                }
                // Every read of this round's slots is above.
                workgroupBarrier();
                let kept = atomicLoad(&hp_kept);
                if keep {
                    hp_put(countOneBits(kept & ((1u << lane) - 1u)), mine_c);
                }
                if lane == 0u {
                    hp_count = countOneBits(kept);
                    hp_base += countOneBits(mergers);
                    atomicStore(&hp_merges, 0u);
                }
                workgroupBarrier();
            }
            // The node's clusters, for its sibling's climber (or the root's box): each lane
            // takes up the cluster now at its index; the slots left (one fewer) go with them.
            let left_count = hp_count;
            if lane < left_count {
                mine_c = hp_get(lane);
                atomicStore(&work[seg.work_base + lists + lo + lane], mine_c.r);
                store_box(lo + lane, mine_c.bx);
                store_subtree(lo + lane, mine_c.sub);
            }
            if lane + 1u < left_count {
                atomicStore(&work[seg.work_base + free + lo + lane], hp_pool[hp_base + lane]);
            }
            if lane == 0u {
                atomicStore(&work[seg.work_base + counts + node], left_count);
                if root {
                    write_bounds(mine_c.bx);
                    topo_out[seg.topo_base + 2u * (n - 1u)] = NO_PARENT;
                }
            }
            if owner == lane && root {
                c.climbing = false;
            }
        }

        if !wg_any(c.climbing, lane) {
            break;
        }
        // Release: the clusters this node's merge stored (by any lane of the workgroup) before
        // the exchange below tells the sibling's climber about them.
        storageBarrier();
        if c.climbing {
            let p = hp_karras_parent(c.node);
            // A left child [lo, s] is inner node s, a right one [s + 1, hi] node s + 1.
            let left = c.node == c.hi;
            // The sibling needs the end of this node's range it cannot know: the left child's
            // first leaf, the right child's last.
            let before = atomicExchange(&work[seg.work_base + xchg + p], select(c.hi, c.lo, left) + 1u);
            // First to arrive: the sibling's climber takes over.
            c.climbing = before != 0u;
            if c.climbing {
                let other = before - 1u;
                c.split = select(c.lo - 1u, c.hi, left);
                c.lo = min(c.lo, other);
                c.hi = max(c.hi, other);
                c.node = p;
                c.pending = true;
            }
        }
        // Acquire: the sibling's clusters (stored before its exchange) are visible below.
        storageBarrier();
    }
}
