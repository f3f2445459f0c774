//! Primary-ray debug views: `HitT`, `Barycentrics` and `RandomMeshColor` of a trace task's view,
//! written to its output texture (RGB; alpha 1 on hit, 0 on miss).
//!
//! Camera rays go through the pixel centres of the viewport (jitter is ignored: a debug view
//! shows the unjittered camera). The camera is derived from the matrices only, so normal and
//! reverse Z, finite and infinite far planes, and both handednesses work:
//! - perspective (`view_to_clip` row 3 depends on view-space xyz): rays start at the eye,
//!   `inverse(world_to_view) · (0,0,0,1)`, towards the unprojected point at NDC depth 0.5, which
//!   lies strictly between the near and far planes whichever way depth runs;
//! - orthographic: rays start on the NDC depth plane (0 or 1) whose view-space point is nearer
//!   the view origin (the near plane, for a near distance ≥ 0) and head to the other.
//!
//! HitT is the world-space distance along the ray from its origin (the eye; the near plane for
//! orthographic views).

use crate::camera::camera;
use crate::device::TraversalBackend;
use crate::error::{Error, Result};
use crate::gpu::reflect::{ReflectedPipeline, ReflectedShader};
use crate::gpu::Recorder;
use crate::scene::traversal::{self, LeafTest, SceneBuffers};
use crate::tasks::{DebugOutputType, InstanceInclusionMask, ViewInfo, WRITABLE_OUTPUT_FORMATS};
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup of the debug view shader (its `@workgroup_size`): `RT_WORKGROUP_SIZE`
/// of `shaders/scene/traversal.wgsl`.
const WORKGROUP_SIZE: u32 = 64;

/// The task name used in errors.
const TASK: &str = "debug view";

/// Uniform parameters of the debug view shader (`DebugParams`).
#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy, Debug, PartialEq)]
struct DebugParams {
    clip_to_world: [[f32; 4]; 4],
    eye: [f32; 4],
    viewport: [u32; 4],
    ortho: u32,
    kind: u32,
    z_origin: f32,
    z_target: f32,
    mask: u32,
    pad: [u32; 3],
}

/// The WGSL storage texel format of a writable output format.
fn wgsl_format(format: wgpu::TextureFormat) -> Option<&'static str> {
    match format {
        wgpu::TextureFormat::Rgba16Float => Some("rgba16float"),
        wgpu::TextureFormat::Rgba32Float => Some("rgba32float"),
        wgpu::TextureFormat::R32Float => Some("r32float"),
        wgpu::TextureFormat::Rg32Float => Some("rg32float"),
        _ => None,
    }
}

/// The WGSL of the debug view pass writing the storage format `format_name` (a name
/// [`wgsl_format`] gives), tracing with `backend`.
fn debug_view_shader(backend: TraversalBackend, format_name: &str) -> ReflectedShader {
    // The lighting cache's sampling module at group 2 (the DirectLightingCache view reads it).
    let [group, access] = crate::cache::sample_params(2, false);
    // One build for every scene: a debug view's speed does not matter, its pipelines' count does.
    traversal::compose(
        backend,
        LeafTest::WithCutouts,
        &["trace/debug_view"],
        &[group, access, ("OUTPUT_FORMAT", format_name)],
    )
}

/// A primary-ray debug view the plan resolved: the view the shader writes (its code) over a
/// viewport of `x, y, width, height` pixels that one dispatch covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct DebugView {
    code: u32,
    viewport: (u32, u32, u32, u32),
    pixels: u32,
}

impl DebugView {
    /// The view of `kind` over `viewport`: `None` for a kind this pass does not write (the
    /// task is unsupported), an error for a viewport of more pixels than one dispatch covers.
    pub fn new(kind: DebugOutputType, viewport: (u32, u32, u32, u32)) -> Result<Option<Self>> {
        let code = match kind {
            DebugOutputType::HitT => 1,
            DebugOutputType::Barycentrics => 2,
            DebugOutputType::RandomMeshColor => 3,
            DebugOutputType::RandomTileColor => 4,
            DebugOutputType::DirectLightingCache => 5,
            _ => return Ok(None),
        };
        let (_, _, w, h) = viewport;
        let Ok(pixels) = u32::try_from(w as u64 * h as u64) else {
            return Err(Error::input(TASK, "viewport", viewport, "too many pixels"));
        };
        Ok(Some(DebugView {
            code,
            viewport,
            pixels,
        }))
    }
}

