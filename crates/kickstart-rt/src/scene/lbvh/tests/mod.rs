//! Tests of the LBVH builder: each build and refit is read back and checked against CPU
//! oracles (structure, exact boxes, leaf refs, SAH cost). Shared helpers here; the tests by
//! part: the build and its sort keys, leaf collapsing and refits, the clustered climb, the
//! range refit.

use super::*;
use crate::cpu::{CpuBvh, SAH_INTERSECTION_COST, SAH_TRAVERSAL_COST};
use crate::gpu::testing::{buffer_with, gpu, read_back, run};
use crate::scene::ingest::{component_rows, ComponentIngest, Ingest, ROW_WORDS};
use glam::Vec3;

mod build;
mod collapse;
mod hploc;
mod range_refit;
mod refit_batch;

/// The builder's shader (the LBVH's passes and the clustered climb) composed and validated with
/// naga without a device; its uniform and the constants the Rust side mirrors checked against it.
#[test]
fn the_shader_validates_and_matches_the_rust_side() {
    use crate::gpu::compose::compose;
    use crate::gpu::wgsl_check::{assert_wgsl_layout, const_u32, validate};
    let module = validate("scene/lbvh", &compose(SHADER_ROOTS, &[]));
    assert_wgsl_layout!(
        module,
        "Params",
        Params {
            count,
            aabb_base,
            node_base,
            order_base,
            topo_base,
            bounds_base,
            flags,
            max_leaf,
            key_bits,
            centroid_base,
            work_base,
            key_base,
            tri_src_base,
            tri_dst_base,
            ingest_row_count,
            ingest_counter,
            karras_base,
            pyramid_base,
            row_base,
            pad => "pad5",
        }
    );
    assert_eq!(const_u32(&module, "WG"), WORKGROUP);
    assert_eq!(const_u32(&module, "HP_WG"), HPLOC_WORKGROUP);
    assert_eq!(
        const_u32(&module, "FLAG_PRIMITIVE_REFS"),
        FLAG_PRIMITIVE_REFS
    );
    assert_eq!(
        const_u32(&module, "FLAG_TRIANGLE_BOXES"),
        FLAG_TRIANGLE_BOXES
    );
    assert_eq!(const_u32(&module, "FLAG_BOUNDS_OUT"), FLAG_BOUNDS_OUT);
    assert_eq!(const_u32(&module, "FLAG_SORTED_BOXES"), FLAG_SORTED_BOXES);
    assert_eq!(
        const_u32(&module, "REFIT_INGEST_ROWS") as usize,
        REFIT_INGEST_ROWS
    );
    assert_eq!(const_u32(&module, "REFIT_BATCH") as usize, REFIT_BATCH);
}

/// Each pass's module composes and validates on its own (it imports all it uses, not relying on
/// another pass's module in the same shader) and holds its entry points; together they hold every
/// pipeline's entry point once.
#[test]
fn every_pass_module_stands_alone() {
    use crate::gpu::compose::compose;
    use crate::gpu::wgsl_check::validate;
    let passes: &[(&str, &[&str])] = &[
        ("scene/lbvh/bounds", &["lbvh_bounds"]),
        (
            "scene/lbvh/morton",
            &[
                "lbvh_morton",
                "lbvh_morton_histogram",
                "lbvh_segment_keys",
                "lbvh_rekey",
            ],
        ),
        ("scene/lbvh/gather", &["lbvh_gather"]),
        ("scene/lbvh/hierarchy", &["lbvh_hierarchy"]),
        ("scene/lbvh/climb", &["lbvh_climb"]),
        (
            "scene/lbvh/range_refit",
            &["lbvh_refit_gather", "lbvh_refit_ingest", "lbvh_range_refit"],
        ),
        ("scene/lbvh/hploc", &["lbvh_climb", "hploc_climb"]),
        (
            "scene/lbvh/compact",
            &[
                "lbvh_compact_mark",
                "lbvh_compact_count",
                "lbvh_compact_scan",
                "lbvh_compact_assign",
                "lbvh_compact_scatter",
            ],
        ),
    ];
    for &(name, entries) in passes {
        let module = validate(name, &compose(&[name], &[]));
        let got: Vec<&str> = module
            .entry_points
            .iter()
            .map(|e| e.name.as_str())
            .collect();
        assert_eq!(got, entries, "{name}");
    }
    let all = validate("scene/lbvh", &compose(SHADER_ROOTS, &[]));
    let mut got: Vec<&str> = all.entry_points.iter().map(|e| e.name.as_str()).collect();
    got.sort_unstable();
    let mut want: Vec<&str> = passes.iter().flat_map(|(_, e)| e.iter().copied()).collect();
    want.sort_unstable();
    want.dedup();
    assert_eq!(got, want);
}

