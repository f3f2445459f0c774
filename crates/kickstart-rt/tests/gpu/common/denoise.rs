//! Denoiser test helpers: an analytic scene (a floor, a back wall and a box, ray cast on the CPU)
//! turned into a G-buffer, converged reference signals on it, noisy inputs (reference × noise of
//! mean 1, new every frame), and a harness that runs one denoise task per frame and reads the
//! output back.

use super::rt::Rng;
use super::*;
use glam::{Mat4, Vec2, Vec3, Vec4};
use kickstart_rt::*;

pub const SIZE: u32 = 64;

/// One visible surface point.
#[derive(Debug, Clone, Copy)]
pub struct Surface {
    pub position: Vec3,
    pub normal: Vec3,
    /// 0 floor, 1 wall, 2 box.
    pub object: u32,
}

/// A camera and the scene's surfaces as it sees them.
pub struct GBuffer {
    pub view: ViewInfo,
    pub surfaces: Vec<Option<Surface>>,
    /// World-space motion of each pixel's surface since the previous frame.
    pub world_motion: Vec<Vec3>,
    /// Viewport-UV motion (previous uv − uv).
    pub uv_motion: Vec<Vec2>,
}

pub fn camera(eye: Vec3) -> (Mat4, Mat4) {
    (
        Mat4::look_at_rh(eye, Vec3::new(0.0, 0.4, -0.5), Vec3::Y),
        Mat4::perspective_rh(60f32.to_radians(), 1.0, 0.1, 50.0),
    )
}

fn ray_box(o: Vec3, d: Vec3, lo: Vec3, hi: Vec3) -> Option<(f32, Vec3)> {
    let inv = d.recip();
    let t0 = (lo - o) * inv;
    let t1 = (hi - o) * inv;
    let tmin = t0.min(t1);
    let tmax = t0.max(t1);
    let near = tmin.max_element();
    let far = tmax.min_element();
    if near > far || far <= 0.0 || near <= 0.0 {
        return None;
    }
    let n = if near == tmin.x {
        Vec3::new(-d.x.signum(), 0.0, 0.0)
    } else if near == tmin.y {
        Vec3::new(0.0, -d.y.signum(), 0.0)
    } else {
        Vec3::new(0.0, 0.0, -d.z.signum())
    };
    Some((near, n))
}

/// The closest surface along a ray: floor y = 0 (|x| ≤ 4, −2 ≤ z ≤ 4), wall z = −2 (|x| ≤ 4,
/// 0 ≤ y ≤ 4), box of size 1 at `box_offset`.
pub fn cast(o: Vec3, d: Vec3, box_offset: Vec3) -> Option<Surface> {
    let mut best: Option<(f32, Surface)> = None;
    let mut consider = |t: f32, s: Surface| {
        if t > 0.0 && best.is_none_or(|(b, _)| t < b) {
            best = Some((t, s));
        }
    };
    if d.y.abs() > 1e-6 {
        let t = -o.y / d.y;
        let p = o + d * t;
        if p.x.abs() <= 4.0 && p.z >= -2.0 && p.z <= 4.0 {
            consider(
                t,
                Surface {
                    position: p,
                    normal: Vec3::Y,
                    object: 0,
                },
            );
        }
    }
    if d.z.abs() > 1e-6 {
        let t = (-2.0 - o.z) / d.z;
        let p = o + d * t;
        if p.x.abs() <= 4.0 && p.y >= 0.0 && p.y <= 4.0 {
            consider(
                t,
                Surface {
                    position: p,
                    normal: Vec3::Z,
                    object: 1,
                },
            );
        }
    }
    let lo = Vec3::new(-0.5, 0.0, -0.5) + box_offset;
    if let Some((t, n)) = ray_box(o, d, lo, lo + Vec3::ONE) {
        consider(
            t,
            Surface {
                position: o + d * t,
                normal: n,
                object: 2,
            },
        );
    }
    best.map(|(_, s)| s)
}

/// The G-buffer of the scene from `eye` with the box at `box_offset`; the previous frame had
/// the camera at `prev_eye` and the box at `prev_box`.
pub fn gbuffer(eye: Vec3, box_offset: Vec3, prev_eye: Vec3, prev_box: Vec3) -> GBuffer {
    gbuffer_jittered(eye, box_offset, prev_eye, prev_box, Vec2::ZERO)
}

