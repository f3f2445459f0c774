//! The G-buffer module decodes every depth and normal type of the same scene to the same surface,
//! checked against an analytic scene computed in f64 on the CPU.

use super::*;
use crate::gpu::shader::compute_pipeline_with_layouts;
use crate::gpu::testing::{self, Rng};
use glam::{DVec2, Mat4, Vec3};

/// Texture size and the viewport inside it (the viewport is offset to test the mapping).
const TEX_W: u32 = 32;
const TEX_H: u32 = 20;
const VP: Viewport = Viewport {
    x: 4,
    y: 2,
    width: 24,
    height: 16,
};
/// Floats per pixel written by the probe shader.
const STRIDE: usize = 20;

const PROBE_WGSL: &str = r#"
#import trace/gbuffer

@group(1) @binding(0) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= gb_pixel_count() {
        return;
    }
    let texel = gb_texel(i);
    let s = gb_surface(texel);
    let o = i * 20u;
    out[o] = select(0.0, 1.0, s.valid);
    out[o + 1u] = s.position.x;
    out[o + 2u] = s.position.y;
    out[o + 3u] = s.position.z;
    out[o + 4u] = s.normal.x;
    out[o + 5u] = s.normal.y;
    out[o + 6u] = s.normal.z;
    out[o + 7u] = s.to_eye.x;
    out[o + 8u] = s.to_eye.y;
    out[o + 9u] = s.to_eye.z;
    out[o + 10u] = s.view_distance;
    out[o + 11u] = gb_roughness(texel);
    let sp = gb_specular(texel);
    out[o + 12u] = sp.x;
    out[o + 13u] = sp.y;
    out[o + 14u] = sp.z;
    out[o + 15u] = sp.w;
    out[o + 16u] = select(0.0, 1.0, gb_mask(texel));
    let q = gb_project(s.position);
    out[o + 17u] = q.x;
    out[o + 18u] = q.y;
    out[o + 19u] = q.z;
}
"#;

/// Runs the probe over the viewport and returns `STRIDE` floats per viewport pixel.
fn probe(inputs: &GBufferInputs<'_>) -> Vec<f32> {
    let g = testing::gpu();
    let binder = GBufferBinder::new(&g.device);
    let out_layout = g
        .device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: None,
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: false },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
    let mut library = crate::gpu::compose::ShaderLibrary::builtin();
    library.replace("test/gbuffer_probe", PROBE_WGSL);
    let source = library
        .compose(&["test/gbuffer_probe"], &[("GBUFFER_GROUP", "0")])
        .unwrap();
    let pipeline = compute_pipeline_with_layouts(
        &g.device,
        "g-buffer probe",
        &source,
        "main",
        &[binder.layout(), &out_layout],
    );
    let n = (inputs.viewport.width * inputs.viewport.height) as usize;
    let out = testing::buffer((n * STRIDE * 4) as u64);
    testing::run(|rec| {
        let params = rec.uniform("g-buffer params", &inputs.params());
        let gb = binder.bind_group(&g.device, &params, inputs);
        let ob = g.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &out_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: out.as_entire_binding(),
            }],
        });
        rec.dispatch("probe", &pipeline, &[&gb, &ob], (n as u32).div_ceil(64));
    });
    bytemuck::cast_slice(&testing::read_back(&out, 0, (n * STRIDE * 4) as u64)).to_vec()
}

/// The tilted plane every test camera looks at: `dot(n, p) = d`.
const PLANE_N: DVec3 = DVec3::new(0.2, 1.0, 0.3);
const PLANE_D: f64 = -0.4;