/// A primitive box (min, max) as the AABB input holds it.
type Aabb = ([f32; 3], [f32; 3]);

/// The documented empty box.
const EMPTY: Aabb = ([1e30; 3], [-1e30; 3]);
/// Fill of every output word the builder must not touch.
const SENTINEL: u32 = 0xDEAD_BEEF;

/// Deterministic xorshift64* for test data.
struct Rng(u64);

impl Rng {
    fn next_u32(&mut self) -> u32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 32) as u32
    }
    fn f(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 / (1u32 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f()
    }
    fn vec(&mut self, lo: f32, hi: f32) -> [f32; 3] {
        [self.range(lo, hi), self.range(lo, hi), self.range(lo, hi)]
    }
}

fn random_box(rng: &mut Rng) -> Aabb {
    let c = rng.vec(-10.0, 10.0);
    let h = rng.vec(0.0, 1.0);
    (
        [c[0] - h[0], c[1] - h[1], c[2] - h[2]],
        [c[0] + h[0], c[1] + h[1], c[2] + h[2]],
    )
}

/// Empty as the builder defines it: min.x > max.x or any NaN.
fn is_empty(b: &Aabb) -> bool {
    b.0.iter().chain(b.1.iter()).any(|v| v.is_nan()) || b.0[0] > b.1[0]
}

fn union(a: Option<Aabb>, b: Option<Aabb>) -> Option<Aabb> {
    match (a, b) {
        (Some(a), Some(b)) => Some((
            [0, 1, 2].map(|i| a.0[i].min(b.0[i])),
            [0, 1, 2].map(|i| a.1[i].max(b.1[i])),
        )),
        (a, None) => a,
        (None, b) => b,
    }
}

/// The box as the nodes store it: empty (None) → (+1e30, −1e30).
fn stored(b: Option<Aabb>) -> Aabb {
    b.unwrap_or(EMPTY)
}

fn words_to_box(w: &[u32]) -> Aabb {
    (
        [0, 1, 2].map(|i| f32::from_bits(w[i])),
        [4, 5, 6].map(|i| f32::from_bits(w[i])),
    )
}

fn area(b: &Aabb) -> f64 {
    let d = [0, 1, 2].map(|i| f64::from((b.1[i] - b.0[i]).max(0.0)));
    2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
}

/// Where one test build puts things (all bases non-zero to catch offset mistakes).
#[derive(Clone, Copy)]
struct Bases {
    aabb: u32,
    node: u32,
    order: u32,
    topo: u32,
    bounds: u32,
}

const BASES: Bases = Bases {
    aabb: 3,
    node: 5,
    order: 7,
    topo: 11,
    bounds: 2,
};

/// GPU buffers of one test BVH and what was read back.
struct GpuTree {
    n: u32,
    bases: Bases,
    leaf_refs: LeafRefs,
    max_leaf: u32,
    nodes: wgpu::Buffer,
    order: wgpu::Buffer,
    topology: wgpu::Buffer,
    bounds: wgpu::Buffer,
    node_words: Vec<u32>,
    order_words: Vec<u32>,
}

fn words(data: &[u8]) -> Vec<u32> {
    bytemuck::cast_slice(data).to_vec()
}

fn sentinel_buffer(words: u64) -> wgpu::Buffer {
    buffer_with(bytemuck::cast_slice(&vec![SENTINEL; words as usize]))
}

/// The AABB buffer: `bases.aabb` junk primitives, then `aabbs`, then one more junk.
fn aabb_buffer(aabbs: &[Aabb], base: u32) -> wgpu::Buffer {
    let junk = ([-5e3f32; 3], [5e3f32; 3]);
    let mut data: Vec<f32> = Vec::new();
    let all = std::iter::repeat_n(&junk, base as usize)
        .chain(aabbs.iter())
        .chain(std::iter::once(&junk));
    for b in all {
        data.extend_from_slice(&[b.0[0], b.0[1], b.0[2], 0.0, b.1[0], b.1[1], b.1[2], 0.0]);
    }
    buffer_with(bytemuck::cast_slice(&data))
}

