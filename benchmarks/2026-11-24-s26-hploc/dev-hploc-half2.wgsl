// Clustered BVH build over the LBVH's Morton order: locally-ordered clustering (PLOC, Meister &
// Bittner 2018) done hierarchically while climbing the Karras tree, after H-PLOC (Benthin et al.
// 2024). Appended to lbvh.wgsl (its boxes, SAH summaries, node writer and workgroup vote);
// driven by src/scene/lbvh.rs, which documents the pass order.
//
// Entry point (256 invocations, one per sorted leaf; the Karras hierarchy of lbvh_hierarchy is
// bound at `topology`, base 0):
//   hploc_climb  climbs the Karras tree bottom-up like lbvh_climb (the second arriver at a node
//                goes on). A node's clusters are its leaves while it covers at most HP_KEEP of
//                them; at every node covering more, and at the root, the clusters of its two
//                children (at most 2 HP_KEEP) are merged by PLOC in workgroup memory until
//                HP_KEEP remain (one at the root). Each merge makes one node of the output tree,
//                written in the final node format (boxes, SAH leaf collapsing) and, in
//                `topo_out`, in the topology format of lbvh.wgsl (so lbvh_climb refits it).
//
// Why clusters: a Karras node splits at the highest differing Morton bit, wherever the geometry
// is; PLOC pairs each cluster with the one whose union box is smallest among its neighbours in
// Morton order, so boxes hug the geometry (SAH cost and node visits per ray drop, most on
// scenes whose parts are far apart in Morton order, like architecture).
//
// `work` layout (u32 words, all accessed atomically; n primitives):
//   [0, 6)                        centroid bounds (lbvh_bounds)
//   6                             output nodes allocated so far (cleared before the climb)
//   [8, 8 + 6 (n-1))              box of output node X at 8 + 6 X
//   [8 + 6 (n-1), 8 + 7 (n-1))    per Karras node P: the first arriver's far range end + 1
//                                 (cleared before the climb; 0 = nobody arrived yet)
//   [8 + 7 (n-1), 8 + 10 (n-1))   SAH summary of output node X (as lbvh_climb's)
//   [8 + 10 (n-1), 8 + 11 (n-1))  per Karras node P covering > HP_KEEP leaves: its cluster count
//   [8 + 11 (n-1), 8 + 12 (n-1) + 1)
//                                 cluster lists: such a node's clusters from its first sorted
//                                 position (output node index, or LEAF_BIT | sorted position)
//
// Output node indices are handed out from the top (n - 2 down to 0); the root's last merge is
// the last one made anywhere (everything else happened in its subtrees before), so the root is
// node 0, where traversal starts.

@group(0) @binding(9) var<storage, read_write> topo_out: array<u32>;

// Lanes of one merge (a slice of the workgroup): the most clusters one merge holds.
const HP_SLICE: u32 = 32u;
const HP_SLICES: u32 = 1u;
// Clusters kept by a node that covers more leaves than this.
const HP_KEEP: u32 = 16u;
// Neighbour search radius in cluster order (about the Morton order of the clusters' leaves).
// Measured on the H100 (BENCHMARKS.md, session 21), dragon climb / SAH ratio, apartment's
// largest mesh SAH ratio: the whole slice (32) 2.11 ms / 1.113 / 1.093; 16: 2.11 / 1.103 / 0.999;
// 8: 1.80 / 1.110 / 1.061; 4: 1.32 / 1.108 / 1.062. The apartment baked into one mesh traces 6 %
// slower at 8 than at 32 (peer workload 1481 against 1571 Mrays/s): a fast-trace build spends
// the time.
const HP_RADIUS: u32 = 16u;
const HP_NONE: u32 = 0xFFFFFFFFu;
const HP_COUNTER: u32 = 6u;