/// The cameras: perspective with normal Z, reverse-Z infinite perspective, orthographic.
fn cameras() -> Vec<(&'static str, Mat4, Mat4)> {
    let view = Mat4::look_at_rh(Vec3::new(0.5, 2.0, 3.0), Vec3::new(0.0, -0.3, 0.0), Vec3::Y);
    let aspect = VP.width as f32 / VP.height as f32;
    vec![
        (
            "perspective",
            view,
            Mat4::perspective_rh(0.9, aspect, 0.1, 100.0),
        ),
        (
            "reverse-z infinite",
            view,
            Mat4::perspective_infinite_reverse_rh(0.9, aspect, 0.05),
        ),
        (
            "orthographic",
            view,
            Mat4::orthographic_rh(-2.0, 2.0, -1.5, 1.5, 0.5, 20.0),
        ),
    ]
}

/// The analytic surface at each viewport pixel: position (None: the ray misses the plane).
fn analytic(cam: &CameraFrame) -> Vec<Option<DVec3>> {
    analytic_jittered(cam, DVec2::ZERO)
}

/// As [`analytic`] for a projection jittered by `jitter` pixels: texel (x, y) shows the point at
/// unjittered pixel coordinate (x + 0.5, y + 0.5) − jitter.
fn analytic_jittered(cam: &CameraFrame, jitter: DVec2) -> Vec<Option<DVec3>> {
    let n = PLANE_N.normalize();
    let mut out = Vec::new();
    for py in 0..VP.height {
        for px in 0..VP.width {
            let uv = DVec2::new(
                (px as f64 + 0.5 - jitter.x) / VP.width as f64,
                (py as f64 + 0.5 - jitter.y) / VP.height as f64,
            );
            let ndc = DVec2::new(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0);
            let a = cam.clip_to_world.project_point3(ndc.extend(0.5));
            let (origin, dir) = if cam.perspective {
                (cam.eye, (a - cam.eye).normalize())
            } else {
                (a - cam.forward * 100.0, cam.forward)
            };
            let denom = n.dot(dir);
            let t = (PLANE_D / PLANE_N.length() - n.dot(origin)) / denom;
            out.push((denom.abs() > 1e-9 && t > 0.0).then(|| origin + dir * t));
        }
    }
    out
}

/// Rows of `TEX_W × TEX_H` texels, `f(x, y)` inside the viewport and `outside` elsewhere.
fn texels<T: Pod, const N: usize>(outside: [T; N], f: impl Fn(usize) -> [T; N]) -> Vec<u8> {
    let mut v = Vec::new();
    for y in 0..TEX_H {
        for x in 0..TEX_W {
            let inside =
                (VP.x..VP.x + VP.width).contains(&x) && (VP.y..VP.y + VP.height).contains(&y);
            let t = if inside {
                f(((y - VP.y) * VP.width + (x - VP.x)) as usize)
            } else {
                outside
            };
            v.extend_from_slice(bytemuck::cast_slice::<T, u8>(&t));
        }
    }
    v
}

/// Octahedral encoding in [-1, 1]² (the inverse of the shader's decode).
fn oct_encode(n: DVec3) -> DVec2 {
    let p = n / (n.x.abs() + n.y.abs() + n.z.abs());
    if p.z >= 0.0 {
        p.truncate()
    } else {
        let s = DVec2::new(p.x.signum(), p.y.signum());
        (DVec2::ONE - DVec2::new(p.y.abs(), p.x.abs())) * s
    }
}

/// The texel of normal `n` in `ty`'s encoding.
fn encode_normal(ty: NormalType, n: DVec3) -> [f32; 4] {
    let o = oct_encode(n);
    let h = o * 0.5 + 0.5;
    let v = match ty {
        NormalType::RgbVector => [n.x, n.y, n.z, 0.7],
        NormalType::RgbNormalizedVector => [n.x * 0.5 + 0.5, n.y * 0.5 + 0.5, n.z * 0.5 + 0.5, 0.7],
        NormalType::RgOctahedron => [o.x, o.y, 0.3, 0.9],
        NormalType::BaOctahedron => [0.3, 0.9, o.x, o.y],
        NormalType::RgNormalizedOctahedron => [h.x, h.y, 0.3, 0.9],
        NormalType::BaNormalizedOctahedron => [0.3, 0.9, h.x, h.y],
    };
    v.map(|x| x as f32)
}

