//! The skinned refit of `ksrt bench`: every mesh of a scene posed on the GPU by a
//! `kickstart_rt::SkinningTask`, then re-ingested and refit in the same GPU task — a frame of
//! skinned characters. The scenes have no skins, so each mesh gets a rig generated here: a chain
//! of [`JOINTS`] joints stacked up its bounding box's height (y), each vertex weighted to the
//! two joints nearest its height, the chain bending about the x axis by an angle that changes
//! every repetition. After the last repetition one mesh's BLAS is read back and compared with a
//! CPU skinning of the same rig and pose: the figure only counts if the refit saw the pose.

use glam::{Mat4, Vec3};
use kickstart_rt as ksrt;
use wgpu::util::DeviceExt;

use super::harness::Bench;
use super::profile::PassProfile;
use super::report::{PoseCheck, SkinnedRefitReport};
use super::Stats;
use crate::app::gpu;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::scene::{Mesh, Scene};
use kickstart_rt_renderer::sdk_glue as glue;
use kickstart_rt_renderer::upload::{self, UploadedMesh};

/// Joints of every generated rig (a character's spine and neck, roughly).
pub(super) const JOINTS: u32 = 6;

/// The scopes of the figure: the skinning passes first, then the ingestion that copies the
/// posed positions and the refit.
const SPAN: [&str; 3] = ["skinning", "ingest", "blas refit"];

/// Bytes of one vertex's influences: four `Uint8x4` joints, then four `Unorm8x4` weights, in one
/// interleaved buffer (the layout a glTF loader would hand over for `JOINTS_0`/`WEIGHTS_0`).
const INFLUENCE_STRIDE: u64 = 8;

/// One mesh's generated rig.
#[derive(Debug, Clone)]
struct Rig {
    /// Each joint's pivot: on the vertical line through the bounding box's centre, from its
    /// bottom (joint 0) to its top.
    pivots: Vec<Vec3>,
    /// Per vertex: the joints (two used) and their weights as stored (`/ 255` when read).
    influences: Vec<([u8; 4], [u8; 4])>,
}

impl Rig {
    /// The rig of `positions`: a vertex at height `t` (in joint spacings above the bottom) is
    /// weighted to joints `⌊t⌋` and `⌊t⌋ + 1`, linearly — the two nearest by height.
    fn new(positions: &[[f32; 3]]) -> Rig {
        let (lo, hi) = positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(Vec3::from(*p)), hi.max(Vec3::from(*p))),
        );
        let (lo, hi) = if lo.is_finite() && hi.is_finite() {
            (lo, hi)
        } else {
            (Vec3::ZERO, Vec3::ZERO)
        };
        let centre = (lo + hi) * 0.5;
        let spacing = (hi.y - lo.y) / (JOINTS - 1) as f32;
        let pivots = (0..JOINTS)
            .map(|k| Vec3::new(centre.x, lo.y + k as f32 * spacing, centre.z))
            .collect();
        let influences = positions
            .iter()
            .map(|p| {
                // A flat mesh (no height) hangs on joint 0 alone.
                let t = if spacing > 0.0 {
                    ((p[1] - lo.y) / spacing).clamp(0.0, (JOINTS - 1) as f32)
                } else {
                    0.0
                };
                let below = (t.floor() as u32).min(JOINTS - 2);
                let up = ((t - below as f32) * 255.0).round() as u8;
                // The weights sum to exactly 255 (1.0), as glTF requires.
                ([below as u8, below as u8 + 1, 0, 0], [255 - up, up, 0, 0])
            })
            .collect();
        Rig { pivots, influences }
    }

    /// The joint matrices of a chain bent by `angle` radians at every joint about the x axis:
    /// joint `k` is joint `k - 1`'s matrix times a rotation about its own pivot, so the parts on
    /// either side of a pivot stay joined and the top bends the most.
    fn matrices(&self, angle: f32) -> Vec<Mat4> {
        let mut chain = Mat4::IDENTITY;
        self.pivots
            .iter()
            .map(|&p| {
                chain *= Mat4::from_translation(p)
                    * Mat4::from_rotation_x(angle)
                    * Mat4::from_translation(-p);
                chain
            })
            .collect()
    }

    /// The CPU skinning of `rest` by `matrices`, with the weights as the GPU reads them.
    fn posed(&self, rest: &[[f32; 3]], matrices: &[Mat4]) -> Vec<Vec3> {
        rest.iter()
            .zip(&self.influences)
            .map(|(p, (j, w))| {
                (0..4)
                    .filter(|&i| w[i] != 0)
                    .map(|i| {
                        f32::from(w[i]) / 255.0
                            * matrices[j[i] as usize].transform_point3(Vec3::from(*p))
                    })
                    .sum()
            })
            .collect()
    }
}

