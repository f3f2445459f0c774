//! Keeps the SDK's geometry and instances in step with Bevy's `Mesh3d` entities.
//!
//! Extraction copies what changed in the main world (meshes and transforms of visible
//! entities, and entities that lost their mesh or visibility); [`sync_scene`] turns that into
//! one SDK task a frame — register a geometry the first time a mesh is used, register, move or
//! remove instances, rebuild what changed — once Bevy's mesh allocator holds the mesh's data.

use std::collections::{HashMap, HashSet};

use bevy::asset::AssetId;
use bevy::light::GlobalAmbientLight;
use bevy::math::Affine3A;
use bevy::mesh::{Mesh, MeshVertexAttribute, PrimitiveTopology, VertexFormat as BevyVertexFormat};
use bevy::prelude::*;
use bevy::render::Extract;
use bevy::render::mesh::allocator::MeshAllocator;
use bevy::render::mesh::{RenderMesh, RenderMeshBufferInfo};
use bevy::render::render_asset::{ExtractedAssets, RenderAssets};
use kickstart_rt as ksrt;

use crate::RayTracedLighting;
use crate::sdk::SdkContext;

/// What changed in the main world since the last [`sync_scene`].
#[derive(Resource, Default)]
pub(crate) struct ExtractedScene {
    /// Visible mesh entities added or changed: mesh, object-to-world transform, and whether the
    /// mesh is deformed by skinning or morph targets (left out).
    changed: Vec<(Entity, AssetId<Mesh>, Affine3A, bool)>,
    /// Entities to remove from the SDK's scene: despawned, hidden or without a mesh now.
    removed: Vec<Entity>,
    /// The first directional light: direction light travels, and exposed radiance scale.
    pub sun: Option<Sun>,
}

/// The first directional light, as the composite and the shadow trace need it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sun {
    /// Unit vector from surfaces towards the light.
    pub to_light: Vec3,
    /// Linear colour × illuminance (lux), before the camera's exposure.
    pub illuminance: Vec3,
}

type MeshEntity<'a> = (
    Entity,
    &'a Mesh3d,
    &'a GlobalTransform,
    &'a InheritedVisibility,
    Has<bevy::mesh::skinning::SkinnedMesh>,
    Has<bevy::mesh::morph::MeshMorphWeights>,
);

/// A mesh entity whose mesh, transform or visibility changed (or that was just spawned).
type MeshEntityChanged = Or<(
    Changed<Mesh3d>,
    Changed<GlobalTransform>,
    Changed<InheritedVisibility>,
)>;

/// Extracts mesh entities that were added, moved, re-meshed, shown or hidden, and those that
/// were despawned or lost their mesh.
pub(crate) fn extract_mesh_instances(
    mut scene: ResMut<ExtractedScene>,
    changed: Extract<Query<MeshEntity, MeshEntityChanged>>,
    mut removed: Extract<RemovedComponents<Mesh3d>>,
) {
    for (entity, mesh, transform, visibility, skinned, morphed) in &changed {
        if visibility.get() {
            let affine = transform.affine();
            scene
                .changed
                .push((entity, mesh.id(), affine, skinned || morphed));
        } else {
            scene.removed.push(entity);
        }
    }
    scene.removed.extend(removed.read());
}

/// Extracts the first directional light, and warns once when Bevy's ambient light would add to
/// the ray-traced GI.
pub(crate) fn extract_lights(
    mut scene: ResMut<ExtractedScene>,
    lights: Extract<Query<(&DirectionalLight, &GlobalTransform, &ViewVisibility)>>,
    ambient: Extract<Option<Res<GlobalAmbientLight>>>,
    cameras: Extract<Query<&RayTracedLighting>>,
    mut warned: Local<bool>,
) {
    scene.sun = lights
        .iter()
        .find(|(_, _, visible)| visible.get())
        .map(|(light, transform, _)| Sun {
            to_light: transform.back().as_vec3(),
            illuminance: light.color.to_linear().to_vec3() * light.illuminance,
        });
    let ambient_on = ambient.as_ref().is_some_and(|a| a.brightness > 0.0);
    if ambient_on && !*warned && cameras.iter().any(|c| c.gi) {
        warn!(
            "kickstart-rt: GlobalAmbientLight is on ({} cd/m²) while ray-traced GI is: both add \
             indirect light; set its brightness to 0",
            ambient.as_ref().map_or(0.0, |a| a.brightness)
        );
        *warned = true;
    }
}

