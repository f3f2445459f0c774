//! Skinning tasks: the posed positions against a CPU oracle of the same formula for every
//! attribute format, morph targets, interleaved layouts and unaligned offsets; and a skinned
//! mesh refitted in the same task traced at its new pose (both traversal backends).

use crate::common;

use common::rt::*;
use common::*;
use glam::{Affine3A, Mat4, Quat, Vec3, Vec4};
use kickstart_rt::*;

const STORAGE_COPY: wgpu::BufferUsages =
    wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_SRC);

/// One mesh's skinning data on the CPU.
#[derive(Clone)]
struct Pose {
    rest: Vec<Vec3>,
    joints: Vec<[u32; 4]>,
    weights: Vec<[f32; 4]>,
    matrices: Vec<Mat4>,
    /// Deltas by target, then vertex.
    morphs: Vec<Vec<Vec3>>,
    morph_weights: Vec<f32>,
}

impl Pose {
    /// The oracle: `Σ w · M[j] · (rest + Σ mw · delta)`, ignoring zero weights and joints past
    /// the matrices; a vertex with no usable influence keeps the morphed rest position.
    fn posed(&self, skinned: bool) -> Vec<Vec3> {
        (0..self.rest.len())
            .map(|v| {
                let mut p = self.rest[v];
                for (t, &w) in self.morph_weights.iter().enumerate() {
                    p += w * self.morphs[t][v];
                }
                if !skinned {
                    return p;
                }
                let mut sum = Vec3::ZERO;
                let mut used = false;
                for i in 0..4 {
                    let (j, w) = (self.joints[v][i] as usize, self.weights[v][i]);
                    if w != 0.0 && j < self.matrices.len() {
                        sum += w * self.matrices[j].transform_point3(p);
                        used = true;
                    }
                }
                if used {
                    sum
                } else {
                    p
                }
            })
            .collect()
    }
}

/// A random pose of `n` vertices, `joints` joints and `targets` morph targets; every fifth
/// vertex has zero weights and every seventh names a joint past the matrices.
fn random_pose(rng: &mut Rng, n: usize, joints: u32, targets: usize) -> Pose {
    let matrices = (0..joints)
        .map(|_| {
            Mat4::from_scale_rotation_translation(
                rng.v(0.5, 1.5),
                Quat::from_axis_angle(rng.unit(), rng.range(-3.0, 3.0)),
                rng.v(-2.0, 2.0),
            )
        })
        .collect();
    let mut pose = Pose {
        rest: (0..n).map(|_| rng.v(-1.0, 1.0)).collect(),
        joints: Vec::new(),
        weights: Vec::new(),
        matrices,
        morphs: (0..targets)
            .map(|_| (0..n).map(|_| rng.v(-0.3, 0.3)).collect())
            .collect(),
        morph_weights: (0..targets)
            .map(|t| if t == 1 { 0.0 } else { rng.range(-1.0, 1.0) })
            .collect(),
    };
    for v in 0..n {
        let mut j = [0; 4].map(|_| rng.below(joints));
        let mut w = [rng.f(), rng.f(), rng.f(), rng.f()];
        let total: f32 = w.iter().sum();
        w = w.map(|x| x / total);
        if v % 5 == 0 {
            w = [0.0; 4];
        }
        if v % 7 == 0 {
            j[2] = joints + 3;
        }
        pose.joints.push(j);
        pose.weights.push(w);
    }
    pose
}

/// Bytes of `values` written every `stride` bytes from `offset`, in a buffer of `len` bytes
/// filled with 0xAB elsewhere.
fn strided(values: &[Vec<u8>], offset: usize, stride: usize, len: usize) -> Vec<u8> {
    let mut out = vec![0xAB; len];
    for (k, v) in values.iter().enumerate() {
        let at = offset + k * stride;
        out[at..at + v.len()].copy_from_slice(v);
    }
    out
}

