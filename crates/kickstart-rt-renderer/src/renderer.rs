//! One frame end to end: rasterise the main view (and the lidar view), let the SDK inject, trace
//! and denoise ([`crate::frame`]), composite. `ksrt render` and `ksrt view` both drive this.
//!
//! An animated scene (one with [`Scene::rigs`]) is posed on the CPU at the time
//! [`Renderer::set_time`] asks for, each time it changes: see [`Animator`] for why the CPU.
//!
//! Nothing here waits for the GPU or reads a clock: [`Renderer::record_frame`] records into the
//! caller's encoder and returns the SDK's tasks, which the caller marks complete once its
//! submission is done (natively by polling the device, on the web when the queue reports it).

use glam::Vec3;
use kickstart_rt as ksrt;

use crate::composite::{Composite, Show};
use crate::error::AnyResult;
use crate::frame::{Effects, FrameInputs, SdkFrame};
use crate::raster::{halton_jitter, FrameView, GpuScene, ViewTargets};
use crate::scene::{Camera, Mesh, Scene};
use crate::upload::{self, SceneHandles, UploadedMesh};

/// How to render.
#[derive(Debug, Clone)]
pub struct RendererOptions {
    /// Main view size, pixels.
    pub size: (u32, u32),
    /// Effects on.
    pub effects: Effects,
    /// Seed of the SDK's noise (added to the frame index).
    pub seed: u32,
    /// Side of the square lidar view, pixels.
    pub lidar_size: u32,
    /// Measure the SDK's passes with GPU timestamps.
    pub gpu_timing: bool,
    /// Format of the display image (`Rgba8UnormSrgb` for files, the surface's in the viewer).
    pub ldr_format: wgpu::TextureFormat,
    /// Frames the caller keeps in flight (1..=3): the SDK context is made to allow two GPU
    /// tasks (the frame's and the debug view's) per frame in flight.
    pub frames_in_flight: u32,
    /// Create every SDK pipeline up front (`prepare_pipelines`), so that no frame stalls on a
    /// compile (the viewer). Off, each is created when a task first needs it: a batch render
    /// then compiles only what its effects use (most of its start-up on software Vulkan).
    pub prepare_pipelines: bool,
    /// Rays per pixel of each effect and the denoising method.
    pub preset: ksrt::Preset,
    /// The SDK's traversal backend choice.
    pub backend: ksrt::BackendChoice,
    /// A clock in milliseconds (any origin) timing the SDK's `build_gpu_task` calls into
    /// [`Renderer::last_sdk_build_ms`]; `None`: not timed (0).
    pub clock: Option<fn() -> f64>,
}

impl RendererOptions {
    /// Defaults for `size`: every effect, seed 0, a 128² lidar view, no timing, sRGB RGBA8,
    /// pipelines created up front, the quality preset (every pixel traced), the automatic
    /// backend, no clock.
    pub fn new(size: (u32, u32)) -> Self {
        RendererOptions {
            size,
            effects: Effects::default(),
            seed: 0,
            lidar_size: 128,
            gpu_timing: false,
            ldr_format: wgpu::TextureFormat::Rgba8UnormSrgb,
            frames_in_flight: 1,
            prepare_pipelines: true,
            preset: ksrt::Preset::Quality,
            backend: ksrt::BackendChoice::Auto,
            clock: None,
        }
    }
}

/// The renderer of one scene.
pub struct Renderer {
    /// The scene on the GPU and the rasteriser.
    pub raster: GpuScene,
    /// The main view's G-buffer and direct light.
    pub main: ViewTargets,
    lidar: ViewTargets,
    /// The SDK side.
    pub sdk: SdkFrame,
    composite: Composite,
    /// The composite, HDR linear (`Rgba16Float`).
    pub hdr: wgpu::Texture,
    /// The composite, tone mapped (`RendererOptions::ldr_format`).
    pub ldr: wgpu::Texture,
    /// Frames rendered so far.
    pub frame: u32,
    prev_view: Option<FrameView>,
    lidar_on: bool,
    /// What the composite shows.
    pub show: Show,
    /// CPU time of the SDK's `build_gpu_task` calls in the last [`Self::record_frame`], ms.
    pub last_sdk_build_ms: f64,
    clock: Option<fn() -> f64>,
    uploads: Vec<UploadedMesh>,
    animator: Option<Animator>,
}

