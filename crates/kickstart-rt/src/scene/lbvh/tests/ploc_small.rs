//! The clustered TLAS of at most [`PLOC_SMALL_MAX`] refs built in one workgroup (`ploc small`),
//! and the climb in its place on a device without the workgroup memory for it.

use super::hploc::topology_depth;
use super::*;

/// Whether the test device runs the one-workgroup build (CI's minimal-device pass, with
/// WebGPU's default 16 KiB of workgroup memory, does not).
fn one_workgroup_device() -> bool {
    gpu().device.limits().max_compute_workgroup_storage_size >= PLOC_SMALL_WORKGROUP_BYTES
}

/// Dispatches a clustered build of primitive-index leaves over `n` boxes records.
fn tlas_build_dispatches(lbvh: &mut Lbvh, aabbs: &[Aabb]) -> u32 {
    let n = aabbs.len() as u32;
    let input = aabb_buffer(aabbs, 0);
    let nodes = sentinel_buffer(u64::from(Lbvh::node_count(n)) * 16);
    let order = sentinel_buffer(u64::from(n));
    let topology = sentinel_buffer(u64::from(Lbvh::topology_words(n)));
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
                topology: Some((&topology, 0)),
                leaf_refs: LeafRefs::PrimitiveIndex,
                max_leaf: 1,
                bounds_out: None,
                key_bits: TLAS_KEY_BITS,
                centroid_bounds: None,
                clustered: true,
                hierarchy_only: false,
            },
        );
        dispatches = rec.dispatches;
    });
    dispatches
}

/// Every inner node's subtree is one range of node indices from its own: the left child (if
/// inner) right after it, the right child after the left child's subtree. Returns the inner
/// nodes under `node`, itself included.
fn assert_depth_first(topo: &[u32], node: u32) -> u32 {
    let mut inner = 1;
    let mut next = node + 1;
    for side in 0..2 {
        let c = topo[2 * node as usize + side];
        if c & 0x8000_0000 == 0 {
            assert_eq!(c, next, "child {side} of node {node}: numbered depth first");
            let below = assert_depth_first(topo, c);
            next += below;
            inner += below;
        }
    }
    inner
}

/// A clustered TLAS build over `aabbs` checked like every build (exact boxes, every ref once,
/// parent refs, `bounds_out`, nothing written past the outputs); numbered depth first where it
/// was built in one workgroup.
fn build_small_tlas_and_check(lbvh: &mut Lbvh, aabbs: &[Aabb]) -> (GpuTree, f64) {
    let (tree, sah) = build_and_check_clustered_refs(lbvh, aabbs);
    let n = aabbs.len() as u32;
    if n >= 2 && n <= PLOC_SMALL_MAX && lbvh.ploc_small.is_some() {
        let topo = read_words(&tree.topology);
        let inner = assert_depth_first(&topo[tree.bases.topo as usize..], 0);
        assert_eq!(inner, n - 1, "{n} refs: every inner node under the root");
    }
    (tree, sah)
}

#[test]
fn ploc_small_builds_the_small_tlas_in_one_dispatch() {
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(29);
    let one_workgroup = one_workgroup_device();
    // Every count up to a few runs of 8, around the workgroup's 256 runs, the most it takes, and
    // one past it (the climb).
    for n in (2..=40).chain([255, 256, 257, 1000, 2047, 2048, 2049]) {
        let aabbs: Vec<Aabb> = (0..n).map(|_| random_box(&mut rng)).collect();
        let dispatches = tlas_build_dispatches(&mut lbvh, &aabbs);
        if one_workgroup && n <= PLOC_SMALL_MAX as usize {
            assert_eq!(dispatches, 1, "{n} refs: one dispatch");
        } else {
            // Bounds, keys, the sort, the hierarchy and the climb.
            assert!(dispatches >= 4, "{n} refs: {dispatches} dispatches");
        }
        build_small_tlas_and_check(&mut lbvh, &aabbs);
    }
}

#[test]
fn ploc_small_hard_soup_and_identical_boxes() {
    let mut lbvh = Lbvh::new(&gpu().device);
    // Duplicates, flat, empty, NaN and huge boxes (empty ones last in the order); identical
    // boxes pair up (the tie rule), not into a chain.
    build_small_tlas_and_check(&mut lbvh, &hard_soup(2048, 31));
    build_small_tlas_and_check(&mut lbvh, &hard_soup(301, 32));
    let same = vec![([1.0, 2.0, 3.0], [2.0, 3.0, 4.0]); 2048];
    let (tree, _) = build_small_tlas_and_check(&mut lbvh, &same);
    let depth = topology_depth(&tree);
    assert!(depth <= 24, "2048 identical boxes: depth {depth}");
    // All empty: still a valid tree over every ref.
    build_small_tlas_and_check(&mut lbvh, &vec![EMPTY; 100]);
}

#[test]
fn ploc_small_is_deterministic() {
    let mut lbvh = Lbvh::new(&gpu().device);
    let aabbs = clustered_boxes(1500, 41);
    let (a, _) = build_small_tlas_and_check(&mut lbvh, &aabbs);
    let (b, _) = build_small_tlas_and_check(&mut lbvh, &aabbs);
    assert_eq!(a.node_words, b.node_words, "same nodes on every build");
    assert_eq!(a.order_words, b.order_words, "same order on every build");
}

#[test]
fn ploc_small_clusters_as_well_as_the_climb_and_refits() {
    // Instances in far-apart rooms: the one-workgroup PLOC's tree is about as good as the
    // climb's (its neighbour search reads quantised boxes; H-PLOC merges within Karras
    // subtrees, PLOC over all clusters at once), and better than the LBVH's; a refit of it keeps
    // every ref with exact boxes.
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut climbing = Lbvh::new(&gpu().device).without_ploc_small();
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
    let climb_sah = build_and_check_clustered_refs(&mut climbing, &rooms).1;
    let (tree, small_sah) = build_small_tlas_and_check(&mut lbvh, &rooms);
    eprintln!("rooms: SAH lbvh {lbvh_sah:.3}, climb {climb_sah:.3}, one workgroup {small_sah:.3}");
    assert!(
        small_sah <= 1.03 * climb_sah,
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