/// The WGSL of the debug view pass with `backend` for every writable output format, labelled.
pub(crate) fn shader_variants(backend: TraversalBackend) -> Vec<(String, String)> {
    WRITABLE_OUTPUT_FORMATS
        .iter()
        .filter_map(|&f| {
            let name = wgsl_format(f)?;
            Some((
                format!("debug view ({f:?})"),
                debug_view_shader(backend, name).source().to_string(),
            ))
        })
        .collect()
}

/// The primary-ray debug view pass (`debug view`); pipelines are created per output format on
/// first use.
pub(crate) struct DebugViewPass {
    backend: TraversalBackend,
    pipelines: Vec<(wgpu::TextureFormat, ReflectedPipeline)>,
}

impl DebugViewPass {
    /// A pass tracing with `backend`, with no pipelines yet.
    pub fn new(backend: TraversalBackend) -> Self {
        DebugViewPass {
            backend,
            pipelines: Vec::new(),
        }
    }

    /// The pipeline writing `format`, created on first use.
    fn pipeline(
        &mut self,
        device: &wgpu::Device,
        format: wgpu::TextureFormat,
    ) -> Result<&ReflectedPipeline> {
        let index = match self.pipelines.iter().position(|(f, _)| *f == format) {
            Some(i) => i,
            None => {
                let Some(name) = wgsl_format(format) else {
                    return Err(Error::input(
                        TASK,
                        "output format",
                        format,
                        "must be one of WRITABLE_OUTPUT_FORMATS",
                    ));
                };
                let pipeline = debug_view_shader(self.backend, name).pipeline(
                    device,
                    "kickstart-rt debug view",
                    "main",
                );
                self.pipelines.push((format, pipeline));
                self.pipelines.len() - 1
            }
        };
        Ok(&self.pipelines[index].1)
    }

    /// Creates every pipeline now (so the first frame that uses one does not stall).
    pub fn prepare(&mut self, device: &wgpu::Device) {
        for format in WRITABLE_OUTPUT_FORMATS {
            // Every writable format has a WGSL name, so this cannot fail.
            let _ = self.pipeline(device, format);
        }
    }

    /// Records the primary-ray debug view `debug` (resolved by the plan: [`DebugView::new`]) of
    /// `view` into `output` (a storage view of `format`); primary rays see instances with
    /// `VISIBLE_IN_RT`.
    #[allow(clippy::too_many_arguments)] // one argument per input of the view
    pub fn record(
        &mut self,
        rec: &mut Recorder<'_>,
        scene: &SceneBuffers<'_>,
        output: &wgpu::TextureView,
        format: wgpu::TextureFormat,
        debug: DebugView,
        view: &ViewInfo,
        (cache, bilinear): (&crate::cache::DirectLightingCache, bool),
    ) {
        let (kind_code, pixels) = (debug.code, debug.pixels);
        let (x, y, w, h) = debug.viewport;
        if pixels == 0 {
            return;
        }
        let (clip_to_world, eye, ortho, z_origin, z_target) = camera(view);
        let params = rec.uniform(
            "kickstart-rt debug view params",
            &DebugParams {
                clip_to_world,
                eye,
                viewport: [x, y, w, h],
                ortho,
                kind: kind_code,
                z_origin,
                z_target,
                mask: InstanceInclusionMask::VISIBLE_IN_RT.0,
                pad: [bilinear as u32, 0, 0],
            },
        );
        let device = rec.device;
        // validate::render_task admits only WRITABLE_OUTPUT_FORMATS, which all have WGSL names.
        let pipeline = self
            .pipeline(device, format)
            .expect("a validated output format has a pipeline");
        let scene_group = scene.bind_group(rec.device, &pipeline.pipeline);
        let io_group = pipeline.bind_resources(
            device,
            "kickstart-rt debug view io",
            1,
            &[
                ("params", params.as_entire_binding()),
                ("output", wgpu::BindingResource::TextureView(output)),
            ],
        );
        let cache_group = pipeline.bind_resources(
            device,
            "kickstart-rt debug view cache",
            2,
            &cache.sample_resources(),
        );
        rec.dispatch(
            "debug view",
            &pipeline.pipeline,
            &[&scene_group, &io_group, &cache_group],
            pixels.div_ceil(WORKGROUP_SIZE),
        );
    }
}