/// The bend of mesh `mesh` at repetition `iteration`, radians: 2° to 5°, a different phase a
/// mesh, never the rest pose, and different in consecutive repetitions.
fn angle(iteration: u32, mesh: usize) -> f32 {
    let phase = 0.9 * iteration as f32 + mesh as f32;
    (2.0 + 1.5 * (1.0 + phase.sin())).to_radians()
}

/// How the bench lays out the meshes' skinning buffers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum SkinBuffers {
    /// One rest-pose, one influence and one posed buffer for every mesh, each mesh at its own
    /// offset (how an engine that pools its vertex data hands them over): the SDK poses them
    /// all in one dispatch.
    Pooled,
    /// A buffer of each kind per mesh: one dispatch and one barrier a mesh.
    PerMesh,
}

/// Byte alignment of each mesh's data in a pooled buffer (the largest storage offset alignment
/// a device may ask for).
const POOL_ALIGN: usize = 256;

/// Buffers of one kind being filled: the chunks of the current buffer and where each went.
struct PoolBuilder {
    layout: SkinBuffers,
    label: &'static str,
    usage: wgpu::BufferUsages,
    bytes: Vec<u8>,
    /// Per chunk: its buffer (an index into `finished`, or the pooled buffer) and offset.
    placed: Vec<(usize, u64)>,
    finished: Vec<Vec<u8>>,
}

impl PoolBuilder {
    fn new(layout: SkinBuffers, label: &'static str, usage: wgpu::BufferUsages) -> Self {
        PoolBuilder {
            layout,
            label,
            usage,
            bytes: Vec::new(),
            placed: Vec::new(),
            finished: Vec::new(),
        }
    }

    /// Adds one mesh's chunk.
    fn push(&mut self, chunk: &[u8]) {
        match self.layout {
            SkinBuffers::Pooled => {
                self.bytes
                    .resize(self.bytes.len().next_multiple_of(POOL_ALIGN), 0);
                self.placed.push((0, self.bytes.len() as u64));
                self.bytes.extend_from_slice(chunk);
            }
            SkinBuffers::PerMesh => {
                self.placed.push((self.finished.len(), 0));
                self.finished.push(chunk.to_vec());
            }
        }
    }

    /// Uploads the buffers; returns each chunk's buffer and offset, in order.
    fn upload(mut self, device: &wgpu::Device) -> Vec<(wgpu::Buffer, u64)> {
        if self.layout == SkinBuffers::Pooled {
            self.finished = vec![std::mem::take(&mut self.bytes)];
        }
        let buffers: Vec<wgpu::Buffer> = self
            .finished
            .iter()
            .map(|bytes| {
                // At least 16 bytes: a mesh without vertices still binds one.
                let mut contents = bytes.clone();
                contents.resize(contents.len().max(16), 0);
                device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(self.label),
                    contents: &contents,
                    usage: self.usage,
                })
            })
            .collect();
        self.placed
            .iter()
            .map(|&(b, offset)| (buffers[b].clone(), offset))
            .collect()
    }
}

/// One mesh ready to skin: its rig, and where its rest pose, influences and posed positions
/// lie on the GPU (buffer, byte offset).
struct SkinnedMesh {
    rig: Rig,
    vertex_count: u32,
    rest: (wgpu::Buffer, u64),
    influences: (wgpu::Buffer, u64),
    /// The posed positions (`Float32x3`), first the rest pose: the geometry registers from it.
    posed: (wgpu::Buffer, u64),
}

