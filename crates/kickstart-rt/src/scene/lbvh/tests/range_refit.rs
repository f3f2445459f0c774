//! The range refit of a fast-build BLAS, from staged triangles and from the application's bytes.

use super::*;

/// `n` random staged triangles (3 `vec4`: xyz, w 0; the second vertex's w = 1 marks a
/// dropped triangle), every 11th dropped and every 7th degenerate (a point).
pub(super) fn staged_triangles(rng: &mut Rng, n: usize, spread: f32) -> Vec<[f32; 4]> {
    let mut tris = Vec::with_capacity(3 * n);
    for t in 0..n {
        let c = rng.vec(-spread, spread);
        let mut v: [[f32; 4]; 3] = std::array::from_fn(|_| {
            let d = rng.vec(-1.0, 1.0);
            [c[0] + d[0], c[1] + d[1], c[2] + d[2], 0.0]
        });
        if t % 7 == 3 {
            v[1] = v[0];
            v[2] = v[0];
        }
        if t % 11 == 5 {
            v[1][3] = f32::from_bits(1);
        }
        tris.extend(v);
    }
    tris
}

/// Each staged triangle's box as `scene/triangle_box.wgsl` makes it (dropped: the empty box).
pub(super) fn staged_boxes(tris: &[[f32; 4]]) -> Vec<Aabb> {
    tris.chunks(3)
        .map(|v| {
            if v[1][3].to_bits() == 1 {
                return EMPTY;
            }
            let lo = [0, 1, 2].map(|a| v[0][a].min(v[1][a]).min(v[2][a]));
            let hi = [0, 1, 2].map(|a| v[0][a].max(v[1][a]).max(v[2][a]));
            (lo, hi)
        })
        .collect()
}

/// Builds a fast-build tree over `before`'s boxes, range-refits it to the triangles `after`
/// and checks everything: the refit's dispatches, exact node boxes and root box over the
/// same refs, and the triangles gathered bit-exactly into sorted order.
fn range_refit_and_check(lbvh: &mut Lbvh, before: &[[f32; 4]], after: &[[f32; 4]]) {
    let n = (before.len() / 3) as u32;
    let (tree, _) = build_and_check(lbvh, &staged_boxes(before), LeafRefs::SortedPosition);
    let refs =
        |t: &GpuTree| -> Vec<u32> { t.node_words.chunks(16).flat_map(|w| [w[3], w[7]]).collect() };
    let refs_before = refs(&tree);
    let (src_base, dst_base) = (5u32, 3u32);
    let mut src = vec![[7.0f32; 4]; 3 * src_base as usize];
    src.extend_from_slice(after);
    let src = buffer_with(bytemuck::cast_slice(&src));
    let dst = sentinel_buffer((u64::from(dst_base + n) + 1) * 12);
    let mut dispatches = 0;
    run(|rec| {
        lbvh.refit_triangles(
            rec,
            &LbvhTriangleRefit {
                source: RefitSource::Staged {
                    triangles: &src,
                    base: src_base,
                },
                dst: &dst,
                dst_base,
                count: n,
                nodes: &tree.nodes,
                node_base: tree.bases.node,
                order: &tree.order,
                order_base: tree.bases.order,
                topology: (&tree.topology, tree.bases.topo),
                bounds_out: Some((&tree.bounds, tree.bases.bounds)),
            },
        );
        dispatches = rec.dispatches;
    });
    // The gather (which also makes the pyramid); the nodes that straddle blocks of 256.
    let expected = if n > 256 { 2 } else { 1 };
    assert_eq!(dispatches, expected, "{n} triangles: dispatches");
    let order = tree.order_words.clone();
    let (tree, _) = check_read_back(tree, &staged_boxes(after), false);
    assert_eq!(
        refs(&tree),
        refs_before,
        "{n} triangles: the refit keeps every ref"
    );
    let got = read_words(&dst);
    let after_words: &[u32] = bytemuck::cast_slice(after);
    let base = 12 * dst_base as usize;
    assert_untouched(&got, base, 12 * n as usize, "gathered triangles");
    for (k, &p) in order.iter().enumerate() {
        let p = p as usize;
        assert_eq!(
            &got[base + 12 * k..base + 12 * k + 12],
            &after_words[12 * p..12 * p + 12],
            "{n} triangles: sorted position {k}"
        );
    }
}

#[test]
fn range_refit_of_triangles_equals_exact_boxes_and_gathers_them() {
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(41);
    // One node; one partial block; exactly one block; one more than a block; several
    // blocks (one group: its last block makes the pyramid's top); more than 256 blocks (two
    // groups, then a last stage over them); every level odd somewhere.
    for (n, spread) in [
        (2usize, 1.0f32),
        (3, 1.0),
        (100, 5.0),
        (256, 20.0),
        (257, 20.0),
        (3001, 40.0),
        (40_000, 100.0),
        (70_001, 150.0),
    ] {
        let before = staged_triangles(&mut rng, n, spread);
        // Move every triangle; a few jump across the scene, a few become dropped and a
        // few dropped ones come back.
        let mut after = before.clone();
        for (t, v) in after.chunks_mut(3).enumerate() {
            let d = if t % 17 == 0 {
                rng.vec(-spread, spread)
            } else {
                rng.vec(-0.5, 0.5)
            };
            for x in v.iter_mut() {
                for a in 0..3 {
                    x[a] += d[a];
                }
            }
            match t % 23 {
                4 => v[1][3] = f32::from_bits(1),
                16 => v[1][3] = 0.0,
                _ => {}
            }
        }
        range_refit_and_check(&mut lbvh, &before, &after);
    }
}