/// What [`Renderer::register`] registered: the scene's buffers and its SDK handles.
pub struct Registration {
    /// Per [`Scene::meshes`]: its vertex and index buffers.
    pub uploads: Vec<UploadedMesh>,
    /// The SDK's geometry and instance handles.
    pub handles: SceneHandles,
}

/// Poses an animated scene's deformable meshes: at each new time, every rig's mesh is skinned
/// and morphed on the CPU ([`Scene::posed_meshes`]), its positions written over its vertex
/// buffer (which the rasteriser draws and the SDK copies from) and its normals over the
/// rasteriser's, and its geometry (registered with `allow_update`) updated and refitted by the
/// SDK in a BVH task of its own, which also refits the TLAS.
///
/// Why the CPU and not the SDK's `SkinningTask`: the rasteriser needs the posed normals too,
/// which the task does not produce; the CPU reference must trace the very same triangles, which
/// [`Scene::posed`] gives it from the same function; and the meshes `ksrt` plays are small
/// (the built-in dancers' are 3,068 vertices each), so a pose costs well under a millisecond a
/// mesh. The cost grows with the posed vertices: a large skinned file pays its skinning, its
/// normals and the upload of both on the CPU each frame it moves.
struct Animator {
    /// The model posed: the scene's hierarchy, rigs and animations, and the data of the meshes
    /// the rigs pose (the others' are left empty, and the textures out).
    scene: Scene,
    /// Per [`Scene::meshes`]: its SDK geometry.
    geometries: Vec<ksrt::GeometryHandle>,
    /// Scene time of the pose on the GPU; `None` before the first (the rest pose).
    posed_at: Option<f32>,
    /// Scene time asked for.
    time: f32,
}

impl Animator {
    /// An animator of `scene`, or `None` when nothing in it deforms.
    fn new(scene: &Scene, geometries: &[ksrt::GeometryHandle]) -> Option<Animator> {
        if scene.rigs.is_empty() {
            return None;
        }
        // Only the posed meshes' data is kept: a large still scene around a small rig would
        // otherwise be held twice.
        let posed = upload::posed_meshes(scene);
        let meshes = scene
            .meshes
            .iter()
            .zip(&posed)
            .map(|(m, &p)| {
                if p {
                    return m.clone();
                }
                Mesh {
                    name: m.name.clone(),
                    positions: Vec::new(),
                    normals: Vec::new(),
                    indices: Vec::new(),
                    color: m.color,
                    uvs: Vec::new(),
                    material: Default::default(),
                    deform: Default::default(),
                }
            })
            .collect();
        Some(Animator {
            scene: Scene {
                meshes,
                instances: scene.instances.clone(),
                nodes: scene.nodes.clone(),
                skins: scene.skins.clone(),
                rigs: scene.rigs.clone(),
                animations: scene.animations.clone(),
                ..Default::default()
            },
            geometries: geometries.to_vec(),
            posed_at: None,
            time: 0.0,
        })
    }

    /// Poses the meshes at the time asked for when it differs from the pose on the GPU: writes
    /// their vertices and normals for the next submission and records the SDK's update and
    /// refit of their BVHs into `encoder`. Returns the SDK's task, if one was built.
    fn pose(
        &mut self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        ctx: &ksrt::ExecuteContext,
        raster: &GpuScene,
        uploads: &[UploadedMesh],
    ) -> AnyResult<Option<ksrt::GpuTaskHandle>> {
        if self.posed_at == Some(self.time) {
            return Ok(None);
        }
        let mut container = ctx.create_task_container();
        let posed = self.scene.posed_meshes(self.time);
        for p in &posed {
            let (Some(uploaded), Some(&handle)) =
                (uploads.get(p.mesh), self.geometries.get(p.mesh))
            else {
                continue;
            };
            // Queue writes run before the next submission's commands: this frame's, since the
            // caller submits each frame's encoder before recording the next.
            queue.write_buffer(&uploaded.vertices, 0, bytemuck::cast_slice(&p.positions));
            raster.write_normals(queue, p.mesh, &p.normals);
            container.schedule_bvh_task(ksrt::GeometryTask {
                operation: ksrt::TaskOperation::Update,
                handle,
                input: upload::geometry_input(uploaded, true),
            });
        }
        container.schedule_bvh_task(crate::sdk_glue::bvh_build_task(
            posed.len().max(1) as u32,
            Some(crate::sdk_glue::Tlas::Auto),
        ));
        let task = ctx.build_gpu_task(container, encoder)?;
        self.posed_at = Some(self.time);
        Ok(Some(task))
    }
}

