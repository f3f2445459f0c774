//! Skinned and morphed meshes, traced at the pose Bevy draws them in.
//!
//! Bevy deforms these meshes in its vertex shader, out of the SDK's reach. So each frame the
//! plugin extracts every such entity's pose as Bevy's own skinning computes it (each joint's
//! `GlobalTransform` × its inverse bindpose; the morph weights of `MeshMorphWeights`), and
//! [`DeformedMeshes::pose`] schedules one SDK `SkinningTask` per entity into the frame's scene
//! task: it poses the rest positions from Bevy's vertex buffer into the entity's range of one
//! positions buffer shared by every deformed entity, from which the SDK refits the entity's
//! `allow_update` geometry in the same task.

use std::collections::{HashMap, HashSet};

use bevy::asset::AssetId;
use bevy::math::Affine3A;
use bevy::mesh::morph::{MeshMorphWeights, MorphWeights};
use bevy::mesh::skinning::{SkinnedMesh, SkinnedMeshInverseBindposes};
use bevy::mesh::{Mesh, VertexFormat as BevyVertexFormat};
use bevy::prelude::*;
use bevy::render::Extract;
use bevy::render::mesh::RenderMeshBufferInfo;
use kickstart_rt as ksrt;

use crate::cutout::{self, Opacity};
use crate::scene::{ExtractedScene, RenderData};

/// Bytes of one vertex's morph displacements in Bevy's morph target buffer
/// (`MorphAttributes`: position, normal and tangent, each padded to 16 bytes; the position
/// comes first).
const MORPH_ATTRIBUTES_SIZE: u64 = 48;

/// One deformed entity's pose this frame, as extracted.
pub(crate) struct Pose {
    /// The main-world entity.
    pub entity: Entity,
    /// Its mesh.
    pub mesh: AssetId<Mesh>,
    /// Object to world: the instance's transform when the mesh is not skinned (Bevy draws a
    /// skinned mesh by its joints alone).
    pub transform: Affine3A,
    /// Each joint's world matrix × its inverse bindpose, as Bevy's skinning computes them;
    /// `None` without a `SkinnedMesh`.
    pub joints: Option<Vec<Mat4>>,
    /// The morph targets' weights (empty without `MeshMorphWeights`).
    pub weights: Vec<f32>,
    /// What its material lets through.
    pub opacity: Opacity,
}

/// What [`extract_poses`] reads of a deformed entity.
type DeformedEntity<'a> = (
    Entity,
    &'a Mesh3d,
    &'a GlobalTransform,
    &'a InheritedVisibility,
    Option<&'a SkinnedMesh>,
    Option<&'a MeshMorphWeights>,
    Option<&'a MeshMaterial3d<StandardMaterial>>,
);

/// Entities that Bevy skins or morphs.
type Deformed = Or<(With<SkinnedMesh>, With<MeshMorphWeights>)>;

/// Extracts the pose of every visible skinned or morphed mesh entity, every frame: a pose is not
/// compared with the last one (an animated mesh's changes every frame), so every deformed
/// entity is posed and refit every frame.
pub(crate) fn extract_poses(
    mut scene: ResMut<ExtractedScene>,
    deformed: Extract<Query<DeformedEntity, Deformed>>,
    transforms: Extract<Query<&GlobalTransform>>,
    bindposes: Extract<Option<Res<Assets<SkinnedMeshInverseBindposes>>>>,
    morph_weights: Extract<Query<&MorphWeights>>,
    materials: Extract<Option<Res<Assets<StandardMaterial>>>>,
    mut warned: Local<HashSet<AssetId<StandardMaterial>>>,
) {
    scene.poses.clear();
    for (entity, mesh, transform, visibility, skin, morph, material) in &deformed {
        if !visibility.get() {
            continue;
        }
        let joints = skin.map(|skin| joint_matrices(skin, &transforms, bindposes.as_deref()));
        let weights = match morph {
            Some(MeshMorphWeights::Value { weights }) => weights.clone(),
            Some(MeshMorphWeights::Reference(source)) => morph_weights
                .get(*source)
                .map(|w| w.weights().to_vec())
                .unwrap_or_default(),
            None => Vec::new(),
        };
        let opacity = match (material, materials.as_ref()) {
            (Some(m), Some(assets)) => assets.get(m.id()).map_or(Opacity::Opaque, |asset| {
                cutout::material_opacity(m.id(), asset, &mut warned)
            }),
            _ => Opacity::Opaque,
        };
        scene.poses.push(Pose {
            entity,
            mesh: mesh.id(),
            transform: transform.affine(),
            joints,
            weights,
            opacity,
        });
    }
}

