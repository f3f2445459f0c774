//! A scene's meshes on the GPU and registered with the SDK: vertex and index buffers made once
//! and shared by every context that registers them, the SDK's geometry and instance tasks, and
//! building a task container into a submission.

use kickstart_rt as ksrt;
use wgpu::util::DeviceExt;

use crate::error::AnyResult;
use crate::scene::{Mesh, Scene};

/// A mesh's vertex and index buffers, made once and reused by every context that registers it.
pub struct UploadedMesh {
    /// Positions, `Float32x3`.
    pub vertices: wgpu::Buffer,
    /// `u32` triangle-list indices.
    pub indices: wgpu::Buffer,
    /// Vertex count.
    pub vertex_count: u32,
    /// Index count.
    pub index_count: u32,
    /// The mesh's name.
    pub name: String,
}

/// Uploads one mesh; the SDK copies out of these buffers, hence `COPY_SRC`.
pub fn upload(device: &wgpu::Device, mesh: &Mesh) -> UploadedMesh {
    let usage =
        wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::INDEX | wgpu::BufferUsages::COPY_SRC;
    UploadedMesh {
        vertices: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(mesh.name.as_str()),
            contents: bytemuck::cast_slice(&mesh.positions),
            usage,
        }),
        indices: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(mesh.name.as_str()),
            contents: bytemuck::cast_slice(&mesh.indices),
            usage,
        }),
        vertex_count: mesh.positions.len() as u32,
        index_count: mesh.indices.len() as u32,
        name: mesh.name.clone(),
    }
}

/// Uploads every mesh of a scene.
pub fn upload_scene(device: &wgpu::Device, scene: &Scene) -> Vec<UploadedMesh> {
    scene.meshes.iter().map(|m| upload(device, m)).collect()
}

/// The SDK's description of an uploaded mesh.
pub fn geometry_input(m: &UploadedMesh, allow_update: bool) -> ksrt::GeometryInput {
    ksrt::GeometryInput {
        name: m.name.clone(),
        components: vec![ksrt::GeometryComponent {
            vertex_buffer: ksrt::VertexBufferInput {
                buffer: m.vertices.clone(),
                offset: 0,
                stride: 12,
                count: m.vertex_count,
                format: ksrt::VertexFormat::Float32x3,
            },
            index_buffer: Some(ksrt::IndexBufferInput {
                buffer: m.indices.clone(),
                offset: 0,
                count: m.index_count,
                format: ksrt::IndexFormat::Uint32,
            }),
            transform: None,
            index_range: None,
            opacity: None,
        }],
        allow_update,
        ..Default::default()
    }
}

/// The SDK handles of a registered scene: one geometry per mesh, one instance per instance, in
/// the scene's order.
pub struct SceneHandles {
    /// Per [`Scene::meshes`].
    pub geometries: Vec<ksrt::GeometryHandle>,
    /// Per [`Scene::instances`].
    pub instances: Vec<ksrt::InstanceHandle>,
}

impl SceneHandles {
    /// Scene instance index of each instance slot index (what a ray hit reports), for mapping
    /// hits back to meshes.
    pub fn instance_of_slot(&self) -> std::collections::HashMap<u32, usize> {
        self.instances
            .iter()
            .enumerate()
            .map(|(k, h)| (h.index(), k))
            .collect()
    }
}

/// Schedules the registration of every mesh (and, when `instances`, every instance) of `scene`,
/// each geometry with `allow_update` and `build_hint`.
pub fn schedule_scene(
    ctx: &ksrt::ExecuteContext,
    container: &mut ksrt::TaskContainer,
    scene: &Scene,
    uploads: &[UploadedMesh],
    allow_update: bool,
    build_hint: ksrt::BuildHint,
    instances: bool,
) -> SceneHandles {
    let geometries = ctx.create_geometry_handles(uploads.len());
    for (m, &handle) in uploads.iter().zip(&geometries) {
        container.schedule_bvh_task(ksrt::GeometryTask {
            operation: ksrt::TaskOperation::Register,
            handle,
            input: ksrt::GeometryInput {
                build_hint,
                ..geometry_input(m, allow_update)
            },
        });
    }
    let mut handles = Vec::new();
    if instances {
        handles = ctx.create_instance_handles(scene.instances.len());
        for (inst, &handle) in scene.instances.iter().zip(&handles) {
            container.schedule_bvh_task(ksrt::InstanceTask {
                operation: ksrt::TaskOperation::Register,
                handle,
                input: ksrt::InstanceInput::new(geometries[inst.mesh], inst.transform),
            });
        }
    }
    SceneHandles {
        geometries,
        instances: handles,
    }
}

/// Schedules the registration of every mesh and instance of `scene` as a renderer's static scene
/// (no `allow_update`, `BuildHint::Auto`: fast-trace BLASes).
pub fn schedule_static_scene(
    ctx: &ksrt::ExecuteContext,
    container: &mut ksrt::TaskContainer,
    scene: &Scene,
    uploads: &[UploadedMesh],
) -> SceneHandles {
    schedule_scene(
        ctx,
        container,
        scene,
        uploads,
        false,
        ksrt::BuildHint::Auto,
        true,
    )
}

/// Builds `container` into a new encoder, lets `after` record more (read-back copies), submits.
pub fn submit(
    ctx: &ksrt::ExecuteContext,
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    container: ksrt::TaskContainer,
    after: impl FnOnce(&mut wgpu::CommandEncoder),
) -> AnyResult<ksrt::GpuTaskHandle> {
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("ksrt"),
    });
    let task = ctx.build_gpu_task(container, &mut encoder)?;
    after(&mut encoder);
    queue.submit([encoder.finish()]);
    Ok(task)
}