/// Rigs `meshes` and uploads their skinning buffers laid out as `layout`. The rest positions
/// get buffers of their own, since the scene's upload lacks the `STORAGE` usage that the
/// skinning pass reads through.
fn skinned_meshes(device: &wgpu::Device, meshes: &[Mesh], layout: SkinBuffers) -> Vec<SkinnedMesh> {
    let storage = wgpu::BufferUsages::STORAGE;
    let mut rest = PoolBuilder::new(layout, "ksrt bench rest pose", storage);
    let mut influences = PoolBuilder::new(layout, "ksrt bench influences", storage);
    let posed_usage = storage | wgpu::BufferUsages::COPY_SRC;
    let mut posed = PoolBuilder::new(layout, "ksrt bench posed", posed_usage);
    let rigs: Vec<Rig> = meshes.iter().map(|m| Rig::new(&m.positions)).collect();
    for (mesh, rig) in meshes.iter().zip(&rigs) {
        let bytes: &[u8] = bytemuck::cast_slice(&mesh.positions);
        let packed: Vec<u8> = rig
            .influences
            .iter()
            .flat_map(|(j, w)| j.iter().chain(w).copied())
            .collect();
        rest.push(bytes);
        influences.push(&packed);
        posed.push(bytes);
    }
    let (rest, influences, posed) = (
        rest.upload(device),
        influences.upload(device),
        posed.upload(device),
    );
    rigs.into_iter()
        .zip(meshes)
        .zip(rest.into_iter().zip(influences).zip(posed))
        .map(|((rig, mesh), ((rest, influences), posed))| SkinnedMesh {
            rig,
            vertex_count: mesh.positions.len() as u32,
            rest,
            influences,
            posed,
        })
        .collect()
}

impl SkinnedMesh {
    /// The skinning task of mesh `k` at repetition `iteration`.
    fn task(&self, k: usize, iteration: u32) -> ksrt::SkinningTask {
        let (influences, at) = &self.influences;
        ksrt::SkinningTask {
            name: format!("ksrt bench mesh {k}"),
            rest_positions: ksrt::SkinAttribute {
                buffer: self.rest.0.clone(),
                offset: self.rest.1,
                stride: 12,
                format: ksrt::VertexFormat::Float32x3,
            },
            vertex_count: self.vertex_count,
            influences: Some(ksrt::SkinInfluences {
                joints: ksrt::SkinAttribute {
                    buffer: influences.clone(),
                    offset: *at,
                    stride: INFLUENCE_STRIDE,
                    format: ksrt::JointFormat::Uint8x4,
                },
                weights: ksrt::SkinAttribute {
                    buffer: influences.clone(),
                    offset: at + 4,
                    stride: INFLUENCE_STRIDE,
                    format: ksrt::WeightFormat::Unorm8x4,
                },
            }),
            joint_matrices: self.rig.matrices(angle(iteration, k)),
            morph_targets: None,
            morph_weights: Vec::new(),
            output: ksrt::SkinningOutput {
                buffer: self.posed.0.clone(),
                offset: self.posed.1,
                stride: 12,
            },
        }
    }
}

/// A scene's meshes ready to skin, and the `allow_update` geometry input of each (the scene's
/// own, reading the posed positions).
pub(super) struct SkinnedScene {
    meshes: Vec<SkinnedMesh>,
    inputs: Vec<ksrt::GeometryInput>,
}

impl SkinnedScene {
    /// Rigs and uploads every mesh of `scene` (`uploads` are its meshes on the GPU, in order),
    /// their skinning buffers laid out as `layout`.
    pub(super) fn new(
        device: &wgpu::Device,
        scene: &Scene,
        uploads: &[UploadedMesh],
        layout: SkinBuffers,
    ) -> Self {
        let meshes = skinned_meshes(device, &scene.meshes, layout);
        let inputs = uploads
            .iter()
            .zip(&meshes)
            .map(|(u, s)| {
                // The scene's input (indices, cutout opacity) with the posed positions.
                let mut input = upload::geometry_input(u, true);
                let vertices = &mut input.components[0].vertex_buffer;
                (vertices.buffer, vertices.offset) = s.posed.clone();
                input
            })
            .collect();
        SkinnedScene { meshes, inputs }
    }

    /// Registers every geometry at the rest pose and builds its BLAS, untimed.
    pub(super) fn register(
        &self,
        bench: &Bench,
        ctx: &ksrt::ExecuteContext,
    ) -> AnyResult<Vec<ksrt::GeometryHandle>> {
        let handles = ctx.create_geometry_handles(self.inputs.len());
        let mut c = ctx.create_task_container();
        for (input, &handle) in self.inputs.iter().zip(&handles) {
            c.schedule_bvh_task(ksrt::GeometryTask {
                operation: ksrt::TaskOperation::Register,
                handle,
                input: input.clone(),
            });
        }
        c.schedule_bvh_task(glue::bvh_build_task(handles.len() as u32, None));
        let task = upload::submit(ctx, bench.device, bench.queue, c, |_| {})?;
        gpu::complete(ctx, bench.device, task)?;
        Ok(handles)
    }