fn joint_bytes(j: [u32; 4], format: JointFormat) -> Vec<u8> {
    match format {
        JointFormat::Uint8x4 => j.map(|x| x as u8).to_vec(),
        JointFormat::Uint16x4 => bytemuck::cast_slice(&j.map(|x| x as u16)).to_vec(),
        JointFormat::Uint32x4 => bytemuck::cast_slice(&j).to_vec(),
    }
}

/// The weights as stored, and as the GPU reads them back (quantised for the unorm formats).
fn weight_bytes(w: [f32; 4], format: WeightFormat) -> (Vec<u8>, [f32; 4]) {
    match format {
        WeightFormat::Float32x4 => (bytemuck::cast_slice(&w).to_vec(), w),
        WeightFormat::Unorm8x4 => {
            let q = w.map(|x| (x * 255.0).round() as u8);
            (q.to_vec(), q.map(|x| x as f32 / 255.0))
        }
        WeightFormat::Unorm16x4 => {
            let q = w.map(|x| (x * 65535.0).round() as u16);
            (
                bytemuck::cast_slice(&q).to_vec(),
                q.map(|x| x as f32 / 65535.0),
            )
        }
    }
}

/// How one case lays its data out.
#[derive(Clone, Copy)]
struct Layout {
    rest_format: VertexFormat,
    joints: JointFormat,
    weights: WeightFormat,
    /// Byte offset of the first value in every input buffer (not storage-aligned on purpose).
    offset: usize,
    /// Extra bytes after every value.
    pad: usize,
    skinned: bool,
    targets: usize,
}

/// Skins `pose` on the GPU with `layout`; returns the output buffer's bytes, the output's
/// offset and stride, and the oracle's positions (from the weights as the GPU reads them).
fn skin_on_gpu(pose: &mut Pose, layout: Layout) -> (Vec<u8>, usize, usize, Vec<Vec3>) {
    let n = pose.rest.len();
    let rest_size = layout.rest_format.size() as usize;
    let rest: Vec<Vec<u8>> = pose
        .rest
        .iter()
        .map(|p| {
            let v = Vec4::new(p.x, p.y, p.z, 9.0).to_array();
            bytemuck::cast_slice(&v[..rest_size / 4]).to_vec()
        })
        .collect();
    let (o, pad) = (layout.offset, layout.pad);
    let rest_stride = rest_size + pad;
    let rest_buffer = buffer(
        &strided(&rest, o, rest_stride, o + n * rest_stride),
        STORAGE_COPY,
    );
    let mut influences = None;
    if layout.skinned {
        // Joints and weights interleaved in one buffer.
        let js = layout.joints.size() as usize;
        let ws = layout.weights.size() as usize;
        let stride = js + ws + pad;
        let mut both = Vec::new();
        for v in 0..n {
            let (wb, read) = weight_bytes(pose.weights[v], layout.weights);
            pose.weights[v] = read;
            let mut b = joint_bytes(pose.joints[v], layout.joints);
            b.extend(wb);
            both.push(b);
        }
        let buf = buffer(&strided(&both, o, stride, o + n * stride), STORAGE_COPY);
        influences = Some(SkinInfluences {
            joints: SkinAttribute {
                buffer: buf.clone(),
                offset: o as u64,
                stride: stride as u64,
                format: layout.joints,
            },
            weights: SkinAttribute {
                buffer: buf,
                offset: (o + js) as u64,
                stride: stride as u64,
                format: layout.weights,
            },
        });
    }
    let morph_targets = (layout.targets > 0).then(|| {
        let stride = 12 + pad;
        let target_stride = n * stride + 8;
        let values: Vec<Vec<u8>> = (0..layout.targets)
            .flat_map(|t| (0..n).map(move |v| (t, v)))
            .map(|(t, v)| bytemuck::cast_slice(&pose.morphs[t][v].to_array()).to_vec())
            .collect();
        let mut bytes = vec![0xAB; o + layout.targets * target_stride];
        for (k, val) in values.iter().enumerate() {
            let at = o + (k / n) * target_stride + (k % n) * stride;
            bytes[at..at + 12].copy_from_slice(val);
        }
        MorphTargetsInput {
            buffer: buffer(&bytes, STORAGE_COPY),
            offset: o as u64,
            stride: stride as u64,
            target_stride: target_stride as u64,
            count: layout.targets as u32,
        }
    });
    // Positions interleaved with 12 other bytes a vertex, which must survive.
    let (out_offset, out_stride) = (o + 4, 24);
    let out = buffer(
        &vec![0xCD; out_offset + n * out_stride],
        STORAGE_COPY | wgpu::BufferUsages::COPY_DST,
    );
    let ctx = context(2);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(SkinningTask {
        name: "random pose".into(),
        rest_positions: SkinAttribute {
            buffer: rest_buffer,
            offset: o as u64,
            stride: rest_stride as u64,
            format: layout.rest_format,
        },
        vertex_count: n as u32,
        influences,
        joint_matrices: if layout.skinned {
            pose.matrices.clone()
        } else {
            Vec::new()
        },
        morph_targets,
        morph_weights: pose.morph_weights[..layout.targets].to_vec(),
        output: SkinningOutput {
            buffer: out.clone(),
            offset: out_offset as u64,
            stride: out_stride as u64,
        },
    });
    build_submit_complete(&ctx, c);
    pose.morph_weights.truncate(layout.targets);
    pose.morphs.truncate(layout.targets);
    (
        read_buffer(&out),
        out_offset,
        out_stride,
        pose.posed(layout.skinned),
    )
}

