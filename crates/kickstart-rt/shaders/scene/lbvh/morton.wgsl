// The sort keys: Morton keys of the primitives (lbvh_morton, and lbvh_morton_histogram with the
// radix sort's first histogram), and a batch's build keys between its two sorts.

#import scene/lbvh/common
#import gpu/digit_histogram

// Spreads the low 10 bits of v to every third bit.
fn spread3(v: u32) -> u32 {
    var x = v & 0x3ffu;
    x = (x | (x << 16u)) & 0x030000ffu;
    x = (x | (x << 8u)) & 0x0300f00fu;
    x = (x | (x << 4u)) & 0x030c30c3u;
    x = (x | (x << 2u)) & 0x09249249u;
    return x;
}

// Cell 0..cells-1 of c in [lo, hi]; a zero or non-finite extent, or a non-finite c, gives cell 0
// (such primitives still get a leaf; only their place in the order is arbitrary).
fn cell(c: f32, lo: f32, hi: f32, cells: f32) -> u32 {
    let extent = hi - lo;
    let t = (c - lo) / extent * cells;
    // Finite first: only then is the comparison meaningful (NaN may be assumed away).
    if !is_finite(extent) || !(extent > 0.0) || !is_finite(t) {
        return 0u;
    }
    return u32(clamp(t, 0.0, cells - 1.0));
}

@compute @workgroup_size(256)
fn lbvh_morton(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
               @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    // params.count: every position of the batch, the builds' padding included.
    if g >= params.count {
        return;
    }
    keys[g] = batch_morton_key(g);
    values[g] = g;
}

// The sort key of position g of a batch: its build's Morton key of primitive g - key_base, or
// the empty key in the padding after the build's primitives (sorted last within the build).
fn batch_morton_key(g: u32) -> u32 {
    seg = segs[segment_at(g)];
    return morton_key(g - seg.key_base);
}

// Primitive i's sort key.
fn morton_key(i: u32) -> u32 {
    // Empty primitives (and a batch's padding past the build's primitives): all ones, the
    // largest key, so they sort last.
    let empty_key = (1u << seg.key_bits) - 1u;
    if i >= seg.count {
        return empty_key;
    }
    let b = prim_box(i);
    var key = empty_key;
    if !is_empty(b) {
        // work[seg.work_base + 0..6], or the caller's words bound in its place (see lbvh_bounds).
        let cb = seg.centroid_base;
        let lo = vec3<f32>(dec(~atomicLoad(&work[seg.work_base + cb])), dec(~atomicLoad(&work[seg.work_base + cb + 1u])),
                           dec(~atomicLoad(&work[seg.work_base + cb + 2u])));
        let hi = vec3<f32>(dec(atomicLoad(&work[seg.work_base + cb + 3u])), dec(atomicLoad(&work[seg.work_base + cb + 4u])),
                           dec(atomicLoad(&work[seg.work_base + cb + 5u])));
        let c = centroid(b);
        // Exact power of two (at most 1024): the same cells as a literal would give.
        let cells = f32(1u << min(seg.key_bits / 3u, 10u));
        let morton = (spread3(cell(c.x, lo.x, hi.x, cells)) << 2u)
            | (spread3(cell(c.y, lo.y, hi.y, cells)) << 1u) | spread3(cell(c.z, lo.z, hi.z, cells));
        // Below the empty key: only when the Morton bits fill the key (24 bits: 8 per axis) can
        // they equal it, and then the far corner cell joins its neighbour, the next lower code.
        // With a spare bit (31 = 3 x 10 + 1) no code is lowered.
        key = min(morton, empty_key - 1u);
    }
    return key;
}

// lbvh_morton and the radix sort's first histogram (its digit 0: key bits 0..7) in one pass,
// for sorts of more than one block (gpu/digit_histogram: the sort's counters and
// layout), so the sort skips its first histogram dispatch (RadixSort::first_histogram).
@group(0) @binding(10) var<storage, read_write> sort_hist: array<u32>;

@compute @workgroup_size(256)
fn lbvh_morton_histogram(@builtin(local_invocation_index) lid: u32,
                         @builtin(workgroup_id) wid: vec3<u32>,
                         @builtin(num_workgroups) nwg: vec3<u32>) {
    let block = wid.y * nwg.x + wid.x;
    let nblocks = (params.count + DIGIT_BLOCK - 1u) / DIGIT_BLOCK;
    if block >= nblocks {
        return;
    }
    digit_bins_clear(lid);
    for (var j = 0u; j < DIGIT_BLOCK / WG; j++) {
        let i = block * DIGIT_BLOCK + j * WG + lid;
        if i < params.count {
            let key = batch_morton_key(i);
            keys[i] = key;
            values[i] = i;
            digit_bins_count(key & (DIGIT_VALUES - 1u), lid);
        }
    }
    sort_hist[digit_hist_at(lid, block, nblocks)] = digit_bins_total(lid);
}

// A batch of builds sorts all of their keys at once: by Morton key first, then (stably) by
// build, so each build's primitives are back in its own range, in Morton order. Between the two
// sorts the keys become build indices (lbvh_segment_keys), after them Morton keys again
// (lbvh_rekey), which the hierarchy reads.

@compute @workgroup_size(256)
fn lbvh_segment_keys(@builtin(local_invocation_index) lid: u32,
                     @builtin(workgroup_id) wid: vec3<u32>,
                     @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    if g < params.count {
        keys[g] = segment_at(values[g]);
    }
}

@compute @workgroup_size(256)
fn lbvh_rekey(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
              @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    if g < params.count {
        keys[g] = batch_morton_key(values[g]);
    }
}