/// `skin`'s joint matrices as Bevy's skinning computes them: a joint's `GlobalTransform` ×
/// its inverse bindpose, the identity where either is missing.
fn joint_matrices(
    skin: &SkinnedMesh,
    transforms: &Query<&GlobalTransform>,
    bindposes: Option<&Assets<SkinnedMeshInverseBindposes>>,
) -> Vec<Mat4> {
    let bindposes = bindposes.and_then(|b| b.get(&skin.inverse_bindposes));
    skin.joints
        .iter()
        .enumerate()
        .map(|(i, joint)| {
            let bindpose = bindposes.and_then(|b| b.get(i));
            match (bindpose, transforms.get(*joint)) {
                (Some(bindpose), Ok(transform)) => transform.affine() * *bindpose,
                _ => Mat4::IDENTITY,
            }
        })
        .collect()
}

/// One deformed entity in the SDK's scene: its own geometry, refit from its own positions
/// buffer each frame.
struct Posed {
    mesh: AssetId<Mesh>,
    opacity: Opacity,
    geometry: ksrt::GeometryHandle,
    instance: ksrt::InstanceHandle,
    /// The cutout it was registered with, given again with each update.
    cutout: Option<ksrt::ComponentOpacity>,
    /// The instance's transform.
    transform: Affine3A,
}

/// The posed positions (`Float32x3`) of every deformed entity, one after another in one buffer
/// laid out again each frame: the SDK poses the entities that share Bevy's vertex buffer in one
/// dispatch, and no buffer is created an entity. Every entity is posed anew each frame, so a
/// new layout or a bigger buffer moves no data.
#[derive(Default)]
struct PosedPool {
    buffer: Option<wgpu::Buffer>,
}

impl PosedPool {
    /// A buffer of at least `bytes` (fewer where the device's largest buffer is smaller): the
    /// current one, or a new one of the next power of two.
    fn reserve(&mut self, device: &wgpu::Device, bytes: u64) -> wgpu::Buffer {
        let max = device.limits().max_buffer_size;
        let want = bytes
            .max(16)
            .checked_next_power_of_two()
            .unwrap_or(max)
            .min(max);
        match &self.buffer {
            Some(b) if b.size() >= bytes.min(max) => b.clone(),
            _ => {
                let b = device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("kickstart-rt posed positions"),
                    size: want,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                });
                self.buffer = Some(b.clone());
                b
            }
        }
    }
}

/// Where one entity's posed positions go this frame: the pool and the byte offset.
type Output<'a> = (&'a wgpu::Buffer, u64);

/// The skinned and morphed entities the SDK traces.
#[derive(Default)]
pub(crate) struct DeformedMeshes {
    entries: HashMap<Entity, Posed>,
    pool: PosedPool,
    /// Meshes that cannot be posed, each logged once.
    unsupported: HashSet<AssetId<Mesh>>,
}

/// Where one mesh's data lies in Bevy's buffers, for posing and tracing it.
struct MeshBuffers {
    /// Bevy's vertex buffer and the byte offset of the mesh's vertex 0 in it.
    vertices: wgpu::Buffer,
    first_vertex: u64,
    stride: u64,
    vertex_count: u32,
    /// Byte offset of the position in a vertex.
    position: u64,
    /// The joints' and weights' offsets in a vertex and formats, when the mesh has them.
    influences: Option<(u64, ksrt::JointFormat, u64, ksrt::WeightFormat)>,
    /// Bevy's morph target buffer, the byte offset of the mesh's displacements and the number
    /// of targets.
    morph: Option<(wgpu::Buffer, u64, u32)>,
    indices: Option<ksrt::IndexBufferInput>,
}

impl DeformedMeshes {
    /// Takes `entity` out of the SDK's scene, if it is there.
    pub fn remove(&mut self, ctx: &ksrt::ExecuteContext, entity: Entity) {
        if let Some(d) = self.entries.remove(&entity) {
            if let Err(e) = ctx.destroy_instance_handle(d.instance) {
                warn!("kickstart-rt: removing a deformed mesh's instance: {e}");
            }
            if let Err(e) = ctx.destroy_geometry_handle(d.geometry) {
                warn!("kickstart-rt: dropping a deformed mesh's geometry: {e}");
            }
        }
    }

