//! A batch of range refits: every refit of a task in one pair of dispatches, with the same
//! nodes, triangles, root boxes and dropped-triangle counts as each refit alone (whose exact
//! boxes `range_refit.rs` checks).

use super::range_refit::{raw_geometry, refit_of, staged_boxes, staged_triangles};
use super::*;

/// Test trees built one by one, then copied into one set of buffers at their own offsets, as the
/// scene's pools hold every BLAS: what a batch needs to share its dispatches.
struct Pool {
    nodes: wgpu::Buffer,
    order: wgpu::Buffer,
    topology: wgpu::Buffer,
    bounds: wgpu::Buffer,
    /// Per tree: its first word in each buffer (nodes, order, topology, bounds).
    at: Vec<[usize; 4]>,
}

impl Pool {
    fn of(trees: &[GpuTree]) -> Pool {
        let mut words: [Vec<u32>; 4] = Default::default();
        let mut at = Vec::new();
        for t in trees {
            let parts = [&t.nodes, &t.order, &t.topology, &t.bounds].map(read_words);
            at.push(std::array::from_fn(|i| words[i].len()));
            for (all, part) in words.iter_mut().zip(parts) {
                all.extend(part);
            }
        }
        let [nodes, order, topology, bounds] = words.map(|w| buffer_with(bytemuck::cast_slice(&w)));
        Pool {
            nodes,
            order,
            topology,
            bounds,
            at,
        }
    }

    /// Tree `i`'s refit in the pool (its bases shifted by where it lies).
    fn refit<'a>(
        &'a self,
        tree: &GpuTree,
        i: usize,
        source: RefitSource<'a>,
        dst: &'a wgpu::Buffer,
        dst_base: u32,
    ) -> LbvhTriangleRefit<'a> {
        let [nodes, order, topology, bounds] = self.at[i].map(|w| w as u32);
        LbvhTriangleRefit {
            source,
            dst,
            dst_base,
            count: tree.n,
            nodes: &self.nodes,
            node_base: nodes / 16 + tree.bases.node,
            order: &self.order,
            order_base: order + tree.bases.order,
            topology: (&self.topology, topology + tree.bases.topo),
            bounds_out: Some((&self.bounds, bounds / 4 + tree.bases.bounds)),
        }
    }

    /// Asserts tree `i`'s words in the pool equal the tree's own buffers (refit alone), sentinels
    /// around them included.
    fn assert_equals(&self, tree: &GpuTree, i: usize, what: &str) {
        let pool = [&self.nodes, &self.order, &self.topology, &self.bounds].map(read_words);
        let own = [&tree.nodes, &tree.order, &tree.topology, &tree.bounds].map(read_words);
        for (k, name) in ["nodes", "order", "topology", "root box"]
            .iter()
            .enumerate()
        {
            let at = self.at[i][k];
            assert_same_words(
                &pool[k][at..at + own[k].len()],
                &own[k],
                &format!(
                    "{what}: {name} of the batch's refit of {} triangles",
                    tree.n
                ),
            );
        }
    }
}

/// Asserts two word slices are equal, naming the first difference and how many there are
/// (not printing thousands of words).
fn assert_same_words(got: &[u32], want: &[u32], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    let differ: Vec<usize> = (0..got.len()).filter(|&k| got[k] != want[k]).collect();
    if let Some(&k) = differ.first() {
        panic!(
            "{what}: {} of {} words differ, first at {k}: {:#x} instead of {:#x}",
            differ.len(),
            got.len(),
            got[k],
            want[k]
        );
    }
}

/// Moves staged triangles as an animation would.
fn moved(rng: &mut Rng, tris: &[[f32; 4]]) -> Vec<[f32; 4]> {
    let mut after = tris.to_vec();
    for v in after.chunks_mut(3) {
        let d = rng.vec(-0.5, 0.5);
        for x in v.iter_mut() {
            for a in 0..3 {
                x[a] += d[a];
            }
        }
    }
    after
}