/// Checks the output bytes against the oracle, and that nothing else of the buffer changed.
fn assert_posed(bytes: &[u8], offset: usize, stride: usize, want: &[Vec3], what: &str) {
    for (v, w) in want.iter().enumerate() {
        let at = offset + v * stride;
        let got: [f32; 3] = bytemuck::pod_read_unaligned(&bytes[at..at + 12]);
        let got = Vec3::from(got);
        let tol = 1e-5 * (1.0 + w.abs().max_element());
        assert!(
            (got - *w).abs().max_element() <= tol,
            "{what}: vertex {v}: {got} != {w}"
        );
        assert!(
            bytes[at + 12..at + stride].iter().all(|&b| b == 0xCD),
            "{what}: vertex {v}'s other bytes"
        );
    }
    assert!(
        bytes[..offset].iter().all(|&b| b == 0xCD),
        "{what}: bytes before the output"
    );
}

#[test]
fn skinning_matches_the_cpu_oracle_for_every_format() {
    let mut rng = Rng(fuzz_seed("skinning", 41));
    let cases = [
        (
            VertexFormat::Float32x3,
            JointFormat::Uint16x4,
            WeightFormat::Float32x4,
            0,
        ),
        (
            VertexFormat::Float32x4,
            JointFormat::Uint8x4,
            WeightFormat::Unorm8x4,
            4,
        ),
        (
            VertexFormat::Float32x3,
            JointFormat::Uint32x4,
            WeightFormat::Unorm16x4,
            8,
        ),
    ];
    for (k, (rest_format, joints, weights, pad)) in cases.into_iter().enumerate() {
        let mut pose = random_pose(&mut rng, 700, 9, 0);
        let layout = Layout {
            rest_format,
            joints,
            weights,
            offset: 260 + 4 * k,
            pad,
            skinned: true,
            targets: 0,
        };
        let (bytes, o, s, want) = skin_on_gpu(&mut pose, layout);
        assert_posed(
            &bytes,
            o,
            s,
            &want,
            &format!("{rest_format:?}/{joints:?}/{weights:?}"),
        );
        // The case must move vertices (a pass that copied the rest pose would fail here).
        let moved = want
            .iter()
            .zip(&pose.rest)
            .filter(|(a, b)| (**a - **b).length() > 0.1);
        assert!(moved.count() > 400);
    }
}

