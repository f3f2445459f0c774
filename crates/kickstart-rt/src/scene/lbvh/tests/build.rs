//! The build: trees of every shape and count, sort keys of every width, given centroid bounds,
//! dispatch counts.

use super::*;

#[test]
fn lbvh_tiny_counts_both_leaf_refs() {
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(7);
    for n in 0..=3 {
        let aabbs: Vec<Aabb> = (0..n).map(|_| random_box(&mut rng)).collect();
        for refs in [LeafRefs::SortedPosition, LeafRefs::PrimitiveIndex] {
            build_and_check(&mut lbvh, &aabbs, refs);
        }
    }
    // One empty primitive, two identical ones, an empty and a real one.
    let b = random_box(&mut rng);
    for aabbs in [vec![EMPTY], vec![b, b], vec![EMPTY, b], vec![b, EMPTY, b]] {
        build_and_check(&mut lbvh, &aabbs, LeafRefs::PrimitiveIndex);
    }
}

#[test]
fn lbvh_random_1000_both_leaf_refs() {
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(1000);
    let aabbs: Vec<Aabb> = (0..1000).map(|_| random_box(&mut rng)).collect();
    for refs in [LeafRefs::SortedPosition, LeafRefs::PrimitiveIndex] {
        build_and_check(&mut lbvh, &aabbs, refs);
    }
}
#[test]
fn lbvh_20k_duplicates_flat_and_empty() {
    let mut lbvh = Lbvh::new(&gpu().device);
    let aabbs = hard_soup(20_011, 20);
    build_and_check(&mut lbvh, &aabbs, LeafRefs::SortedPosition);
    // All identical, and all empty.
    let same = vec![([1.0, 2.0, 3.0], [1.0, 2.5, 3.0]); 3000];
    build_and_check(&mut lbvh, &same, LeafRefs::PrimitiveIndex);
    build_and_check(&mut lbvh, &vec![EMPTY; 700], LeafRefs::SortedPosition);
}

#[test]
fn lbvh_three_builds_in_one_encoder_grow_scratch() {
    // Each build needs more scratch than the one before, and the TLAS-key builds (3 sort
    // passes) leave their sorted pairs in the sort's scratch, which the next build's sort
    // overwrites or replaces: every build must still be correct.
    let mut lbvh = Lbvh::new(&gpu().device);
    let sets = [
        (hard_soup(300, 1), BLAS_KEY_BITS),
        (hard_soup(5000, 2), TLAS_KEY_BITS),
        (hard_soup(9000, 3), TLAS_KEY_BITS),
    ];
    let n = sets.each_ref().map(|(a, _)| a.len() as u32);
    let inputs = sets.each_ref().map(|(a, _)| aabb_buffer(a, 0));
    let nodes = n.map(|n| sentinel_buffer(u64::from(Lbvh::node_count(n)) * 16));
    let order = n.map(|n| sentinel_buffer(u64::from(n)));
    run(|rec| {
        for i in 0..sets.len() {
            lbvh.build(
                rec,
                &LbvhBuild {
                    aabbs: &inputs[i],
                    aabb_base: 0,
                    count: n[i],
                    nodes: &nodes[i],
                    node_base: 0,
                    order: &order[i],
                    order_base: 0,
                    topology: None,
                    leaf_refs: LeafRefs::SortedPosition,
                    max_leaf: 1,
                    bounds_out: None,
                    key_bits: sets[i].1,
                    centroid_bounds: None,
                    clustered: false,
                    hierarchy_only: false,
                    compact_counts: None,
                },
            );
        }
    });
    // Scratch covers the largest build (work words, keys, values, topology).
    assert!(lbvh.scratch_bytes() >= 4 * (10 * 9000 + 2 * 9000 + 4 * 9000));
    for (i, (aabbs, _)) in sets.iter().enumerate() {
        check_tree(
            aabbs,
            &read_words(&nodes[i]),
            &read_words(&order[i]),
            LeafRefs::SortedPosition,
            true,
            1,
        );
    }
}

/// The sort key `lbvh_morton` makes for cells `c` with `key_bits`: the Morton code of
/// `min(key_bits / 3, 10)` bits per axis (x in the highest bit of each triple), below the
/// all-ones key of empty primitives.
fn morton_key(c: [u32; 3], key_bits: u32) -> u32 {
    let mut key = 0;
    for b in 0..(key_bits / 3).min(10) {
        for (axis, shift) in [(0, 2), (1, 1), (2, 0)] {
            key |= ((c[axis] >> b) & 1) << (3 * b + shift);
        }
    }
    key.min(empty_key(key_bits) - 1)
}

fn empty_key(key_bits: u32) -> u32 {
    (1 << key_bits) - 1
}