    /// Schedules this frame's poses: a `SkinningTask` and a geometry update (or, the first
    /// time, registration) for each entity in `poses`; entities no longer deformed, visible or
    /// alive, and those whose mesh Bevy re-uploaded (in `replaced`), leave or start over.
    /// Returns the number of geometries built or refit.
    pub fn pose(
        &mut self,
        ctx: &ksrt::ExecuteContext,
        container: &mut ksrt::TaskContainer,
        poses: &[Pose],
        replaced: &HashSet<&AssetId<Mesh>>,
        data: &RenderData,
    ) -> u32 {
        let current: HashMap<Entity, &Pose> = poses.iter().map(|p| (p.entity, p)).collect();
        let stale: Vec<Entity> = (self.entries.iter())
            .filter(|(e, d)| {
                current
                    .get(e)
                    .is_none_or(|p| p.mesh != d.mesh || p.opacity != d.opacity)
                    || replaced.contains(&d.mesh)
            })
            .map(|(e, _)| *e)
            .collect();
        for entity in stale {
            self.remove(ctx, entity);
        }
        for id in replaced {
            self.unsupported.remove(*id);
        }
        let mut ready = Vec::new();
        for pose in poses {
            if self.unsupported.contains(&pose.mesh) || pose.opacity == Opacity::Invisible {
                continue;
            }
            match mesh_buffers(pose.mesh, data) {
                Ok(Some(mesh)) => ready.push((pose, mesh)),
                // Not uploaded yet: next frame.
                Ok(None) => {}
                Err(why) => {
                    warn!(
                        "kickstart-rt: deformed mesh {:?} is not ray traced: {why}",
                        pose.mesh
                    );
                    self.unsupported.insert(pose.mesh);
                }
            }
        }
        let bytes = |m: &MeshBuffers| u64::from(m.vertex_count.max(1)) * 12;
        let total = ready.iter().map(|(_, m)| bytes(m)).sum();
        let pool = self.pool.reserve(data.device.wgpu_device(), total);
        let (mut posed, mut offset) = (0, 0);
        for (pose, mesh) in ready {
            if offset + bytes(&mesh) > pool.size() {
                warn!(
                    "kickstart-rt: deformed mesh {:?} is not ray traced this frame: the posed \
                     positions of every deformed mesh pass the device's largest buffer",
                    pose.mesh
                );
                continue;
            }
            if self.pose_one(ctx, container, pose, &mesh, data, (&pool, offset)) {
                posed += 1;
                offset += bytes(&mesh);
            }
        }
        posed
    }

    /// Poses one entity: registers it the first time; returns whether a geometry task was
    /// scheduled.
    fn pose_one(
        &mut self,
        ctx: &ksrt::ExecuteContext,
        container: &mut ksrt::TaskContainer,
        pose: &Pose,
        mesh: &MeshBuffers,
        data: &RenderData,
        output: Output<'_>,
    ) -> bool {
        let skinned =
            mesh.influences.is_some() && pose.joints.as_ref().is_some_and(|j| !j.is_empty());
        // Bevy draws a skinned mesh by its joints' world matrices alone; the SDK's instance
        // then places nothing.
        let transform = if skinned {
            Affine3A::IDENTITY
        } else {
            pose.transform
        };
        if let Some(d) = self.entries.get_mut(&pose.entity) {
            container.schedule_bvh_task(skinning_task(pose, mesh, skinned, output));
            container.schedule_bvh_task(ksrt::GeometryTask {
                operation: ksrt::TaskOperation::Update,
                handle: d.geometry,
                input: geometry_input(pose, mesh, output, d.cutout.clone()),
            });
            if d.transform != transform {
                container.schedule_bvh_task(ksrt::InstanceTask {
                    operation: ksrt::TaskOperation::Update,
                    handle: d.instance,
                    input: crate::scene::instance_input(d.geometry, transform, pose.entity),
                });
                d.transform = transform;
            }
            return true;
        }
        let cutout = match &pose.opacity {
            Opacity::Cutout(c) => {
                let Some(render_mesh) = data.meshes.get(pose.mesh) else {
                    return false;
                };
                let (buffer, first) = (&mesh.vertices, mesh.first_vertex);
                match cutout::component_opacity(c, render_mesh, buffer, first, &data.images) {
                    // The texture is not uploaded yet: next frame.
                    Ok(None) => return false,
                    Ok(Some(opacity)) => Some(opacity),
                    Err(why) => {
                        warn!(
                            "kickstart-rt: mesh {:?} is masked but traced opaque: {why}",
                            pose.mesh
                        );
                        None
                    }
                }
            }
            _ => None,
        };
        let (geometry, instance) = (ctx.create_geometry_handle(), ctx.create_instance_handle());
        // The skinning task is recorded before the registration, which copies the posed
        // positions.
        container.schedule_bvh_task(skinning_task(pose, mesh, skinned, output));
        container.schedule_bvh_task(ksrt::GeometryTask {
            operation: ksrt::TaskOperation::Register,
            handle: geometry,
            input: geometry_input(pose, mesh, output, cutout.clone()),
        });
        container.schedule_bvh_task(ksrt::InstanceTask {
            operation: ksrt::TaskOperation::Register,
            handle: instance,
            input: crate::scene::instance_input(geometry, transform, pose.entity),
        });
        self.entries.insert(
            pose.entity,
            Posed {
                mesh: pose.mesh,
                opacity: pose.opacity,
                geometry,
                instance,
                cutout,
                transform,
            },
        );
        true
    }
}

