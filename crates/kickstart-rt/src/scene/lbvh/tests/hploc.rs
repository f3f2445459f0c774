//! The clustered climb (`hploc climb`): valid, deterministic trees of lower SAH cost.

use super::collapse::{assert_is_optimum, collapsed_leaves_are_the_optimum, optimal_collapsed_sah};
use super::*;

#[test]
fn hploc_small_and_random_counts_make_valid_trees() {
    // Every count up to past two clusters' worth (the root's merge alone, then merges
    // below it), and a few across workgroups: exact boxes, every primitive once, parent
    // refs, root at node 0 (check_tree walks from there).
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(17);
    for n in (0..=40).chain([255, 256, 257, 1000, 3001]) {
        let aabbs: Vec<Aabb> = (0..n).map(|_| random_box(&mut rng)).collect();
        for max_leaf in [1, 4] {
            build_and_check_clustered(&mut lbvh, &aabbs, max_leaf);
        }
    }
}

#[test]
fn hploc_with_primitive_index_leaves_as_the_tlas_builds() {
    // The TLAS's leaves name primitives, not sorted positions: every count from none to
    // past two clusters' worth and across workgroups gives a valid tree over the same
    // boxes, far-apart groups (instances in rooms) a lower SAH cost than the LBVH's, and a
    // refit (instances moved) exact boxes with every ref kept.
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(19);
    for n in (0..=40).chain([255, 256, 257, 1000, 1024]) {
        let aabbs: Vec<Aabb> = (0..n).map(|_| random_box(&mut rng)).collect();
        build_and_check_clustered_refs(&mut lbvh, &aabbs);
    }
    let centres: Vec<[f32; 3]> = (0..8).map(|_| rng.vec(-500.0, 500.0)).collect();
    let mut rooms: Vec<Aabb> = clustered_boxes(1000, 20);
    for (i, b) in rooms.iter_mut().enumerate() {
        *b = shifted(b, centres[i % centres.len()]);
    }
    let (_, lbvh_sah) = build_and_check_with(
        &mut lbvh,
        &rooms,
        LeafRefs::PrimitiveIndex,
        1,
        TLAS_KEY_BITS,
    );
    let (tree, ploc_sah) = build_and_check_clustered_refs(&mut lbvh, &rooms);
    assert!(
        ploc_sah < 0.9 * lbvh_sah,
        "clustered TLAS SAH {ploc_sah} vs LBVH {lbvh_sah}"
    );
    let refs =
        |t: &GpuTree| -> Vec<u32> { t.node_words.chunks(16).flat_map(|w| [w[3], w[7]]).collect() };
    let refs_before = refs(&tree);
    let after = scatter_a_third(&rooms, 22);
    refit_to(&mut lbvh, &tree, &after, 1);
    let (tree, _) = check_read_back(tree, &after, false);
    assert_eq!(refs(&tree), refs_before, "refit keeps every ref");
}

#[test]
fn hploc_hard_soup_and_identical_boxes() {
    // Duplicates, flat, empty, NaN and huge boxes; then 20k identical boxes, where every
    // merge ties: the tie rule must pair them up, not chain them (the traversal's stack
    // holds 64 entries per level).
    let mut lbvh = Lbvh::new(&gpu().device);
    for max_leaf in [1, 4] {
        build_and_check_clustered(&mut lbvh, &hard_soup(20_000, 21), max_leaf);
    }
    let same = vec![([1.0, 2.0, 3.0], [2.0, 3.0, 4.0]); 20_000];
    let (tree, _) = build_and_check_clustered(&mut lbvh, &same, 1);
    let depth = topology_depth(&tree);
    assert!(depth <= 40, "20k identical boxes: depth {depth}");
}

