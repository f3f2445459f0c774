//! Keeps the SDK's geometry and instances in step with Bevy's `Mesh3d` entities.
//!
//! Extraction copies what changed in the main world (meshes, materials' opacity and transforms
//! of visible entities, and entities that lost their mesh or visibility), and every skinned or
//! morphed entity's pose; [`sync_scene`] turns that into one SDK task a frame — register a
//! geometry the first time a mesh is used with an opacity (a masked material's texture and
//! cutoff make their own geometry), register, move or remove instances, pose and refit the
//! deformed meshes ([`crate::skin`]), rebuild what changed — once Bevy holds the mesh's data
//! and texture.

use std::collections::{HashMap, HashSet};

use bevy::asset::AssetId;
use bevy::ecs::system::SystemParam;
use bevy::light::GlobalAmbientLight;
use bevy::math::Affine3A;
use bevy::mesh::morph::MeshMorphWeights;
use bevy::mesh::skinning::SkinnedMesh;
use bevy::mesh::{Mesh, MeshVertexAttribute, PrimitiveTopology, VertexFormat as BevyVertexFormat};
use bevy::prelude::*;
use bevy::render::Extract;
use bevy::render::mesh::allocator::MeshAllocator;
use bevy::render::mesh::{RenderMesh, RenderMeshBufferInfo};
use bevy::render::render_asset::{ExtractedAssets, RenderAssets};
use bevy::render::renderer::RenderDevice;
use bevy::render::texture::GpuImage;
use kickstart_rt as ksrt;

use crate::RayTracedLighting;
use crate::cutout::{self, Cutout, Opacity};
use crate::sdk::SdkContext;
use crate::skin::{DeformedMeshes, Pose};

/// A visible mesh entity added or changed, as extracted.
struct ChangedEntity {
    entity: Entity,
    mesh: AssetId<Mesh>,
    /// Object to world.
    transform: Affine3A,
    /// What its material lets through.
    opacity: Opacity,
}

/// The `StandardMaterial`s added or modified in the main world's last update (a main-world
/// resource): entities using them are extracted again, since their opacity may have changed.
#[derive(Resource, Default)]
pub(crate) struct ChangedMaterials(HashSet<AssetId<StandardMaterial>>);

/// Main world, once an update: collects the materials whose asset events came since the last.
pub(crate) fn collect_changed_materials(
    mut events: MessageReader<AssetEvent<StandardMaterial>>,
    mut changed: ResMut<ChangedMaterials>,
) {
    changed.0.clear();
    for event in events.read() {
        match event {
            AssetEvent::Added { id }
            | AssetEvent::Modified { id }
            | AssetEvent::LoadedWithDependencies { id } => {
                changed.0.insert(*id);
            }
            AssetEvent::Removed { .. } | AssetEvent::Unused { .. } => {}
        }
    }
}

/// What changed in the main world since the last [`sync_scene`].
#[derive(Resource, Default)]
pub(crate) struct ExtractedScene {
    /// Visible mesh entities added or changed.
    changed: Vec<ChangedEntity>,
    /// Entities to remove from the SDK's scene: despawned, hidden or without a mesh now.
    removed: Vec<Entity>,
    /// The first directional light: direction light travels, and exposed radiance scale.
    pub sun: Option<Sun>,
    /// This frame's pose of every visible skinned or morphed mesh entity.
    pub poses: Vec<Pose>,
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
    Option<&'a MeshMaterial3d<StandardMaterial>>,
    Has<SkinnedMesh>,
    Has<MeshMorphWeights>,
);

/// A mesh entity whose mesh, material, transform or visibility changed (or that was just
/// spawned).
type MeshEntityChanged = Or<(
    Changed<Mesh3d>,
    Changed<MeshMaterial3d<StandardMaterial>>,
    Changed<GlobalTransform>,
    Changed<InheritedVisibility>,
)>;

/// Components whose removal [`extract_mesh_instances`] follows.
#[derive(SystemParam)]
pub(crate) struct Removed<'w, 's> {
    meshes: Extract<'w, 's, RemovedComponents<'static, 'static, Mesh3d>>,
    skins: Extract<'w, 's, RemovedComponents<'static, 'static, SkinnedMesh>>,
    morphs: Extract<'w, 's, RemovedComponents<'static, 'static, MeshMorphWeights>>,
}