    /// One frame at repetition `iteration`'s pose: every mesh skinned, its geometry updated
    /// and every BLAS refit, in one container (the SDK records the skinning first).
    pub(super) fn frame(
        &self,
        ctx: &ksrt::ExecuteContext,
        handles: &[ksrt::GeometryHandle],
        iteration: u32,
    ) -> ksrt::TaskContainer {
        let mut c = ctx.create_task_container();
        for (k, ((mesh, input), &handle)) in self
            .meshes
            .iter()
            .zip(&self.inputs)
            .zip(handles)
            .enumerate()
        {
            c.schedule_bvh_task(mesh.task(k, iteration));
            c.schedule_bvh_task(ksrt::GeometryTask {
                operation: ksrt::TaskOperation::Update,
                handle,
                input: input.clone(),
            });
        }
        c.schedule_bvh_task(glue::bvh_build_task(handles.len() as u32, None));
        c
    }

    /// Vertices posed a frame.
    fn vertices(&self) -> u64 {
        self.meshes.iter().map(|m| u64::from(m.vertex_count)).sum()
    }
}

/// One layout's run of the skinned refit: the span, the skinning passes' time, where the last
/// repetition's time went, and the pose check.
struct SkinnedRun {
    time: Stats,
    skinning: Stats,
    profile: Vec<PassProfile>,
    check: PoseCheck,
    vertices: u64,
}

impl Bench<'_> {
    /// (b′) Every mesh skinned to a new pose, its geometry updated and every BLAS refit, in one
    /// task (`skinning` + `ingest` + `blas refit` passes), with the skinning buffers pooled;
    /// the skinning passes' own time beside it; the same with a buffer set per mesh; each
    /// checked: the last pose reached the BLAS ([`check_pose`]).
    pub(super) fn skinned_refit(
        &self,
        scene: &Scene,
        uploads: &[UploadedMesh],
    ) -> AnyResult<SkinnedRefitReport> {
        let pooled = self.skinned_run(scene, uploads, SkinBuffers::Pooled)?;
        let per_mesh = self.skinned_run(scene, uploads, SkinBuffers::PerMesh)?;
        Ok(SkinnedRefitReport {
            joints: JOINTS,
            vertices: pooled.vertices,
            skinning_share: pooled.skinning.median_ms / pooled.time.median_ms,
            time: pooled.time,
            skinning: pooled.skinning,
            profile: pooled.profile,
            check: pooled.check,
            per_mesh_buffers: per_mesh.time,
        })
    }

    /// The skinned refit with the skinning buffers laid out as `layout`.
    fn skinned_run(
        &self,
        scene: &Scene,
        uploads: &[UploadedMesh],
        layout: SkinBuffers,
    ) -> AnyResult<SkinnedRun> {
        let skinned = SkinnedScene::new(self.device, scene, uploads, layout);
        let ctx = self.context()?;
        let handles = skinned.register(self, &ctx)?;
        // Every repetition, warm-ups included, takes the next pose: each refit moves vertices.
        let mut iteration = 0;
        let mut skinning = Vec::new();
        let time = self.repeat(|timed| {
            iteration += 1;
            let ms = self.timed(
                &ctx,
                skinned.frame(&ctx, &handles, iteration),
                &SPAN,
                |_| {},
            )?;
            if timed {
                let passes = self.last_passes.borrow();
                let skin = passes.iter().filter(|p| p.label == "skinning");
                skinning.push(skin.map(|p| p.ms).sum());
            }
            Ok(ms)
        })?;
        let profile = self.last_profile();
        let check = check_pose(&ctx, scene, &skinned, &handles, iteration)?;
        Ok(SkinnedRun {
            time,
            skinning: Stats::new(skinning),
            profile,
            check,
            vertices: skinned.vertices(),
        })
    }
}