/// One registered geometry: a Bevy mesh asset.
struct Geometry {
    handle: ksrt::GeometryHandle,
}

/// One registered instance: a mesh entity.
struct Instance {
    handle: ksrt::InstanceHandle,
    mesh: AssetId<Mesh>,
    /// Its last transform (kept to re-register it when its mesh is replaced).
    transform: Affine3A,
}

/// The SDK's view of the scene: which mesh and entity has which handle.
#[derive(Resource, Default)]
pub(crate) struct SceneSync {
    geometries: HashMap<AssetId<Mesh>, Geometry>,
    instances: HashMap<Entity, Instance>,
    /// Entities whose mesh is not uploaded yet (or was replaced), retried each frame.
    waiting: HashMap<Entity, (AssetId<Mesh>, Affine3A)>,
    /// Meshes the SDK cannot trace, each logged once.
    unsupported: HashSet<AssetId<Mesh>>,
    /// Whether deformed (skinned or morphed) meshes were logged.
    warned_deformed: bool,
}

/// Records this frame's scene changes as one SDK task (submitted at once: Bevy's mesh uploads,
/// queued earlier in the frame, run before it).
pub(crate) fn sync_scene(
    sdk: Res<SdkContext>,
    mut sync: ResMut<SceneSync>,
    mut extracted: ResMut<ExtractedScene>,
    meshes: Res<RenderAssets<RenderMesh>>,
    extracted_meshes: Res<ExtractedAssets<RenderMesh>>,
    allocator: Res<MeshAllocator>,
) {
    let ctx = &sdk.ctx;
    let mut container = ctx.create_task_container();
    let sync = &mut *sync;
    sync.drop_meshes(
        ctx,
        extracted_meshes
            .removed
            .iter()
            .chain(&extracted_meshes.modified),
    );
    for entity in extracted.removed.drain(..) {
        sync.waiting.remove(&entity);
        sync.remove_instance(ctx, entity);
    }
    for (entity, mesh, transform, deformed) in extracted.changed.drain(..) {
        if deformed {
            sync.leave_out_deformed(ctx, entity);
        } else {
            sync.change(ctx, &mut container, entity, mesh, transform);
        }
    }
    let built = sync.register_waiting(ctx, &mut container, &meshes, &allocator);

    if container.is_empty() {
        return;
    }
    debug!(
        "kickstart-rt: scene update: {} new geometries, {} instances, {} waiting",
        built,
        sync.instances.len(),
        sync.waiting.len()
    );
    container.schedule_bvh_task(ksrt::BvhBuildTask {
        max_blas_build_count: built.max(1),
        ..Default::default()
    });
    if let Err(e) = ctx.invoke_gpu_task(container) {
        error!("kickstart-rt: updating the ray-traced scene failed: {e}");
    }
}

