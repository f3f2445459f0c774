//! A scene's meshes on the GPU and registered with the SDK: vertex and index buffers made once
//! and shared by every context that registers them, each cutout's coordinates and texture, the
//! SDK's geometry and instance tasks, and building a task container into a submission.

use std::collections::HashMap;

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
    /// What makes the mesh a cutout (glTF `alphaMode: MASK`) for the SDK: `None` for an opaque
    /// mesh, and for every mesh [`upload`] makes alone.
    pub cutout: Option<UploadedCutout>,
}

/// A cutout mesh's opacity on the GPU, as the SDK bakes it into micro-maps.
pub struct UploadedCutout {
    /// Where the opacity comes from.
    pub source: CutoutSource,
    /// The micro-map level, from [`micromap_level`].
    pub micromap_level: u32,
}

/// Where a cutout's opacity comes from.
pub enum CutoutSource {
    /// The MASK test of the base colour texture's alpha.
    Texture {
        /// The coordinates, `Float32x2` a vertex (non-finite ones written as 0, as the SDK reads
        /// them); `VERTEX` too, so the rasteriser draws from the same buffer.
        uvs: wgpu::Buffer,
        /// Index of the texture in [`Scene::textures`].
        texture_index: usize,
        /// The texture (`Rgba8Unorm`, viewable as sRGB), shared with the rasteriser.
        texture: wgpu::Texture,
        /// glTF `baseColorFactor.a`.
        factor: f32,
        /// glTF `alphaCutoff`.
        cutoff: f32,
    },
    /// A MASK material without a texture whose factor is below its cutoff: nothing of the mesh
    /// is opaque. One zero flag a triangle (`u32`), so the mesh keeps its geometry, instances
    /// and handles like any other and only lets every ray through.
    Invisible {
        /// The flags, all 0.
        flags: wgpu::Buffer,
    },
}

impl UploadedCutout {
    /// The SDK's description of this opacity.
    pub fn opacity(&self) -> ksrt::ComponentOpacity {
        match &self.source {
            CutoutSource::Texture {
                uvs,
                texture,
                factor,
                cutoff,
                ..
            } => ksrt::ComponentOpacity {
                micromap_level: self.micromap_level,
                ..ksrt::ComponentOpacity::texture(
                    texture.create_view(&Default::default()),
                    ksrt::UvBufferInput {
                        buffer: uvs.clone(),
                        offset: 0,
                        stride: 8,
                        format: ksrt::UvFormat::Float32x2,
                    },
                    *factor,
                    *cutoff,
                )
            },
            CutoutSource::Invisible { flags } => {
                ksrt::ComponentOpacity::per_triangle(flags.clone(), 0)
            }
        }
    }
}

/// Uploads one mesh, opaque whatever its material (cutouts need the scene's textures:
/// [`upload_scene`]); the SDK copies out of these buffers, hence `COPY_SRC`, and a posed mesh's
/// positions are written over its rest pose every frame (`Renderer`), hence `COPY_DST`.
pub fn upload(device: &wgpu::Device, mesh: &Mesh) -> UploadedMesh {
    let usage = wgpu::BufferUsages::VERTEX
        | wgpu::BufferUsages::INDEX
        | wgpu::BufferUsages::COPY_SRC
        | wgpu::BufferUsages::COPY_DST;
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
        cutout: None,
    }
}

/// Uploads every mesh of a scene, with the coordinates and texture of each cutout (each texture
/// once however many meshes use it).
pub fn upload_scene(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    scene: &Scene,
) -> Vec<UploadedMesh> {
    let mut textures: HashMap<usize, wgpu::Texture> = HashMap::new();
    scene
        .meshes
        .iter()
        .map(|m| UploadedMesh {
            cutout: upload_cutout(device, queue, scene, m, &mut textures),
            ..upload(device, m)
        })
        .collect()
}