/// As [`gbuffer`], rendered with the projection shifted by `jitter` pixels (x right, y down): the
/// pixel centre `c` shows the point at unjittered pixel coordinate `c − jitter`.
pub fn gbuffer_jittered(
    eye: Vec3,
    box_offset: Vec3,
    prev_eye: Vec3,
    prev_box: Vec3,
    jitter: Vec2,
) -> GBuffer {
    let (w2v, v2c) = camera(eye);
    let (pw2v, pv2c) = camera(prev_eye);
    let inv = (v2c * w2v).inverse();
    let prev_clip = pv2c * pw2v;
    let n = (SIZE * SIZE) as usize;
    let mut surfaces = Vec::with_capacity(n);
    let mut world_motion = vec![Vec3::ZERO; n];
    let mut uv_motion = vec![Vec2::ZERO; n];
    for y in 0..SIZE {
        for x in 0..SIZE {
            let ndc = Vec2::new(
                (x as f32 + 0.5 - jitter.x) / SIZE as f32 * 2.0 - 1.0,
                1.0 - (y as f32 + 0.5 - jitter.y) / SIZE as f32 * 2.0,
            );
            let a = inv.project_point3(ndc.extend(0.0));
            let b = inv.project_point3(ndc.extend(0.5));
            let s = cast(a, (b - a).normalize(), box_offset);
            let i = (y * SIZE + x) as usize;
            if let Some(s) = s {
                let moved = if s.object == 2 {
                    prev_box - box_offset
                } else {
                    Vec3::ZERO
                };
                world_motion[i] = moved;
                let c = prev_clip * (s.position + moved).extend(1.0);
                let prev_uv = Vec2::new(c.x / c.w * 0.5 + 0.5, 0.5 - c.y / c.w * 0.5);
                let uv = Vec2::new(
                    (x as f32 + 0.5) / SIZE as f32,
                    (y as f32 + 0.5) / SIZE as f32,
                );
                uv_motion[i] = prev_uv - uv;
            }
            surfaces.push(s);
        }
    }
    GBuffer {
        view: ViewInfo {
            world_to_view: w2v,
            view_to_clip: v2c,
            prev_world_to_view: pw2v,
            prev_view_to_clip: pv2c,
            jitter,
        },
        surfaces,
        world_motion,
        uv_motion,
    }
}

/// A converged diffuse-like signal: smooth on each surface, a step between surfaces and box
/// faces.
pub fn reference(s: &Surface) -> Vec3 {
    match s.object {
        0 => Vec3::new(0.6, 0.5, 0.4) * (0.6 + 0.4 * (s.position.x * 1.5).cos()),
        1 => Vec3::new(0.3, 0.4, 0.7) * (0.7 + 0.3 * (s.position.y * 2.0).sin()),
        _ => {
            if s.normal.y > 0.5 {
                Vec3::new(0.9, 0.9, 0.2)
            } else if s.normal.x.abs() > 0.5 {
                Vec3::new(0.9, 0.2, 0.2)
            } else {
                Vec3::new(0.2, 0.8, 0.3)
            }
        }
    }
}

/// The reference image of `g` (rgb, hit distance 1); black where there is no surface.
pub fn reference_image(g: &GBuffer, f: impl Fn(&Surface) -> Vec3) -> Vec<Vec4> {
    g.surfaces
        .iter()
        .map(|s| s.map_or(Vec4::ZERO, |s| f(&s).extend(1.0)))
        .collect()
}

/// `reference` × a per-pixel factor uniform in [0, 2] (mean 1): one-sample-like noise.
pub fn noisy(reference: &[Vec4], rng: &mut Rng) -> Vec<Vec4> {
    reference
        .iter()
        .map(|r| {
            let k = 2.0 * rng.f();
            (r.truncate() * k).extend(r.w)
        })
        .collect()
}

/// Mean squared error of rgb over the pixels with a surface.
pub fn mse(g: &GBuffer, a: &[Vec4], b: &[Vec4]) -> f64 {
    let mut sum = 0.0f64;
    let mut n = 0usize;
    for (i, s) in g.surfaces.iter().enumerate() {
        if s.is_some() {
            let d = a[i].truncate() - b[i].truncate();
            sum += d.length_squared() as f64 / 3.0;
            n += 1;
        }
    }
    sum / n.max(1) as f64
}

/// PSNR (peak 1) of `a` against `reference`.
pub fn psnr(g: &GBuffer, a: &[Vec4], reference: &[Vec4]) -> f64 {
    10.0 * (1.0 / mse(g, a, reference)).log10()
}