// Per slice: the lane whose merge runs now, that merge's parameters (HP_INFO words), the cluster
// count, and how many merges the current round makes.
const HP_INFO: u32 = 8u;
var<workgroup> hp_owner: array<atomic<u32>, HP_SLICES>;
var<workgroup> hp_info: array<u32, 8>;
var<workgroup> hp_count: array<u32, HP_SLICES>;
var<workgroup> hp_merges: array<atomic<u32>, HP_SLICES>;
var<workgroup> hp_base: array<u32, HP_SLICES>;
// Per slice: the output node indices its merge may use (see hp_pool_entry).
var<workgroup> hp_pool: array<u32, 32>;
// Per lane: the cluster it holds (ref, box, SAH summary) and its nearest neighbour.
var<workgroup> hp_ref: array<u32, 32>;
var<workgroup> hp_lo: array<vec4<f32>, 32>;
var<workgroup> hp_hi: array<vec4<f32>, 32>;
// Merged area of lanes i and i + d (1 <= d <= HP_RADIUS) at (d - 1) * HP_SLICE + i: each pair's
// area is computed once, by its lower lane; lanes at one distance use consecutive words (no bank
// conflicts: the search steps all lanes through the same distance together).
var<workgroup> hp_pair: array<f32, 512>;
var<workgroup> hp_sub: array<u32, 96>;
var<workgroup> hp_nn: array<u32, 32>;
// Per slice: the goal of its merge (HP_NONE: no merge), and the lanes whose clusters survive
// the round (one bit each).
var<workgroup> hp_goal: array<u32, HP_SLICES>;
var<workgroup> hp_kept: array<atomic<u32>, HP_SLICES>;

// Whether any slice's merge still has more clusters than its goal (uniform; one barrier). Reads
// what the slices' first lanes stored before the caller's last barrier.
fn hp_any_merging(lid: u32) -> bool {
    if lid == 0u {
        var more = 0u;
        for (var s = 0u; s < HP_SLICES; s++) {
            more |= select(0u, 1u, hp_count[s] > hp_goal[s]);
        }
        wg_go = more;
    }
    return workgroupUniformLoad(&wg_go) != 0u;
}

fn hp_xchg_at() -> u32 {
    return BOXES_AT + 6u * (params.count - 1u);
}

fn hp_counts_at() -> u32 {
    return BOXES_AT + 10u * (params.count - 1u);
}

fn hp_lists_at() -> u32 {
    return BOXES_AT + 11u * (params.count - 1u);
}

fn hp_free_at() -> u32 {
    return BOXES_AT + 12u * (params.count - 1u) + 1u;
}

// Karras parent of a node in topology encoding (the hierarchy is at base 0 of `topology`).
fn hp_karras_parent(node: u32) -> u32 {
    let n = params.count;
    if (node & LEAF_BIT) != 0u {
        return topology[3u * (n - 1u) + (node & 0x7fffffffu)] & PARENT_INDEX_MASK;
    }
    return topology[2u * (n - 1u) + node] & PARENT_INDEX_MASK;
}

// A cluster as one lane holds it.
struct Cluster {
    r: u32,
    bx: Box,
    sub: Subtree,
}

// Cluster `r` from the input (a leaf) or from the output nodes made so far.
fn hp_load(r: u32) -> Cluster {
    if (r & LEAF_BIT) != 0u {
        let k = r & 0x7fffffffu;
        let b = leaf_box(k);
        return Cluster(r, b, leaf_subtree(k, b));
    }
    return Cluster(r, load_box(r), load_subtree(r));
}

fn hp_put(li: u32, c: Cluster) {
    hp_ref[li] = c.r;
    hp_lo[li] = vec4<f32>(c.bx.lo, 0.0);
    hp_hi[li] = vec4<f32>(c.bx.hi, 0.0);
    hp_sub[3u * li] = bitcast<u32>(c.sub.cost);
    hp_sub[3u * li + 1u] = subtree_word(c.sub);
    hp_sub[3u * li + 2u] = c.sub.first;
}