/// The cutout of mesh `m`, or `None` where it is opaque: not a MASK material, or one without a
/// texture whose factor reaches its cutoff (the factor alone decides then).
fn upload_cutout(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    scene: &Scene,
    m: &Mesh,
    textures: &mut HashMap<usize, wgpu::Texture>,
) -> Option<UploadedCutout> {
    let test = m.mask()?;
    let Some((texture_index, tex)) = m.material.base_color_texture.zip(scene.mask_texture(m))
    else {
        if test.opaque(1.0) {
            return None;
        }
        let flags = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(m.name.as_str()),
            contents: &vec![0u8; 4 * m.triangle_count().max(1)],
            usage: wgpu::BufferUsages::COPY_SRC,
        });
        return Some(UploadedCutout {
            source: CutoutSource::Invisible { flags },
            micromap_level: 0,
        });
    };
    let texture = textures
        .entry(texture_index)
        .or_insert_with(|| upload_texture(device, queue, &tex.image, &tex.name))
        .clone();
    Some(UploadedCutout {
        micromap_level: micromap_level(m, tex.image.dimensions()),
        source: CutoutSource::Texture {
            uvs: uv_buffer(device, m),
            texture_index,
            texture,
            factor: test.factor,
            cutoff: test.cutoff,
        },
    })
}

/// The coordinates of `m` as one `Float32x2` a vertex: the file's (non-finite ones as 0, what
/// the SDK reads for them), or zeros where it has none (every texture then reads its texel at
/// (0, 0)). `VERTEX` for the rasteriser, `COPY_SRC` for the SDK.
pub fn uv_buffer(device: &wgpu::Device, m: &Mesh) -> wgpu::Buffer {
    let uvs: Vec<[f32; 2]> = if m.uvs.len() == m.positions.len() {
        m.uvs
            .iter()
            .map(|c| {
                if c[0].is_finite() && c[1].is_finite() {
                    *c
                } else {
                    [0.0; 2]
                }
            })
            .collect()
    } else {
        vec![[0.0; 2]; m.positions.len()]
    };
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(m.name.as_str()),
        // A vertex buffer of no bytes cannot be bound: one pair stands in.
        contents: bytemuck::cast_slice(if uvs.is_empty() {
            &[[0.0f32; 2]]
        } else {
            &uvs[..]
        }),
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_SRC,
    })
}

/// Uploads one RGBA8 texture as `Rgba8Unorm`, viewable as sRGB (colours) or linear
/// (metallic-roughness, and the alpha the SDK bakes cutouts from: alpha is linear in both).
pub fn upload_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    img: &image::RgbaImage,
    name: &str,
) -> wgpu::Texture {
    let size = wgpu::Extent3d {
        width: img.width().max(1),
        height: img.height().max(1),
        depth_or_array_layers: 1,
    };
    let tex = device.create_texture(&wgpu::TextureDescriptor {
        label: Some(name),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8Unorm,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[wgpu::TextureFormat::Rgba8UnormSrgb],
    });
    queue.write_texture(
        tex.as_image_copy(),
        img.as_raw(),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(4 * img.width()),
            rows_per_image: None,
        },
        size,
    );
    tex
}

/// The micro-map level of a cutout mesh whose texture is `(width, height)` texels: the smallest
/// level at which a micro-triangle is no larger than a texel on the mesh's mean triangle, that
/// is 4^level ≥ texels a triangle = (the mesh's total area in texture space × width × height) /
/// triangles, at most the SDK's 6. The mean rather than the largest triangle: the maps then hold
/// at least one bit for each texel the mesh covers and at most four, so their memory follows the
/// texture's resolution, not the one triangle that spans most of it. A mesh tiling a texture
/// many times over a triangle hits the cap: split such triangles (the built-in fence has one
/// quad a tile).
pub fn micromap_level(mesh: &Mesh, (width, height): (u32, u32)) -> u32 {
    let triangles = mesh.triangle_count();
    if triangles == 0 {
        return 0;
    }
    let area: f64 = (0..triangles)
        .map(|t| {
            let [a, b, c] = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)].map(|(u, v)| mesh.uv_at(t, u, v));
            let cross = (f64::from(b[0]) - f64::from(a[0])) * (f64::from(c[1]) - f64::from(a[1]))
                - (f64::from(b[1]) - f64::from(a[1])) * (f64::from(c[0]) - f64::from(a[0]));
            0.5 * cross.abs()
        })
        .filter(|a| a.is_finite())
        .sum();
    let texels = area * f64::from(width) * f64::from(height) / triangles as f64;
    let max = ksrt::ComponentOpacity::MAX_MICROMAP_LEVEL;
    (0..max)
        .find(|&l| 4f64.powi(l as i32) >= texels)
        .unwrap_or(max)
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
            opacity: m.cutout.as_ref().map(UploadedCutout::opacity),
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
    schedule_scene_with(
        ctx,
        container,
        scene,
        uploads,
        |_| allow_update,
        build_hint,
        instances,
    )
}