/// Asserts every word outside `[start, start + len)` is still the sentinel.
fn assert_untouched(all: &[u32], start: usize, len: usize, what: &str) {
    for (i, &w) in all.iter().enumerate() {
        if i < start || i >= start + len {
            assert_eq!(
                w, SENTINEL,
                "{what}: word {i} outside [{start}, +{len}) written"
            );
        }
    }
}

fn read_words(b: &wgpu::Buffer) -> Vec<u32> {
    words(&read_back(b, 0, b.size()))
}

/// Builds over `aabbs` on the GPU (one primitive per leaf), checks everything and returns
/// the tree and its SAH cost.
fn build_and_check(lbvh: &mut Lbvh, aabbs: &[Aabb], leaf_refs: LeafRefs) -> (GpuTree, f64) {
    build_and_check_leaves(lbvh, aabbs, leaf_refs, 1)
}

/// [`build_and_check`] with leaves collapsed up to `max_leaf` primitives.
fn build_and_check_leaves(
    lbvh: &mut Lbvh,
    aabbs: &[Aabb],
    leaf_refs: LeafRefs,
    max_leaf: u32,
) -> (GpuTree, f64) {
    build_and_check_with(lbvh, aabbs, leaf_refs, max_leaf, BLAS_KEY_BITS)
}

/// [`build_and_check_leaves`] with sort keys of `key_bits` bits.
fn build_and_check_with(
    lbvh: &mut Lbvh,
    aabbs: &[Aabb],
    leaf_refs: LeafRefs,
    max_leaf: u32,
    key_bits: u32,
) -> (GpuTree, f64) {
    build_and_check_opts(lbvh, aabbs, leaf_refs, max_leaf, key_bits, false)
}

/// A clustered BLAS build (`hploc climb`) over `aabbs`, checked like every build.
fn build_and_check_clustered(lbvh: &mut Lbvh, aabbs: &[Aabb], max_leaf: u32) -> (GpuTree, f64) {
    let refs = LeafRefs::SortedPosition;
    build_and_check_opts(lbvh, aabbs, refs, max_leaf, BLAS_KEY_BITS, true)
}

/// A clustered build with primitive-index leaves (the TLAS's), checked like every build.
fn build_and_check_clustered_refs(lbvh: &mut Lbvh, aabbs: &[Aabb]) -> (GpuTree, f64) {
    let refs = LeafRefs::PrimitiveIndex;
    build_and_check_opts(lbvh, aabbs, refs, 1, TLAS_KEY_BITS, true)
}

/// [`build_and_check_with`], clustered or not.
fn build_and_check_opts(
    lbvh: &mut Lbvh,
    aabbs: &[Aabb],
    leaf_refs: LeafRefs,
    max_leaf: u32,
    key_bits: u32,
    clustered: bool,
) -> (GpuTree, f64) {
    let bases = BASES;
    let n = aabbs.len() as u32;
    let node_count = u64::from(Lbvh::node_count(n));
    let topo_words = u64::from(Lbvh::topology_words(n));
    let input = aabb_buffer(aabbs, bases.aabb);
    let tree = GpuTree {
        n,
        bases,
        leaf_refs,
        max_leaf,
        nodes: sentinel_buffer((u64::from(bases.node) + node_count + 1) * 16),
        order: sentinel_buffer(u64::from(bases.order + n) + 1),
        topology: sentinel_buffer(u64::from(bases.topo) + topo_words + 1),
        bounds: sentinel_buffer((u64::from(bases.bounds) + 3) * 4),
        node_words: Vec::new(),
        order_words: Vec::new(),
    };
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
                leaf_refs,
                max_leaf,
                bounds_out: Some((&tree.bounds, bases.bounds)),
                key_bits,
                centroid_bounds: None,
                clustered,
                hierarchy_only: false,
                compact_counts: None,
            },
        )
    });
    let topo = read_words(&tree.topology);
    assert_untouched(
        &topo,
        bases.topo as usize,
        if n >= 2 { topo_words as usize } else { 0 },
        "topology",
    );
    if n >= 2 {
        check_parent_refs(&topo[bases.topo as usize..], n, clustered);
    }
    check_read_back(tree, aabbs, true)
}