/// Extracts mesh entities that were added, moved, re-meshed, re-materialed, shown or hidden,
/// those whose material asset changed or that stopped being skinned or morphed, and those that
/// were despawned or lost their mesh. Skinned and morphed entities are left to
/// [`crate::skin::extract_poses`].
pub(crate) fn extract_mesh_instances(
    mut scene: ResMut<ExtractedScene>,
    changed: Extract<Query<MeshEntity, MeshEntityChanged>>,
    all: Extract<Query<MeshEntity>>,
    changed_materials: Extract<Option<Res<ChangedMaterials>>>,
    materials: Extract<Option<Res<Assets<StandardMaterial>>>>,
    mut removed: Removed,
    mut warned: Local<HashSet<AssetId<StandardMaterial>>>,
) {
    let opacity = |material: Option<&MeshMaterial3d<StandardMaterial>>,
                   warned: &mut HashSet<AssetId<StandardMaterial>>| {
        let material = material.map(|m| m.id());
        match (material, materials.as_ref()) {
            (Some(id), Some(assets)) => assets
                .get(id)
                .map_or(Opacity::Opaque, |m| cutout::material_opacity(id, m, warned)),
            // Another material type, or none: traced opaque.
            _ => Opacity::Opaque,
        }
    };
    let material_changed = |m: Option<&MeshMaterial3d<StandardMaterial>>| {
        let changed = changed_materials.as_ref().map(|c| &c.0);
        m.zip(changed).is_some_and(|(m, c)| c.contains(&m.id()))
    };
    // Only in an update that changed a material: it scans every mesh entity.
    let any_material_changed = changed_materials.as_ref().is_some_and(|c| !c.0.is_empty());
    let modified = any_material_changed
        .then(|| all.iter().filter(|e| material_changed(e.4)))
        .into_iter()
        .flatten();
    // An entity that is no longer deformed is traced as a static mesh again.
    let undeformed: Vec<Entity> = removed.skins.read().chain(removed.morphs.read()).collect();
    let undeformed = undeformed.into_iter().filter_map(|e| all.get(e).ok());
    for (entity, mesh, transform, visibility, material, skinned, morphed) in
        changed.iter().chain(modified).chain(undeformed)
    {
        if skinned || morphed {
            // Posed every frame by `skin::extract_poses`.
            continue;
        }
        if visibility.get() {
            let opacity = opacity(material, &mut warned);
            scene.changed.push(ChangedEntity {
                entity,
                mesh: mesh.id(),
                transform: transform.affine(),
                opacity,
            });
        } else {
            scene.removed.push(entity);
        }
    }
    scene.removed.extend(removed.meshes.read());
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

/// What one SDK geometry is made of: a Bevy mesh, and the masked material's test when its
/// triangles are cutouts (each texture, channel, factor and cutoff bakes its own micro-maps).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
struct GeometryKey {
    mesh: AssetId<Mesh>,
    cutout: Option<Cutout>,
}

/// One registered geometry.
struct Geometry {
    handle: ksrt::GeometryHandle,
    /// Instances of it: a cutout's geometry goes with its last instance (a material edited
    /// over and over would otherwise leave one behind each time); an opaque mesh's stays for
    /// reuse until the mesh goes.
    users: u32,
}

/// One registered instance: a mesh entity.
struct Instance {
    handle: ksrt::InstanceHandle,
    key: GeometryKey,
    /// Its last transform (kept to re-register it when its geometry is replaced).
    transform: Affine3A,
}

/// The SDK's view of the scene: which mesh and entity has which handle.
#[derive(Resource, Default)]
pub(crate) struct SceneSync {
    geometries: HashMap<GeometryKey, Geometry>,
    instances: HashMap<Entity, Instance>,
    /// Entities whose mesh or texture is not uploaded yet (or was replaced), retried each
    /// frame.
    waiting: HashMap<Entity, (GeometryKey, Affine3A)>,
    /// Meshes the SDK cannot trace, each logged once.
    unsupported: HashSet<AssetId<Mesh>>,
    /// The skinned and morphed entities, posed every frame.
    deformed: DeformedMeshes,
}

/// Bevy's render-world meshes and textures, and what changed in them this frame.
#[derive(SystemParam)]
pub(crate) struct RenderData<'w> {
    pub meshes: Res<'w, RenderAssets<RenderMesh>>,
    extracted_meshes: Res<'w, ExtractedAssets<RenderMesh>>,
    pub allocator: Res<'w, MeshAllocator>,
    pub images: Res<'w, RenderAssets<GpuImage>>,
    extracted_images: Res<'w, ExtractedAssets<GpuImage>>,
    pub device: Res<'w, RenderDevice>,
}