/// [`schedule_scene`] with `allow_update` chosen per mesh (by index into [`Scene::meshes`]).
pub fn schedule_scene_with(
    ctx: &ksrt::ExecuteContext,
    container: &mut ksrt::TaskContainer,
    scene: &Scene,
    uploads: &[UploadedMesh],
    allow_update: impl Fn(usize) -> bool,
    build_hint: ksrt::BuildHint,
    instances: bool,
) -> SceneHandles {
    let geometries = ctx.create_geometry_handles(uploads.len());
    for (k, (m, &handle)) in uploads.iter().zip(&geometries).enumerate() {
        container.schedule_bvh_task(ksrt::GeometryTask {
            operation: ksrt::TaskOperation::Register,
            handle,
            input: ksrt::GeometryInput {
                build_hint,
                ..geometry_input(m, allow_update(k))
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

/// The meshes of `scene` that a rig poses (by index into [`Scene::meshes`]): the ones whose
/// vertices change every frame.
pub fn posed_meshes(scene: &Scene) -> Vec<bool> {
    let mut posed = vec![false; scene.meshes.len()];
    for rig in &scene.rigs {
        if let Some(p) = scene
            .instances
            .get(rig.instance)
            .and_then(|i| posed.get_mut(i.mesh))
        {
            *p = true;
        }
    }
    posed
}

/// Schedules the registration of every mesh and instance of `scene` as a renderer's scene
/// (`BuildHint::Auto`): a mesh a rig poses with `allow_update` (a fast-build BLAS the renderer
/// refits every frame), every other without (a fast-trace BLAS built once).
pub fn schedule_static_scene(
    ctx: &ksrt::ExecuteContext,
    container: &mut ksrt::TaskContainer,
    scene: &Scene,
    uploads: &[UploadedMesh],
) -> SceneHandles {
    let posed = posed_meshes(scene);
    schedule_scene_with(
        ctx,
        container,
        scene,
        uploads,
        |k| posed.get(k).copied().unwrap_or(false),
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

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// A unit quad whose coordinates span `tiles` × `tiles` texture repeats.
    fn quad(tiles: f32) -> Mesh {
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let mut m = Mesh::new("quad", p, vec![0, 1, 2, 0, 2, 3], Vec3::ONE)
            .unwrap_or_else(|e| panic!("{e}"));
        m.uvs = vec![[0.0, 0.0], [tiles, 0.0], [tiles, tiles], [0.0, tiles]];
        m
    }

    #[test]
    fn micromap_level_makes_micro_triangles_no_larger_than_a_texel() {
        // A leaf card over a 64² texture: 2048 texels a triangle, 4^6 = 4096 micro-triangles.
        assert_eq!(micromap_level(&quad(1.0), (64, 64)), 6);
        // A fence cell over a 32² tile: 512 texels a triangle, 4^5 = 1024.
        assert_eq!(micromap_level(&quad(1.0), (32, 32)), 5);
        // 8 texels a triangle: 4^2 = 16 ≥ 8 > 4^1.
        assert_eq!(micromap_level(&quad(1.0), (4, 4)), 2);
        // A texel across two triangles: level 0.
        assert_eq!(micromap_level(&quad(1.0), (1, 1)), 0);
        // Tiled 8 × 8 times: far finer than the cap; the cap it is.
        assert_eq!(micromap_level(&quad(8.0), (64, 64)), 6);
        // No coordinates: one texel everywhere, one bit a triangle.
        let mut bare = quad(1.0);
        bare.uvs.clear();
        assert_eq!(micromap_level(&bare, (64, 64)), 0);
    }
}