/// Every parent ref in the topology names the node that lists the child, with the
/// block-local bit exactly when the parent's leaves lie in one block of `WORKGROUP` sorted
/// positions (the climb's workgroup-memory phase relies on it; a wrong bit deadlocks a node's
/// two climbers or only slows the climb). A clustered tree's node indices say nothing of
/// blocks: the bit is never set there.
fn check_parent_refs(topo: &[u32], n: u32, clustered: bool) {
    const LEAF: u32 = 0x8000_0000;
    const LOCAL: u32 = 0x4000_0000;
    let inner = (n - 1) as usize;
    // Leaf range of every inner node, children before parents (iterative post-order).
    let mut range = vec![(u32::MAX, 0u32); inner];
    let mut stack = vec![(0usize, false)];
    while let Some((i, children_done)) = stack.pop() {
        let kids = [topo[2 * i], topo[2 * i + 1]];
        if children_done {
            let r = kids.map(|c| {
                if c & LEAF != 0 {
                    (c & !LEAF, c & !LEAF)
                } else {
                    range[c as usize]
                }
            });
            range[i] = (r[0].0.min(r[1].0), r[0].1.max(r[1].1));
            continue;
        }
        stack.push((i, true));
        stack.extend(
            kids.iter()
                .filter(|&&c| c & LEAF == 0)
                .map(|&c| (c as usize, false)),
        );
    }
    assert_eq!(topo[2 * inner], u32::MAX, "root's parent ref");
    for (i, &(first, last)) in range.iter().enumerate() {
        let local = !clustered && first / WORKGROUP == last / WORKGROUP;
        let expected = i as u32 | if local { LOCAL } else { 0 };
        for c in [topo[2 * i], topo[2 * i + 1]] {
            let at = if c & LEAF != 0 {
                3 * inner + (c & !LEAF) as usize
            } else {
                2 * inner + c as usize
            };
            assert_eq!(
                topo[at], expected,
                "parent ref of child {c:#x} of node {i} {first}..={last}"
            );
        }
    }
}

/// `b` moved by `d`.
fn shifted(b: &Aabb, d: [f32; 3]) -> Aabb {
    (
        [0, 1, 2].map(|a| b.0[a] + d[a]),
        [0, 1, 2].map(|a| b.1[a] + d[a]),
    )
}

/// Refits `tree` (as built) to the primitive boxes `after`, collapsing up to `max_leaf`.
fn refit_to(lbvh: &mut Lbvh, tree: &GpuTree, after: &[Aabb], max_leaf: u32) {
    refit_to_with(lbvh, tree, after, max_leaf, false);
}

/// [`refit_to`], the boxes given in sorted order (`after[order[k]]` at `k`) when
/// `sorted_boxes`, as a BLAS refit's gather writes them.
fn refit_to_with(
    lbvh: &mut Lbvh,
    tree: &GpuTree,
    after: &[Aabb],
    max_leaf: u32,
    sorted_boxes: bool,
) {
    let input = if sorted_boxes {
        let sorted: Vec<Aabb> = tree
            .order_words
            .iter()
            .map(|&p| after[p as usize])
            .collect();
        aabb_buffer(&sorted, tree.bases.aabb)
    } else {
        aabb_buffer(after, tree.bases.aabb)
    };
    run(|rec| {
        lbvh.refit(
            rec,
            &LbvhRefit {
                aabbs: &input,
                aabb_base: tree.bases.aabb,
                count: tree.n,
                nodes: &tree.nodes,
                node_base: tree.bases.node,
                order: &tree.order,
                order_base: tree.bases.order,
                topology: (&tree.topology, tree.bases.topo),
                leaf_refs: tree.leaf_refs,
                max_leaf,
                bounds_out: Some((&tree.bounds, tree.bases.bounds)),
                sorted_boxes,
            },
        )
    });
}

