//! Refits, the SAH cost against the CPU builder's, and leaf collapsing against its optimum.

use super::*;

#[test]
fn lbvh_refit_equals_exact_boxes_on_same_topology() {
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(5);
    for (n, refs, sorted_boxes) in [
        (1usize, LeafRefs::PrimitiveIndex, false),
        (2, LeafRefs::SortedPosition, false),
        (1000, LeafRefs::SortedPosition, false),
        (3001, LeafRefs::PrimitiveIndex, false),
        // Boxes in sorted order (a BLAS refit's): leaf k reads box k, not box order[k].
        (1, LeafRefs::SortedPosition, true),
        (3001, LeafRefs::SortedPosition, true),
        (700, LeafRefs::PrimitiveIndex, true),
    ] {
        let before = hard_soup(n, n as u64);
        let (tree, _) = build_and_check(&mut lbvh, &before, refs);
        let refs_before: Vec<u32> = tree
            .node_words
            .chunks(16)
            .flat_map(|w| [w[3], w[7]])
            .collect();
        // Move every box; some empties become real and some real ones empty.
        let after: Vec<Aabb> = before
            .iter()
            .enumerate()
            .map(|(i, b)| match i % 13 {
                0 => EMPTY,
                1 => random_box(&mut rng),
                _ if is_empty(b) => *b,
                _ => shifted(b, rng.vec(-3.0, 3.0)),
            })
            .collect();
        refit_to_with(&mut lbvh, &tree, &after, 1, sorted_boxes);
        // Exact boxes of the new primitives over the same tree (the order was made for
        // the old boxes, so empties need not be last any more).
        let order_before = tree.order_words.clone();
        let (tree, _) = check_read_back(tree, &after, false);
        assert_eq!(tree.order_words, order_before, "refit keeps the order");
        let refs_after: Vec<u32> = tree
            .node_words
            .chunks(16)
            .flat_map(|w| [w[3], w[7]])
            .collect();
        assert_eq!(refs_after, refs_before, "refit keeps every ref");
    }
}

#[test]
fn lbvh_sah_within_2x_of_cpu_sah() {
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(99);
    for (n, spread) in [(2000usize, 100.0f32), (4000, 20.0)] {
        let tris: Vec<[Vec3; 3]> = (0..n)
            .map(|_| {
                let c = Vec3::from(rng.vec(0.0, spread));
                [0; 3].map(|_| c + Vec3::from(rng.vec(-1.0, 1.0)))
            })
            .collect();
        let aabbs: Vec<Aabb> = tris
            .iter()
            .map(|t| {
                let lo = t[0].min(t[1]).min(t[2]);
                let hi = t[0].max(t[1]).max(t[2]);
                (lo.to_array(), hi.to_array())
            })
            .collect();
        let (_, gpu_sah) = build_and_check(&mut lbvh, &aabbs, LeafRefs::SortedPosition);
        let cpu_sah = f64::from(CpuBvh::build(&tris).sah_cost());
        eprintln!("SAH n={n}: gpu lbvh {gpu_sah:.2}, cpu binned {cpu_sah:.2}");
        assert!(
            gpu_sah <= 2.0 * cpu_sah,
            "LBVH SAH {gpu_sah} vs CPU {cpu_sah}"
        );
    }
}

/// A subtree in the collapse oracle: box, primitive count, optimal cost, and its sorted
/// positions as one range `(first, count)` when they are one.
type Solved = (Option<Aabb>, u32, f64, Option<u32>);