pub fn make_texture(format: wgpu::TextureFormat, usage: wgpu::TextureUsages) -> wgpu::TextureView {
    texture(format, SIZE, SIZE, usage)
}

pub fn write_texture(view: &wgpu::TextureView, texels: &[Vec4]) {
    let data: Vec<f32> = texels.iter().flat_map(|v| v.to_array()).collect();
    write_texture_bytes(view, bytemuck::cast_slice(&data), 16);
}

fn write_texture_bytes(view: &wgpu::TextureView, bytes: &[u8], texel_bytes: u32) {
    gpu().queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: view.texture(),
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        bytes,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(SIZE * texel_bytes),
            rows_per_image: None,
        },
        view.texture().size(),
    );
}

pub fn read_texture(view: &wgpu::TextureView) -> Vec<Vec4> {
    let g = gpu();
    let buf = g.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: (SIZE * SIZE * 16) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut e = encoder();
    e.copy_texture_to_buffer(
        view.texture().as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buf,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(SIZE * 16),
                rows_per_image: None,
            },
        },
        view.texture().size(),
    );
    submit(e);
    let bytes = read_buffer(&buf);
    bytemuck::cast_slice::<u8, f32>(&bytes)
        .chunks(4)
        .map(Vec4::from_slice)
        .collect()
}

/// Which motion input the harness gives the denoiser.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// None: reprojection with the matrices.
    Matrices,
    /// `RgViewSpace`.
    ViewSpace,
    /// `RgbWorldSpace`.
    WorldSpace,
}

/// One denoising context and the textures of its task.
pub struct Harness {
    pub ctx: ExecuteContext,
    pub handle: DenoisingContextHandle,
    pub signal: SignalType,
    depth: wgpu::TextureView,
    normal: wgpu::TextureView,
    motion: wgpu::TextureView,
    inputs: Vec<wgpu::TextureView>,
    pub outputs: Vec<wgpu::TextureView>,
    pub half_resolution_mode: HalfResolutionMode,
    /// The task's viewport (`None`: the whole texture).
    pub viewport: Option<Viewport>,
}

impl Harness {
    pub fn new(signal: SignalType, method: DenoisingMethod) -> Self {
        let ctx = context(2);
        let handle = ctx
            .create_denoising_context_handle(DenoisingContextInput {
                max_width: SIZE,
                max_height: SIZE,
                signal_type: signal,
                method,
            })
            .expect("denoising context");
        let read = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
        let write = wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC;
        let n = if signal == SignalType::SpecularAndDiffuse {
            2
        } else {
            1
        };
        Harness {
            ctx,
            handle,
            signal,
            depth: make_texture(wgpu::TextureFormat::R32Float, read),
            normal: make_texture(wgpu::TextureFormat::Rgba32Float, read),
            motion: make_texture(wgpu::TextureFormat::Rgba32Float, read),
            inputs: (0..n)
                .map(|_| make_texture(wgpu::TextureFormat::Rgba32Float, read))
                .collect(),
            outputs: (0..n)
                .map(|_| make_texture(wgpu::TextureFormat::Rgba32Float, write))
                .collect(),
            half_resolution_mode: HalfResolutionMode::Off,
            viewport: None,
        }
    }

    /// The task's common inputs for `g`.
    pub fn common(&self, g: &GBuffer, motion: Motion, mode: DenoiseMode) -> DenoiseTaskCommon {
        DenoiseTaskCommon {
            context: self.handle,
            viewport: self.viewport,
            depth: DepthInput {
                texture: self.depth.clone(),
                depth_type: DepthType::RClipSpace,
            },
            normal: NormalInput {
                texture: self.normal.clone(),
                normal_type: NormalType::RgbVector,
                normal_to_world: Mat4::IDENTITY,
            },
            roughness: RoughnessInput::default(),
            motion: match motion {
                Motion::Matrices => None,
                Motion::ViewSpace => Some(MotionInput {
                    texture: self.motion.clone(),
                    motion_type: MotionType::RgViewSpace,
                    scale: Vec3::ONE,
                }),
                Motion::WorldSpace => Some(MotionInput {
                    texture: self.motion.clone(),
                    motion_type: MotionType::RgbWorldSpace,
                    scale: Vec3::ONE,
                }),
            },
            view: g.view,
            half_resolution_mode: self.half_resolution_mode,
            mode,
        }
    }