/// Reads back nodes, order and bounds of `tree` and checks them against `aabbs`.
fn check_read_back(mut tree: GpuTree, aabbs: &[Aabb], empties_last: bool) -> (GpuTree, f64) {
    let n = tree.n;
    let b = tree.bases;
    let node_words = read_words(&tree.nodes);
    assert_untouched(
        &node_words,
        b.node as usize * 16,
        Lbvh::node_count(n) as usize * 16,
        "nodes",
    );
    let order_words = read_words(&tree.order);
    assert_untouched(&order_words, b.order as usize, n as usize, "order");
    let bounds = read_words(&tree.bounds);
    assert_untouched(&bounds, b.bounds as usize * 4, 8, "bounds_out");
    tree.node_words =
        node_words[b.node as usize * 16..][..Lbvh::node_count(n) as usize * 16].to_vec();
    tree.order_words = order_words[b.order as usize..][..n as usize].to_vec();
    let (root, sah) = check_tree(
        aabbs,
        &tree.node_words,
        &tree.order_words,
        tree.leaf_refs,
        empties_last,
        effective_max_leaf(tree.max_leaf, tree.leaf_refs),
    );
    let bw = &bounds[b.bounds as usize * 4..][..8];
    assert_eq!(words_to_box(bw), stored(root), "bounds_out is the union");
    assert_eq!((bw[3], bw[7]), (0, 0), "bounds_out w");
    (tree, sah)
}

/// State of the recursive tree check.
struct Walk<'a> {
    /// (ref, box as stored) of a node's left (false) or right (true) child.
    child: &'a dyn Fn(usize, bool) -> (u32, Aabb),
    /// Primitive boxes (None: empty).
    boxes: &'a [Option<Aabb>],
    order: &'a [u32],
    leaf_refs: LeafRefs,
    /// Largest leaf allowed.
    max_leaf: u32,
    /// Primitives found in a leaf.
    seen: Vec<bool>,
    /// Inner nodes reached.
    visited: Vec<bool>,
    /// Every child's stored box and its primitive count (0: inner), for the SAH.
    children: Vec<(Aabb, u32)>,
}

impl Walk<'_> {
    /// Checks the subtree of inner node `node`; returns its exact box (None: empty).
    fn visit(&mut self, node: usize) -> Option<Aabb> {
        assert!(!self.visited[node], "inner node {node} reached twice");
        self.visited[node] = true;
        let mut total = None;
        for right in [false, true] {
            let (r, stored_box) = (self.child)(node, right);
            let leaf = r & 0x8000_0000 != 0;
            let count = if leaf { ((r >> 28) & 7) + 1 } else { 0 };
            let subtree = if leaf {
                assert!(
                    count <= self.max_leaf,
                    "leaf {r:#x}: more than {}",
                    self.max_leaf
                );
                let first = (r & 0x0fff_ffff) as usize;
                assert!(
                    first + count as usize <= self.boxes.len(),
                    "leaf ref {r:#x} out of range"
                );
                let mut b = None;
                for k in first..first + count as usize {
                    let prim = match self.leaf_refs {
                        LeafRefs::SortedPosition => self.order[k] as usize,
                        LeafRefs::PrimitiveIndex => k,
                    };
                    assert!(!self.seen[prim], "primitive {prim} in two leaves");
                    self.seen[prim] = true;
                    b = union(b, self.boxes[prim]);
                }
                b
            } else {
                assert!(
                    (r as usize) < self.visited.len(),
                    "inner ref {r} out of range"
                );
                self.visit(r as usize)
            };
            assert_eq!(
                stored_box,
                stored(subtree),
                "node {node} child {right}: exact union"
            );
            self.children.push((stored_box, count));
            total = union(total, subtree);
        }
        total
    }
}