/// The application's bytes of a geometry of `n` triangles in two components, and how many
/// of its triangles the ingestion must drop (out-of-range index, non-finite position):
/// component A is a strip of Float32x3 vertices (stride 16, at an unaligned offset) with u32
/// indices, every 13th triangle with an index past the end and every 97th vertex NaN;
/// component B holds the rest, non-indexed (stride 12) and transformed.
pub(super) fn raw_geometry(
    rng: &mut Rng,
    n: u32,
    spread: f32,
) -> (Vec<u8>, Vec<ComponentIngest>, [u32; 2]) {
    let n_a = n * 2 / 3;
    let n_b = n - n_a;
    let verts_a = n_a + 2;
    let mut raw = vec![0xABu8; 6];
    let a_offset = raw.len() as u64;
    let mut walk = rng.vec(-spread, spread);
    let mut positions_a = Vec::new();
    for v in 0..verts_a {
        let d = rng.vec(-1.0, 1.0);
        walk = [0, 1, 2].map(|a| (walk[a] + d[a]).clamp(-spread, spread));
        let p = if v % 97 == 40 {
            [f32::NAN, 0.0, 0.0]
        } else {
            walk
        };
        positions_a.push(p);
        for x in p.iter().chain(&[9.0]) {
            raw.extend_from_slice(&x.to_le_bytes());
        }
    }
    raw.resize(raw.len().div_ceil(4) * 4, 0xCD);
    let index_offset = raw.len() as u64;
    let mut dropped = [0u32; 2];
    for t in 0..n_a {
        let mut idx = [t, t + 1, t + 2];
        if t % 13 == 6 {
            idx[1] = verts_a + 5;
        }
        for i in idx {
            raw.extend_from_slice(&i.to_le_bytes());
        }
        if idx.iter().any(|&i| i >= verts_a) {
            dropped[0] += 1;
        } else if idx.iter().any(|&i| positions_a[i as usize][0].is_nan()) {
            dropped[1] += 1;
        }
    }
    let b_offset = raw.len() as u64;
    for _ in 0..n_b {
        let c = rng.vec(-spread, spread);
        for _ in 0..3 {
            let d = rng.vec(-1.0, 1.0);
            for a in 0..3 {
                raw.extend_from_slice(&(c[a] + d[a]).to_le_bytes());
            }
        }
    }
    let component = |offset, stride, count, index, triangles, transform, base| ComponentIngest {
        vertex_byte_offset: offset,
        vertex_stride: stride,
        vertex_format: crate::tasks::VertexFormat::Float32x3,
        vertex_count: count,
        index,
        first_index: 0,
        triangle_count: triangles,
        transform,
        primitive_base: base,
        opacity: None,
    };
    let transform = glam::Affine3A::from_scale_rotation_translation(
        glam::Vec3::new(0.5, 2.0, 1.0),
        glam::Quat::from_rotation_y(0.3),
        glam::Vec3::new(10.0, -3.0, 1.0),
    );
    let comps = vec![
        component(
            a_offset,
            16,
            verts_a,
            Some((index_offset, crate::tasks::IndexFormat::Uint32)),
            n_a,
            None,
            0,
        ),
        component(b_offset, 12, 3 * n_b, None, n_b, Some(transform), n_a),
    ];
    (raw, comps, dropped)
}