/// The lidar camera of frame `frame`: at the main camera's eye, looking along the `frame`-th of
/// 64 directions spread evenly over the sphere (a Fibonacci lattice), 90° field of view, so 64
/// frames see every direction around the viewer.
pub fn lidar_camera(eye: Vec3, frame: u32) -> Camera {
    let n = 64;
    let k = frame % n;
    let z = 1.0 - (2.0 * k as f32 + 1.0) / n as f32;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = k as f32 * 2.399_963;
    let dir = Vec3::new(r * phi.cos(), z, r * phi.sin());
    Camera {
        eye,
        at: eye + dir,
        up: Vec3::Y,
        fov_y_deg: 90.0,
    }
}

impl Renderer {
    /// Uploads `scene`, registers it with a new SDK context, submits its BVH builds and makes the
    /// targets ([`Self::register`] then [`Self::from_registered`], without waiting between).
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        opts: &RendererOptions,
    ) -> AnyResult<Renderer> {
        let (ctx, registered) = Self::register(device, queue, scene, opts)?;
        Ok(Self::from_registered(
            device, queue, scene, opts, ctx, registered,
        ))
    }

    /// Uploads `scene`, registers it with a new SDK context and submits the build of its BVHs
    /// (`invoke_gpu_task`: completed by the SDK once the device reports the submission done).
    /// The meshes a rig poses are registered with `allow_update`.
    pub fn register(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        opts: &RendererOptions,
    ) -> AnyResult<(ksrt::ExecuteContext, Registration)> {
        let defaults = ksrt::InitSettings {
            backend: opts.backend,
            ..Default::default()
        };
        let settings = ksrt::InitSettings {
            gpu_timing: opts.gpu_timing,
            // The frame's task and the debug view's, and an animated scene's pose.
            supported_working_sets: defaults
                .supported_working_sets
                .max(3 * opts.frames_in_flight),
            ..defaults
        };
        let ctx = ksrt::ExecuteContext::new(device, queue, settings)?;
        let uploads = upload::upload_scene(device, queue, scene);
        let mut c = ctx.create_task_container();
        let handles = upload::schedule_static_scene(&ctx, &mut c, scene, &uploads);
        c.schedule_bvh_task(crate::sdk_glue::bvh_build_task(
            uploads.len().max(1) as u32,
            Some(crate::sdk_glue::Tlas::Auto),
        ));
        ctx.invoke_gpu_task(c)?;
        Ok((ctx, Registration { uploads, handles }))
    }

    /// The renderer of `scene` on `ctx`, where [`Self::register`] registered it as `registered`:
    /// the pipelines (every SDK one too, with [`RendererOptions::prepare_pipelines`]), the
    /// rasteriser's scene and the targets.
    pub fn from_registered(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        opts: &RendererOptions,
        ctx: ksrt::ExecuteContext,
        registered: Registration,
    ) -> Renderer {
        let Registration { uploads, handles } = registered;
        let animator = Animator::new(scene, &handles.geometries);
        if opts.prepare_pipelines {
            ctx.prepare_pipelines();
        }
        let raster = GpuScene::new(device, queue, scene, &uploads);
        let size = (opts.size.0.max(1), opts.size.1.max(1));
        let main = ViewTargets::new(device, &raster, size);
        let lidar_size = opts.lidar_size.max(1);
        let lidar = ViewTargets::new(device, &raster, (lidar_size, lidar_size));
        let mut sdk = SdkFrame::new(
            device,
            ctx,
            size,
            opts.effects,
            raster.shadow_light.as_ref(),
            raster.scene_size,
            opts.seed,
        );
        sdk.preset = opts.preset;
        let target = |format, label| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: size.0,
                    height: size.1,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            })
        };
        Renderer {
            composite: Composite::new(device, opts.ldr_format),
            hdr: target(wgpu::TextureFormat::Rgba16Float, "ksrt hdr"),
            ldr: target(opts.ldr_format, "ksrt ldr"),
            raster,
            main,
            lidar,
            sdk,
            frame: 0,
            prev_view: None,
            lidar_on: opts.effects.lidar,
            show: Default::default(),
            last_sdk_build_ms: 0.0,
            clock: opts.clock,
            uploads,
            animator,
        }
    }

    /// Sets the scene time, seconds, that the next frames show: an animated scene's first
    /// animation at that time (looping); nothing for a still scene. The pose is made (and the
    /// shadow map redrawn) by the next [`Self::record_frame`] whose time differs from the last.
    pub fn set_time(&mut self, seconds: f32) {
        if let Some(a) = &mut self.animator {
            a.time = if seconds.is_finite() { seconds } else { 0.0 };
        }
    }

    /// The vertex buffer (`Float32x3` positions) of mesh `mesh` of the scene: what the
    /// rasteriser draws and the SDK copies, a posed mesh's last pose.
    pub fn vertex_buffer(&self, mesh: usize) -> Option<&wgpu::Buffer> {
        self.uploads.get(mesh).map(|u| &u.vertices)
    }

    /// Whether the scene has deformable meshes that [`Self::set_time`] poses.
    pub fn is_animated(&self) -> bool {
        self.animator.is_some()
    }

    /// Forgets the previous frame's camera: the next frame has no motion and drops the
    /// denoisers' history (a camera cut).
    pub fn cut(&mut self) {
        self.prev_view = None;
    }

    /// Records one frame of `camera` into `encoder`: shadow map (first frame), G-buffer and
    /// lighting of the main and lidar views, the SDK's tasks, and the composite into
    /// [`Self::hdr`] and [`Self::ldr`]. Returns the SDK's tasks, to be marked complete once the
    /// GPU has run `encoder`'s submission.
    pub fn record_frame(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        camera: &Camera,
    ) -> AnyResult<Vec<ksrt::GpuTaskHandle>> {
        // The pose first, so that the frame draws and traces it; its task is returned last,
        // after the frame's (whose GPU timings the callers read from the first task).
        let mut pose_task = None;
        if let Some(animator) = &mut self.animator {
            pose_task =
                animator.pose(queue, encoder, &self.sdk.ctx, &self.raster, &self.uploads)?;
            if pose_task.is_some() && self.frame > 0 {
                self.raster.record_shadow_map(encoder);
            }
        }
        if self.frame == 0 {
            self.raster.record_shadow_map(encoder);
        }
        let view = FrameView::new(
            camera,
            self.main.size,
            self.raster.scene_size,
            halton_jitter(self.frame),
            self.prev_view.as_ref(),
        );
        self.main.set_view(queue, &view);
        self.raster.record_view(encoder, &self.main.as_ref());
        let lidar_view = if self.lidar_on && self.sdk.effects.lidar {
            let v = FrameView::new(
                &lidar_camera(camera.eye, self.frame),
                self.lidar.size,
                self.raster.scene_size,
                glam::Vec2::ZERO,
                None,
            );
            self.lidar.set_view(queue, &v);
            self.raster.record_view(encoder, &self.lidar.as_ref());
            Some(v)
        } else {
            None
        };
        let discard_history = self.prev_view.is_none();
        let sdk_start = self.clock.map(|now| now());
        let mut tasks = self.sdk.record(
            encoder,
            &FrameInputs {
                main: &self.main,
                view: &view,
                lidar: lidar_view.as_ref().map(|v| (&self.lidar, v)),
                frame: self.frame,
                discard_history,
            },
        )?;
        tasks.extend(pose_task);
        if let (Some(now), Some(start)) = (self.clock, sdk_start) {
            self.last_sdk_build_ms = now() - start;
        }
        let produced = self.sdk.produced();
        self.composite.record(
            device,
            queue,
            encoder,
            &self.main,
            &self.sdk.outputs,
            produced,
            self.show,
            &self.hdr.create_view(&Default::default()),
            &self.ldr.create_view(&Default::default()),
        );
        self.prev_view = Some(view);
        self.frame += 1;
        Ok(tasks)
    }

    /// Records the trace tasks alone once more on the last frame's G-buffer, with white noise of
    /// index `sample`, into the raw outputs (see [`SdkFrame::record_traces`](crate::frame::SdkFrame::record_traces)).
    pub fn record_traces(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        sample: u32,
    ) -> AnyResult<Option<ksrt::GpuTaskHandle>> {
        let view = self
            .prev_view
            .as_ref()
            .ok_or("record_traces: no frame has been rendered yet")?;
        let inputs = FrameInputs {
            main: &self.main,
            view,
            lidar: None,
            frame: self.frame,
            discard_history: false,
        };
        Ok(self.sdk.record_traces(encoder, &inputs, sample)?)
    }
}