/// Reads back the BLAS of the scene's mesh with the most vertices and compares its triangles
/// with a CPU skinning of that mesh at repetition `iteration`'s pose: an error unless every
/// vertex is finite and within 1e-4 (relative to the mesh's size) of the CPU's, the pose moved
/// some vertex by more than 1e-3 of the size, and the root's boxes hold every triangle (the
/// refit ran on the new positions, not only their copy).
pub(super) fn check_pose(
    ctx: &ksrt::ExecuteContext,
    scene: &Scene,
    skinned: &SkinnedScene,
    handles: &[ksrt::GeometryHandle],
    iteration: u32,
) -> AnyResult<PoseCheck> {
    let (k, mesh) = scene
        .meshes
        .iter()
        .enumerate()
        .max_by_key(|(_, m)| m.positions.len())
        .ok_or("the scene has no geometry")?;
    let rig = &skinned.meshes[k].rig;
    let want = rig.posed(&mesh.positions, &rig.matrices(angle(iteration, k)));
    let blas = ctx.read_back_blas(handles[k])?;
    if blas.triangles.is_empty() {
        return Err(format!("{}: its BLAS holds no triangle", mesh.name).into());
    }
    let (lo, hi) = want.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let size = (hi - lo).max_element().max(1e-6);
    let root = blas.nodes.first().ok_or("the BLAS has no root")?;
    let root_lo = root[0].min.min(root[1].min) - 1e-4 * size;
    let root_hi = root[0].max.max(root[1].max) + 1e-4 * size;
    let (mut max_error, mut max_moved) = (0.0f32, 0.0f32);
    for (tri, &prim) in blas.triangles.iter().zip(&blas.primitive_indices) {
        for (c, got) in tri.iter().enumerate() {
            let v = mesh.indices[3 * prim as usize + c] as usize;
            if !got.is_finite() {
                return Err(format!("{}: vertex {v} posed at {got}", mesh.name).into());
            }
            if got.cmplt(root_lo).any() || got.cmpgt(root_hi).any() {
                return Err(format!(
                    "{}: vertex {v} at {got} lies outside the refit root box {root_lo}..{root_hi}",
                    mesh.name
                )
                .into());
            }
            max_error = max_error.max((*got - want[v]).abs().max_element());
            max_moved = max_moved.max((*got - Vec3::from(mesh.positions[v])).length());
        }
    }
    let check = PoseCheck {
        mesh: mesh.name.clone(),
        triangles: blas.triangles.len(),
        max_error: f64::from(max_error / size),
        max_displacement: f64::from(max_moved / size),
    };
    if check.max_error > 1e-4 {
        return Err(format!(
            "{}: the BLAS is {:.2e} of the mesh's size from the CPU skinning",
            mesh.name, check.max_error
        )
        .into());
    }
    if check.max_displacement < 1e-3 {
        return Err(format!(
            "{}: the BLAS holds the rest pose (moved {:.2e} of its size)",
            mesh.name, check.max_displacement
        )
        .into());
    }
    Ok(check)
}

#[cfg(test)]
mod tests {
    use super::*;
    use kickstart_rt_renderer::scene::builtin::icosphere;
    use kickstart_rt_renderer::scene::Instance;

    /// A unit sphere stretched to 2 high.
    fn tall_sphere() -> Vec<[f32; 3]> {
        icosphere(2)
            .0
            .iter()
            .map(|p| [p[0], 2.0 * p[1], p[2]])
            .collect()
    }