/// The optimal SAH cost (relative to the root's area, as `check_tree`) of collapsing
/// subtrees of the read-back topology into leaves of at most `max_leaf` primitives, a
/// subtree only when its leaves are one range of sorted positions (always in a Karras tree):
/// the CPU oracle of the climb's decisions, in f64.
pub(super) fn optimal_collapsed_sah(tree: &GpuTree, aabbs: &[Aabb], max_leaf: u32) -> f64 {
    let topo = read_words(&tree.topology);
    let topo = &topo[tree.bases.topo as usize..];
    let n = tree.n as usize;
    let boxes: Vec<Option<Aabb>> = aabbs.iter().map(|b| (!is_empty(b)).then_some(*b)).collect();
    // The subtree of topology ref `c` (depth is small for these inputs: recursion is fine
    // in a test).
    fn solve(
        c: u32,
        topo: &[u32],
        tree: &GpuTree,
        boxes: &[Option<Aabb>],
        max_leaf: u32,
    ) -> Solved {
        if c & 0x8000_0000 != 0 {
            let k = c & 0x7fff_ffff;
            let b = boxes[tree.order_words[k as usize] as usize];
            let a = b.as_ref().map_or(0.0, area);
            return (b, 1, a * f64::from(SAH_INTERSECTION_COST), Some(k));
        }
        let i = c as usize;
        let l = solve(topo[2 * i], topo, tree, boxes, max_leaf);
        let r = solve(topo[2 * i + 1], topo, tree, boxes, max_leaf);
        let b = union(l.0, r.0);
        let a = b.as_ref().map_or(0.0, area);
        let count = l.1 + r.1;
        let range = match (l.3, r.3) {
            (Some(lf), Some(rf)) if lf + l.1 == rf || rf + r.1 == lf => Some(lf.min(rf)),
            _ => None,
        };
        let split = a * f64::from(SAH_TRAVERSAL_COST) + l.2 + r.2;
        let leaf = a * f64::from(count) * f64::from(SAH_INTERSECTION_COST);
        let cost = if range.is_some() && count <= max_leaf && leaf <= split {
            leaf
        } else {
            split
        };
        (b, count, cost, range)
    }
    assert!(n >= 2);
    let l = solve(topo[0], topo, tree, &boxes, max_leaf);
    let r = solve(topo[1], topo, tree, &boxes, max_leaf);
    let root = union(l.0, r.0);
    let ra = area(&stored(root)).max(f64::from(f32::MIN_POSITIVE));
    f64::from(SAH_TRAVERSAL_COST) + (l.2 + r.2) / ra
}
#[test]
fn lbvh_collapsed_leaves_are_the_sah_optimum_of_the_topology() {
    collapsed_leaves_are_the_optimum(false);
}

/// Builds (clustered or not) over two box sets with leaves of up to 2, 4 and 8: each SAH
/// cost must be the collapse optimum of its topology, and below one primitive per leaf.
pub(super) fn collapsed_leaves_are_the_optimum(clustered: bool) {
    let mut lbvh = Lbvh::new(&gpu().device);
    let refs = LeafRefs::SortedPosition;
    for (aabbs, name) in [
        (clustered_boxes(6000, 3), "clustered"),
        (hard_soup(5003, 8), "hard soup"),
    ] {
        let mut build = |max_leaf| {
            build_and_check_opts(&mut lbvh, &aabbs, refs, max_leaf, BLAS_KEY_BITS, clustered)
        };
        let (_, single) = build(1);
        for max_leaf in [2, 4, 8] {
            // check_tree: every primitive in exactly one leaf of ≤ max_leaf, exact boxes.
            let (tree, sah) = build(max_leaf);
            let optimum = optimal_collapsed_sah(&tree, &aabbs, max_leaf);
            eprintln!("{name} max_leaf {max_leaf}: SAH {sah:.3} (one per leaf {single:.3})");
            assert_is_optimum(sah, optimum, &format!("{name} max_leaf {max_leaf}"));
            assert!(sah < single, "{name}: collapsing must lower the SAH cost");
        }
    }
}

/// `sah` equals the oracle's `optimum` (f32 boxes against f64 sums).
pub(super) fn assert_is_optimum(sah: f64, optimum: f64, what: &str) {
    assert!(
        (sah - optimum).abs() <= 1e-4 * optimum,
        "{what}: SAH {sah} but the optimum is {optimum}"
    );
}
#[test]
fn lbvh_collapse_is_off_for_primitive_index_refs() {
    // A TLAS leaf's instances are not one range: max_leaf is ignored there.
    let mut lbvh = Lbvh::new(&gpu().device);
    let aabbs = clustered_boxes(3000, 4);
    let (tree, _) = build_and_check_leaves(&mut lbvh, &aabbs, LeafRefs::PrimitiveIndex, 8);
    let counts_one = tree
        .node_words
        .chunks(16)
        .flat_map(|w| [w[3], w[7]])
        .filter(|r| r & 0x8000_0000 != 0)
        .all(|r| r & 0x7000_0000 == 0);
    assert!(counts_one, "every TLAS leaf holds one instance");
}

#[test]
fn lbvh_refit_with_collapse_makes_the_optimum_for_the_new_boxes() {
    let mut lbvh = Lbvh::new(&gpu().device);
    let before = clustered_boxes(4000, 5);
    let (tree, _) = build_and_check_leaves(&mut lbvh, &before, LeafRefs::SortedPosition, 4);
    let after = scatter_a_third(&before, 6);
    refit_to(&mut lbvh, &tree, &after, 4);
    let (tree, sah) = check_read_back(tree, &after, false);
    let optimum = optimal_collapsed_sah(&tree, &after, 4);
    assert_is_optimum(sah, optimum, "refit for the new boxes");
}