/// Boxes whose centroids sit at cell centres of the grid of `key_bits` keys over
/// `[0, cells]` per axis (two anchors at the corners fix the centroid bounds), so every cell
/// is exact in f32 and the GPU's keys can be predicted: random cells, many primitives
/// sharing a cell (equal keys), empty ones, and the far corner cell (whose code is lowered
/// when the Morton bits fill the key). Returns the boxes and each one's expected key.
fn grid_boxes(n: usize, key_bits: u32, seed: u64) -> (Vec<Aabb>, Vec<u32>) {
    let mut rng = Rng(seed);
    let g = 1u32 << (key_bits / 3).min(10);
    let half = 0.25f32;
    let at = |c: [f32; 3]| -> Aabb { (c.map(|v| v - half), c.map(|v| v + half)) };
    let mut boxes = vec![at([0.0; 3]), at([g as f32; 3])];
    let mut keys = vec![0, morton_key([g - 1; 3], key_bits)];
    let shared: Vec<[u32; 3]> = (0..5)
        .map(|_| [0; 3].map(|_| rng.next_u32() % g))
        .chain([[g - 1, g - 1, g - 2], [g - 1; 3]]) // the corner and its Morton neighbour
        .collect();
    while boxes.len() < n {
        let cell = match rng.next_u32() % 8 {
            0 => {
                boxes.push(if boxes.len() % 2 == 0 {
                    EMPTY
                } else {
                    ([f32::NAN, 0.0, 0.0], [1.0; 3])
                });
                keys.push(empty_key(key_bits));
                continue;
            }
            1..=2 => shared[rng.next_u32() as usize % shared.len()],
            _ => [0; 3].map(|_| rng.next_u32() % g),
        };
        boxes.push(at(cell.map(|c| c as f32 + 0.5)));
        keys.push(morton_key(cell, key_bits));
    }
    (boxes, keys)
}

#[test]
fn lbvh_order_is_the_stable_sort_of_the_morton_keys_of_every_key_width() {
    // TLAS keys (24 bits, 8 per axis: 3 sort passes ending in the sort's scratch, the
    // corner cell lowered), BLAS keys (31 bits, 10 per axis and a spare bit: 4 passes),
    // 4 bits (one pass), and the one-workgroup sort below 1025 primitives: the order must be
    // exactly the stable sort of the predicted keys (equal keys in primitive order, empties
    // last).
    let mut lbvh = Lbvh::new(&gpu().device);
    for (n, bits, refs) in [
        (6000, TLAS_KEY_BITS, LeafRefs::PrimitiveIndex),
        (4100, BLAS_KEY_BITS, LeafRefs::SortedPosition),
        (3000, 4, LeafRefs::PrimitiveIndex),
        (900, TLAS_KEY_BITS, LeafRefs::PrimitiveIndex),
    ] {
        let (boxes, keys) = grid_boxes(n, bits, u64::from(bits) * 31 + n as u64);
        let (tree, _) = build_and_check_with(&mut lbvh, &boxes, refs, 1, bits);
        let mut expected: Vec<u32> = (0..n as u32).collect();
        expected.sort_by_key(|&i| keys[i as usize]); // stable
        assert_eq!(tree.order_words, expected, "n {n}, {bits} key bits");
    }
}

#[test]
fn lbvh_tlas_keys_keep_the_tree_exact_and_its_sah_close() {
    // Coarser keys only change the order within a cell: the tree is still exact (checked by
    // check_tree) over clustered boxes, coincident ones and empties, and not much worse.
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut coincident = clustered_boxes(2000, 9);
    coincident.extend(vec![([1.0, 2.0, 3.0], [1.5, 2.5, 3.5]); 1500]);
    coincident.extend(vec![EMPTY; 300]);
    // A dense cluster in a scene stretched by one far box: many boxes share a coarse cell.
    let mut stretched = clustered_boxes(6000, 10);
    stretched.push(([3000.0; 3], [3001.0; 3]));
    for (aabbs, name) in [
        (clustered_boxes(8000, 7), "clustered"),
        (hard_soup(6007, 11), "hard soup"),
        (coincident, "coincident"),
        (stretched, "stretched"),
    ] {
        let (_, fine) = build_and_check_with(
            &mut lbvh,
            &aabbs,
            LeafRefs::PrimitiveIndex,
            1,
            BLAS_KEY_BITS,
        );
        let (_, coarse) = build_and_check_with(
            &mut lbvh,
            &aabbs,
            LeafRefs::PrimitiveIndex,
            1,
            TLAS_KEY_BITS,
        );
        eprintln!("{name}: SAH with 10 bits per axis {fine:.4}, with 8 {coarse:.4}");
        assert!(coarse <= 1.05 * fine, "{name}: SAH {coarse} vs {fine}");
        if name == "stretched" {
            // The price of coarse keys, documented at TLAS_KEY_BITS: below the root (cost
            // 1), the cluster's subtree costs 3.6 times as much on this input (10 times with
            // 7 bits per axis).
            assert!(coarse - 1.0 <= 4.0 * (fine - 1.0), "SAH {coarse} vs {fine}");
        }
    }
}