/// The SDK geometry of a deformed entity: its posed positions, with Bevy's indices.
fn geometry_input(
    pose: &Pose,
    mesh: &MeshBuffers,
    (output, offset): Output<'_>,
    opacity: Option<ksrt::ComponentOpacity>,
) -> ksrt::GeometryInput {
    ksrt::GeometryInput {
        name: format!("{} ({:?})", pose.entity, pose.mesh),
        components: vec![ksrt::GeometryComponent {
            vertex_buffer: ksrt::VertexBufferInput {
                buffer: output.clone(),
                offset,
                stride: 12,
                count: mesh.vertex_count,
                format: ksrt::VertexFormat::Float32x3,
            },
            index_buffer: mesh.indices.clone(),
            transform: None,
            index_range: None,
            opacity,
        }],
        allow_update: true,
        ..Default::default()
    }
}

/// An attribute of `mesh`'s vertices in Bevy's vertex buffer, `offset` bytes into a vertex.
fn attribute<F>(mesh: &MeshBuffers, offset: u64, format: F) -> ksrt::SkinAttribute<F> {
    ksrt::SkinAttribute {
        buffer: mesh.vertices.clone(),
        offset: mesh.first_vertex + offset,
        stride: mesh.stride,
        format,
    }
}

/// The SDK task posing `mesh` at `pose` into `output`.
fn skinning_task(
    pose: &Pose,
    mesh: &MeshBuffers,
    skinned: bool,
    (output, offset): Output<'_>,
) -> ksrt::SkinningTask {
    let influences = mesh.influences.filter(|_| skinned).map(
        |(joints, joint_format, weights, weight_format)| ksrt::SkinInfluences {
            joints: attribute(mesh, joints, joint_format),
            weights: attribute(mesh, weights, weight_format),
        },
    );
    let joint_matrices = match (&pose.joints, skinned) {
        (Some(joints), true) => joints.iter().map(|m| to_sdk(*m)).collect(),
        _ => Vec::new(),
    };
    let (morph_targets, morph_weights) = match &mesh.morph {
        Some((buffer, offset, count)) => {
            // Bevy reads as many weights as the entity gives; missing ones weigh nothing.
            let weights = (0..*count as usize)
                .map(|t| pose.weights.get(t).copied().unwrap_or(0.0))
                .collect();
            let targets = ksrt::MorphTargetsInput {
                buffer: buffer.clone(),
                offset: *offset,
                stride: MORPH_ATTRIBUTES_SIZE,
                target_stride: MORPH_ATTRIBUTES_SIZE * u64::from(mesh.vertex_count),
                count: *count,
            };
            (Some(targets), weights)
        }
        None => (None, Vec::new()),
    };
    ksrt::SkinningTask {
        name: format!("{}", pose.entity),
        rest_positions: attribute(mesh, mesh.position, ksrt::VertexFormat::Float32x3),
        vertex_count: mesh.vertex_count,
        influences,
        joint_matrices,
        morph_targets,
        morph_weights,
        output: ksrt::SkinningOutput {
            buffer: output.clone(),
            offset,
            stride: 12,
        },
    }
}