impl SceneSync {
    /// Mesh assets that changed or went: their instances wait for the new data (or for their
    /// entity to go too), and their geometries are dropped.
    fn drop_meshes<'a>(
        &mut self,
        ctx: &ksrt::ExecuteContext,
        ids: impl Iterator<Item = &'a AssetId<Mesh>>,
    ) {
        for id in ids {
            self.unsupported.remove(id);
            let Some(geometry) = self.geometries.remove(id) else {
                continue;
            };
            let users: Vec<Entity> = self
                .instances
                .iter()
                .filter(|(_, i)| i.mesh == *id)
                .map(|(e, _)| *e)
                .collect();
            for entity in users {
                if let Some(instance) = self.instances.remove(&entity) {
                    destroy_instance(ctx, instance.handle);
                    self.waiting.insert(entity, (*id, instance.transform));
                }
            }
            if let Err(e) = ctx.destroy_geometry_handle(geometry.handle) {
                warn!("kickstart-rt: dropping a mesh's geometry: {e}");
            }
        }
    }

    /// Removes `entity`'s instance from the SDK's scene, if it has one.
    fn remove_instance(&mut self, ctx: &ksrt::ExecuteContext, entity: Entity) {
        if let Some(instance) = self.instances.remove(&entity) {
            destroy_instance(ctx, instance.handle);
        }
    }

    /// A skinned or morphed mesh entity: left out of the scene (logged the first time).
    fn leave_out_deformed(&mut self, ctx: &ksrt::ExecuteContext, entity: Entity) {
        // Bevy skins and morphs in its vertex shader, out of the SDK's reach: tracing the
        // rest pose would cast shadows and bounce light where the mesh is not.
        if !self.warned_deformed {
            warn!(
                "kickstart-rt: skinned and morphed meshes are left out of ray tracing (Bevy \
                 deforms them in its vertex shader); entity {entity} is the first"
            );
            self.warned_deformed = true;
        }
        self.waiting.remove(&entity);
        self.remove_instance(ctx, entity);
    }

    /// A mesh entity added, moved or re-meshed: an instance of the same mesh moves at once;
    /// otherwise the entity waits for its mesh's geometry ([`Self::register_waiting`]).
    fn change(
        &mut self,
        ctx: &ksrt::ExecuteContext,
        container: &mut ksrt::TaskContainer,
        entity: Entity,
        mesh: AssetId<Mesh>,
        transform: Affine3A,
    ) {
        match self.instances.get_mut(&entity) {
            Some(instance) if instance.mesh == mesh => {
                let Some(geometry) = self.geometries.get(&mesh).map(|g| g.handle) else {
                    return;
                };
                container.schedule_bvh_task(ksrt::InstanceTask {
                    operation: ksrt::TaskOperation::Update,
                    handle: instance.handle,
                    input: instance_input(geometry, transform, entity),
                });
                instance.transform = transform;
            }
            Some(_) => {
                self.remove_instance(ctx, entity);
                self.waiting.insert(entity, (mesh, transform));
            }
            None => {
                self.waiting.insert(entity, (mesh, transform));
            }
        }
    }

    /// Registers an instance for every waiting entity whose mesh Bevy has uploaded (and its
    /// geometry, the first time the mesh is used); returns the number of new geometries.
    fn register_waiting(
        &mut self,
        ctx: &ksrt::ExecuteContext,
        container: &mut ksrt::TaskContainer,
        meshes: &RenderAssets<RenderMesh>,
        allocator: &MeshAllocator,
    ) -> u32 {
        let mut built = 0;
        let waiting: Vec<_> = self.waiting.iter().map(|(e, m)| (*e, *m)).collect();
        for (entity, (mesh, transform)) in waiting {
            let geometry = match self.geometries.get(&mesh) {
                Some(g) => g.handle,
                None => match register_geometry(ctx, container, mesh, meshes, allocator) {
                    Ok(Some(handle)) => {
                        self.geometries.insert(mesh, Geometry { handle });
                        built += 1;
                        handle
                    }
                    // Not uploaded yet: try again next frame.
                    Ok(None) => continue,
                    Err(why) => {
                        if self.unsupported.insert(mesh) {
                            warn!("kickstart-rt: mesh {mesh:?} is not ray traced: {why}");
                        }
                        self.waiting.remove(&entity);
                        continue;
                    }
                },
            };
            let handle = ctx.create_instance_handle();
            container.schedule_bvh_task(ksrt::InstanceTask {
                operation: ksrt::TaskOperation::Register,
                handle,
                input: instance_input(geometry, transform, entity),
            });
            self.instances.insert(
                entity,
                Instance {
                    handle,
                    mesh,
                    transform,
                },
            );
            self.waiting.remove(&entity);
        }
        built
    }
}

fn destroy_instance(ctx: &ksrt::ExecuteContext, handle: ksrt::InstanceHandle) {
    if let Err(e) = ctx.destroy_instance_handle(handle) {
        warn!("kickstart-rt: removing an instance: {e}");
    }
}

/// The SDK instance of `entity`: `geometry` placed by `transform`.
fn instance_input(
    geometry: ksrt::GeometryHandle,
    transform: Affine3A,
    entity: Entity,
) -> ksrt::InstanceInput {
    let mut input = ksrt::InstanceInput::new(geometry, to_sdk_affine(transform));
    input.name = format!("{entity}");
    input
}