/// Builds `aabbs` (one primitive per leaf) into fresh node and order buffers, with no
/// topology or bounds output, as a TLAS build does; returns those buffers and the number of
/// dispatches recorded.
fn build_minimal(
    lbvh: &mut Lbvh,
    aabbs: &[Aabb],
    leaf_refs: LeafRefs,
    key_bits: u32,
    centroid_bounds: Option<(&wgpu::Buffer, u32)>,
) -> (wgpu::Buffer, wgpu::Buffer, u32) {
    let n = aabbs.len() as u32;
    let input = aabb_buffer(aabbs, 0);
    let nodes = sentinel_buffer(u64::from(Lbvh::node_count(n)) * 16);
    let order = sentinel_buffer(u64::from(n));
    let mut dispatches = 0;
    run(|rec| {
        lbvh.build(
            rec,
            &LbvhBuild {
                aabbs: &input,
                aabb_base: 0,
                count: n,
                nodes: &nodes,
                node_base: 0,
                order: &order,
                order_base: 0,
                topology: None,
                leaf_refs,
                max_leaf: 1,
                bounds_out: None,
                key_bits,
                centroid_bounds,
                clustered: false,
                hierarchy_only: false,
                compact_counts: None,
            },
        );
        dispatches = rec.dispatches;
    });
    (nodes, order, dispatches)
}

#[test]
fn lbvh_given_centroid_bounds_build_the_same_tree() {
    // The TLAS's instance pass merges the centroid bounds and the build skips its bounds
    // pass: given the same words (here from the CPU oracle, at a non-zero base, in a buffer
    // of their own), the build must make the same order and nodes, bit for bit.
    let mut lbvh = Lbvh::new(&gpu().device);
    for (aabbs, refs) in [
        (hard_soup(5003, 21), LeafRefs::PrimitiveIndex),
        (clustered_boxes(900, 22), LeafRefs::SortedPosition),
    ] {
        let n = aabbs.len() as u32;
        let (own, _) = build_and_check_with(&mut lbvh, &aabbs, refs, 1, TLAS_KEY_BITS);
        let mut words = vec![SENTINEL; 3];
        words.extend(cpu_centroid_bounds(aabbs.iter().copied()));
        let given = buffer_with(bytemuck::cast_slice(&words));
        let (nodes, order, dispatches) =
            build_minimal(&mut lbvh, &aabbs, refs, TLAS_KEY_BITS, Some((&given, 3)));
        assert_eq!(read_words(&order), own.order_words, "order, {n} primitives");
        assert_eq!(read_words(&nodes), own.node_words, "nodes, {n} primitives");
        assert_eq!(read_words(&given), words, "the given words are only read");
        // Morton, sort (5 dispatches: the first histogram is the morton pass's; or 1 up to
        // 1024 primitives), hierarchy, climb.
        assert_eq!(dispatches, if n > 1024 { 8 } else { 4 });
    }
}

#[test]
fn lbvh_build_dispatch_counts() {
    // A BLAS build of more than 1024 primitives: bounds, morton, 4 sort passes, hierarchy,
    // climb; a sort pass is 2 dispatches up to SUMMING_MAX_BLOCKS blocks of 1024 (the
    // scatter sums the histogram rows), 3 above, and the morton pass makes the first pass's
    // histogram. A TLAS build: 3 sort passes and no copy back. Up to 2048 (the values are the
    // positions): one sort dispatch.
    let limit = crate::gpu::radix_sort::SUMMING_MAX_BLOCKS as usize * 1024;
    let mut lbvh = Lbvh::new(&gpu().device);
    for (n, bits, expected) in [
        (5000, BLAS_KEY_BITS, 11),
        (5000, TLAS_KEY_BITS, 9),
        (1000, TLAS_KEY_BITS, 5),
        (2048, TLAS_KEY_BITS, 5),
        (2048, BLAS_KEY_BITS, 5),
        (2049, TLAS_KEY_BITS, 9),
        (limit, TLAS_KEY_BITS, 9),
        (limit + 1, TLAS_KEY_BITS, 12),
    ] {
        let aabbs = hard_soup(n, 12);
        let (_, _, dispatches) =
            build_minimal(&mut lbvh, &aabbs, LeafRefs::PrimitiveIndex, bits, None);
        assert_eq!(dispatches, expected, "{n} primitives, {bits} key bits");
    }
}