#[cfg(test)]
mod tests {
    //! Renders small images of known quads and checks pixels analytically (camera rays rebuilt
    //! in f64 on the CPU, hit points from the ray/plane intersection).
    use super::*;
    use crate::gpu::testing;
    use crate::trace::test_scene::{TestInstance, TestScene, Tri};
    use glam::{Affine3A, DMat4, DVec2, Mat4, Vec3};

    const W: u32 = 32;
    const H: u32 = 24;
    /// Viewport origin inside a larger texture (pixels outside must stay untouched).
    const VX: u32 = 2;
    const VY: u32 = 3;
    const TW: u32 = W + 5;
    const TH: u32 = H + 4;
    const EYE: Vec3 = Vec3::new(0.0, 0.0, 5.0);

    /// Every pipeline `prepare` creates (one per writable output format) validated with naga
    /// without a device, and the uniform against the WGSL.
    #[test]
    fn every_variant_validates_and_matches_the_rust_layout() {
        use crate::gpu::wgsl_check::{assert_wgsl_layout, validate};
        for format in WRITABLE_OUTPUT_FORMATS {
            let name = wgsl_format(format).unwrap();
            let module = validate(
                &format!("debug view ({format:?})"),
                debug_view_shader(TraversalBackend::Software, name).source(),
            );
            assert!(module.entry_points.iter().any(|e| e.name == "main"));
            // `pad[0]` carries the shader's `bilinear` flag (see `record`).
            assert_wgsl_layout!(
                module,
                "DebugParams",
                DebugParams {
                    clip_to_world,
                    eye,
                    viewport,
                    ortho,
                    kind,
                    z_origin,
                    z_target,
                    mask,
                    pad => "bilinear",
                }
            );
        }
        assert_eq!(wgsl_format(wgpu::TextureFormat::Rgba8Unorm), None);
    }

    /// The quad [-1, 1]² at z = 0: triangle 0 below the diagonal x = y, triangle 1 above.
    fn quad() -> Vec<Tri> {
        let p = |x: f32, y: f32| Vec3::new(x, y, 0.0);
        vec![
            [p(-1.0, -1.0), p(1.0, -1.0), p(1.0, 1.0)],
            [p(-1.0, -1.0), p(1.0, 1.0), p(-1.0, 1.0)],
        ]
    }

    fn view(view_to_clip: Mat4) -> ViewInfo {
        ViewInfo {
            world_to_view: Mat4::look_at_rh(EYE, Vec3::ZERO, Vec3::Y),
            view_to_clip,
            ..Default::default()
        }
    }