/// Random unit normals, one per viewport pixel (any direction: decoding is what is tested).
fn random_normals(seed: u64) -> Vec<DVec3> {
    let mut rng = Rng(seed);
    (0..VP.width * VP.height)
        .map(|_| loop {
            let v = DVec3::new(
                rng.range(-1.0, 1.0) as f64,
                rng.range(-1.0, 1.0) as f64,
                rng.range(-1.0, 1.0) as f64,
            );
            let l = v.length();
            if l > 0.1 && l < 1.0 {
                break v / l;
            }
        })
        .collect()
}

fn close(a: f32, b: f64, tol: f64, what: &str) {
    assert!(
        (a as f64 - b).abs() <= tol,
        "{what}: got {a}, expected {b} (tolerance {tol})"
    );
}

/// Checks the probe's output `out` against the analytic surfaces `surf` (and their `normals`)
/// seen by `cam`: position, normal, direction to the eye, view distance, the defaults and the
/// projection back to the pixel.
fn check_decoded(
    out: &[f32],
    surf: &[Option<DVec3>],
    normals: &[DVec3],
    cam: &CameraFrame,
    what: &str,
) {
    for (i, expected) in surf.iter().enumerate() {
        let o = &out[i * STRIDE..(i + 1) * STRIDE];
        let Some(p) = expected else {
            assert_eq!(o[0], 0.0, "{what}: pixel {i} has no surface");
            continue;
        };
        assert_eq!(o[0], 1.0, "{what}: pixel {i} has a surface");
        let scale = 1e-4 * (1.0 + (p - cam.eye).length());
        for k in 0..3 {
            close(
                o[1 + k],
                p[k],
                scale,
                &format!("{what}: pixel {i} position"),
            );
            close(
                o[4 + k],
                normals[i][k],
                2e-5,
                &format!("{what}: pixel {i} normal"),
            );
        }
        let to_eye = if cam.perspective {
            (cam.eye - *p).normalize()
        } else {
            -cam.forward
        };
        for k in 0..3 {
            close(o[7 + k], to_eye[k], 1e-4, &format!("{what}: to_eye"));
        }
        let dist = if cam.perspective {
            (cam.eye - *p).length()
        } else {
            (*p - cam.eye).dot(cam.forward).abs()
        };
        close(o[10], dist, scale, &format!("{what}: view distance"));
        // Defaults: roughness 0.3, metalness 1, no mask.
        close(o[11], 0.3, 1e-6, what);
        close(o[12], 1.0, 0.0, what);
        close(o[16], 1.0, 0.0, what);
        // gb_project takes the surface back to its pixel centre.
        let px = (i as u32 % VP.width) as f64 + 0.5;
        let py = (i as u32 / VP.width) as f64 + 0.5;
        close(o[17], px, 2e-3, &format!("{what}: projected x"));
        close(o[18], py, 2e-3, &format!("{what}: projected y"));
    }
}