#[test]
fn a_batch_of_range_refits_equals_each_refit_alone() {
    let g = gpu();
    let mut lbvh = Lbvh::new(&g.device);
    let mut rng = Rng(53);
    // From raw bytes (more than one block each), then from staged triangles: one block or less,
    // exactly one, one and a bit, many.
    let raw_counts = [257u32, 600, 3001, 20_000];
    let staged_counts = [2u32, 3, 200, 256, 257, 1000, 40_000];
    let counts: Vec<u32> = raw_counts.iter().chain(&staged_counts).copied().collect();
    let mut trees = Vec::new();
    for &n in &counts {
        let boxes = staged_boxes(&staged_triangles(&mut rng, n as usize, 40.0));
        trees.push(build_and_check(&mut lbvh, &boxes, LeafRefs::SortedPosition).0);
    }
    let pool = Pool::of(&trees);
    // The raw refits' bytes in one buffer (each geometry's offsets shifted), their rows and a
    // pair of counters each.
    let mut raw = Vec::new();
    let mut comps_of = Vec::new();
    let mut dropped = Vec::new();
    for &n in &raw_counts {
        let (bytes, mut comps, d) = raw_geometry(&mut rng, n, 40.0);
        let shift = raw.len() as u64;
        for c in &mut comps {
            c.vertex_byte_offset += shift;
            c.index = c.index.map(|(at, f)| (at + shift, f));
        }
        raw.extend(bytes);
        raw.resize(raw.len().div_ceil(4) * 4, 0xEE);
        comps_of.push(comps);
        dropped.push(d);
    }
    let raw = buffer_with(&raw);
    let rows: Vec<Vec<u32>> = comps_of
        .iter()
        .map(|c| component_rows(c, 0).expect("the components fit"))
        .collect();
    let counters = buffer_with(&vec![0u8; 8 * raw_counts.len()]);
    // The staged refits' triangles, each after a gap.
    let mut staged = Vec::new();
    let mut staged_at = Vec::new();
    for &n in &staged_counts {
        staged.extend(vec![[7.0f32; 4]; 3]);
        staged_at.push((staged.len() / 3) as u32);
        let before = staged_triangles(&mut rng, n as usize, 40.0);
        staged.extend(moved(&mut rng, &before));
    }
    let staged = buffer_with(bytemuck::cast_slice(&staged));
    // Every refit's triangles into one buffer, one triangle apart.
    let dst_at: Vec<u32> = counts
        .iter()
        .scan(1u32, |at, &n| {
            let first = *at;
            *at += n + 1;
            Some(first)
        })
        .collect();
    let dst_words = u64::from(dst_at.last().unwrap() + counts.last().unwrap() + 1) * 12;
    let dst = sentinel_buffer(dst_words);
    let source = |i: usize| -> RefitSource<'_> {
        match i.checked_sub(raw_counts.len()) {
            None => RefitSource::Raw(RawTriangles {
                raw: &raw,
                rows: &rows[i],
                counters: &counters,
                counter_base: 2 * i as u32,
            }),
            Some(s) => RefitSource::Staged {
                triangles: &staged,
                base: staged_at[s],
            },
        }
    };
    let refits: Vec<LbvhTriangleRefit<'_>> = trees
        .iter()
        .enumerate()
        .map(|(i, t)| pool.refit(t, i, source(i), &dst, dst_at[i]))
        .collect();
    let mut dispatches = 0;
    run(|rec| {
        lbvh.refit_triangles_batch(rec, &refits);
        dispatches = rec.dispatches;
    });
    // The raw refits' ingest and range refit, the staged refits' gather and range refit.
    assert_eq!(dispatches, 4, "two kinds of source, two passes each");
    let batch_dst = read_words(&dst);
    let batch_counters = read_words(&counters);
    assert_eq!(
        batch_counters,
        dropped.iter().flatten().copied().collect::<Vec<_>>(),
        "dropped triangles of each raw refit"
    );
    // Each refit alone into the tree's own buffers: the same words.
    for (i, tree) in trees.iter().enumerate() {
        let n = tree.n as usize;
        let own_dst = sentinel_buffer((tree.n as u64 + 2) * 12);
        let own_counters = buffer_with(&vec![0u8; 8 * raw_counts.len()]);
        let own_source = match source(i) {
            RefitSource::Raw(t) => RefitSource::Raw(RawTriangles {
                counters: &own_counters,
                ..t
            }),
            s => s,
        };
        run(|rec| lbvh.refit_triangles(rec, &refit_of(tree, own_source, &own_dst, 1)));
        pool.assert_equals(tree, i, "batch against alone");
        let at = 12 * dst_at[i] as usize;
        assert_same_words(
            &batch_dst[at..at + 12 * n],
            &read_words(&own_dst)[12..12 * (n + 1)],
            &format!("gathered triangles of the batch's refit of {n}"),
        );
        assert_eq!(batch_dst[at - 1], SENTINEL, "the word before refit {i}");
        assert_eq!(batch_dst[at + 12 * n], SENTINEL, "the word after refit {i}");
    }
}

