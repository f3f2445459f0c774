//! The clustered TLAS of at most [`PLOC_SMALL_MAX`] refs built in one workgroup (`ploc small`).

use super::hploc::topology_depth;
use super::*;

/// A clustered build of primitive-index leaves (the TLAS's) without `bounds_out` over `aabbs`:
/// the one-workgroup path when it has at most [`PLOC_SMALL_MAX`] boxes. Checks that it took one
/// dispatch where the climbing build takes two (hierarchy and climb), the tree (every primitive
/// once, exact boxes), the topology's parent refs, and that nothing past the outputs was
/// written. Returns the tree and its SAH cost.
fn build_small_tlas_and_check(lbvh: &mut Lbvh, aabbs: &[Aabb]) -> (GpuTree, f64) {
    let bases = BASES;
    let n = aabbs.len() as u32;
    let topo_words = u64::from(Lbvh::topology_words(n));
    let input = aabb_buffer(aabbs, bases.aabb);
    let tree = GpuTree {
        n,
        bases,
        leaf_refs: LeafRefs::PrimitiveIndex,
        max_leaf: 1,
        nodes: sentinel_buffer((u64::from(bases.node + Lbvh::node_count(n)) + 1) * 16),
        order: sentinel_buffer(u64::from(bases.order + n) + 1),
        topology: sentinel_buffer(u64::from(bases.topo) + topo_words + 1),
        bounds: sentinel_buffer((u64::from(bases.bounds) + 3) * 4),
        node_words: Vec::new(),
        order_words: Vec::new(),
    };
    let mut dispatches = [0; 2];
    for (with_bounds, count) in [(false, 0), (true, 1)] {
        run(|rec| {
            lbvh.build(
                rec,
                &LbvhBuild {
                    aabbs: &input,
                    aabb_base: bases.aabb,
                    count: n,
                    nodes: &tree.nodes,
                    node_base: bases.node,
                    order: &tree.order,
                    order_base: bases.order,
                    topology: Some((&tree.topology, bases.topo)),
                    leaf_refs: LeafRefs::PrimitiveIndex,
                    max_leaf: 1,
                    // With bounds_out the build climbs (the caller's bounds_out is written by
                    // the climb): the dispatch count to compare with. Its outputs are
                    // overwritten by the one-workgroup build that follows.
                    bounds_out: with_bounds.then_some((&tree.bounds, bases.bounds)),
                    key_bits: TLAS_KEY_BITS,
                    centroid_bounds: None,
                    clustered: true,
                    hierarchy_only: false,
                },
            );
            dispatches[count] = rec.dispatches;
        });
    }
    // The one-workgroup build last, so its outputs are the ones read back.
    let bounds_before = read_words(&tree.bounds);
    run(|rec| {
        lbvh.build(
            rec,
            &LbvhBuild {
                aabbs: &input,
                aabb_base: bases.aabb,
                count: n,
                nodes: &tree.nodes,
                node_base: bases.node,
                order: &tree.order,
                order_base: bases.order,
                topology: Some((&tree.topology, bases.topo)),
                leaf_refs: LeafRefs::PrimitiveIndex,
                max_leaf: 1,
                bounds_out: None,
                key_bits: TLAS_KEY_BITS,
                centroid_bounds: None,
                clustered: true,
                hierarchy_only: false,
            },
        )
    });
    if (2..=PLOC_SMALL_MAX).contains(&n) {
        assert_eq!(
            dispatches[0] + 1,
            dispatches[1],
            "{n} refs: one dispatch in place of the hierarchy and the climb"
        );
    }
    assert_eq!(
        read_words(&tree.bounds),
        bounds_before,
        "{n}: no bounds_out"
    );
    let topo = read_words(&tree.topology);
    assert_untouched(&topo, bases.topo as usize, topo_words as usize, "topology");
    check_parent_refs(&topo[bases.topo as usize..], n, true);
    let mut tree = tree;
    let node_words = read_words(&tree.nodes);
    assert_untouched(
        &node_words,
        bases.node as usize * 16,
        Lbvh::node_count(n) as usize * 16,
        "nodes",
    );
    let order_words = read_words(&tree.order);
    assert_untouched(&order_words, bases.order as usize, n as usize, "order");
    tree.node_words =
        node_words[bases.node as usize * 16..][..Lbvh::node_count(n) as usize * 16].to_vec();
    tree.order_words = order_words[bases.order as usize..][..n as usize].to_vec();
    let (_, sah) = check_tree(
        aabbs,
        &tree.node_words,
        &tree.order_words,
        LeafRefs::PrimitiveIndex,
        true,
        1,
    );
    (tree, sah)
}

#[test]
fn ploc_small_builds_the_small_tlas_in_one_workgroup() {
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(29);
    // Every count up to a few runs of 8, around the workgroup's 256 runs, the most it takes.
    for n in (2..=40).chain([255, 256, 257, 1000, 2047, 2048]) {
        let aabbs: Vec<Aabb> = (0..n).map(|_| random_box(&mut rng)).collect();
        build_small_tlas_and_check(&mut lbvh, &aabbs);
    }
    // Duplicates, flat, empty, NaN and huge boxes; identical boxes pair up (the tie rule), not
    // into a chain.
    build_small_tlas_and_check(&mut lbvh, &hard_soup(2048, 31));
    let same = vec![([1.0, 2.0, 3.0], [2.0, 3.0, 4.0]); 2048];
    let (tree, _) = build_small_tlas_and_check(&mut lbvh, &same);
    let depth = topology_depth(&tree);
    assert!(depth <= 24, "2048 identical boxes: depth {depth}");
}

#[test]
fn ploc_small_clusters_as_well_as_the_climb_and_refits() {
    // Instances in far-apart rooms: the one-workgroup PLOC's tree is as good as the climb's
    // (H-PLOC merges within its Karras subtrees; PLOC over all clusters at once is at least
    // as free), and better than the LBVH's; a refit of it keeps every ref with exact boxes.
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(37);
    let centres: Vec<[f32; 3]> = (0..8).map(|_| rng.vec(-500.0, 500.0)).collect();
    let mut rooms: Vec<Aabb> = clustered_boxes(2000, 38);
    for (i, b) in rooms.iter_mut().enumerate() {
        *b = shifted(b, centres[i % centres.len()]);
    }
    let lbvh_sah = build_and_check_with(
        &mut lbvh,
        &rooms,
        LeafRefs::PrimitiveIndex,
        1,
        TLAS_KEY_BITS,
    )
    .1;
    let climb_sah = build_and_check_clustered_refs(&mut lbvh, &rooms).1;
    let (tree, small_sah) = build_small_tlas_and_check(&mut lbvh, &rooms);
    eprintln!("rooms: SAH lbvh {lbvh_sah:.3}, climb {climb_sah:.3}, one workgroup {small_sah:.3}");
    assert!(
        small_sah <= 1.02 * climb_sah,
        "one workgroup {small_sah} vs climb {climb_sah}"
    );
    assert!(
        small_sah < 0.9 * lbvh_sah,
        "one workgroup {small_sah} vs LBVH {lbvh_sah}"
    );
    let refs =
        |t: &GpuTree| -> Vec<u32> { t.node_words.chunks(16).flat_map(|w| [w[3], w[7]]).collect() };
    let refs_before = refs(&tree);
    let after = scatter_a_third(&rooms, 39);
    refit_to(&mut lbvh, &tree, &after, 1);
    let (tree, _) = check_read_back(tree, &after, false);
    assert_eq!(refs(&tree), refs_before, "refit keeps every ref");
}