/// Both depth types and all six normal types decode the same surfaces, for every camera, and
/// the projection helper maps each surface back to its pixel.
#[test]
fn every_depth_and_normal_type_decodes_the_same_scene() {
    let normals = random_normals(7);
    // A normal_to_world that is not the identity (a rotation), so the transform is exercised.
    let rot = Mat4::from_rotation_y(0.6);
    for (name, w2v, v2c) in cameras() {
        let cam = CameraFrame::new(w2v, v2c);
        let surf = analytic(&cam);
        assert!(
            surf.iter().filter(|s| s.is_some()).count() > 100,
            "{name}: plane visible"
        );
        let clip_depth = texels([cam.far_ndc as f32], |i| match surf[i] {
            Some(p) => [cam.world_to_clip.project_point3(p).z as f32],
            None => [cam.far_ndc as f32],
        });
        let world_pos = texels([f32::NAN; 4], |i| match surf[i] {
            Some(p) => [p.x as f32, p.y as f32, p.z as f32, 1.0],
            None => [f32::NAN; 4],
        });
        let depths = [
            (
                DepthType::RClipSpace,
                testing::texture_with(wgpu::TextureFormat::R32Float, TEX_W, TEX_H, &clip_depth),
            ),
            (
                DepthType::RgbWorldSpace,
                testing::texture_with(wgpu::TextureFormat::Rgba32Float, TEX_W, TEX_H, &world_pos),
            ),
        ];
        let view = ViewInfo {
            world_to_view: w2v,
            view_to_clip: v2c,
            prev_world_to_view: w2v,
            prev_view_to_clip: v2c,
            jitter: glam::Vec2::ZERO,
        };
        for ty in [
            NormalType::RgbVector,
            NormalType::RgbNormalizedVector,
            NormalType::RgOctahedron,
            NormalType::BaOctahedron,
            NormalType::RgNormalizedOctahedron,
            NormalType::BaNormalizedOctahedron,
        ] {
            // The stored normals are in "object" space: normal_to_world rotates them.
            let inv = rot.inverse().as_dmat4();
            let normal_tex = testing::texture_with(
                wgpu::TextureFormat::Rgba32Float,
                TEX_W,
                TEX_H,
                &texels([0.0; 4], |i| {
                    encode_normal(ty, inv.transform_vector3(normals[i]))
                }),
            );
            for (depth_type, depth_tex) in &depths {
                let depth = DepthInput {
                    texture: depth_tex.clone(),
                    depth_type: *depth_type,
                };
                let normal = NormalInput {
                    texture: normal_tex.clone(),
                    normal_type: ty,
                    normal_to_world: rot,
                };
                let inputs = GBufferInputs {
                    depth: &depth,
                    normal: &normal,
                    roughness: None,
                    specular: None,
                    input_mask: None,
                    view: &view,
                    viewport: VP,
                };
                let out = probe(&inputs);
                let what = format!("{name}, {depth_type:?}, {ty:?}");
                check_decoded(&out, &surf, &normals, &cam, &what);
            }
        }
    }
}

/// Roughness (texture channel by mask, multiplier, clamps), specular and the input mask.
/// A depth buffer rasterised with a jittered projection decodes onto the surface the texel
/// shows (not the unjittered ray through the texel centre), for each camera; without the jitter
/// the same texels land a fraction of a pixel away, far outside the tolerance on this tilted
/// plane.
#[test]
fn jittered_clip_depth_is_unprojected_where_it_was_sampled() {
    let jitter = DVec2::new(0.37, -0.41);
    let normals = random_normals(3);
    let normal_tex = testing::texture_with(
        wgpu::TextureFormat::Rgba32Float,
        TEX_W,
        TEX_H,
        &texels([0.0; 4], |i| {
            encode_normal(NormalType::RgbVector, normals[i])
        }),
    );
    for (name, w2v, v2c) in cameras() {
        let cam = CameraFrame::new(w2v, v2c);
        let surf = analytic_jittered(&cam, jitter);
        let clip_depth = texels([cam.far_ndc as f32], |i| match surf[i] {
            Some(p) => [cam.world_to_clip.project_point3(p).z as f32],
            None => [cam.far_ndc as f32],
        });
        let depth = DepthInput {
            texture: testing::texture_with(
                wgpu::TextureFormat::R32Float,
                TEX_W,
                TEX_H,
                &clip_depth,
            ),
            depth_type: DepthType::RClipSpace,
        };
        let normal = NormalInput {
            texture: normal_tex.clone(),
            normal_type: NormalType::RgbVector,
            normal_to_world: Mat4::IDENTITY,
        };
        let mut worst_unjittered = 0.0f64;
        for with_jitter in [true, false] {
            let view = ViewInfo {
                world_to_view: w2v,
                view_to_clip: v2c,
                prev_world_to_view: w2v,
                prev_view_to_clip: v2c,
                jitter: if with_jitter {
                    jitter.as_vec2()
                } else {
                    glam::Vec2::ZERO
                },
            };
            let inputs = GBufferInputs {
                depth: &depth,
                normal: &normal,
                roughness: None,
                specular: None,
                input_mask: None,
                view: &view,
                viewport: VP,
            };
            let out = probe(&inputs);
            for (i, expected) in surf.iter().enumerate() {
                let Some(p) = expected else { continue };
                let o = &out[i * STRIDE..(i + 1) * STRIDE];
                let got = DVec3::new(o[1] as f64, o[2] as f64, o[3] as f64);
                let scale = 1e-4 * (1.0 + (p - cam.eye).length());
                if with_jitter {
                    for k in 0..3 {
                        close(
                            o[1 + k],
                            p[k],
                            scale,
                            &format!("{name}: pixel {i} position"),
                        );
                    }
                } else {
                    worst_unjittered = worst_unjittered.max((got - *p).length() / scale);
                }
            }
        }
        // The check above would not notice a decoder that ignores the jitter unless ignoring it
        // costs more than the tolerance here.
        assert!(
            worst_unjittered > 10.0,
            "{name}: ignoring the jitter moves points only {worst_unjittered} tolerances"
        );
    }
}