/// Records this frame's scene changes and poses as one SDK task (submitted at once: Bevy's mesh
/// uploads, queued earlier in the frame, run before it): the skinning passes, then the new
/// geometries' builds and the deformed ones' refits, then the TLAS.
pub(crate) fn sync_scene(
    sdk: Res<SdkContext>,
    mut sync: ResMut<SceneSync>,
    mut extracted: ResMut<ExtractedScene>,
    data: RenderData,
) {
    let ctx = &sdk.ctx;
    let mut container = ctx.create_task_container();
    let sync = &mut *sync;
    let meshes: HashSet<_> = (data.extracted_meshes.removed.iter())
        .chain(&data.extracted_meshes.modified)
        .collect();
    for id in &meshes {
        sync.unsupported.remove(id);
    }
    // A replaced texture is baked again: the SDK copied the old one's opacity.
    let images: HashSet<_> = (data.extracted_images.removed.iter())
        .chain(&data.extracted_images.modified)
        .collect();
    sync.drop_geometries(ctx, |key| {
        meshes.contains(&key.mesh) || key.cutout.is_some_and(|c| images.contains(&c.image))
    });
    for entity in extracted.removed.drain(..) {
        sync.waiting.remove(&entity);
        sync.remove_instance(ctx, entity);
        sync.deformed.remove(ctx, entity);
    }
    for pose in &extracted.poses {
        // Newly skinned or morphed: its static instance goes.
        sync.waiting.remove(&pose.entity);
        sync.remove_instance(ctx, pose.entity);
    }
    for changed in extracted.changed.drain(..) {
        sync.change(ctx, &mut container, &changed);
    }
    let built = sync.register_waiting(ctx, &mut container, &data);
    let poses = std::mem::take(&mut extracted.poses);
    let posed = (sync.deformed).pose(ctx, &mut container, &poses, &meshes, &data);

    if container.is_empty() {
        return;
    }
    debug!(
        "kickstart-rt: scene update: {built} new geometries, {posed} posed, {} instances, {} \
         waiting",
        sync.instances.len(),
        sync.waiting.len()
    );
    container.schedule_bvh_task(ksrt::BvhBuildTask {
        // Every deformed mesh is refit this frame: its pose would lag otherwise.
        max_blas_build_count: (built + posed).max(1),
        ..Default::default()
    });
    if let Err(e) = ctx.invoke_gpu_task(container) {
        error!("kickstart-rt: updating the ray-traced scene failed: {e}");
    }
}

impl SceneSync {
    /// Drops the geometries `dropped` selects (their mesh or texture changed or went): their
    /// instances wait for the new data (or for their entity to go too).
    fn drop_geometries(
        &mut self,
        ctx: &ksrt::ExecuteContext,
        dropped: impl Fn(&GeometryKey) -> bool,
    ) {
        let keys: Vec<GeometryKey> = self
            .geometries
            .keys()
            .filter(|k| dropped(k))
            .copied()
            .collect();
        for key in keys {
            let users: Vec<Entity> = self
                .instances
                .iter()
                .filter(|(_, i)| i.key == key)
                .map(|(e, _)| *e)
                .collect();
            for entity in users {
                if let Some(instance) = self.instances.remove(&entity) {
                    destroy_instance(ctx, instance.handle);
                    self.waiting.insert(entity, (key, instance.transform));
                }
            }
            if let Some(geometry) = self.geometries.remove(&key) {
                destroy_geometry(ctx, geometry.handle);
            }
        }
    }

    /// Removes `entity`'s instance from the SDK's scene, if it has one (and a cutout geometry
    /// left without instances).
    fn remove_instance(&mut self, ctx: &ksrt::ExecuteContext, entity: Entity) {
        let Some(instance) = self.instances.remove(&entity) else {
            return;
        };
        destroy_instance(ctx, instance.handle);
        let key = instance.key;
        let Some(geometry) = self.geometries.get_mut(&key) else {
            return;
        };
        geometry.users = geometry.users.saturating_sub(1);
        if geometry.users == 0
            && key.cutout.is_some()
            && let Some(geometry) = self.geometries.remove(&key)
        {
            destroy_geometry(ctx, geometry.handle);
        }
    }