#[test]
fn morph_targets_are_added_before_skinning() {
    let mut rng = Rng(fuzz_seed("morphs", 43));
    for skinned in [false, true] {
        let mut pose = random_pose(&mut rng, 333, 5, 3);
        let layout = Layout {
            rest_format: VertexFormat::Float32x3,
            joints: JointFormat::Uint16x4,
            weights: WeightFormat::Float32x4,
            offset: 12,
            pad: 4,
            skinned,
            targets: 3,
        };
        let (bytes, o, s, want) = skin_on_gpu(&mut pose, layout);
        assert_posed(&bytes, o, s, &want, &format!("morphs, skinned {skinned}"));
        if !skinned {
            // Morphs alone move every vertex by its weighted deltas.
            let moved = want
                .iter()
                .zip(&pose.rest)
                .filter(|(a, b)| (**a - **b).length() > 1e-3);
            assert!(moved.count() > 300);
        }
    }
}

/// Meshes whose data share one rest, one influence and one output buffer (as an engine that
/// pools its vertex data passes them).
struct Pooled {
    rest: wgpu::Buffer,
    influences: wgpu::Buffer,
    out: wgpu::Buffer,
    /// Per mesh: its first byte in the rest, influence and output buffers.
    at: Vec<(u64, u64, u64)>,
}

/// Packs `poses` (Float32x3 rest positions, Uint32x4 joints then Float32x4 weights a vertex)
/// into pooled buffers, each mesh `gap` bytes after the last (gap: a multiple of 4, not of the
/// storage offset alignment); the output buffer is filled with 0xCD.
fn pooled(poses: &[Pose], gap: u64) -> Pooled {
    let (mut rest, mut inf, mut at) = (Vec::new(), Vec::new(), Vec::new());
    let mut out_len = 0u64;
    for p in poses {
        rest.resize(rest.len() + gap as usize, 0xAB);
        inf.resize(inf.len() + gap as usize, 0xAB);
        out_len += gap;
        at.push((rest.len() as u64, inf.len() as u64, out_len));
        rest.extend(
            p.rest
                .iter()
                .flat_map(|v| bytemuck::cast::<[f32; 3], [u8; 12]>(v.to_array())),
        );
        for (j, w) in p.joints.iter().zip(&p.weights) {
            inf.extend(bytemuck::cast_slice(j));
            inf.extend(bytemuck::cast_slice(w));
        }
        out_len += 12 * p.rest.len() as u64;
    }
    Pooled {
        rest: buffer(&rest, STORAGE_COPY),
        influences: buffer(&inf, STORAGE_COPY),
        out: buffer(&vec![0xCD; out_len as usize + 16], STORAGE_COPY),
        at,
    }
}

/// The task posing mesh `k` of `pool` by `pose`'s matrices from `rest` (buffer, byte offset)
/// into `out` (buffer, byte offset).
fn pooled_task(
    pool: &Pooled,
    k: usize,
    pose: &Pose,
    rest: (&wgpu::Buffer, u64),
    out: (&wgpu::Buffer, u64),
) -> SkinningTask {
    let inf = pool.at[k].1;
    fn attribute<F>(pool: &Pooled, offset: u64, format: F) -> SkinAttribute<F> {
        SkinAttribute {
            buffer: pool.influences.clone(),
            offset,
            stride: 32,
            format,
        }
    }
    SkinningTask {
        name: format!("pooled mesh {k}"),
        rest_positions: SkinAttribute {
            buffer: rest.0.clone(),
            offset: rest.1,
            stride: 12,
            format: VertexFormat::Float32x3,
        },
        vertex_count: pose.rest.len() as u32,
        influences: Some(SkinInfluences {
            joints: attribute(pool, inf, JointFormat::Uint32x4),
            weights: attribute(pool, inf + 16, WeightFormat::Float32x4),
        }),
        joint_matrices: pose.matrices.clone(),
        morph_targets: None,
        morph_weights: Vec::new(),
        output: SkinningOutput {
            buffer: out.0.clone(),
            offset: out.1,
            stride: 12,
        },
    }
}