#[test]
fn roughness_specular_and_mask_textures_are_read_per_texel() {
    let (_, w2v, v2c) = cameras()[0];
    let cam = CameraFrame::new(w2v, v2c);
    let surf = analytic(&cam);
    let depth = DepthInput {
        texture: testing::texture_with(
            wgpu::TextureFormat::R32Float,
            TEX_W,
            TEX_H,
            &texels([1.0], |i| match surf[i] {
                Some(p) => [cam.world_to_clip.project_point3(p).z as f32],
                None => [1.0],
            }),
        ),
        depth_type: DepthType::RClipSpace,
    };
    let normal = NormalInput {
        texture: testing::texture_with(
            wgpu::TextureFormat::Rgba32Float,
            TEX_W,
            TEX_H,
            &texels([0.0f32; 4], |_| [0.0, 1.0, 0.0, 0.0]),
        ),
        normal_type: NormalType::RgbVector,
        normal_to_world: Mat4::IDENTITY,
    };
    let green = |i: usize| (i % 17) as f32 / 16.0;
    let roughness = RoughnessInput {
        texture: Some(testing::texture_with(
            wgpu::TextureFormat::Rgba32Float,
            TEX_W,
            TEX_H,
            &texels([0.0; 4], |i| [0.9, green(i), 0.9, 0.9]),
        )),
        roughness_mask: glam::Vec4::new(0.0, 1.0, 0.0, 0.0),
        global_roughness: 0.5,
        roughness_multiplier: 2.0,
        min_roughness: 0.1,
        max_roughness: 0.8,
    };
    let specular = SpecularInput {
        texture: Some(testing::texture_with(
            wgpu::TextureFormat::Rgba32Float,
            TEX_W,
            TEX_H,
            &texels([0.0; 4], |i| [i as f32, 0.25, 0.5, 0.75]),
        )),
        global_metalness: 0.0,
    };
    let mask = testing::texture_with(
        wgpu::TextureFormat::Rgba8Unorm,
        TEX_W,
        TEX_H,
        &texels([0u8; 4], |i| {
            if i % 3 == 0 {
                [0, 9, 9, 9]
            } else {
                [200, 0, 0, 0]
            }
        }),
    );
    let view = ViewInfo {
        world_to_view: w2v,
        view_to_clip: v2c,
        ..Default::default()
    };
    let inputs = GBufferInputs {
        depth: &depth,
        normal: &normal,
        roughness: Some(&roughness),
        specular: Some(&specular),
        input_mask: Some(&mask),
        view: &view,
        viewport: VP,
    };
    let out = probe(&inputs);
    for i in 0..(VP.width * VP.height) as usize {
        let o = &out[i * STRIDE..(i + 1) * STRIDE];
        let expected = (green(i) as f64 * 2.0).clamp(0.1, 0.8);
        close(o[11], expected, 1e-6, &format!("roughness of pixel {i}"));
        assert_eq!(
            &o[12..16],
            &[i as f32, 0.25, 0.5, 0.75],
            "specular of pixel {i}"
        );
        assert_eq!(
            o[16],
            if i % 3 == 0 { 0.0 } else { 1.0 },
            "mask of pixel {i}"
        );
    }
}