    /// A mesh entity added, moved, re-meshed or re-materialed: an instance of the same geometry
    /// moves at once; otherwise the entity waits for its geometry ([`Self::register_waiting`]).
    /// A fully transparent one is left out.
    fn change(
        &mut self,
        ctx: &ksrt::ExecuteContext,
        container: &mut ksrt::TaskContainer,
        changed: &ChangedEntity,
    ) {
        let (entity, transform) = (changed.entity, changed.transform);
        let cutout = match changed.opacity {
            Opacity::Opaque => None,
            Opacity::Cutout(c) => Some(c),
            Opacity::Invisible => {
                // No ray hits a surface masked out everywhere: nothing to trace.
                debug!("kickstart-rt: entity {entity}'s material masks it out entirely");
                self.waiting.remove(&entity);
                self.remove_instance(ctx, entity);
                return;
            }
        };
        let key = GeometryKey {
            mesh: changed.mesh,
            cutout,
        };
        match self.instances.get_mut(&entity) {
            Some(instance) if instance.key == key => {
                let Some(geometry) = self.geometries.get(&key).map(|g| g.handle) else {
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
                self.waiting.insert(entity, (key, transform));
            }
            None => {
                self.waiting.insert(entity, (key, transform));
            }
        }
    }

    /// Registers an instance for every waiting entity whose mesh (and texture) Bevy has
    /// uploaded, and its geometry the first time it is used; returns the number of new
    /// geometries.
    fn register_waiting(
        &mut self,
        ctx: &ksrt::ExecuteContext,
        container: &mut ksrt::TaskContainer,
        data: &RenderData,
    ) -> u32 {
        let mut built = 0;
        let waiting: Vec<_> = self.waiting.iter().map(|(e, m)| (*e, *m)).collect();
        for (entity, (key, transform)) in waiting {
            let geometry = match self.geometries.get_mut(&key) {
                Some(g) => g,
                None => match register_geometry(ctx, container, &key, data) {
                    Ok(Some(handle)) => {
                        built += 1;
                        self.geometries
                            .entry(key)
                            .or_insert(Geometry { handle, users: 0 })
                    }
                    // Not uploaded yet: try again next frame.
                    Ok(None) => continue,
                    Err(why) => {
                        if self.unsupported.insert(key.mesh) {
                            warn!("kickstart-rt: mesh {:?} is not ray traced: {why}", key.mesh);
                        }
                        self.waiting.remove(&entity);
                        continue;
                    }
                },
            };
            geometry.users += 1;
            let handle = ctx.create_instance_handle();
            container.schedule_bvh_task(ksrt::InstanceTask {
                operation: ksrt::TaskOperation::Register,
                handle,
                input: instance_input(geometry.handle, transform, entity),
            });
            self.instances.insert(
                entity,
                Instance {
                    handle,
                    key,
                    transform,
                },
            );
            self.waiting.remove(&entity);
        }
        built
    }
}

fn destroy_geometry(ctx: &ksrt::ExecuteContext, handle: ksrt::GeometryHandle) {
    if let Err(e) = ctx.destroy_geometry_handle(handle) {
        warn!("kickstart-rt: dropping a mesh's geometry: {e}");
    }
}

fn destroy_instance(ctx: &ksrt::ExecuteContext, handle: ksrt::InstanceHandle) {
    if let Err(e) = ctx.destroy_instance_handle(handle) {
        warn!("kickstart-rt: removing an instance: {e}");
    }
}

/// The SDK instance of `entity`: `geometry` placed by `transform`.
pub(crate) fn instance_input(
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

/// Schedules the registration of `key`'s geometry and returns its new handle; `Ok(None)` while
/// Bevy has not uploaded the mesh or its texture yet, `Err` for a mesh the SDK cannot trace. A
/// cutout the SDK cannot take is registered opaque, with a warning.
fn register_geometry(
    ctx: &ksrt::ExecuteContext,
    container: &mut ksrt::TaskContainer,
    key: &GeometryKey,
    data: &RenderData,
) -> Result<Option<ksrt::GeometryHandle>, String> {
    let mesh = key.mesh;
    let Some(render_mesh) = data.meshes.get(mesh) else {
        return Ok(None);
    };
    let Some(vertices) = data.allocator.mesh_vertex_slice(&mesh) else {
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
    let first_vertex = vertices.range.start as u64 * stride;
    let opacity = match &key.cutout {
        None => None,
        Some(c) => {
            let buffer = &vertices.buffer;
            match cutout::component_opacity(c, render_mesh, buffer, first_vertex, &data.images) {
                Ok(None) => return Ok(None),
                Ok(Some(opacity)) => Some(opacity),
                Err(why) => {
                    warn!("kickstart-rt: mesh {mesh:?} is masked but traced opaque: {why}");
                    None
                }
            }
        }
    };
    let vertex_buffer = ksrt::VertexBufferInput {
        buffer: (**vertices.buffer).clone(),
        offset: first_vertex + offset,
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
            let Some(indices) = data.allocator.mesh_index_slice(&mesh) else {
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
                opacity,
            }],
            ..Default::default()
        },
    });
    Ok(Some(handle))
}

/// Byte offset and SDK format of the position attribute in a Bevy vertex layout.
pub(crate) fn position_attribute(
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
    let (offset, format) = cutout::attribute(mesh_layout, layout, position)?;
    let format = match format {
        BevyVertexFormat::Float32x3 => ksrt::VertexFormat::Float32x3,
        BevyVertexFormat::Float32x4 => ksrt::VertexFormat::Float32x4,
        BevyVertexFormat::Float16x4 => ksrt::VertexFormat::Float16x4,
        BevyVertexFormat::Snorm16x4 => ksrt::VertexFormat::Snorm16x4,
        other => return Err(format!("position format {other:?}")),
    };
    Ok((offset, format))
}