    #[test]
    fn each_vertex_hangs_on_the_two_joints_nearest_its_height() {
        let positions = tall_sphere();
        let rig = Rig::new(&positions);
        assert_eq!(rig.pivots.len(), JOINTS as usize);
        let (bottom, top) = positions.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| {
            (lo.min(p[1]), hi.max(p[1]))
        });
        assert_eq!(rig.pivots[0].y, bottom);
        assert!((rig.pivots[5].y - top).abs() < 1e-5);
        assert!(top - bottom > 3.0);
        let spacing = (top - bottom) / (JOINTS - 1) as f32;
        for (p, (j, w)) in positions.iter().zip(&rig.influences) {
            assert_eq!(u32::from(w[0]) + u32::from(w[1]), 255);
            assert_eq!((j[1], w[2], w[3]), (j[0] + 1, 0, 0));
            let (below, above) = (rig.pivots[j[0] as usize].y, rig.pivots[j[1] as usize].y);
            assert!(
                p[1] >= below - 1e-5 && p[1] <= above + 1e-5,
                "{p:?}: joints {j:?}"
            );
            // The nearer joint weighs more.
            let up = f32::from(w[1]) / 255.0;
            assert!(
                (up - (p[1] - below) / spacing).abs() < 0.003,
                "{p:?}: {w:?}"
            );
        }
    }

    #[test]
    fn the_chain_bends_more_at_the_top_and_stays_joined() {
        let positions = tall_sphere();
        let rig = Rig::new(&positions);
        let rest: Vec<Vec3> = positions.iter().map(|p| Vec3::from(*p)).collect();
        let unbent = rig.posed(&positions, &rig.matrices(0.0));
        assert!(unbent
            .iter()
            .zip(&rest)
            .all(|(a, b)| (*a - *b).length() < 1e-5));
        let m = rig.matrices(5f32.to_radians());
        // Joint k + 1's pivot is where joint k puts it: the segments stay joined.
        for k in 0..JOINTS as usize - 1 {
            let p = rig.pivots[k + 1];
            assert!((m[k].transform_point3(p) - m[k + 1].transform_point3(p)).length() < 1e-5);
        }
        let posed = rig.posed(&positions, &m);
        let moved = |y: f32| {
            rest.iter()
                .zip(&posed)
                .filter(|(r, _)| (r.y - y).abs() < 0.3)
                .map(|(r, p)| (*p - *r).length())
                .fold(0.0f32, f32::max)
        };
        assert!(moved(1.8) > 2.0 * moved(-1.0) && moved(1.8) > 0.1);
    }

    #[test]
    fn the_angle_changes_every_repetition_and_stays_a_few_degrees() {
        for mesh in 0..100 {
            for i in 0..50 {
                let (a, b) = (angle(i, mesh).to_degrees(), angle(i + 1, mesh).to_degrees());
                assert!((2.0..=5.0).contains(&a) && a != b, "{mesh} {i}: {a} {b}");
            }
        }
    }

    /// GPU (lavapipe): two spheres skinned and refit untimed, the BLAS checked against the CPU
    /// pose; on a device with timestamp queries the timed figure too.
    #[test]
    fn a_skinned_refit_reaches_the_blas() {
        let (device, queue) = crate::app::testing::device();
        let bench = Bench::new(device, queue, 1);
        let meshes = (0..2)
            .map(|k| {
                Mesh::new(
                    format!("sphere {k}"),
                    tall_sphere(),
                    icosphere(2).1,
                    Vec3::ONE,
                )
                .unwrap()
            })
            .collect();
        let scene = Scene {
            meshes,
            instances: (0..2)
                .map(|mesh| Instance {
                    mesh,
                    transform: glam::Affine3A::IDENTITY,
                })
                .collect(),
            ..Default::default()
        };
        let uploads = upload::upload_scene(device, queue, &scene);
        let skinned = SkinnedScene::new(device, &scene, &uploads, SkinBuffers::Pooled);
        let ctx = bench.context().unwrap();
        let handles = skinned.register(&bench, &ctx).unwrap();
        // Before any skinning the BLAS holds the rest pose, which the check refuses.
        let err = check_pose(&ctx, &scene, &skinned, &handles, 7)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("rest pose") || err.contains("from the CPU"),
            "{err}"
        );
        for iteration in [1, 2] {
            let task = upload::submit(
                &ctx,
                device,
                queue,
                skinned.frame(&ctx, &handles, iteration),
                |_| {},
            )
            .unwrap();
            gpu::complete(&ctx, device, task).unwrap();
            let check = check_pose(&ctx, &scene, &skinned, &handles, iteration).unwrap();
            assert!(check.max_displacement > 0.01, "{check:?}");
        }
        if device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            let r = bench.skinned_refit(&scene, &uploads).unwrap();
            assert_eq!(r.vertices, 2 * tall_sphere().len() as u64);
            assert!(
                r.skinning.median_ms >= 0.0 && r.skinning.median_ms <= r.time.median_ms,
                "{r:?}"
            );
            assert!(
                r.profile.iter().any(|p| p.scope == "skinning"),
                "{:?}",
                r.profile
            );
            assert!(
                r.profile.iter().any(|p| p.scope == "blas refit"),
                "{:?}",
                r.profile
            );
        }
    }
}