    /// Renders `kind` into a zeroed TW×TH texture (viewport at (VX, VY), W×H); returns RGBA
    /// texels (missing channels 0).
    fn render(
        scene: &TestScene,
        v: &ViewInfo,
        kind: DebugOutputType,
        format: wgpu::TextureFormat,
    ) -> Vec<[f32; 4]> {
        let g = testing::gpu();
        let tex = g.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("debug view test output"),
            size: wgpu::Extent3d {
                width: TW,
                height: TH,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view_tex = tex.create_view(&Default::default());
        let mut pass = DebugViewPass::new(testing::backend());
        let cache =
            crate::cache::DirectLightingCache::new(&testing::gpu().device, 64, testing::backend());
        testing::run(|rec| {
            let debug = DebugView::new(kind, (VX, VY, W, H)).unwrap().unwrap();
            pass.record(
                rec,
                &scene.buffers(),
                &view_tex,
                format,
                debug,
                v,
                (&cache, true),
            );
        });
        let texel = format.block_copy_size(None).unwrap();
        let row = (TW * texel).div_ceil(256) * 256;
        let buf = testing::buffer(row as u64 * TH as u64);
        let mut enc = g.device.create_command_encoder(&Default::default());
        enc.copy_texture_to_buffer(
            tex.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buf,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: None,
                },
            },
            tex.size(),
        );
        g.queue.submit([enc.finish()]);
        let bytes = testing::read_back(&buf, 0, row as u64 * TH as u64);
        let mut out = Vec::new();
        for y in 0..TH {
            for x in 0..TW {
                let at = (y * row + x * texel) as usize;
                let px = &bytes[at..at + texel as usize];
                let mut c = [0.0f32; 4];
                match format {
                    wgpu::TextureFormat::Rgba16Float => {
                        for (i, ch) in px.chunks(2).enumerate() {
                            c[i] = half_to_f32(u16::from_le_bytes([ch[0], ch[1]]));
                        }
                    }
                    _ => {
                        for (i, ch) in px.chunks(4).enumerate() {
                            c[i] = f32::from_le_bytes([ch[0], ch[1], ch[2], ch[3]]);
                        }
                    }
                }
                out.push(c);
            }
        }
        out
    }

    fn half_to_f32(h: u16) -> f32 {
        let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
        let e = ((h >> 10) & 0x1f) as i32;
        let m = (h & 0x3ff) as f32;
        sign * if e == 0 {
            m * 2f32.powi(-24)
        } else {
            (1.0 + m / 1024.0) * 2f32.powi(e - 15)
        }
    }

    /// The CPU camera ray of viewport pixel (px, py) as the docs define it: (origin, unit dir).
    fn camera_ray(v: &ViewInfo, px: u32, py: u32) -> (glam::DVec3, glam::DVec3) {
        let inv: DMat4 = (v.view_to_clip.as_dmat4() * v.world_to_view.as_dmat4()).inverse();
        let ndc = DVec2::new(
            (px as f64 + 0.5) / W as f64 * 2.0 - 1.0,
            1.0 - (py as f64 + 0.5) / H as f64 * 2.0,
        );
        let (_, _, ortho, z_origin, z_target) = camera(v);
        let origin = if ortho == 1 {
            inv.project_point3(ndc.extend(z_origin as f64))
        } else {
            EYE.as_dvec3()
        };
        let target = inv.project_point3(ndc.extend(z_target as f64));
        (origin, (target - origin).normalize())
    }

    /// Checks HitT and Barycentrics of the quad for one projection; `hit_t0` is the expected
    /// distance of the quad's centre plane hit measured from the ray origin.
    fn check_quad(projection: Mat4) {
        let scene = TestScene::single(quad());
        let v = view(projection);
        let hit_t = render(
            &scene,
            &v,
            DebugOutputType::HitT,
            wgpu::TextureFormat::Rgba32Float,
        );
        let bary = render(
            &scene,
            &v,
            DebugOutputType::Barycentrics,
            wgpu::TextureFormat::Rgba32Float,
        );
        let (mut hits, mut misses) = (0, 0);
        for ty in 0..TH {
            for tx in 0..TW {
                let i = (ty * TW + tx) as usize;
                let inside = (VX..VX + W).contains(&tx) && (VY..VY + H).contains(&ty);
                if !inside {
                    assert_eq!(hit_t[i], [0.0; 4], "outside the viewport at {tx},{ty}");
                    continue;
                }
                let (o, d) = camera_ray(&v, tx - VX, ty - VY);
                let t = -o.z / d.z;
                let p = o + d * t;
                let m = p.x.abs().max(p.y.abs());
                if (m - 1.0).abs() < 1e-3 || (p.x - p.y).abs() < 1e-3 {
                    continue; // on an edge: either answer is right
                }
                if m > 1.0 {
                    misses += 1;
                    assert_eq!(hit_t[i], [0.0; 4], "miss at {tx},{ty}");
                    assert_eq!(bary[i], [0.0; 4], "miss at {tx},{ty}");
                    continue;
                }
                hits += 1;
                let [r, g, b, a] = hit_t[i];
                assert!(
                    a == 1.0 && r == g && g == b && (r as f64 - t).abs() <= 1e-4 * t,
                    "HitT at {tx},{ty}: {:?}, want {t}",
                    hit_t[i]
                );
                let (u, w) = if p.x > p.y {
                    ((p.x - p.y) / 2.0, (p.y + 1.0) / 2.0)
                } else {
                    ((p.x + 1.0) / 2.0, (p.y - p.x) / 2.0)
                };
                let want = [1.0 - u - w, u, w];
                let [b0, b1, b2, ba] = bary[i];
                assert!(
                    ba == 1.0 && ((b0 + b1 + b2) - 1.0).abs() < 1e-5,
                    "{:?}",
                    bary[i]
                );
                for (got, want) in [b0, b1, b2].iter().zip(want) {
                    assert!(
                        (*got as f64 - want).abs() < 1e-4,
                        "barycentrics at {tx},{ty}: {:?}, want {want:?}",
                        bary[i]
                    );
                }
            }
        }
        assert!(hits > 50 && misses > 50, "{hits} hits, {misses} misses");
    }

    const FOV: f32 = 1.0;
    const ASPECT: f32 = W as f32 / H as f32;

    #[test]
    fn debug_view_perspective_normal_z_hit_t_and_barycentrics() {
        check_quad(Mat4::perspective_rh(FOV, ASPECT, 0.1, 100.0));
    }

    #[test]
    fn debug_view_perspective_reverse_z_infinite_hit_t_and_barycentrics() {
        check_quad(Mat4::perspective_infinite_reverse_rh(FOV, ASPECT, 0.1));
    }

    #[test]
    fn debug_view_orthographic_normal_and_reverse_z_start_at_the_near_plane() {
        for (near, far) in [(0.5, 20.0), (20.0, 0.5)] {
            let proj = Mat4::orthographic_rh(-1.6, 1.6, -1.2, 1.2, near, far);
            check_quad(proj);
            // Rays start on the near plane (view distance 0.5): the quad is 4.5 away.
            let (o, _) = camera_ray(&view(proj), 0, 0);
            assert!((o.z - 4.5).abs() < 1e-4, "origin {o}");
        }
    }

    #[test]
    fn debug_view_random_mesh_color_differs_per_instance_and_respects_the_mask() {
        let mut hidden = TestInstance::new(0, Affine3A::from_translation(Vec3::new(0.0, 0.0, 1.0)));
        // Not VISIBLE_IN_RT: in front of everything, yet never seen.
        hidden.mask = InstanceInclusionMask::DIRECT_LIGHT_INJECTION_TARGET.0;
        let scene = TestScene::new(
            vec![quad()],
            vec![
                TestInstance::new(0, Affine3A::from_translation(Vec3::new(-1.1, 0.0, 0.0))),
                TestInstance::new(0, Affine3A::from_translation(Vec3::new(1.1, 0.0, 0.0))),
                hidden,
            ],
        );
        let v = view(Mat4::perspective_rh(FOV, ASPECT, 0.1, 100.0));
        for format in [
            wgpu::TextureFormat::Rgba16Float,
            wgpu::TextureFormat::Rgba32Float,
        ] {
            let img = render(&scene, &v, DebugOutputType::RandomMeshColor, format);
            let mut colours: [Option<[f32; 4]>; 2] = [None, None];
            for py in 0..H {
                for px in 0..W {
                    let c = img[((py + VY) * TW + px + VX) as usize];
                    let (o, d) = camera_ray(&v, px, py);
                    let p = o + d * (-o.z / d.z);
                    let inst = if (p.x + 1.1).abs() < 0.99 && p.y.abs() < 0.99 {
                        0
                    } else if (p.x - 1.1).abs() < 0.99 && p.y.abs() < 0.99 {
                        1
                    } else {
                        if p.y.abs() > 1.01 || p.x.abs() > 2.11 {
                            assert_eq!(c[3], 0.0, "miss at {px},{py}");
                        }
                        continue;
                    };
                    assert_eq!(c[3], 1.0);
                    match colours[inst] {
                        None => colours[inst] = Some(c),
                        Some(k) => assert_eq!(k, c, "instance {inst} at {px},{py}"),
                    }
                }
            }
            let (Some(a), Some(b)) = (colours[0], colours[1]) else {
                panic!("both instances visible: {colours:?}");
            };
            assert_ne!(a, b);
        }
    }

    #[test]
    fn debug_view_writes_single_and_two_channel_formats_and_rejects_other_kinds() {
        let scene = TestScene::single(quad());
        let v = view(Mat4::perspective_rh(FOV, ASPECT, 0.1, 100.0));
        for format in [
            wgpu::TextureFormat::R32Float,
            wgpu::TextureFormat::Rg32Float,
        ] {
            let img = render(&scene, &v, DebugOutputType::HitT, format);
            // The centre pixel looks straight at the quad's centre, 5 away.
            let c = img[((VY + H / 2) * TW + VX + W / 2) as usize];
            assert!((c[0] - 5.0).abs() < 0.05, "{format:?}: {c:?}");
        }
        let g = testing::gpu();
        let mut pass = DebugViewPass::new(testing::backend());
        // Every writable output format compiles (also on the minimal device).
        pass.prepare(&g.device);
        assert_eq!(pass.pipelines.len(), WRITABLE_OUTPUT_FORMATS.len());
        // A view this pass does not write is no debug view (the task is unsupported).
        assert_eq!(
            DebugView::new(DebugOutputType::Normal, (0, 0, 4, 4)),
            Ok(None)
        );
        assert!(DebugView::new(DebugOutputType::HitT, (0, 0, 1 << 16, 1 << 16)).is_err());
    }
}