#[test]
fn a_batch_splits_at_its_tables_and_scratch_and_at_other_buffers() {
    let buffer = || sentinel_buffer(4);
    let (a, b) = (buffer(), buffer());
    let rows = vec![0u32; 40 * ROW_WORDS];
    let refit = |count: u32, source: RefitSource<'static>, nodes: &'static wgpu::Buffer| {
        LbvhTriangleRefit {
            source,
            dst: nodes,
            dst_base: 0,
            count,
            nodes,
            node_base: 0,
            order: nodes,
            order_base: 0,
            topology: (nodes, 0),
            bounds_out: None,
        }
    };
    // Leaked so the refits can borrow them for 'static (a test's few bytes).
    let (a, b): (&'static wgpu::Buffer, &'static wgpu::Buffer) =
        (Box::leak(Box::new(a)), Box::leak(Box::new(b)));
    let rows: &'static [u32] = Box::leak(rows.into_boxed_slice());
    let staged = |n| {
        refit(
            n,
            RefitSource::Staged {
                triangles: a,
                base: 0,
            },
            a,
        )
    };
    let raw = |n| {
        let t = RawTriangles {
            raw: b,
            rows,
            counters: b,
            counter_base: 0,
        };
        refit(n, RefitSource::Raw(t), a)
    };
    let lens = |refits: &[LbvhTriangleRefit<'_>]| {
        let all: Vec<&LbvhTriangleRefit<'_>> = refits.iter().collect();
        let mut out = Vec::new();
        let mut start = 0;
        while start < all.len() {
            let len = chunk_len(&all[start..]);
            out.push(len);
            start += len;
        }
        out
    };
    // The table of refits.
    let count = 2 * REFIT_BATCH + 76;
    let many: Vec<_> = (0..count).map(|_| staged(300)).collect();
    assert_eq!(lens(&many), [REFIT_BATCH, REFIT_BATCH, 76]);
    // The table of rows: 40 a refit.
    let per = REFIT_INGEST_ROWS / 40;
    let raws: Vec<_> = (0..2 * per + 1).map(|_| raw(300)).collect();
    assert_eq!(lens(&raws), [per, per, 1]);
    // The scratch: positions past REFIT_BATCH_POSITIONS start a new pair, unless one refit
    // alone has more.
    let big = REFIT_BATCH_POSITIONS / 2 + 1;
    let bigs = [staged(big), staged(big), staged(10), staged(2 * big)];
    assert_eq!(lens(&bigs), [1, 2, 1]);
    // Another kind of source, or other buffers.
    let mixed = [staged(300), raw(300), raw(300), staged(300)];
    assert_eq!(lens(&mixed), [1, 2, 1]);
    let other = [
        staged(300),
        refit(
            300,
            RefitSource::Staged {
                triangles: a,
                base: 0,
            },
            b,
        ),
    ];
    assert_eq!(lens(&other), [1, 1]);
}
