// Hierarchy (Karras 2012, section 4): inner node i covers a key range starting or ending at i.

#import scene/lbvh/common

// Length of the common prefix of sorted keys i and j, or -1 when j is outside [0, n). Equal keys
// fall back to the indices (32 + clz(i ^ j)), so duplicates still give a valid binary tree.
fn delta(i: i32, j: i32) -> i32 {
    let n = i32(seg.count);
    if j < 0 || j >= n {
        return -1;
    }
    let a = keys[seg.key_base + u32(i)];
    let b = keys[seg.key_base + u32(j)];
    if a == b {
        return 32 + i32(countLeadingZeros(u32(i) ^ u32(j)));
    }
    return i32(countLeadingZeros(a ^ b));
}

@compute @workgroup_size(256)
fn lbvh_hierarchy(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
                  @builtin(num_workgroups) nwg: vec3<u32>) {
    let pos = linear_id(lid, wid, nwg);
    seg = segs[segment_at(pos)];
    let k = pos - seg.key_base;
    let n = seg.count;
    if k >= n {
        return;
    }
    // One primitive is never sorted (no keys were made): its order is the identity. Sorted
    // values are positions of the batch: the build's own start taken off.
    order[seg.order_base + k] = select(values[pos] - seg.key_base, k, n < 2u);
    if k + 1u >= n {
        return; // n - 1 inner nodes
    }
    let i = i32(k);
    // The Karras tree goes to karras_base (topo_base unless the build is clustered).
    let inner_parents = seg.karras_base + 2u * (n - 1u);
    let leaf_parents = seg.karras_base + 3u * (n - 1u);
    if k == 0u {
        topology[inner_parents] = NO_PARENT;
    }
    // Direction of the range: towards the neighbour sharing the longer prefix.
    let d = select(-1, 1, delta(i, i + 1) - delta(i, i - 1) > 0);
    let delta_min = delta(i, i - d);
    // Upper bound of the range length, then binary search for the other end.
    var l_max = 2;
    while delta(i, i + l_max * d) > delta_min {
        l_max *= 2;
    }
    var l = 0;
    var t = l_max / 2;
    while t >= 1 {
        if delta(i, i + (l + t) * d) > delta_min {
            l += t;
        }
        t /= 2;
    }
    let j = i + l * d;
    // Split: the last position sharing more than the node's prefix with i.
    let delta_node = delta(i, j);
    var s = 0;
    var div = 2;
    t = (l + div - 1) / div;
    loop {
        if delta(i, i + (s + t) * d) > delta_node {
            s += t;
        }
        if t <= 1 {
            break;
        }
        div *= 2;
        t = (l + div - 1) / div;
    }
    let gamma = i + s * d + min(d, 0);
    let first = u32(min(i, j));
    let last = u32(max(i, j));
    let g = u32(gamma);
    var left = g;
    var right = g + 1u;
    // The children's parent ref says whether this node's leaves all lie in one climb
    // workgroup's block: the climb then joins it in workgroup memory (see lbvh_climb).
    let ref_k = k | select(0u, PARENT_LOCAL_BIT, first / WG == last / WG);
    if first == g {
        left = LEAF_BIT | g;
        topology[leaf_parents + g] = ref_k;
    } else {
        topology[inner_parents + g] = ref_k;
    }
    if last == g + 1u {
        right = LEAF_BIT | (g + 1u);
        topology[leaf_parents + g + 1u] = ref_k;
    } else {
        topology[inner_parents + g + 1u] = ref_k;
    }
    topology[seg.karras_base + 2u * k] = left;
    topology[seg.karras_base + 2u * k + 1u] = right;
    topology[range_ends_at() + k] = u32(j);
}