/// The posed positions at byte `at` of `bytes`.
fn positions_at(bytes: &[u8], at: u64, n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|v| {
            let i = at as usize + 12 * v;
            Vec3::from(bytemuck::pod_read_unaligned::<[f32; 3]>(&bytes[i..i + 12]))
        })
        .collect()
}

fn assert_near(got: &[Vec3], want: &[Vec3], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}");
    for (v, (g, w)) in got.iter().zip(want).enumerate() {
        let tol = 1e-5 * (1.0 + w.abs().max_element());
        assert!(
            (*g - *w).abs().max_element() <= tol,
            "{what}: vertex {v}: {g} != {w}"
        );
    }
}

#[test]
fn meshes_in_pooled_buffers_are_posed_together_and_dependent_tasks_in_order() {
    let mut rng = Rng(fuzz_seed("pooled skinning", 47));
    // Sizes around the 64-vertex workgroup: each mesh must find its own workgroups.
    let sizes = [1, 63, 64, 65, 200, 7];
    let poses: Vec<Pose> = sizes
        .iter()
        .map(|&n| random_pose(&mut rng, n, 6, 0))
        .collect();
    let pool = pooled(&poses, 20);
    let second = buffer(&vec![0xCD; 12 * 64 + 8], STORAGE_COPY);
    // Mesh 2's output read back as the rest pose of another mesh (into `second`), then mesh 2
    // posed again, differently: the reader must see the first pose, the buffer the second.
    // Both use mesh 2's influences (the pooled buffer's), with matrices of their own.
    let again = Pose {
        matrices: random_pose(&mut rng, 1, 6, 0).matrices,
        ..poses[2].clone()
    };
    let reader = Pose {
        rest: poses[2].posed(true),
        matrices: random_pose(&mut rng, 1, 6, 0).matrices,
        ..poses[2].clone()
    };
    let ctx = context(2);
    let mut c = ctx.create_task_container();
    for (k, pose) in poses.iter().enumerate() {
        let (rest, _, out) = pool.at[k];
        c.schedule_bvh_task(pooled_task(
            &pool,
            k,
            pose,
            (&pool.rest, rest),
            (&pool.out, out),
        ));
    }
    let mesh2_out = (&pool.out, pool.at[2].2);
    c.schedule_bvh_task(pooled_task(&pool, 2, &reader, mesh2_out, (&second, 8)));
    let (rest2, ..) = pool.at[2];
    c.schedule_bvh_task(pooled_task(
        &pool,
        2,
        &again,
        (&pool.rest, rest2),
        mesh2_out,
    ));
    build_submit_complete(&ctx, c);

    let bytes = read_buffer(&pool.out);
    for (k, pose) in poses.iter().enumerate() {
        // The later task wins.
        let want = if k == 2 { &again } else { pose }.posed(true);
        let got = positions_at(&bytes, pool.at[k].2, pose.rest.len());
        assert_near(&got, &want, &format!("mesh {k} of {}", sizes[k]));
    }
    // Nothing between the meshes changed.
    for k in 0..poses.len() {
        let end = pool.at[k].2 as usize;
        let start = end - 20;
        assert!(
            bytes[start..end].iter().all(|&b| b == 0xCD),
            "the gap before mesh {k}"
        );
    }
    let read = positions_at(&read_buffer(&second), 8, 64);
    assert_near(
        &read,
        &reader.posed(true),
        "the task reading mesh 2's first pose",
    );
}