/// A `Depth32Float` depth buffer binds and decodes: cleared to a constant NDC depth it is a plane
/// facing the camera; cleared to the far plane it holds no surface.
#[test]
fn depth32float_buffers_decode_and_the_far_plane_is_empty() {
    let g = testing::gpu();
    let (_, w2v, v2c) = cameras()[0];
    let cam = CameraFrame::new(w2v, v2c);
    let normal = NormalInput {
        texture: testing::texture_with(
            wgpu::TextureFormat::Rgba32Float,
            TEX_W,
            TEX_H,
            &texels([0.0f32; 4], |_| [0.0, 0.0, 1.0, 0.0]),
        ),
        normal_type: NormalType::RgbVector,
        normal_to_world: Mat4::IDENTITY,
    };
    let view = ViewInfo {
        world_to_view: w2v,
        view_to_clip: v2c,
        ..Default::default()
    };
    for clear in [0.97f32, 1.0] {
        let texture = g.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("test depth"),
            size: wgpu::Extent3d {
                width: TEX_W,
                height: TEX_H,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Depth32Float,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::RENDER_ATTACHMENT,
            view_formats: &[],
        });
        let view_tex = texture.create_view(&Default::default());
        let mut enc = g.device.create_command_encoder(&Default::default());
        enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: None,
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &view_tex,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(clear),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        g.queue.submit([enc.finish()]);
        let depth = DepthInput {
            texture: view_tex,
            depth_type: DepthType::RClipSpace,
        };
        let inputs = GBufferInputs {
            depth: &depth,
            normal: &normal,
            roughness: None,
            specular: None,
            input_mask: None,
            view: &view,
            viewport: VP,
        };
        let out = probe(&inputs);
        for i in 0..(VP.width * VP.height) as usize {
            let o = &out[i * STRIDE..(i + 1) * STRIDE];
            if clear == 1.0 {
                assert_eq!(o[0], 0.0, "far plane at pixel {i}: no surface");
                continue;
            }
            let ndc = DVec2::new(
                ((i as u32 % VP.width) as f64 + 0.5) / VP.width as f64 * 2.0 - 1.0,
                1.0 - ((i as u32 / VP.width) as f64 + 0.5) / VP.height as f64 * 2.0,
            );
            let p = cam.clip_to_world.project_point3(ndc.extend(clear as f64));
            assert_eq!(o[0], 1.0, "pixel {i} has a surface: {o:?}");
            for k in 0..3 {
                close(o[1 + k], p[k], 1e-3, &format!("pixel {i} position"));
            }
        }
    }
}

/// The far plane's NDC depth follows the projection: 1 for normal Z, 0 for reverse Z, finite or
/// infinite, perspective or orthographic.
#[test]
fn far_plane_depth_is_derived_from_the_projection() {
    let v = Mat4::IDENTITY;
    let cases = [
        (Mat4::perspective_rh(1.0, 1.0, 0.1, 10.0), 1.0),
        (Mat4::perspective_infinite_rh(1.0, 1.0, 0.1), 1.0),
        (Mat4::perspective_infinite_reverse_rh(1.0, 1.0, 0.1), 0.0),
        (Mat4::orthographic_rh(-1.0, 1.0, -1.0, 1.0, 0.1, 10.0), 1.0),
        (Mat4::orthographic_rh(-1.0, 1.0, -1.0, 1.0, 10.0, 0.1), 0.0),
    ];
    for (i, (p, far)) in cases.into_iter().enumerate() {
        assert_eq!(CameraFrame::new(v, p).far_ndc, far, "case {i}");
    }
}