#[test]
fn hploc_lowers_the_sah_cost_of_the_lbvh() {
    // Boxes in a few far-apart groups (rooms of a building): where a Karras split falls
    // by Morton bit, not by geometry, clustering pays most.
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(23);
    let centres: Vec<[f32; 3]> = (0..12).map(|_| rng.vec(-500.0, 500.0)).collect();
    let mut aabbs: Vec<Aabb> = clustered_boxes(8000, 24);
    for (i, b) in aabbs.iter_mut().enumerate() {
        *b = shifted(b, centres[i % centres.len()]);
    }
    // A soup of overlapping boxes leaves little to gain (lavapipe: 91.9 → 90.1), but the
    // clustered tree must not be worse; the groups gain a quarter (4.19 → 3.08).
    let soup = clustered_boxes(8000, 25);
    for (aabbs, name, most) in [(aabbs, "groups", 0.85), (soup, "soup", 1.0)] {
        let (_, lbvh_sah) = build_and_check_leaves(&mut lbvh, &aabbs, LeafRefs::SortedPosition, 1);
        let (_, ploc_sah) = build_and_check_clustered(&mut lbvh, &aabbs, 1);
        eprintln!("{name}: SAH lbvh {lbvh_sah:.3}, clustered {ploc_sah:.3}");
        assert!(
            ploc_sah < most * lbvh_sah,
            "{name}: clustered SAH {ploc_sah} vs LBVH {lbvh_sah}"
        );
    }
}

#[test]
fn hploc_builds_the_same_tree_every_time() {
    // Output slots come from each node's pool, in the order of its merging lanes, not from
    // a device-wide counter: the same input gives the same nodes and topology word for word,
    // whatever order the workgroups ran in. Between the builds the builder runs another
    // input, so nothing is left over from the first.
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(41);
    let aabbs: Vec<Aabb> = (0..20_000).map(|_| random_box(&mut rng)).collect();
    let other: Vec<Aabb> = (0..20_000).map(|_| random_box(&mut rng)).collect();
    for max_leaf in [1, 4] {
        let (first, _) = build_and_check_clustered(&mut lbvh, &aabbs, max_leaf);
        let topo_first = read_words(&first.topology);
        build_and_check_clustered(&mut lbvh, &other, max_leaf);
        let (second, _) = build_and_check_clustered(&mut lbvh, &aabbs, max_leaf);
        assert!(
            first.node_words == second.node_words,
            "max_leaf {max_leaf}: the nodes differ between two builds of the same boxes"
        );
        assert!(
            topo_first == read_words(&second.topology),
            "max_leaf {max_leaf}: the topology differs between two builds of the same boxes"
        );
    }
}

#[test]
fn hploc_collapsed_leaves_are_the_sah_optimum_of_ranges() {
    // Only subtrees whose leaves are one range of sorted positions may be one leaf (a leaf
    // ref is a range); among those the build must take every collapse that pays.
    collapsed_leaves_are_the_optimum(true);
}

#[test]
fn hploc_refit_keeps_the_clustered_topology() {
    // A refit runs lbvh_climb over the clustered topology (device-scope phase only): exact
    // boxes for moved primitives, refs unchanged without collapsing, the collapse optimum
    // with it.
    let mut lbvh = Lbvh::new(&gpu().device);
    let before = clustered_boxes(5000, 31);
    let after = scatter_a_third(&before, 32);
    let (tree, _) = build_and_check_clustered(&mut lbvh, &before, 1);
    let refs =
        |t: &GpuTree| -> Vec<u32> { t.node_words.chunks(16).flat_map(|w| [w[3], w[7]]).collect() };
    let refs_before = refs(&tree);
    refit_to(&mut lbvh, &tree, &after, 1);
    let (tree, _) = check_read_back(tree, &after, false);
    assert_eq!(refs(&tree), refs_before, "refit keeps every ref");
    let (tree, _) = build_and_check_clustered(&mut lbvh, &before, 4);
    // As a fast-trace BLAS is refit: the boxes in sorted order.
    refit_to_with(&mut lbvh, &tree, &after, 4, true);
    let (tree, sah) = check_read_back(tree, &after, false);
    let optimum = optimal_collapsed_sah(&tree, &after, 4);
    assert_is_optimum(sah, optimum, "clustered refit for the new boxes");
}

/// Depth of the tree (root = 1) from its read-back topology.
fn topology_depth(tree: &GpuTree) -> usize {
    let topo = read_words(&tree.topology);
    let topo = &topo[tree.bases.topo as usize..];
    let mut deepest = 0;
    let mut stack = vec![(0u32, 1usize)];
    while let Some((i, d)) = stack.pop() {
        deepest = deepest.max(d);
        for c in [topo[2 * i as usize], topo[2 * i as usize + 1]] {
            if c & 0x8000_0000 == 0 {
                stack.push((c, d + 1));
            }
        }
    }
    deepest
}