/// Checks a read-back tree: structure, exact boxes, leaf refs. Returns the root box (None:
/// empty) and the SAH cost computed like `CpuBvh::sah_cost`.
fn check_tree(
    aabbs: &[Aabb],
    nodes: &[u32],
    order: &[u32],
    leaf_refs: LeafRefs,
    empties_last: bool,
    max_leaf: u32,
) -> (Option<Aabb>, f64) {
    let n = aabbs.len();
    let boxes: Vec<Option<Aabb>> = aabbs.iter().map(|b| (!is_empty(b)).then_some(*b)).collect();
    // order: a permutation, empty primitives last.
    let mut sorted = order.to_vec();
    sorted.sort_unstable();
    assert!(
        sorted.iter().copied().eq(0..n as u32),
        "order is a permutation"
    );
    let valid = boxes.iter().filter(|b| b.is_some()).count();
    for (k, &p) in order.iter().enumerate() {
        if empties_last {
            assert_eq!(
                boxes[p as usize].is_none(),
                k >= valid,
                "empties sort last ({k})"
            );
        }
    }
    let child = |node: usize, right: bool| -> (u32, Aabb) {
        let w = &nodes[node * 16..][..16];
        let (r, b) = if right {
            (w[7], [&w[8..11], &w[12..15]].concat())
        } else {
            (w[3], [&w[0..3], &w[4..7]].concat())
        };
        assert_eq!((w[11], w[15]), (0, 0), "node {node}: w of entries 2 and 3");
        (r, words_to_box(&[b[0], b[1], b[2], 0, b[3], b[4], b[5], 0]))
    };
    if n < 2 {
        let (lr, lb) = child(0, false);
        let (rr, rb) = child(0, true);
        assert_eq!(
            (rr, rb),
            (0x8000_0000, EMPTY),
            "right child of a small root"
        );
        assert_eq!(lr, 0x8000_0000, "left child ref of a small root");
        let root = boxes.first().copied().flatten();
        assert_eq!(lb, stored(root));
        return (root, 1.0);
    }
    let mut walk = Walk {
        child: &child,
        boxes: &boxes,
        order,
        leaf_refs,
        max_leaf,
        seen: vec![false; n],
        visited: vec![false; n - 1],
        children: Vec::new(),
    };
    let root = walk.visit(0);
    // Collapsed subtrees' inner nodes stay in the buffer, unreferenced.
    assert!(
        max_leaf > 1 || walk.visited.iter().all(|&v| v),
        "every inner node reachable"
    );
    assert!(walk.seen.iter().all(|&s| s), "every primitive in a leaf");
    // As CpuBvh::sah_cost: the root, then every child (inner: traversal cost; leaf: one
    // intersection per primitive), areas relative to the root's.
    let ra = area(&stored(root)).max(f64::from(f32::MIN_POSITIVE));
    let sah = f64::from(SAH_TRAVERSAL_COST)
        + walk
            .children
            .iter()
            .map(|&(b, count)| {
                let cost = if count > 0 {
                    f64::from(SAH_INTERSECTION_COST) * f64::from(count)
                } else {
                    f64::from(SAH_TRAVERSAL_COST)
                };
                area(&b) / ra * cost
            })
            .sum::<f64>();
    (root, sah)
}

/// ~20k primitives: many identical boxes (equal Morton keys), flat boxes, several kinds of
/// empty ones (documented empty, min.x > max.x only, NaN lanes), a few huge ones.
fn hard_soup(n: usize, seed: u64) -> Vec<Aabb> {
    let mut rng = Rng(seed);
    let dups: Vec<Aabb> = (0..4).map(|_| random_box(&mut rng)).collect();
    (0..n)
        .map(|i| match rng.next_u32() % 10 {
            0..=3 => dups[i % dups.len()],
            4 => {
                let mut b = random_box(&mut rng);
                b.1[i % 3] = b.0[i % 3]; // flat
                b
            }
            5 => match i % 4 {
                0 => EMPTY,
                1 => ([1.0, 0.0, 0.0], [0.0, 1.0, 1.0]),
                2 => ([0.0, f32::NAN, 0.0], [1.0, 1.0, 1.0]),
                _ => ([0.0, 0.0, 0.0], [1.0, 1.0, f32::NAN]),
            },
            6 if i % 97 == 0 => ([-1e6, -1e6, 0.0], [1e6, 1e6, 0.0]),
            _ => random_box(&mut rng),
        })
        .collect()
}

/// Clustered random triangles' boxes (the shape of a mesh: many small, overlapping boxes).
fn clustered_boxes(n: usize, seed: u64) -> Vec<Aabb> {
    let mut rng = Rng(seed);
    (0..n)
        .map(|_| {
            let c = rng.vec(0.0, 30.0);
            let d = rng.vec(0.05, 1.0);
            (
                [0, 1, 2].map(|i| c[i] - d[i]),
                [0, 1, 2].map(|i| c[i] + d[i]),
            )
        })
        .collect()
}

/// `before` with every third box moved up to 200 away: decisions made for the old boxes
/// no longer hold.
fn scatter_a_third(before: &[Aabb], seed: u64) -> Vec<Aabb> {
    let mut rng = Rng(seed);
    before
        .iter()
        .enumerate()
        .map(|(i, b)| {
            if i % 3 == 0 {
                shifted(b, rng.vec(-200.0, 200.0))
            } else {
                *b
            }
        })
        .collect()
}
