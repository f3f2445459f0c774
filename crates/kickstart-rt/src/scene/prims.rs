//! Small per-primitive passes of the BVH builds (`shaders/scene/prims.wgsl`): triangle AABBs for the
//! BLAS builder, triangle gather into the builder's sorted order, and instance world AABBs for the
//! TLAS. Layouts: `docs/ray-tracing-core.md`.

use crate::gpu::reflect::{ReflectedPipeline, ReflectedShader};
use crate::gpu::Recorder;

/// Threads per workgroup of the triangle entry points of `scene/prims.wgsl` (one primitive each).
const WORKGROUP: u32 = 64;
/// Threads per workgroup of `instance_refs` (the shader's `INSTANCE_WG`): wider, so fewer
/// workgroups merge the centroid bounds with device atomics.
const INSTANCE_WORKGROUP: u32 = 256;
/// `instance_refs` flag: merge the boxes' centroid bounds.
const MERGE_CENTROID_BOUNDS: u32 = 1;
/// Most refs one instance is opened into: the shader's `MAX_REFS`, written into its source by
/// [`Prims::new`] so the two cannot differ (the ref layout `i * k + j` depends on both).
pub(crate) const MAX_REFS_PER_INSTANCE: u32 = 32;

/// The pipelines (one module, one entry point each).
pub(crate) struct Prims {
    /// `triangle_aabbs` entry point.
    triangle_aabbs: ReflectedPipeline,
    /// `gather_triangles` entry point.
    gather_triangles: ReflectedPipeline,
    /// `gather_triangles_boxes` entry point.
    gather_triangles_boxes: ReflectedPipeline,
    /// `instance_refs` entry point (one ref an instance).
    instance_refs: ReflectedPipeline,
    /// `instance_refs_opened` entry point (instances opened into more refs: a workgroup each).
    instance_refs_opened: ReflectedPipeline,
    /// Bound in place of missing centroid-bounds words (never written: the flag is off).
    no_bounds: wgpu::Buffer,
}

/// The WGSL of the per-primitive passes, labelled.
pub(crate) fn shader_variants() -> Vec<(String, String)> {
    let max_refs = MAX_REFS_PER_INSTANCE.to_string();
    let shader = ReflectedShader::compose(&["scene/prims"], &[("MAX_REFS", &max_refs)]);
    vec![("scene/prims".into(), shader.source().to_string())]
}