/// Where `mesh`'s positions, joints, weights, morph displacements and indices lie in Bevy's
/// buffers; `Ok(None)` while Bevy has not uploaded it, `Err` for a mesh that cannot be posed.
fn mesh_buffers(mesh: AssetId<Mesh>, data: &RenderData) -> Result<Option<MeshBuffers>, String> {
    let (Some(render_mesh), Some(vertices)) = (
        data.meshes.get(mesh),
        data.allocator.mesh_vertex_slice(&mesh),
    ) else {
        return Ok(None);
    };
    if render_mesh.primitive_topology() != bevy::mesh::PrimitiveTopology::TriangleList {
        return Err(format!(
            "topology {:?} (only triangle lists are traced)",
            render_mesh.primitive_topology()
        ));
    }
    let mesh_layout = &render_mesh.layout.0;
    let layout = mesh_layout.layout();
    let (position, format) = crate::scene::position_attribute(mesh_layout, layout)?;
    if format != ksrt::VertexFormat::Float32x3 {
        return Err(format!(
            "position format {format:?} (posing reads Float32x3)"
        ));
    }
    let joints = cutout::attribute(mesh_layout, layout, &Mesh::ATTRIBUTE_JOINT_INDEX);
    let weights = cutout::attribute(mesh_layout, layout, &Mesh::ATTRIBUTE_JOINT_WEIGHT);
    let influences = match (joints, weights) {
        (Ok((joints, joint_format)), Ok((weights, weight_format))) => Some((
            joints,
            joint_format_of(joint_format)?,
            weights,
            weight_format_of(weight_format)?,
        )),
        // Without both, Bevy draws the mesh unskinned.
        _ => None,
    };
    let stride = layout.array_stride;
    let vertex_count = vertices.range.end - vertices.range.start;
    let morph = match data.allocator.mesh_morph_target_slice(&mesh) {
        Some(slice) if vertex_count > 0 => {
            let displacements = slice.range.end - slice.range.start;
            let count = displacements / vertex_count;
            Some((
                (**slice.buffer).clone(),
                u64::from(slice.range.start) * MORPH_ATTRIBUTES_SIZE,
                count.min(ksrt::SkinningTask::MAX_MORPH_TARGETS),
            ))
        }
        _ => None,
    };
    let indices = match &render_mesh.buffer_info {
        RenderMeshBufferInfo::NonIndexed => None,
        RenderMeshBufferInfo::Indexed {
            count,
            index_format,
        } => {
            let Some(slice) = data.allocator.mesh_index_slice(&mesh) else {
                return Ok(None);
            };
            let format = match index_format {
                wgpu::IndexFormat::Uint16 => ksrt::IndexFormat::Uint16,
                wgpu::IndexFormat::Uint32 => ksrt::IndexFormat::Uint32,
            };
            Some(ksrt::IndexBufferInput {
                buffer: (**slice.buffer).clone(),
                offset: u64::from(slice.range.start) * format.size(),
                count: *count,
                format,
            })
        }
    };
    Ok(Some(MeshBuffers {
        vertices: (**vertices.buffer).clone(),
        first_vertex: u64::from(vertices.range.start) * stride,
        stride,
        vertex_count,
        position,
        influences,
        morph,
        indices,
    }))
}

/// The SDK's layout of Bevy's joint indices.
fn joint_format_of(format: BevyVertexFormat) -> Result<ksrt::JointFormat, String> {
    match format {
        BevyVertexFormat::Uint8x4 => Ok(ksrt::JointFormat::Uint8x4),
        BevyVertexFormat::Uint16x4 => Ok(ksrt::JointFormat::Uint16x4),
        BevyVertexFormat::Uint32x4 => Ok(ksrt::JointFormat::Uint32x4),
        other => Err(format!("joint index format {other:?}")),
    }
}

/// The SDK's layout of Bevy's joint weights.
fn weight_format_of(format: BevyVertexFormat) -> Result<ksrt::WeightFormat, String> {
    match format {
        BevyVertexFormat::Float32x4 => Ok(ksrt::WeightFormat::Float32x4),
        BevyVertexFormat::Unorm8x4 => Ok(ksrt::WeightFormat::Unorm8x4),
        BevyVertexFormat::Unorm16x4 => Ok(ksrt::WeightFormat::Unorm16x4),
        other => Err(format!("joint weight format {other:?}")),
    }
}

/// Bevy's and the SDK's glam may be different versions: convert through arrays.
fn to_sdk(m: Mat4) -> glam::Mat4 {
    glam::Mat4::from_cols_array(&m.to_cols_array())
}