/// Bevy's and the SDK's glam may be different versions: convert through arrays.
fn to_sdk_affine(t: Affine3A) -> glam::Affine3A {
    glam::Affine3A::from_cols_array(&t.to_cols_array())
}

/// Schedules the registration of `mesh` and returns its new handle; `Ok(None)` while Bevy has
/// not uploaded it yet, `Err` for a mesh the SDK cannot trace.
fn register_geometry(
    ctx: &ksrt::ExecuteContext,
    container: &mut ksrt::TaskContainer,
    mesh: AssetId<Mesh>,
    meshes: &RenderAssets<RenderMesh>,
    allocator: &MeshAllocator,
) -> Result<Option<ksrt::GeometryHandle>, String> {
    let Some(render_mesh) = meshes.get(mesh) else {
        return Ok(None);
    };
    let Some(vertices) = allocator.mesh_vertex_slice(&mesh) else {
        return Ok(None);
    };
    if render_mesh.primitive_topology() != PrimitiveTopology::TriangleList {
        return Err(format!(
            "topology {:?} (only triangle lists are traced)",
            render_mesh.primitive_topology()
        ));
    }
    let layout = render_mesh.layout.0.layout();
    let (offset, format) = position_attribute(&render_mesh.layout.0, layout)?;
    let stride = layout.array_stride;
    let vertex_buffer = ksrt::VertexBufferInput {
        buffer: (**vertices.buffer).clone(),
        offset: vertices.range.start as u64 * stride + offset,
        stride,
        count: vertices.range.end - vertices.range.start,
        format,
    };
    let index_buffer = match &render_mesh.buffer_info {
        RenderMeshBufferInfo::NonIndexed => None,
        RenderMeshBufferInfo::Indexed {
            count,
            index_format,
        } => {
            let Some(indices) = allocator.mesh_index_slice(&mesh) else {
                return Ok(None);
            };
            let format = match index_format {
                wgpu::IndexFormat::Uint16 => ksrt::IndexFormat::Uint16,
                wgpu::IndexFormat::Uint32 => ksrt::IndexFormat::Uint32,
            };
            Some(ksrt::IndexBufferInput {
                buffer: (**indices.buffer).clone(),
                offset: indices.range.start as u64 * format.size(),
                count: *count,
                format,
            })
        }
    };
    let handle = ctx.create_geometry_handle();
    container.schedule_bvh_task(ksrt::GeometryTask {
        operation: ksrt::TaskOperation::Register,
        handle,
        input: ksrt::GeometryInput {
            name: format!("{mesh:?}"),
            components: vec![ksrt::GeometryComponent {
                vertex_buffer,
                index_buffer,
                transform: None,
                index_range: None,
                opacity: None,
            }],
            ..Default::default()
        },
    });
    Ok(Some(handle))
}

/// Byte offset and SDK format of the position attribute in a Bevy vertex layout.
fn position_attribute(
    mesh_layout: &bevy::mesh::MeshVertexBufferLayout,
    layout: &bevy::mesh::VertexBufferLayout,
) -> Result<(u64, ksrt::VertexFormat), String> {
    let position: &MeshVertexAttribute = &Mesh::ATTRIBUTE_POSITION;
    if mesh_layout
        .get_attribute_compression()
        .contains(bevy::mesh::MeshAttributeCompressionFlags::COMPRESS_POSITION)
    {
        return Err("compressed positions (Mesh::compress_positions) are not supported".into());
    }
    let slot = mesh_layout
        .attribute_ids()
        .iter()
        .position(|id| *id == position.id)
        .ok_or("it has no position attribute")?;
    let attribute = layout
        .attributes
        .get(slot)
        .ok_or("its layout lists fewer attributes than ids")?;
    let format = match attribute.format {
        BevyVertexFormat::Float32x3 => ksrt::VertexFormat::Float32x3,
        BevyVertexFormat::Float32x4 => ksrt::VertexFormat::Float32x4,
        BevyVertexFormat::Float16x4 => ksrt::VertexFormat::Float16x4,
        BevyVertexFormat::Snorm16x4 => ksrt::VertexFormat::Snorm16x4,
        other => return Err(format!("position format {other:?}")),
    };
    Ok((attribute.offset, format))
}