/// A bar along x from 0 to 2 (a thin box of 12 triangles a segment, 4 segments), skinned to
/// two joints: x < 1 follows joint 0, x ≥ 1 joint 1.
fn bar() -> (Mesh, Vec<[u16; 4]>, Vec<[f32; 4]>) {
    let mut mesh = Mesh::default();
    let (mut joints, mut weights) = (Vec::new(), Vec::new());
    for s in 0..4 {
        let x0 = s as f32 * 0.5;
        let cube = Mesh::cuboid(Vec3::new(x0, -0.05, -0.05), Vec3::new(x0 + 0.5, 0.05, 0.05));
        let base = mesh.positions.len() as u32;
        for p in &cube.positions {
            joints.push([u16::from(p.x >= 0.999), 0, 0, 0]);
            weights.push([1.0, 0.0, 0.0, 0.0]);
        }
        mesh.positions.extend(&cube.positions);
        mesh.indices.extend(cube.indices.iter().map(|i| i + base));
    }
    (mesh, joints, weights)
}

#[test]
fn a_skinned_mesh_is_traced_at_the_pose_of_its_task() {
    let ctx = context(2);
    let (mesh, joints, weights) = bar();
    let n = mesh.positions.len() as u32;
    let rest: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.to_array()).collect();
    let rest = buffer(bytemuck::cast_slice(&rest), STORAGE_COPY);
    let joints = buffer(bytemuck::cast_slice(&joints), wgpu::BufferUsages::STORAGE);
    let weights = buffer(bytemuck::cast_slice(&weights), wgpu::BufferUsages::STORAGE);
    let posed = gpu().device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("posed"),
        size: u64::from(n) * 12,
        usage: STORAGE_COPY,
        mapped_at_creation: false,
    });
    let mut input = mesh_input("bar", &mesh, true);
    input.components[0].vertex_buffer.buffer = posed.clone();
    let task = |bend: f32| SkinningTask {
        name: "bar".into(),
        rest_positions: SkinAttribute {
            buffer: rest.clone(),
            offset: 0,
            stride: 12,
            format: VertexFormat::Float32x3,
        },
        vertex_count: n,
        influences: Some(SkinInfluences {
            joints: SkinAttribute {
                buffer: joints.clone(),
                offset: 0,
                stride: 8,
                format: JointFormat::Uint16x4,
            },
            weights: SkinAttribute {
                buffer: weights.clone(),
                offset: 0,
                stride: 16,
                format: WeightFormat::Float32x4,
            },
        }),
        // Joint 1 bends the bar's outer half up about the point (1, 0, 0).
        joint_matrices: vec![
            Mat4::IDENTITY,
            Mat4::from_translation(Vec3::X)
                * Mat4::from_rotation_z(bend)
                * Mat4::from_translation(-Vec3::X),
        ],
        morph_targets: None,
        morph_weights: Vec::new(),
        output: SkinningOutput {
            buffer: posed.clone(),
            offset: 0,
            stride: 12,
        },
    };
    let g = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    // Scheduled after the geometry on purpose: skinning is recorded first regardless.
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: g,
        input: input.clone(),
    });
    c.schedule_bvh_task(task(0.0));
    register_instance(&mut c, ctx.create_instance_handle(), g, Affine3A::IDENTITY);
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    // Rays down the y axis at x = 1.75: straight, the bar is there; bent 90°, it points up
    // along x = 1 and the rays miss, while a ray along -x at height 0.75 hits its side.
    let down = ray(Vec3::new(1.75, 2.0, 0.0), Vec3::NEG_Y, 0.0, 10.0);
    let side = ray(Vec3::new(3.0, 0.75, 0.0), Vec3::NEG_X, 0.0, 10.0);
    let hits = closest(&ctx, &[down, side]);
    assert!(
        (hits[0].t - 1.95).abs() < 1e-4,
        "straight bar: {:?}",
        hits[0]
    );
    assert_eq!(hits[1].t, -1.0, "straight bar: nothing at height 0.75");
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(task(std::f32::consts::FRAC_PI_2));
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Update,
        handle: g,
        input,
    });
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let hits = closest(&ctx, &[down, side]);
    assert_eq!(hits[0].t, -1.0, "bent bar: the rays at x = 1.75 pass");
    // The bent half's side faces +x at x = 1.05.
    assert!((hits[1].t - 1.95).abs() < 1e-4, "bent bar: {:?}", hits[1]);
    assert_pass_backend(&ctx);
}