impl Prims {
    /// Creates the pipelines.
    pub fn new(device: &wgpu::Device) -> Self {
        let max_refs = MAX_REFS_PER_INSTANCE.to_string();
        let shader = ReflectedShader::compose(&["scene/prims"], &[("MAX_REFS", &max_refs)]);
        let make = |entry: &str| shader.pipeline(device, "kickstart-rt prims", entry);
        Prims {
            triangle_aabbs: make("triangle_aabbs"),
            gather_triangles: make("gather_triangles"),
            gather_triangles_boxes: make("gather_triangles_boxes"),
            instance_refs: make("instance_refs"),
            instance_refs_opened: make("instance_refs_opened"),
            no_bounds: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("kickstart-rt no centroid bounds"),
                size: 32,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            }),
        }
    }

    /// AABBs (2 `vec4` per primitive) of the `count` triangles from slot `tri_base` of `tris`
    /// into `aabbs` from primitive `aabb_base`. Dropped triangles get the empty box; degenerate
    /// finite triangles keep their flat box.
    pub fn triangle_aabbs(
        &self,
        rec: &mut Recorder<'_>,
        tris: &wgpu::Buffer,
        tri_base: u32,
        count: u32,
        aabbs: &wgpu::Buffer,
        aabb_base: u32,
    ) {
        if count == 0 {
            return;
        }
        let params = rec.uniform(
            "kickstart-rt triangle aabbs params",
            &[tri_base, count, aabb_base, 0],
        );
        let bind = self.triangle_aabbs.bind_group(
            rec.device,
            "kickstart-rt triangle aabbs",
            0,
            &[
                ("params", &params),
                ("aabb_tris", tris),
                ("tri_aabbs", aabbs),
            ],
        );
        rec.dispatch(
            "blas build: triangle aabbs",
            &self.triangle_aabbs.pipeline,
            &[&bind],
            count.div_ceil(WORKGROUP),
        );
    }

    /// `dst[dst_base + k] = src[src_base + order[order_base + k]]` for `k < count`, whole
    /// triangles (3 `vec4`), bit-exact. With `boxes`, also each triangle's box at its sorted
    /// position `k` (vec4 `2k`, `2k + 1`; the empty box for dropped triangles, as
    /// [`Prims::triangle_aabbs`]): a refit's boxes in the order its climb reads them.
    #[allow(clippy::too_many_arguments)] // the interface the BVH code is written against
    pub fn gather_triangles(
        &self,
        rec: &mut Recorder<'_>,
        src: &wgpu::Buffer,
        src_base: u32,
        order: &wgpu::Buffer,
        order_base: u32,
        count: u32,
        dst: &wgpu::Buffer,
        dst_base: u32,
        boxes: Option<&wgpu::Buffer>,
    ) {
        if count == 0 {
            return;
        }
        let params = rec.uniform(
            "kickstart-rt gather triangles params",
            &[src_base, order_base, count, dst_base],
        );
        let mut buffers = vec![
            ("params", &params),
            ("gather_src", src),
            ("gather_order", order),
            ("gather_dst", dst),
        ];
        let (pipeline, label) = match boxes {
            Some(b) => {
                buffers.push(("gather_boxes", b));
                (&self.gather_triangles_boxes, "gather triangles and boxes")
            }
            None => (&self.gather_triangles, "blas build: gather triangles"),
        };
        let bind = pipeline.bind_group(rec.device, "kickstart-rt gather triangles", 0, &buffers);
        rec.dispatch(
            label,
            &pipeline.pipeline,
            &[&bind],
            count.div_ceil(WORKGROUP),
        );
    }

    /// The TLAS's primitives, `refs_per_instance` (1..=[`MAX_REFS_PER_INSTANCE`]) refs per
    /// instance slot `0..count` (`shaders/scene/prims.wgsl`, `instance_refs`): ref `i * k + j` names
    /// slot `i` and an entry into its BLAS (the root when k = 1; with k > 1 the BLAS opened
    /// largest world box first). Each ref's world box goes to `aabbs` (the empty box for unused
    /// refs and hidden instances) and (slot, entry) to the ref table at the end of `tlas_nodes`
    /// (C node slots, then C table entries: the buffer holds 80 · C bytes). With
    /// `centroid_bounds`, the boxes' centroid bounds are also merged into its six words (cleared
    /// first) for the LBVH.
    #[allow(clippy::too_many_arguments)] // the scene's tables and the TLAS's buffers
    pub fn instance_refs(
        &self,
        rec: &mut Recorder<'_>,
        instances: &wgpu::Buffer,
        geometries: &wgpu::Buffer,
        blas_nodes: &wgpu::Buffer,
        count: u32,
        refs_per_instance: u32,
        aabbs: &wgpu::Buffer,
        tlas_nodes: &wgpu::Buffer,
        centroid_bounds: Option<(&wgpu::Buffer, u32)>,
    ) {
        if count == 0 {
            return;
        }
        let (bounds, bounds_base, flags) = match centroid_bounds {
            Some((b, base)) => {
                // Zero is the identity of the encoded atomicMax.
                rec.encoder
                    .clear_buffer(b, u64::from(base) * 4, Some(6 * 4));
                (b, base, MERGE_CENTROID_BOUNDS)
            }
            None => (&self.no_bounds, 0, 0),
        };
        let k = refs_per_instance.clamp(1, MAX_REFS_PER_INSTANCE);
        let params = rec.uniform(
            "kickstart-rt instance refs params",
            &[count, flags | (k << 8), bounds_base, 0],
        );
        // Opened instances take a workgroup each (at most TLAS_REF_BUDGET / 2 of them: one
        // dimension suffices), unopened ones an invocation each.
        let (pass, workgroups) = if k > 1 {
            (&self.instance_refs_opened, count)
        } else {
            (&self.instance_refs, count.div_ceil(INSTANCE_WORKGROUP))
        };
        let bind = pass.bind_group(
            rec.device,
            "kickstart-rt instance refs",
            0,
            &[
                ("params", &params),
                ("instances", instances),
                ("geometries", geometries),
                ("instance_boxes", aabbs),
                ("instance_centroid_bounds", bounds),
                ("ref_blas_nodes", blas_nodes),
                ("ref_table", tlas_nodes),
            ],
        );
        rec.dispatch(
            "tlas build: instance refs",
            &pass.pipeline,
            &[&bind],
            workgroups,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::testing::{buffer_with, gpu, read_back, run, Rng};
    use glam::{Affine3A, Quat, Vec3};

    /// The passes composed and validated with naga without a device; the constants the Rust side
    /// sizes dispatches and the TLAS by checked against the WGSL.
    #[test]
    fn the_shader_validates_and_matches_the_rust_side() {
        use crate::gpu::compose::compose;
        use crate::gpu::wgsl_check::{const_u32, validate};
        let max_refs = MAX_REFS_PER_INSTANCE.to_string();
        let source = compose(&["scene/prims"], &[("MAX_REFS", &max_refs)]);
        let module = validate("scene/prims", &source);
        assert_eq!(const_u32(&module, "WG"), WORKGROUP);
        assert_eq!(const_u32(&module, "MAX_REFS"), MAX_REFS_PER_INSTANCE);
    }

    /// Sentinel of untouched output words.
    const SENTINEL: u32 = 0xdead_beef;

    /// The first `n` words of `buf`.
    fn words(buf: &wgpu::Buffer, n: usize) -> Vec<u32> {
        bytemuck::cast_slice(&read_back(buf, 0, n as u64 * 4)).to_vec()
    }

    /// The empty box as written by the shaders.
    const EMPTY: [[f32; 4]; 2] = [[1e30, 1e30, 1e30, 0.0], [-1e30, -1e30, -1e30, 0.0]];

    /// `n` random staged triangles (3 `vec4` each) and which are dropped: every fifth from 1
    /// has two equal vertices, from 2 three collinear ones, from 3 is dropped.
    fn test_triangles(rng: &mut Rng, n: usize) -> (Vec<[f32; 4]>, Vec<bool>) {
        let mut tris = vec![[0f32; 4]; 3 * n];
        let mut dropped = vec![false; n];
        for t in 0..n {
            for k in 0..3 {
                tris[3 * t + k] = [
                    rng.range(-50.0, 50.0),
                    rng.range(-50.0, 50.0),
                    rng.range(-50.0, 50.0),
                    0.0,
                ];
            }
            match t % 5 {
                1 => tris[3 * t + 2] = tris[3 * t], // degenerate: two equal vertices
                2 => {
                    // degenerate: collinear (the midpoint of the other two)
                    let [a, b] = [tris[3 * t], tris[3 * t + 1]];
                    tris[3 * t + 2] = [
                        (a[0] + b[0]) * 0.5,
                        (a[1] + b[1]) * 0.5,
                        (a[2] + b[2]) * 0.5,
                        0.0,
                    ];
                }
                3 => {
                    dropped[t] = true;
                    tris[3 * t] = [0.0, 0.0, 0.0, f32::from_bits(t as u32)];
                    tris[3 * t + 1] = [0.0, 0.0, 0.0, f32::from_bits(1)];
                    tris[3 * t + 2] = [0.0; 4];
                }
                _ => tris[3 * t][3] = f32::from_bits(t as u32), // primitive index in w is ignored
            }
        }
        (tris, dropped)
    }

    /// The box words (2 `vec4`) the shaders must write for triangle `t`.
    fn expected_box_words(tris: &[[f32; 4]], dropped: &[bool], t: usize) -> Vec<u32> {
        let want = if dropped[t] {
            EMPTY
        } else {
            let v = &tris[3 * t..3 * t + 3];
            let lo = |a: usize| v[0][a].min(v[1][a]).min(v[2][a]);
            let hi = |a: usize| v[0][a].max(v[1][a]).max(v[2][a]);
            [[lo(0), lo(1), lo(2), 0.0], [hi(0), hi(1), hi(2), 0.0]]
        };
        want.iter().flatten().map(|f| f.to_bits()).collect()
    }

    #[test]
    fn triangle_aabbs_are_exact_and_dropped_triangles_empty() {
        let mut rng = Rng(11);
        let (tris, dropped) = test_triangles(&mut rng, 40);
        let (tri_base, count, aabb_base) = (5u32, 30u32, 3u32);
        let tri_buf = buffer_with(bytemuck::cast_slice(&tris));
        let aabbs = buffer_with(bytemuck::cast_slice(&vec![SENTINEL; 8 * 40]));
        let prims = Prims::new(&gpu().device);
        run(|rec| prims.triangle_aabbs(rec, &tri_buf, tri_base, count, &aabbs, aabb_base));
        let got = words(&aabbs, 8 * 40);
        for p in 0..40usize {
            let box_words = &got[8 * p..8 * p + 8];
            let k = p as i64 - aabb_base as i64;
            if k < 0 || k >= count as i64 {
                assert!(box_words.iter().all(|&w| w == SENTINEL), "aabb {p} written");
                continue;
            }
            let t = tri_base as usize + k as usize;
            let want_words = expected_box_words(&tris, &dropped, t);
            assert_eq!(box_words, &want_words[..], "triangle {t}");
        }
    }

    #[test]
    fn gather_triangles_with_boxes_writes_each_box_at_its_sorted_position() {
        let mut rng = Rng(13);
        let (tris, dropped) = test_triangles(&mut rng, 50);
        let (perm, order) = gather_order(&mut rng);
        let (src_base, order_base, count, dst_base) = (7u32, 4u32, 30u32, 2u32);
        let src_buf = buffer_with(bytemuck::cast_slice(&tris));
        let order_buf = buffer_with(bytemuck::cast_slice(&order));
        let dst = buffer_with(bytemuck::cast_slice(&vec![SENTINEL; 12 * 40]));
        let boxes = buffer_with(bytemuck::cast_slice(&vec![SENTINEL; 8 * 40]));
        let prims = Prims::new(&gpu().device);
        run(|rec| {
            prims.gather_triangles(
                rec,
                &src_buf,
                src_base,
                &order_buf,
                order_base,
                count,
                &dst,
                dst_base,
                Some(&boxes),
            )
        });
        let src_words: &[u32] = bytemuck::cast_slice(&tris);
        let got = words(&dst, 12 * 40);
        let got_boxes = words(&boxes, 8 * 40);
        for k in 0..40usize {
            let box_words = &got_boxes[8 * k..8 * k + 8];
            if k >= count as usize {
                assert!(box_words.iter().all(|&w| w == SENTINEL), "box {k} written");
                continue;
            }
            // Boxes start at 0 (the refit's scratch), triangles at dst_base.
            let s = (src_base + perm[k]) as usize;
            assert_eq!(
                box_words,
                &expected_box_words(&tris, &dropped, s)[..],
                "box {k}"
            );
            let d = dst_base as usize + k;
            assert_eq!(
                &got[12 * d..12 * d + 12],
                &src_words[12 * s..12 * s + 12],
                "dst {d}"
            );
        }
    }

    /// A random permutation of 0..30 and the order buffer's words: 4 sentinels (order_base 4),
    /// then the permutation.
    fn gather_order(rng: &mut Rng) -> (Vec<u32>, Vec<u32>) {
        let mut perm: Vec<u32> = (0..30).collect();
        for i in (1..perm.len()).rev() {
            perm.swap(i, rng.below(i as u32 + 1) as usize);
        }
        let mut order = vec![SENTINEL; 4];
        order.extend(&perm);
        (perm, order)
    }

    #[test]
    fn gather_triangles_applies_the_permutation_bit_exactly() {
        let mut rng = Rng(12);
        // Random bits (NaN and subnormal patterns included): the copy must not touch them.
        let src: Vec<u32> = (0..50 * 12).map(|_| rng.next() as u32).collect();
        let (perm, order) = gather_order(&mut rng);
        let (src_base, order_base, count, dst_base) = (7u32, 4u32, 30u32, 2u32);
        let src_buf = buffer_with(bytemuck::cast_slice(&src));
        let order_buf = buffer_with(bytemuck::cast_slice(&order));
        let dst = buffer_with(bytemuck::cast_slice(&vec![SENTINEL; 12 * 40]));
        let prims = Prims::new(&gpu().device);
        run(|rec| {
            prims.gather_triangles(
                rec, &src_buf, src_base, &order_buf, order_base, count, &dst, dst_base, None,
            )
        });
        let got = words(&dst, 12 * 40);
        for d in 0..40usize {
            let tri = &got[12 * d..12 * d + 12];
            if d < dst_base as usize || d >= (dst_base + count) as usize {
                assert!(tri.iter().all(|&w| w == SENTINEL), "triangle {d} written");
            } else {
                let s = (src_base + perm[d - dst_base as usize]) as usize;
                assert_eq!(tri, &src[12 * s..12 * s + 12], "dst {d} from src {s}");
            }
        }
    }

    /// Words of a geometry record (`GeometryGpu`).
    const GEOMETRY_WORDS: usize = 16;

    /// A geometry record: build flags, triangle count and its BLAS box (opaque).
    fn geometry_words(built: u32, tri_count: u32, lo: [f32; 3], hi: [f32; 3]) -> Vec<u32> {
        let mut g = vec![0, 0, tri_count, built];
        g.extend(lo.iter().chain(&[0.0]).map(|f| f.to_bits()));
        g.extend(hi.iter().chain(&[0.0]).map(|f| f.to_bits()));
        g.extend(crate::scene::opacity::OPAQUE_RECORD);
        g
    }

    /// An instance record (32 words): object-to-world rows of `t`, geometry slot and flags.
    fn instance_words(t: Affine3A, geometry: u32, flags: u32) -> Vec<u32> {
        let m = t.matrix3;
        let mut w = Vec::new();
        for r in 0..3 {
            w.extend([m.x_axis[r], m.y_axis[r], m.z_axis[r], t.translation[r]].map(f32::to_bits));
        }
        w.extend([0u32; 12]); // world_to_object: unused here
        w.extend([geometry, 0xff, flags, 0, 0, 0, 0, 0]);
        w
    }

    /// A random scale (0.01..20 an axis), rotation and translation (up to 1e4 an axis).
    fn random_transform(rng: &mut Rng) -> Affine3A {
        Affine3A::from_scale_rotation_translation(
            Vec3::new(
                rng.range(0.01, 20.0),
                rng.range(0.01, 20.0),
                rng.range(0.01, 20.0),
            ),
            Quat::from_euler(
                glam::EulerRot::ZYX,
                rng.range(-3.2, 3.2),
                rng.range(-3.2, 3.2),
                rng.range(-3.2, 3.2),
            ),
            Vec3::new(
                rng.range(-1e4, 1e4),
                rng.range(-1e4, 1e4),
                rng.range(-1e4, 1e4),
            ),
        )
    }

    /// Asserts that the world box `b` (2 `vec4`) of instance `i` contains every corner of the
    /// geometry box (`gw`, a geometry record) transformed by `t` on the CPU, and is tight (only
    /// the rounding pad).
    fn assert_bounds_transformed_corners(i: usize, b: &[f32], t: Affine3A, gw: &[u32]) {
        let glo = Vec3::from_array([4, 5, 6].map(|w| f32::from_bits(gw[w])));
        let ghi = Vec3::from_array([8, 9, 10].map(|w| f32::from_bits(gw[w])));
        let (mut wlo, mut whi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for c in 0..8 {
            let p = Vec3::select(
                glam::BVec3::new(c & 1 != 0, c & 2 != 0, c & 4 != 0),
                ghi,
                glo,
            );
            let q = t.transform_point3(p);
            wlo = wlo.min(q);
            whi = whi.max(q);
        }
        assert_eq!((b[3], b[7]), (0.0, 0.0));
        // Magnitude of the transform's terms: the scale of its rounding.
        let e = glo.abs().max(ghi.abs());
        let m = t.matrix3;
        let row_dot = |r: usize| Vec3::from(m.row(r)).abs().dot(e);
        let mag = Vec3::new(row_dot(0), row_dot(1), row_dot(2)) + Vec3::from(t.translation).abs();
        for a in 0..3 {
            // Contains every CPU-transformed corner, and is tight (only the rounding pad).
            assert!(
                b[a] <= wlo[a] && b[4 + a] >= whi[a],
                "instance {i} axis {a}: {b:?} vs {wlo} {whi}"
            );
            let tol = 1e-5 * mag[a];
            assert!(
                wlo[a] - b[a] <= tol && b[4 + a] - whi[a] <= tol,
                "instance {i} axis {a} loose: {b:?} vs {wlo} {whi}"
            );
        }
    }

    #[test]
    fn instance_refs_of_one_bound_transformed_corners_and_hidden_ones_are_empty() {
        let mut rng = Rng(13);
        let (lo, hi) = ([-1.0, -2.0, -3.0], [4.0, 5.0, 6.0]);
        let mut geos = geometry_words(1, 10, lo, hi);
        geos.extend(geometry_words(0, 0, lo, hi)); // 1: not built
        geos.extend(geometry_words(1, 0, lo, hi)); // 2: built, no triangles
        geos.extend(geometry_words(1, 4, [1e30; 3], [-1e30; 3])); // 3: all triangles dropped
                                                                  // 4: flat box, extra flag bit
        geos.extend(geometry_words(0b11, 3, [2.0, 2.0, 2.0], [2.0, 3.0, 2.5]));
        let spin = Affine3A::from_scale_rotation_translation(
            Vec3::new(2.0, 0.5, 3.0),
            Quat::from_euler(glam::EulerRot::XYZ, 0.3, 1.1, -0.4),
            Vec3::new(100.0, -7.0, 3.5),
        );
        // (transform, geometry, flags, visible)
        let mut cases = vec![
            (spin, 0, 1, true),
            (spin, 0, 0, false),
            (spin, 1, 1, false),
            (spin, 2, 1, false),
            (spin, 3, 1, false),
            (spin, 99, 1, false), // geometry slot past the table
            (Affine3A::IDENTITY, 0, 1, true),
            (spin, 4, 0b101, true),
        ];
        for _ in 0..60 {
            let t = random_transform(&mut rng);
            cases.push((t, if rng.below(4) == 0 { 4 } else { 0 }, 1, true));
        }
        let inst: Vec<u32> = cases
            .iter()
            .flat_map(|&(t, g, f, _)| instance_words(t, g, f))
            .collect();
        let n = cases.len();
        let inst_buf = buffer_with(bytemuck::cast_slice(&inst));
        let geo_buf = buffer_with(bytemuck::cast_slice(&geos));
        let aabbs = buffer_with(bytemuck::cast_slice(&vec![SENTINEL; 8 * (n + 2)]));
        let prims = Prims::new(&gpu().device);
        // One ref per instance: the BLAS root, never read (a dummy node buffer).
        let blas = buffer_with(&[0u8; 64]);
        let tlas = buffer_with(&vec![0xffu8; 80 * n]);
        run(|rec| {
            prims.instance_refs(
                rec, &inst_buf, &geo_buf, &blas, n as u32, 1, &aabbs, &tlas, None,
            )
        });
        // The ref table after the n node slots: (slot, root entry 0) per instance.
        let table = words(&tlas, 20 * n);
        for i in 0..n {
            assert_eq!(
                &table[16 * n + 4 * i..16 * n + 4 * i + 4],
                &[i as u32, 0, 0, 0]
            );
        }
        let got: Vec<f32> = words(&aabbs, 8 * (n + 2))
            .into_iter()
            .map(f32::from_bits)
            .collect();
        for (i, &(t, g, _, visible)) in cases.iter().enumerate() {
            let b = &got[8 * i..8 * i + 8];
            if !visible {
                assert_eq!(b, EMPTY.as_flattened(), "instance {i}");
                continue;
            }
            let gw = &geos[GEOMETRY_WORDS * g as usize..GEOMETRY_WORDS * (g as usize + 1)];
            assert_bounds_transformed_corners(i, b, t, gw);
        }
        assert!(
            got[8 * n..].iter().all(|&w| w.to_bits() == SENTINEL),
            "past count written"
        );
    }

    /// A BVH2 node (our 16-word layout) of two children (box, reference).
    fn bvh2_node(l: ([f32; 3], [f32; 3], u32), r: ([f32; 3], [f32; 3], u32)) -> Vec<u32> {
        let mut w = Vec::new();
        for (v, e) in [(l.0, l.2), (l.1, r.2), (r.0, 0), (r.1, 0)] {
            w.extend(v.map(f32::to_bits));
            w.push(e);
        }
        w
    }

    /// The BLAS nodes and geometry records of the opening test below, and the leaf refs of its
    /// leaves A–E (geometry 0) and F (geometry 1).
    fn opening_scene() -> (Vec<u32>, Vec<u32>, [u32; 6]) {
        const LEAF: u32 = 0x8000_0000;
        let empty = ([1e30f32; 3], [-1e30f32; 3], LEAF);
        // Geometry 0, nodes from 1 (node_base 1; node 0 of the buffer is junk that must not be
        // read): root 0 → inner 1 (small, x 0..1) and inner 2 (large, x 10..20); node 1 → leaves
        // A, B; node 2 → leaf C and inner 3; node 3 → leaves D and E (the larger, x 15..20).
        let a = ([0.0, 0.0, 0.0], [0.5, 1.0, 1.0], LEAF);
        let b = ([0.5, 0.0, 0.0], [1.0, 1.0, 1.0], LEAF | 1);
        let c = ([10.0, 0.0, 0.0], [12.0, 1.0, 1.0], LEAF | (1 << 28) | 2);
        let d = ([12.0, 0.0, 0.0], [15.0, 1.0, 1.0], LEAF | 4);
        let e = ([15.0, 0.0, 0.0], [20.0, 1.0, 1.0], LEAF | 5);
        let mut nodes = vec![0xdead_beef_u32; 16];
        nodes.extend(bvh2_node(
            ([0.0; 3], [1.0; 3], 1),
            ([10.0, 0.0, 0.0], [20.0, 1.0, 1.0], 2),
        ));
        nodes.extend(bvh2_node(a, b));
        nodes.extend(bvh2_node(c, ([12.0, 0.0, 0.0], [20.0, 1.0, 1.0], 3)));
        nodes.extend(bvh2_node(d, e));
        // Geometry 1 (node_base 5): one triangle, root = (leaf, empty).
        let f = ([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], LEAF);
        nodes.extend(bvh2_node(f, empty));
        // Geometry 0 carries build stamp 5 (flags bits 8-31), which its refs record.
        let mut geos: Vec<u32> = vec![1, 0, 6, 1 | (5 << 8)];
        geos.extend([0.0f32, 0.0, 0.0, 0.0, 20.0, 1.0, 1.0, 0.0].map(f32::to_bits));
        geos.extend(crate::scene::opacity::OPAQUE_RECORD);
        geos.extend([5, 6, 1, 1]);
        geos.extend([-1.0f32, -1.0, -1.0, 0.0, 1.0, 1.0, 1.0, 0.0].map(f32::to_bits));
        geos.extend(crate::scene::opacity::OPAQUE_RECORD);
        (nodes, geos, [a.2, b.2, c.2, d.2, e.2, f.2])
    }

    /// Asserts the refs instance slots 0 (`want`: entry and world x range of each, in ref
    /// order), 1 (hidden) and 2 (one triangle, leaf ref `f`) were opened into, `k` each.
    fn assert_opened_refs(k: u32, want: &[(u32, f32, f32)], table: &[u32], boxes: &[f32], f: u32) {
        let refs = 3 * k as usize;
        let at = 16 * refs;
        for j in 0..k as usize {
            let e = &table[at + 4 * j..at + 4 * j + 4];
            let (lo, hi) = (&boxes[8 * j..8 * j + 3], &boxes[8 * j + 4..8 * j + 7]);
            match want.get(j) {
                Some(&(entry, x0, x1)) => {
                    assert_eq!(e, &[0, entry, 5, 0], "k {k} ref {j}");
                    // The padded world box: x moved by 100, within 2^-21 of the magnitude.
                    assert!(
                        (lo[0] - x0).abs() < 1e-3 && lo[0] <= x0,
                        "k {k} ref {j}: {lo:?}"
                    );
                    assert!(
                        (hi[0] - x1).abs() < 1e-3 && hi[0] >= x1,
                        "k {k} ref {j}: {hi:?}"
                    );
                }
                None => {
                    assert_eq!(e, &[0, 0, 5, 0], "k {k} unused ref {j}");
                    assert_eq!([lo[0], hi[0]], [1e30, -1e30], "k {k} unused ref {j}");
                }
            }
        }
        // Slot 1 is hidden: every ref empty, entries 0.
        for j in 0..k as usize {
            let r = k as usize + j;
            assert_eq!(&table[at + 4 * r..at + 4 * r + 4], &[1, 0, 0, 0]);
            assert_eq!([boxes[8 * r], boxes[8 * r + 4]], [1e30, -1e30]);
        }
        // Slot 2: one triangle; opened (k > 1), its root's one leaf child is its only ref.
        let r = 2 * k as usize;
        let entry = if k == 1 { 0 } else { f };
        assert_eq!(
            &table[at + 4 * r..at + 4 * r + 4],
            &[2, entry, 0, 0],
            "k {k}"
        );
        for j in 1..k as usize {
            assert_eq!(boxes[8 * (r + j)], 1e30, "k {k}: slot 2 ref {j} unused");
        }
    }

    /// An instance record of `geometry` moved by `x` along x (`flags` bit 0: visible).
    fn instance(x: f32, geometry: u32, flags: u32) -> Vec<u32> {
        let mut w = Vec::new();
        for r in 0..3 {
            let row = [f32::from(r == 0), f32::from(r == 1), f32::from(r == 2)];
            w.extend([row[0], row[1], row[2], if r == 0 { x } else { 0.0 }].map(f32::to_bits));
        }
        w.extend([0u32; 12]);
        w.extend([geometry, 0xff, flags, 0, 0, 0, 0, 0]);
        w
    }

    #[test]
    fn instance_refs_open_the_lowest_slot_among_equal_areas() {
        // Root → inner 1 (x -11..-10) and inner 2 (x 10..11): mirror images, so their padded
        // world boxes have exactly equal areas; each holds two leaves. With 3 refs the second
        // opening takes slot 0 (node 1), so its children take slots 0 and 2 and node 2 stays
        // whole in slot 1.
        const LEAF: u32 = 0x8000_0000;
        let p = ([-11.0, 0.0, 0.0], [-10.5, 1.0, 1.0], LEAF);
        let q = ([-10.5, 0.0, 0.0], [-10.0, 1.0, 1.0], LEAF | 1);
        let r = ([10.0, 0.0, 0.0], [10.5, 1.0, 1.0], LEAF | 2);
        let t = ([10.5, 0.0, 0.0], [11.0, 1.0, 1.0], LEAF | 3);
        let mut nodes = bvh2_node(
            ([-11.0, 0.0, 0.0], [-10.0, 1.0, 1.0], 1),
            ([10.0, 0.0, 0.0], [11.0, 1.0, 1.0], 2),
        );
        nodes.extend(bvh2_node(p, q));
        nodes.extend(bvh2_node(r, t));
        let mut geos: Vec<u32> = vec![0, 0, 4, 1];
        geos.extend([-11.0f32, 0.0, 0.0, 0.0, 11.0, 1.0, 1.0, 0.0].map(f32::to_bits));
        geos.extend(crate::scene::opacity::OPAQUE_RECORD);
        let prims = Prims::new(&gpu().device);
        let inst_buf = buffer_with(bytemuck::cast_slice(&instance(0.0, 0, 1)));
        let geo_buf = buffer_with(bytemuck::cast_slice(&geos));
        let blas = buffer_with(bytemuck::cast_slice(&nodes));
        let k = 3;
        let aabbs = buffer_with(bytemuck::cast_slice(&vec![SENTINEL; 8 * k]));
        let tlas = buffer_with(&vec![0xffu8; 80 * k]);
        run(|rec| {
            prims.instance_refs(
                rec, &inst_buf, &geo_buf, &blas, 1, k as u32, &aabbs, &tlas, None,
            )
        });
        let table = words(&tlas, 20 * k);
        let entries: Vec<u32> = (0..k).map(|j| table[16 * k + 4 * j + 1]).collect();
        assert_eq!(entries, [p.2, 2, q.2], "slot 0 opened first");
    }

    #[test]
    fn instance_refs_open_the_largest_subtrees_first_up_to_k() {
        let (nodes, geos, [a, b, c, d, e, f]) = opening_scene();
        // Slots: 0 the tree moved by x + 100, 1 hidden, 2 the one-triangle geometry.
        let inst: Vec<u32> = [
            instance(100.0, 0, 1),
            instance(0.0, 0, 0),
            instance(0.0, 1, 1),
        ]
        .concat();
        let prims = Prims::new(&gpu().device);
        let inst_buf = buffer_with(bytemuck::cast_slice(&inst));
        let geo_buf = buffer_with(bytemuck::cast_slice(&geos));
        let blas = buffer_with(bytemuck::cast_slice(&nodes));
        // (k, refs of slot 0 as (entry, x range of the world box), in ref order)
        type Refs<'a> = &'a [(u32, f32, f32)];
        let cases: [(u32, Refs); 4] = [
            (1, &[(0, 100.0, 120.0)]),
            (2, &[(1, 100.0, 101.0), (2, 110.0, 120.0)]),
            // Node 2 (larger) opens first, then node 3 (larger than node 1), then node 1.
            (
                3,
                &[(1, 100.0, 101.0), (c, 110.0, 112.0), (3, 112.0, 120.0)],
            ),
            (
                8,
                &[
                    (a, 100.0, 100.5),
                    (c, 110.0, 112.0),
                    (d, 112.0, 115.0),
                    (e, 115.0, 120.0),
                    (b, 100.5, 101.0),
                ],
            ),
        ];
        for (k, want) in cases {
            let n = 3usize;
            let refs = n * k as usize;
            let aabbs = buffer_with(bytemuck::cast_slice(&vec![SENTINEL; 8 * refs]));
            let tlas = buffer_with(&vec![0xffu8; 80 * refs]);
            run(|rec| {
                prims.instance_refs(
                    rec, &inst_buf, &geo_buf, &blas, n as u32, k, &aabbs, &tlas, None,
                )
            });
            let table = words(&tlas, 20 * refs);
            let boxes: Vec<f32> = words(&aabbs, 8 * refs)
                .into_iter()
                .map(f32::from_bits)
                .collect();
            assert_opened_refs(k, want, &table, &boxes, f);
        }
    }

    #[test]
    fn instance_refs_merge_the_centroid_bounds_of_their_boxes() {
        // Several workgroups of instances, some hidden (empty boxes, not counted): the words
        // equal the CPU oracle's over the boxes the pass wrote, stale words are zeroed first and
        // the words around them are untouched. All hidden: all zero (nothing counted).
        let mut rng = Rng(14);
        let mut geos: Vec<u32> = vec![0, 0, 12, 1];
        geos.extend([-1.0f32, -2.0, -3.0, 0.0, 4.0, 5.0, 6.0, 0.0].map(f32::to_bits));
        geos.extend(crate::scene::opacity::OPAQUE_RECORD);
        let instance = |t: Affine3A, flags: u32| -> Vec<u32> {
            let m = t.matrix3;
            let mut w = Vec::new();
            for r in 0..3 {
                w.extend(
                    [m.x_axis[r], m.y_axis[r], m.z_axis[r], t.translation[r]].map(f32::to_bits),
                );
            }
            w.extend([0u32; 12]);
            w.extend([0, 0xff, flags, 0, 0, 0, 0, 0]);
            w
        };
        let geo_buf = buffer_with(bytemuck::cast_slice(&geos));
        let prims = Prims::new(&gpu().device);
        for (n, hidden_every) in [(700usize, 7usize), (300, 1)] {
            let inst: Vec<u32> = (0..n)
                .flat_map(|k| {
                    let t = Affine3A::from_scale_rotation_translation(
                        Vec3::splat(rng.range(0.1, 3.0)),
                        Quat::from_rotation_y(rng.range(-3.0, 3.0)),
                        Vec3::new(
                            rng.range(-500.0, 500.0),
                            rng.range(-5.0, 50.0),
                            rng.range(-1e4, 1e4),
                        ),
                    );
                    instance(t, u32::from(k % hidden_every != 0))
                })
                .collect();
            let inst_buf = buffer_with(bytemuck::cast_slice(&inst));
            let aabbs = buffer_with(bytemuck::cast_slice(&vec![SENTINEL; 8 * n]));
            let bounds = buffer_with(bytemuck::cast_slice(&[SENTINEL; 10]));
            let blas = buffer_with(&[0u8; 64]);
            let tlas = buffer_with(&vec![0u8; 80 * n]);
            run(|rec| {
                prims.instance_refs(
                    rec,
                    &inst_buf,
                    &geo_buf,
                    &blas,
                    n as u32,
                    1,
                    &aabbs,
                    &tlas,
                    Some((&bounds, 2)),
                )
            });
            let boxes: Vec<f32> = words(&aabbs, 8 * n)
                .into_iter()
                .map(f32::from_bits)
                .collect();
            let expected = crate::scene::lbvh::cpu_centroid_bounds(
                boxes
                    .chunks(8)
                    .map(|b| ([b[0], b[1], b[2]], [b[4], b[5], b[6]])),
            );
            let got = words(&bounds, 10);
            assert_eq!(got[2..8], expected, "{n} instances");
            assert_eq!(
                [got[0], got[1], got[8], got[9]],
                [SENTINEL; 4],
                "{n} instances"
            );
            if hidden_every == 1 {
                assert_eq!(expected, [0; 6], "nothing counted");
            }
        }
    }
}