#[test]
fn range_refit_from_raw_bytes_equals_ingestion_then_refit() {
    // The fused refit decodes each sorted position's triangle itself: the same triangles,
    // nodes, root box and dropped-triangle counts as the ingestion pass followed by the
    // refit of the staged triangles, in two passes instead of three; exact boxes.
    let g = gpu();
    let mut lbvh = Lbvh::new(&g.device);
    let ingest = Ingest::new(&g.device);
    let mut rng = Rng(47);
    for (n, spread) in [(257u32, 20.0f32), (3001, 40.0), (40_000, 100.0)] {
        let (raw, comps, dropped) = raw_geometry(&mut rng, n, spread);
        assert!(dropped[0] > 0 && dropped[1] > 0, "the data drops both ways");
        let raw = buffer_with(&raw);
        let boxes = staged_boxes(&staged_triangles(&mut rng, n as usize, spread));
        let (src_base, dst_base, counter_base) = (5u32, 3u32, 2u32);
        let words = (u64::from(dst_base + n) + 1) * 12;
        // Ingestion into staged triangles, then the refit of them.
        let (staged_tree, _) = build_and_check(&mut lbvh, &boxes, LeafRefs::SortedPosition);
        let staged = sentinel_buffer((u64::from(src_base + n) + 1) * 12);
        let (staged_dst, staged_counters) = (sentinel_buffer(words), buffer_with(&[0u8; 16]));
        run(|rec| {
            ingest.record(
                rec,
                &raw,
                &comps,
                &staged,
                src_base,
                &staged_counters,
                counter_base,
            );
            lbvh.refit_triangles(
                rec,
                &refit_of(
                    &staged_tree,
                    RefitSource::Staged {
                        triangles: &staged,
                        base: src_base,
                    },
                    &staged_dst,
                    dst_base,
                ),
            );
        });
        // The fused refit.
        let (tree, _) = build_and_check(&mut lbvh, &boxes, LeafRefs::SortedPosition);
        let (dst, counters) = (sentinel_buffer(words), buffer_with(&[0u8; 16]));
        let rows = component_rows(&comps, 0).expect("the components fit");
        assert!(Lbvh::can_refit_from_raw(n, &rows));
        let mut dispatches = 0;
        run(|rec| {
            let source = RefitSource::Raw(RawTriangles {
                raw: &raw,
                rows: &rows,
                counters: &counters,
                counter_base,
            });
            lbvh.refit_triangles(rec, &refit_of(&tree, source, &dst, dst_base));
            dispatches = rec.dispatches;
        });
        assert_eq!(dispatches, 2, "{n} triangles: refit ingest, range refit");
        let counts = read_words(&counters);
        assert_eq!(counts, read_words(&staged_counters), "{n}: dropped counts");
        assert_eq!(
            counts,
            [0, 0, dropped[0], dropped[1]],
            "{n}: dropped counts"
        );
        let got = read_words(&dst);
        assert_untouched(&got, 12 * dst_base as usize, 12 * n as usize, "triangles");
        assert_eq!(got, read_words(&staged_dst), "{n}: the gathered triangles");
        let staged_words = read_words(&staged);
        let staged_tris: &[[f32; 4]] =
            bytemuck::cast_slice(&staged_words[12 * src_base as usize..][..12 * n as usize]);
        let (staged_tree, _) = check_read_back(staged_tree, &staged_boxes(staged_tris), false);
        let (tree, _) = check_read_back(tree, &staged_boxes(staged_tris), false);
        assert_eq!(tree.node_words, staged_tree.node_words, "{n}: nodes");
        assert_eq!(
            read_words(&tree.bounds),
            read_words(&staged_tree.bounds),
            "{n}: root box"
        );
    }
    // Too few triangles for the fused pass (one block: the root would need bounds_out).
    assert!(!Lbvh::can_refit_from_raw(256, &[0; ROW_WORDS]));
    assert!(!Lbvh::can_refit_from_raw(
        1000,
        &vec![0; (REFIT_INGEST_ROWS + 1) * ROW_WORDS]
    ));
}

/// The range refit of `tree` from `source` into `dst` at triangle `dst_base`.
pub(super) fn refit_of<'a>(
    tree: &'a GpuTree,
    source: RefitSource<'a>,
    dst: &'a wgpu::Buffer,
    dst_base: u32,
) -> LbvhTriangleRefit<'a> {
    LbvhTriangleRefit {
        source,
        dst,
        dst_base,
        count: tree.n,
        nodes: &tree.nodes,
        node_base: tree.bases.node,
        order: &tree.order,
        order_base: tree.bases.order,
        topology: (&tree.topology, tree.bases.topo),
        bounds_out: Some((&tree.bounds, tree.bases.bounds)),
    }
}

/// A million triangles: 4100 blocks, 17 groups at the pyramid's first stage. Slow on
/// software Vulkan: run with `--ignored` (the H100 runs).
#[test]
#[ignore]
fn range_refit_of_a_million_triangles() {
    let mut lbvh = Lbvh::new(&gpu().device);
    let mut rng = Rng(43);
    let n = (1 << 20) + 4097 * 256 / 1024;
    let before = staged_triangles(&mut rng, n, 500.0);
    let mut after = before.clone();
    for v in after.chunks_mut(3) {
        let d = rng.vec(-1.0, 1.0);
        for x in v.iter_mut() {
            for a in 0..3 {
                x[a] += d[a];
            }
        }
    }
    assert_eq!(pyramid_level_count(n as u32, 2 * REFIT_GATHER_LEVELS), 17);
    range_refit_and_check(&mut lbvh, &before, &after);
}

#[test]
fn pyramid_boxes_sum_the_levels() {
    for (n, levels) in [
        (1u32, vec![1]),
        (2, vec![2, 1]),
        (5, vec![5, 3, 2, 1]),
        (8, vec![8, 4, 2, 1]),
    ] {
        let counts: Vec<u32> = (0..levels.len() as u32)
            .map(|l| pyramid_level_count(n, l))
            .collect();
        assert_eq!(counts, levels, "{n} boxes");
        assert_eq!(
            pyramid_boxes(n),
            levels.iter().map(|&c| u64::from(c)).sum::<u64>()
        );
    }
}