fn hp_box_at(li: u32) -> Box {
    return Box(hp_lo[li].xyz, hp_hi[li].xyz);
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
    let n = params.count;
    if (r & LEAF_BIT) != 0u {
        return params.topo_base + 3u * (n - 1u) + (r & 0x7fffffffu);
    }
    return params.topo_base + 2u * (n - 1u) + r;
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
fn hploc_climb(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
               @builtin(num_workgroups) nwg: vec3<u32>) {
    let n = params.count;
    // The driver runs lbvh_climb instead below two primitives; `n` is uniform.
    if n < 2u {
        return;
    }
    let k = (wid.y * nwg.x + wid.x) * HP_SLICE + lid;
    let slice = lid / HP_SLICE;
    let lane = lid % HP_SLICE;
    let sl = slice * HP_SLICE;
    let xchg = hp_xchg_at();
    let counts = hp_counts_at();
    let lists = hp_lists_at();
    let free = hp_free_at();

    var c: HpClimber;
    c.node = LEAF_BIT | k;
    c.lo = k;
    c.hi = k;
    c.split = k;
    c.climbing = k < n;
    c.pending = false;

    loop {
        if !wg_any(c.climbing, lid) {
            break;
        }
        // Release: the clusters this node's merge stored (by any lane of the workgroup) before
        // the exchange below tells the sibling's climber about them.
        storageBarrier();
        if c.climbing {
            let p = hp_karras_parent(c.node);
            let left = topology[2u * p] == c.node;
            // The sibling needs the end of this node's range it cannot know: the left child's
            // first leaf, the right child's last.
            let before = atomicExchange(&work[xchg + p], select(c.hi, c.lo, left) + 1u);
            // First to arrive: the sibling's climber takes over.
            c.climbing = before != 0u;
            if c.climbing {
                let other = before - 1u;
                c.split = select(c.lo - 1u, c.hi, left);
                c.lo = min(c.lo, other);
                c.hi = max(c.hi, other);
                c.node = p;
                c.pending = c.hi - c.lo + 1u > HP_KEEP || c.hi - c.lo + 1u == n;
            }
        }
        // Acquire: the sibling's clusters (stored before its exchange) are visible below.
        storageBarrier();

        // The merges of this step, one per slice at a time.
        loop {
            if lid < HP_SLICES {
                atomicStore(&hp_owner[lid], HP_NONE);
            }
            workgroupBarrier();
            if c.pending {
                atomicMin(&hp_owner[slice], lane);
            }
            workgroupBarrier();
            let owner = atomicLoad(&hp_owner[slice]);
            if !wg_any(owner != HP_NONE, lid) {
                break;
            }
            let mine = c.pending && owner == lane;
            if mine {
                // Cluster counts of the two children: a child covering at most HP_KEEP leaves
                // has them as its clusters; a larger one stored its count (it is an inner Karras
                // node: the left child's index is the split, the right one's the split + 1).
                let lsize = c.split - c.lo + 1u;
                let rsize = c.hi - c.split;
                let at = slice * HP_INFO;
                hp_info[at] = c.lo;
                hp_info[at + 1u] = c.split;
                hp_info[at + 2u] = select(lsize, atomicLoad(&work[counts + c.split]), lsize > HP_KEEP);
                hp_info[at + 3u] = select(rsize, atomicLoad(&work[counts + c.split + 1u]), rsize > HP_KEEP);
                hp_info[at + 4u] = select(0u, 1u, lsize > HP_KEEP) | select(0u, 2u, rsize > HP_KEEP)
                    | select(0u, 4u, c.hi - c.lo + 1u == n);
                hp_info[at + 5u] = c.node;
            }
            // Workgroup memory (the info) and storage (the lists the owner's acquire made
            // visible) both hand over to the slice's other lanes here.
            workgroupBarrier();
            storageBarrier();
            let busy = owner != HP_NONE;
            let at = slice * HP_INFO;
            let lo = hp_info[at];
            let split = hp_info[at + 1u];
            let lcount = hp_info[at + 2u];
            let rcount = hp_info[at + 3u];
            let flags = hp_info[at + 4u];
            let root = (flags & 4u) != 0u;
            let goal = select(HP_KEEP, 1u, root);
            let total = lcount + rcount;
            var mine_c: Cluster;
            if busy && lane < total {
                var r: u32;
                if lane < lcount {
                    r = select(LEAF_BIT | (lo + lane), atomicLoad(&work[lists + lo + lane]),
                               (flags & 1u) != 0u);
                } else {
                    let j = lane - lcount;
                    r = select(LEAF_BIT | (split + 1u + j),
                               atomicLoad(&work[lists + split + 1u + j]), (flags & 2u) != 0u);
                }
                mine_c = hp_load(r);
                hp_put(lid, mine_c);
            }
            if busy && lane + 1u < total {
                // Output slots: the children's unused ones, then the node's own Karras index
                // (see the layout notes: the root's last merge takes 0).
                var slot: u32;
                if lane + 1u < lcount {
                    slot = select(lo + 1u + lane, atomicLoad(&work[free + lo + lane]),
                                  (flags & 1u) != 0u);
                } else if lane + 2u < total {
                    let j = lane + 1u - lcount;
                    slot = select(split + 1u + j, atomicLoad(&work[free + split + 1u + j]),
                                  (flags & 2u) != 0u);
                } else {
                    slot = hp_info[at + 5u];
                }
                hp_pool[sl + lane] = slot;
            }
            if lane == 0u {
                hp_count[slice] = total;
                hp_goal[slice] = select(HP_NONE, goal, busy);
                hp_base[slice] = 0u;
                atomicStore(&hp_merges[slice], 0u);
            }
            workgroupBarrier();

            // PLOC rounds: nearest neighbours, mutual pairs merge, survivors close ranks. Every
            // round merges at least once (see hp_tie_before), so HP_SLICE rounds always suffice.
            // Six barriers a round: each costs the whole workgroup, busy slices or not.
            for (var round = 0u; round < HP_SLICE; round++) {
                if !hp_any_merging(lid) {
                    break;
                }
                let count = hp_count[slice];
                let merging = busy && count > goal;
                let holds = merging && lane < count;
                if lane == 0u {
                    atomicStore(&hp_kept[slice], 0u);
                }
                let m_end = min(count, lane + HP_RADIUS + 1u);
                if holds {
                    mine_c = hp_get(lid);
                    for (var m = lane + 1u; m < m_end; m++) {
                        hp_pair[(m - lane - 1u) * HP_SLICE + lane] =
                            hp_area(union_box(mine_c.bx, hp_box_at(sl + m)));
                    }
                }
                workgroupBarrier();
                if holds {
                    var best = HP_NONE;
                    var best_area = 0.0;
                    for (var m = select(0u, lane - HP_RADIUS, lane > HP_RADIUS); m < m_end; m++) {
                        if m == lane {
                            continue;
                        }
                        let a = hp_pair[select((lane - m - 1u) * HP_SLICE + m,
                                               (m - lane - 1u) * HP_SLICE + lane, m > lane)];
                        if best == HP_NONE || a < best_area
                            || (a == best_area && hp_tie_before(lane, m, best)) {
                            best = m;
                            best_area = a;
                        }
                    }
                    hp_nn[lid] = best;
                }
                workgroupBarrier();
                var partner = HP_NONE;
                var rank = 0u;
                var keep = holds;
                if holds {
                    let m = hp_nn[lid];
                    if hp_nn[sl + m] == lane {
                        if lane < m {
                            partner = m;
                            atomicOr(&hp_merges[slice], 1u << lane);
                        } else {
                            keep = false;
                        }
                    }
                }
                if keep {
                    atomicOr(&hp_kept[slice], 1u << lane);
                }
                workgroupBarrier();
                let mergers = atomicLoad(&hp_merges[slice]);
                if partner != HP_NONE {
                    // Slots in the order of the merging lanes: the build is deterministic.
                    rank = countOneBits(mergers & ((1u << lane) - 1u));
                    let o = hp_get(sl + partner);
                    let x = hp_pool[sl + hp_base[slice] + rank];
                    let b = union_box(mine_c.bx, o.bx);
                    let s = join_subtrees(b, mine_c.sub, o.sub);
                    write_node(x, mine_c.bx, child_ref(mine_c.r, mine_c.sub), o.bx,
                               child_ref(o.r, o.sub));
                    store_box(x, b);
                    store_subtree(x, s);
                    topo_out[params.topo_base + 2u * x] = mine_c.r;
                    topo_out[params.topo_base + 2u * x + 1u] = o.r;
                    topo_out[hp_parent_slot(mine_c.r)] = x;
                    topo_out[hp_parent_slot(o.r)] = x;
                    mine_c = Cluster(x, b, s);
                }
                // Every read of this round's slots is above.
                workgroupBarrier();
                if merging {
                    let kept = atomicLoad(&hp_kept[slice]);
                    if keep {
                        hp_put(sl + countOneBits(kept & ((1u << lane) - 1u)), mine_c);
                    }
                    if lane == 0u {
                        hp_count[slice] = countOneBits(kept);
                        hp_base[slice] += countOneBits(mergers);
                        atomicStore(&hp_merges[slice], 0u);
                    }
                }
                workgroupBarrier();
            }
            // The node's clusters, for its sibling's climber (or the root's box): each lane
            // takes up the cluster now at its index.
            let left_count = select(0u, hp_count[slice], busy);
            if lane < left_count {
                mine_c = hp_get(lid);
                atomicStore(&work[lists + lo + lane], mine_c.r);
            }
            // The slots left (one fewer than the clusters) go to the parent's merge.
            if lane + 1u < left_count {
                atomicStore(&work[free + lo + lane], hp_pool[sl + hp_base[slice] + lane]);
            }
            if busy && lane == 0u {
                atomicStore(&work[counts + hp_info[at + 5u]], left_count);
                if root {
                    write_bounds(mine_c.bx);
                    topo_out[params.topo_base + 2u * (n - 1u)] = NO_PARENT;
                }
            }
            if mine {
                c.pending = false;
                if root {
                    c.climbing = false;
                }
            }
        }
    }
}