    /// Uploads `g` and `inputs` (one image per signal, or for shadows the raw trace output in
    /// `.x`), runs the denoise task, returns each output.
    pub fn frame(
        &self,
        g: &GBuffer,
        inputs: &[Vec<Vec4>],
        motion: Motion,
        mode: DenoiseMode,
    ) -> Vec<Vec<Vec4>> {
        let h = self.submit_frame(g, inputs, motion, mode);
        self.ctx.mark_gpu_task_completed(h).expect("complete");
        self.outputs.iter().map(read_texture).collect()
    }

    /// As [`Self::frame`], without marking the task complete or reading back.
    pub fn submit_frame(
        &self,
        g: &GBuffer,
        inputs: &[Vec<Vec4>],
        motion: Motion,
        mode: DenoiseMode,
    ) -> GpuTaskHandle {
        self.upload(g, inputs, motion);
        let task = self.task(self.common(g, motion, mode));
        let mut c = self.ctx.create_task_container();
        c.schedule_render_task(task);
        let mut e = encoder();
        let h = self.ctx.build_gpu_task(c, &mut e).expect("denoise task");
        submit(e);
        h
    }

    /// Writes `g`'s depth, normals and motion and the signal `inputs` into the harness's
    /// textures.
    pub fn upload(&self, g: &GBuffer, inputs: &[Vec<Vec4>], motion: Motion) {
        let (w2v, v2c) = (g.view.world_to_view, g.view.view_to_clip);
        let clip = v2c * w2v;
        let depth: Vec<f32> = g
            .surfaces
            .iter()
            .map(|s| s.map_or(1.0, |s| clip.project_point3(s.position).z))
            .collect();
        write_texture_bytes(&self.depth, bytemuck::cast_slice(&depth), 4);
        let normals: Vec<Vec4> = g
            .surfaces
            .iter()
            .map(|s| s.map_or(Vec4::ZERO, |s| s.normal.extend(0.0)))
            .collect();
        write_texture(&self.normal, &normals);
        let m: Vec<Vec4> = match motion {
            Motion::WorldSpace => g.world_motion.iter().map(|v| v.extend(0.0)).collect(),
            _ => g
                .uv_motion
                .iter()
                .map(|v| v.extend(0.0).extend(0.0))
                .collect(),
        };
        write_texture(&self.motion, &m);
        for (t, img) in self.inputs.iter().zip(inputs) {
            write_texture(t, img);
        }
    }

    /// The harness's denoise task on `common`.
    pub fn task(&self, common: DenoiseTaskCommon) -> RenderTask {
        denoise_task(self.signal, common, &self.inputs, &self.outputs)
    }
}

/// The denoise task of a context of `signal` on `common`, from `inputs` into `outputs` (one
/// texture each per signal).
pub fn denoise_task(
    signal: SignalType,
    common: DenoiseTaskCommon,
    inputs: &[wgpu::TextureView],
    outputs: &[wgpu::TextureView],
) -> RenderTask {
    match signal {
        SignalType::Specular => RenderTask::DenoiseSpecular(DenoiseSpecularTask {
            common,
            input: inputs[0].clone(),
            output: outputs[0].clone(),
        }),
        SignalType::Diffuse => RenderTask::DenoiseDiffuse(DenoiseDiffuseTask {
            common,
            input: inputs[0].clone(),
            output: outputs[0].clone(),
        }),
        SignalType::SpecularAndDiffuse => {
            RenderTask::DenoiseSpecularAndDiffuse(DenoiseSpecularAndDiffuseTask {
                common,
                input_specular: inputs[0].clone(),
                input_diffuse: inputs[1].clone(),
                output_specular: outputs[0].clone(),
                output_diffuse: outputs[1].clone(),
            })
        }
        SignalType::DiffuseOcclusion => {
            RenderTask::DenoiseDiffuseOcclusion(DenoiseDiffuseOcclusionTask {
                common,
                input: inputs[0].clone(),
                output: outputs[0].clone(),
            })
        }
        SignalType::Shadow => RenderTask::DenoiseShadow(DenoiseShadowTask {
            common,
            input: inputs[0].clone(),
            output: outputs[0].clone(),
        }),
        SignalType::MultiShadow => RenderTask::DenoiseMultiShadow(DenoiseMultiShadowTask {
            common,
            input0: inputs[0].clone(),
            input1: inputs[0].clone(),
            output: outputs[0].clone(),
        }),
    }
}
