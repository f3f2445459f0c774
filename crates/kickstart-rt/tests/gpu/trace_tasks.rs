//! The trace tasks through the public API, with the SDK's own BVH build and lighting cache:
//! furnace (a closed sphere whose cache is uniform radiance L), the four-coloured scene of
//! reference/instance-id-bug-report.ko.md, ambient occlusion of an open plane, and the bad
//! inputs the trace tasks name.

use crate::common;
use common::cache::{cast, Rect};
use common::rt::*;
use common::trace::*;
use common::*;
use glam::{Affine3A, DAffine3, DQuat, DVec3, Mat4, Quat, Vec3};
use kickstart_rt::*;
use wgpu::{TextureFormat as F, TextureUsages as U};

/// Registers `mesh` as one instance at `transform` with initial tile colour `colour`.
fn add(ctx: &ExecuteContext, c: &mut TaskContainer, m: &Mesh, transform: Affine3A, colour: Vec3) {
    let g = ctx.create_geometry_handle();
    let i = ctx.create_instance_handle();
    schedule_mesh(c, g, "mesh", m);
    let mut input = InstanceInput::new(g, transform);
    input.initial_tile_color = colour.extend(1.0);
    c.schedule_bvh_task(InstanceTask {
        operation: TaskOperation::Register,
        handle: i,
        input,
    });
}

fn build(ctx: &ExecuteContext, mut c: TaskContainer) {
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 100,
        ..Default::default()
    });
    build_submit_complete(ctx, c);
}

const N: u32 = 16;

#[test]
fn furnace_inside_a_uniform_cache_gives_l_for_specular_and_diffuse_at_every_roughness() {
    let ctx = context(4);
    let l = Vec3::new(0.25, 0.5, 2.0);
    let mut c = ctx.create_task_container();
    add(
        &ctx,
        &mut c,
        &Mesh::icosphere(2),
        Affine3A::from_scale(Vec3::splat(2.0)),
        l,
    );
    build(&ctx, c);
    let mut rng = Rng(9);
    let texels: Vec<(Vec3, Vec3)> = (0..N * N).map(|_| (rng.v(-1.0, 1.0), rng.unit())).collect();
    let gb = |x: u32, y: u32| Some(texels[(y * N + x) as usize]);
    for bilinear in [true, false] {
        for roughness in [0.0, 0.3, 0.7, 1.0] {
            let mut common = gbuffer_common(N, N, Vec3::new(0.0, 1.5, 0.0), gb);
            common.roughness.global_roughness = roughness;
            common.use_bilinear_sampling = bilinear;
            let (spec, diff) = (output(N, N), output(N, N));
            run_tasks(
                &ctx,
                vec![
                    RenderTask::TraceSpecular(TraceSpecularTask {
                        common: common.clone(),
                        output: spec.clone(),
                        demodulate_specular: false,
                        demodulation_output: None,
                    }),
                    RenderTask::TraceDiffuse(TraceDiffuseTask {
                        common,
                        output: diff.clone(),
                        diffuse_brdf: DiffuseBrdf::Lambertian,
                        ambient_occlusion: None,
                    }),
                ],
            );
            for (what, img) in [
                ("specular", read_rgba32(&spec)),
                ("diffuse", read_rgba32(&diff)),
            ] {
                for (i, v) in img.iter().enumerate() {
                    let got = Vec3::new(v[0], v[1], v[2]);
                    assert!(
                        (got - l).abs().max_element() < 1e-4 * 2.0,
                        "{what} roughness {roughness} bilinear {bilinear} texel {i}: {got}, want {l}"
                    );
                    assert!(v[3] > 0.0 && v[3] < 4.0, "{what}: hit distance {}", v[3]);
                }
            }
        }
    }
}

/// Normalised Disney diffuse (Frostbite's form) seen head-on (V = N), integrated over the
/// cosine-weighted hemisphere on the CPU: with V = N, L·H = cos(θ/2), so L·H² = (1 + cos θ)/2.
fn disney_albedo_head_on(roughness: f64) -> f64 {
    let steps = 20000;
    let mut sum = 0.0;
    for i in 0..steps {
        let mu = (i as f64 + 0.5) / steps as f64;
        let fd90 = 0.5 * roughness + 2.0 * (1.0 + mu) / 2.0 * roughness;
        let light = 1.0 + (fd90 - 1.0) * (1.0 - mu).powi(5);
        let energy = 1.0 + (1.0 / 1.51 - 1.0) * roughness;
        sum += light * energy * 2.0 * mu / steps as f64;
    }
    sum
}

/// The same furnace seen head-on with the normalised Disney BRDF: the mean output is L times
/// the BRDF's albedo, integrated independently on the CPU.
#[test]
fn furnace_with_normalised_disney_matches_its_albedo() {
    let ctx = context(4);
    let l = Vec3::new(0.25, 0.5, 2.0);
    let mut c = ctx.create_task_container();
    add(
        &ctx,
        &mut c,
        &Mesh::icosphere(2),
        Affine3A::from_scale(Vec3::splat(2.0)),
        l,
    );
    build(&ctx, c);
    let eye = Vec3::new(0.0, 1.5, 0.0);
    let mut rng = Rng(4);
    let texels: Vec<(Vec3, Vec3)> = (0..N * N)
        .map(|_| {
            let p = rng.v(-0.5, 0.5);
            (p, (eye - p).normalize())
        })
        .collect();
    for roughness in [0.0f32, 0.5, 1.0] {
        let (mut sum, mut n) = (0.0f64, 0.0);
        for frame in 0..4 {
            let mut common = gbuffer_common(N, N, eye, |x, y| Some(texels[(y * N + x) as usize]));
            common.roughness.global_roughness = roughness;
            common.debug_parameters.frame_index = frame;
            let out = output(N, N);
            run_tasks(
                &ctx,
                vec![RenderTask::TraceDiffuse(TraceDiffuseTask {
                    common,
                    output: out.clone(),
                    diffuse_brdf: DiffuseBrdf::NormalizedDisney,
                    ambient_occlusion: None,
                })],
            );
            for v in read_rgba32(&out) {
                sum += (v[2] / l.z) as f64;
                n += 1.0;
            }
        }
        let want = disney_albedo_head_on(roughness as f64);
        assert!(
            (sum / n - want).abs() < 0.02,
            "roughness {roughness}: mean {} × L, albedo {want}",
            sum / n
        );
    }
}

/// A (2, 3) torus knot tube.
fn torus_knot(scale: f32, tube: f32) -> Mesh {
    let (segs, sides) = (96u32, 8u32);
    let curve = |t: f32| {
        let (p, q) = (2.0, 3.0);
        let r = 2.0 + (q * t).cos();
        Vec3::new(r * (p * t).cos(), (q * t).sin(), r * (p * t).sin()) * scale
    };
    let mut positions = Vec::new();
    for i in 0..segs {
        let t = std::f32::consts::TAU * i as f32 / segs as f32;
        let c = curve(t);
        let tangent = (curve(t + 1e-3) - curve(t - 1e-3)).normalize();
        let n = tangent.cross(Vec3::Y).normalize();
        let b = tangent.cross(n);
        for j in 0..sides {
            let a = std::f32::consts::TAU * j as f32 / sides as f32;
            positions.push(c + tube * (n * a.cos() + b * a.sin()));
        }
    }
    let mut indices = Vec::new();
    for i in 0..segs {
        for j in 0..sides {
            let v = |i: u32, j: u32| (i % segs) * sides + j % sides;
            indices.extend([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
            indices.extend([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
        }
    }
    Mesh { positions, indices }
}

/// An open cylinder of radius r along z, from -half to half.
fn tube(r: f32, half: f32) -> Mesh {
    let sides = 16u32;
    let mut positions = Vec::new();
    for end in [-half, half] {
        for j in 0..sides {
            let a = std::f32::consts::TAU * j as f32 / sides as f32;
            positions.push(Vec3::new(r * a.cos(), r * a.sin(), end));
        }
    }
    let mut indices = Vec::new();
    for j in 0..sides {
        let k = (j + 1) % sides;
        indices.extend([j, k, sides + k, j, sides + k, sides + j]);
    }
    Mesh { positions, indices }
}

/// The scene of the instance-id bug report: an icosahedron sphere (red), a torus knot (green), a
/// tube (blue) and a floor (grey), each its own instance with its own cached colour. The diffuse
/// GI of the floor under each mesh must be that mesh's colour — with the bug, every patch took
/// the first instance's.
#[test]
fn four_coloured_scene_keeps_each_meshs_colour_near_it() {
    let ctx = context(4);
    let mut c = ctx.create_task_container();
    let red = Vec3::new(1.0, 0.0, 0.0);
    let green = Vec3::new(0.0, 1.0, 0.0);
    let blue = Vec3::new(0.0, 0.0, 1.0);
    let centres = [-3.0f32, 0.0, 3.0];
    add(
        &ctx,
        &mut c,
        &Mesh::icosphere(1),
        Affine3A::from_scale_rotation_translation(
            Vec3::splat(0.6),
            Quat::IDENTITY,
            Vec3::new(centres[0], 0.8, 0.0),
        ),
        red,
    );
    add(
        &ctx,
        &mut c,
        &torus_knot(0.3, 0.12),
        Affine3A::from_translation(Vec3::new(centres[1], 0.8, 0.0)),
        green,
    );
    add(
        &ctx,
        &mut c,
        &tube(0.35, 1.0),
        Affine3A::from_translation(Vec3::new(centres[2], 0.5, 0.0)),
        blue,
    );
    add(
        &ctx,
        &mut c,
        &Mesh::cuboid(Vec3::new(-6.0, -0.1, -6.0), Vec3::new(6.0, 0.0, 6.0)),
        Affine3A::IDENTITY,
        Vec3::splat(0.3),
    );
    build(&ctx, c);
    // Three 8×8 floor patches, one under each mesh.
    let (w, h) = (24u32, 8u32);
    let pos = |x: u32, y: u32| {
        let cx = centres[(x / 8) as usize];
        Vec3::new(
            cx - 0.35 + 0.7 * ((x % 8) as f32 + 0.5) / 8.0,
            0.0,
            -0.35 + 0.7 * (y as f32 + 0.5) / 8.0,
        )
    };
    let mut sums = [Vec3::ZERO; 3];
    for frame in 0..8 {
        let mut common = gbuffer_common(w, h, Vec3::new(0.0, 4.0, 4.0), |x, y| {
            Some((pos(x, y), Vec3::Y))
        });
        common.debug_parameters.frame_index = frame;
        let out = output(w, h);
        run_tasks(
            &ctx,
            vec![RenderTask::TraceDiffuse(TraceDiffuseTask {
                common,
                output: out.clone(),
                diffuse_brdf: DiffuseBrdf::Lambertian,
                ambient_occlusion: None,
            })],
        );
        for (i, v) in read_rgba32(&out).iter().enumerate() {
            sums[(i as u32 % w / 8) as usize] += Vec3::new(v[0], v[1], v[2]);
        }
    }
    for (k, (sum, want)) in sums.iter().zip([red, green, blue]).enumerate() {
        let mean = *sum / (8.0 * 64.0);
        let own = mean.dot(want);
        let other = (mean - want * own).max_element();
        assert!(
            own > 0.1 && own > 4.0 * other,
            "patch {k}: mean {mean}, expected the colour {want} to dominate"
        );
    }
}

#[test]
fn ao_of_an_open_plane_through_the_sdk_is_one() {
    let ctx = context(4);
    let mut c = ctx.create_task_container();
    add(
        &ctx,
        &mut c,
        &Mesh::cuboid(Vec3::new(-5.0, -0.1, -5.0), Vec3::new(5.0, 0.0, 5.0)),
        Affine3A::IDENTITY,
        Vec3::ONE,
    );
    build(&ctx, c);
    let common = gbuffer_common(N, N, Vec3::new(0.0, 3.0, 0.0), |x, y| {
        Some((
            Vec3::new(x as f32 * 0.1 - 0.8, 0.0, y as f32 * 0.1 - 0.8),
            Vec3::Y,
        ))
    });
    let out = output(N, N);
    run_tasks(
        &ctx,
        vec![RenderTask::TraceAmbientOcclusion(
            TraceAmbientOcclusionTask {
                common,
                output: out.clone(),
                ao_radius: 1.0,
            },
        )],
    );
    assert!(read_rgba32(&out).iter().all(|v| v[0] == 1.0));
}

/// Builds a container holding `task`; expects `InvalidInput` naming `field`, and a usable context.
fn refused(task: RenderTask, field: &str) {
    let ctx = context(2);
    let mut c = ctx.create_task_container();
    c.schedule_render_task(task);
    let mut e = encoder();
    match ctx.build_gpu_task(c, &mut e) {
        Err(Error::InvalidInput { field: f, .. }) => assert_eq!(f, field),
        other => panic!("expected InvalidInput for {field}, got {other:?}"),
    }
    submit(e);
    build_submit_complete(&ctx, ctx.create_task_container());
}

fn plain_common() -> TraceTaskCommon {
    gbuffer_common(8, 8, Vec3::new(0.0, 3.0, 0.0), |_, _| {
        Some((Vec3::ZERO, Vec3::Y))
    })
}

#[test]
fn multi_shadow_outputs_need_four_channels() {
    let light = LightInfo::Point {
        position: Vec3::Y,
        radius: 0.0,
        range: 10.0,
    };
    for (o0, o1, field) in [
        (F::R32Float, F::Rgba16Float, "output0"),
        (F::Rgba16Float, F::Rg32Float, "output1"),
    ] {
        refused(
            RenderTask::TraceMultiShadow(TraceMultiShadowTask {
                common: plain_common(),
                output0: texture(o0, 8, 8, U::STORAGE_BINDING),
                output1: texture(o1, 8, 8, U::STORAGE_BINDING),
                lights: vec![light; 2],
                enable_first_hit_and_end_search: true,
            }),
            field,
        );
    }
    // An output1 smaller than the viewport.
    refused(
        RenderTask::TraceMultiShadow(TraceMultiShadowTask {
            common: plain_common(),
            output0: texture(F::Rgba16Float, 8, 8, U::STORAGE_BINDING),
            output1: texture(F::Rgba16Float, 4, 8, U::STORAGE_BINDING),
            lights: vec![light; 2],
            enable_first_hit_and_end_search: true,
        }),
        "viewport",
    );
}

#[test]
fn integer_and_multisampled_inputs_are_refused() {
    let ao = |common| {
        RenderTask::TraceAmbientOcclusion(TraceAmbientOcclusionTask {
            common,
            output: output(8, 8),
            ao_radius: 1.0,
        })
    };
    let mut c = plain_common();
    c.depth.texture = texture(F::R32Uint, 8, 8, U::TEXTURE_BINDING);
    refused(ao(c), "common.depth.texture");
    let mut c = plain_common();
    c.normal.texture = gpu()
        .device
        .create_texture(&wgpu::TextureDescriptor {
            label: None,
            size: wgpu::Extent3d {
                width: 8,
                height: 8,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 4,
            dimension: wgpu::TextureDimension::D2,
            format: F::Rgba8Unorm,
            usage: U::TEXTURE_BINDING | U::RENDER_ATTACHMENT,
            view_formats: &[],
        })
        .create_view(&Default::default());
    refused(ao(c), "common.normal.texture");
    // A direct lighting texture smaller than the viewport.
    let mut c = plain_common();
    c.direct_lighting = Some(texture(F::Rgba16Float, 4, 4, U::TEXTURE_BINDING));
    refused(
        RenderTask::TraceSpecular(TraceSpecularTask {
            common: c,
            output: output(8, 8),
            demodulate_specular: false,
            demodulation_output: None,
        }),
        "viewport",
    );
}

#[test]
fn specular_demodulation_output_must_match_the_viewport() {
    refused(
        RenderTask::TraceSpecular(TraceSpecularTask {
            common: plain_common(),
            output: output(8, 8),
            demodulate_specular: true,
            demodulation_output: Some(texture(F::Rgba16Float, 4, 4, U::STORAGE_BINDING)),
        }),
        "viewport",
    );
}

// --- Every depth and normal encoding of one G-buffer traces to the same result ---------------

/// The encoding test's box: local extent, yaw about y and position (its base on the ground).
const BOX_LO: Vec3 = Vec3::new(-0.4, 0.0, -0.4);
const BOX_HI: Vec3 = Vec3::new(0.4, 0.7, 0.4);
const BOX_YAW: f32 = 0.5;
const BOX_AT: Vec3 = Vec3::new(0.2, 0.0, -0.1);
/// Half size of the ground slab (top at y = 0).
const GROUND: f64 = 8.0;

fn box_transform() -> Affine3A {
    Affine3A::from_rotation_translation(Quat::from_rotation_y(BOX_YAW), BOX_AT)
}

/// Entry distance and outward normal of a ray with an axis-aligned box (`None` when it starts
/// on or inside the box, or misses).
fn slab(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3) -> Option<(f64, DVec3)> {
    let inv = d.recip();
    let t0 = (lo - o) * inv;
    let t1 = (hi - o) * inv;
    let (tmin, tmax) = (t0.min(t1), t0.max(t1));
    let (near, far) = (tmin.max_element(), tmax.min_element());
    if near > far || near <= 1e-9 {
        return None;
    }
    let axis = (0..3).find(|&k| tmin[k] == near).unwrap();
    let mut n = DVec3::ZERO;
    n[axis] = -d[axis].signum();
    Some((near, n))
}

/// The encoding test's scene on the CPU, in f64: the ground slab's top and the rotated box.
struct GroundAndBox {
    to_world: DAffine3,
    to_local: DAffine3,
}

impl GroundAndBox {
    fn new() -> Self {
        let to_world = DAffine3::from_rotation_translation(
            DQuat::from_rotation_y(BOX_YAW as f64),
            BOX_AT.as_dvec3(),
        );
        GroundAndBox {
            to_world,
            to_local: to_world.inverse(),
        }
    }

    /// The box along a ray: (distance, world normal).
    fn box_hit(&self, o: DVec3, d: DVec3) -> Option<(f64, DVec3)> {
        slab(
            self.to_local.transform_point3(o),
            self.to_local.transform_vector3(d),
            BOX_LO.as_dvec3(),
            BOX_HI.as_dvec3(),
        )
        .map(|(t, n)| (t, self.to_world.transform_vector3(n)))
    }

    /// What a camera ray sees: (position, normal, object: 0 ground, 1 box).
    fn cast(&self, o: DVec3, d: DVec3) -> Option<(DVec3, DVec3, u32)> {
        let mut best: Option<(f64, DVec3, u32)> = None;
        if d.y < 0.0 {
            let t = -o.y / d.y;
            let p = o + d * t;
            if p.x.abs() <= GROUND && p.z.abs() <= GROUND {
                best = Some((t, DVec3::Y, 0));
            }
        }
        if let Some((t, n)) = self.box_hit(o, d) {
            if best.is_none_or(|b| t < b.0) {
                best = Some((t, n, 1));
            }
        }
        best.map(|(t, n, k)| (o + d * t, n, k))
    }

    /// Distance from `p` to the box.
    fn distance_to_box(&self, p: DVec3) -> f64 {
        let q = self.to_local.transform_point3(p);
        (q - q.clamp(BOX_LO.as_dvec3(), BOX_HI.as_dvec3())).length()
    }
}

/// Per-pixel comparison of two traces of one scene: (AO, shadow) values, R channel.
struct Traced {
    ao: Vec<f32>,
    shadow: Vec<f32>,
}

/// Pixels of `b` that differ from `a`: AO by more than `ao_tol`, shadow in kind (lit −1,
/// facing away 0, occluded > 0) or, occluded in both, in distance by more than `t_tol`.
fn differing(a: &Traced, b: &Traced, ao_tol: f32, t_tol: f32) -> (usize, usize) {
    let ao =
        a.ao.iter()
            .zip(&b.ao)
            .filter(|(x, y)| (*x - *y).abs() > ao_tol || x.is_nan() != y.is_nan())
            .count();
    let kind = |v: f32| {
        if v < 0.0 {
            0
        } else if v == 0.0 {
            1
        } else {
            2
        }
    };
    let shadow = a
        .shadow
        .iter()
        .zip(&b.shadow)
        .filter(|(x, y)| kind(**x) != kind(**y) || (kind(**x) == 2 && (*x - *y).abs() > t_tol))
        .count();
    (ao, shadow)
}

/// The encoding test's image size.
const ENC_W: u32 = 48;
const ENC_H: u32 = 48;

/// A static camera (previous view = current) with `world_to_view` and `view_to_clip`.
fn static_view(world_to_view: Mat4, view_to_clip: Mat4) -> ViewInfo {
    ViewInfo {
        world_to_view,
        view_to_clip,
        prev_world_to_view: world_to_view,
        prev_view_to_clip: view_to_clip,
        ..Default::default()
    }
}

/// The encoding test's setup: the ground slab and the rotated box built on the device and on
/// the CPU, the camera (one frustum as a normal-Z and a reverse-Z infinite projection), what
/// each pixel sees, and the light and AO radius of every trace.
struct EncodingScene {
    ctx: ExecuteContext,
    scene: GroundAndBox,
    world_to_view: Mat4,
    normal_z: Mat4,
    reverse_z: Mat4,
    /// Per pixel: (position, normal, object: 0 ground, 1 box), `None` where nothing is seen.
    surfaces: Vec<Option<(DVec3, DVec3, u32)>>,
    positions: Vec<Option<DVec3>>,
    normals: Vec<DVec3>,
    n_surface: usize,
    to_light: DVec3,
    light: LightInfo,
    ao_radius: f32,
}

impl EncodingScene {
    fn new() -> Self {
        let ctx = context(4);
        let mut c = ctx.create_task_container();
        add(
            &ctx,
            &mut c,
            &Mesh::cuboid(
                Vec3::new(-GROUND as f32, -0.1, -GROUND as f32),
                Vec3::new(GROUND as f32, 0.0, GROUND as f32),
            ),
            Affine3A::IDENTITY,
            Vec3::ONE,
        );
        add(
            &ctx,
            &mut c,
            &Mesh::cuboid(BOX_LO, BOX_HI),
            box_transform(),
            Vec3::ONE,
        );
        build(&ctx, c);
        let scene = GroundAndBox::new();

        let fov = 0.8;
        let world_to_view =
            Mat4::look_at_rh(Vec3::new(1.8, 2.2, 2.4), Vec3::new(0.1, 0.3, -0.1), Vec3::Y);
        let normal_z = Mat4::perspective_rh(fov, 1.0, 0.1, 50.0);
        let reverse_z = Mat4::perspective_infinite_reverse_rh(fov, 1.0, 0.1);
        let view = static_view(world_to_view, normal_z);
        let surfaces: Vec<Option<(DVec3, DVec3, u32)>> = (0..ENC_W * ENC_H)
            .map(|i| {
                let (o, d) = pixel_ray(&view, ENC_W, ENC_H, i % ENC_W, i / ENC_W);
                scene.cast(o, d)
            })
            .collect();
        let positions: Vec<Option<DVec3>> = surfaces.iter().map(|s| s.map(|s| s.0)).collect();
        // Where nothing was rendered the normal points down, away from the light: a decode that
        // took the far plane for a surface would write "shadowed at distance 0" there, not "lit".
        let normals: Vec<DVec3> = surfaces
            .iter()
            .map(|s| s.map_or(DVec3::NEG_Y, |s| s.1))
            .collect();
        let n_surface = surfaces.iter().filter(|s| s.is_some()).count();
        let n_box = surfaces
            .iter()
            .filter(|s| s.is_some_and(|s| s.2 == 1))
            .count();
        assert!(
            n_surface < (ENC_W * ENC_H) as usize - 40 && n_box > 150,
            "the view shows sky ({}), ground and box ({n_box})",
            (ENC_W * ENC_H) as usize - n_surface
        );

        let to_light = DVec3::new(-1.0, 0.9, -0.6).normalize();
        let light = LightInfo::Directional {
            direction: -to_light.as_vec3(),
            angular_extent: 0.0,
        };
        EncodingScene {
            ctx,
            scene,
            world_to_view,
            normal_z,
            reverse_z,
            surfaces,
            positions,
            normals,
            n_surface,
            to_light,
            light,
            ao_radius: 0.5,
        }
    }

    /// The camera with the projection `view_to_clip`.
    fn view_of(&self, view_to_clip: Mat4) -> ViewInfo {
        static_view(self.world_to_view, view_to_clip)
    }

    /// The AO task and the hard shadow task at frame 5 on the G-buffer (`depth`, `normal`)
    /// seen with `view_to_clip`: their R channels.
    fn trace(&self, depth: DepthInput, normal: NormalInput, view_to_clip: Mat4) -> Traced {
        let mut common = TraceTaskCommon::new(depth, normal);
        common.view = self.view_of(view_to_clip);
        common.ray_offset.offset_type = RayOffsetType::WorldPosition;
        common.debug_parameters.frame_index = 5;
        let (ao, shadow) = (output(ENC_W, ENC_H), output(ENC_W, ENC_H));
        run_tasks(
            &self.ctx,
            vec![
                RenderTask::TraceAmbientOcclusion(TraceAmbientOcclusionTask {
                    common: common.clone(),
                    output: ao.clone(),
                    ao_radius: self.ao_radius,
                }),
                RenderTask::TraceShadow(TraceShadowTask {
                    common,
                    output: shadow.clone(),
                    light: self.light,
                    enable_first_hit_and_end_search: false,
                }),
            ],
        );
        Traced {
            ao: read_rgba32(&ao).iter().map(|v| v[0]).collect(),
            shadow: read_rgba32(&shadow).iter().map(|v| v[0]).collect(),
        }
    }

    /// The depth input of the pixels' surfaces in `enc`, seen with `view_to_clip`, each
    /// clip-space view distance times `scale`.
    fn depth(&self, enc: DepthEncoding, view_to_clip: Mat4, scale: f64) -> DepthInput {
        encode_depth(
            enc,
            ENC_W,
            ENC_H,
            &self.view_of(view_to_clip),
            &self.positions,
            scale,
        )
    }

    /// The normal input of the pixels' normals in `ty` and `format`, via `normal_to_world`.
    fn normal(&self, ty: NormalType, format: F, normal_to_world: Mat4) -> NormalInput {
        encode_normals(ty, format, normal_to_world, ENC_W, ENC_H, &self.normals)
    }

    /// World-space float normals in `ty`.
    fn f32_normals(&self, ty: NormalType) -> NormalInput {
        self.normal(ty, F::Rgba32Float, Mat4::IDENTITY)
    }
}

/// The reference's shadow against the CPU, away from the boundaries of (object, kind) regions.
fn check_reference_shadow(e: &EncodingScene, reference: &Traced) {
    let labels: Vec<Option<(u32, u32, Option<f64>)>> = e
        .surfaces
        .iter()
        .map(|s| {
            s.map(|(p, n, k)| {
                if n.dot(e.to_light) <= 0.0 {
                    (k, 1, None)
                } else if let Some((t, _)) = e.scene.box_hit(p, e.to_light) {
                    (k, 2, Some(t))
                } else {
                    (k, 0, None)
                }
            })
        })
        .collect();
    let kinds: Vec<Option<(u32, u32)>> = labels.iter().map(|l| l.map(|l| (l.0, l.1))).collect();
    let mut checked = [0usize; 3];
    for (i, label) in labels.iter().enumerate() {
        let got = reference.shadow[i];
        let Some((_, kind, t)) = *label else {
            assert_eq!(got, -1.0, "pixel {i} shows nothing: lit");
            assert_eq!(reference.ao[i], 1.0, "pixel {i} shows nothing: open");
            continue;
        };
        if !away_from_boundaries(&kinds, ENC_W, ENC_H, i as u32 % ENC_W, i as u32 / ENC_W, 1) {
            continue;
        }
        checked[kind as usize] += 1;
        match kind {
            // Lit: minus the tangent of the light's angular radius, at least f16's smallest
            // normal (this light is a point at infinity).
            0 => assert_eq!(got, -6.103_515_6e-5, "pixel {i}: the light is visible"),
            1 => assert_eq!(got, 0.0, "pixel {i}: faces away from the light"),
            _ => {
                let t = t.unwrap();
                assert!(
                    (got as f64 - t).abs() < 2e-3 * (1.0 + t),
                    "pixel {i}: occluder at {t}, traced {got}"
                );
            }
        }
    }
    assert!(
        checked.iter().all(|&n| n > 40),
        "lit / facing away / shadowed pixels checked: {checked:?}"
    );
}

/// The reference's AO against the CPU: exactly 1 where no geometry lies within the radius above
/// the surface (ground far from the box, the box's top); below 1 only where the box or the
/// ground is within it.
fn check_reference_ao(e: &EncodingScene, reference: &Traced) {
    let ao_radius = e.ao_radius;
    let (mut open, mut occluded) = (0, 0);
    for (i, s) in e.surfaces.iter().enumerate() {
        let Some((p, n, k)) = s else { continue };
        let ground_open = *k == 0 && e.scene.distance_to_box(*p) > ao_radius as f64 + 1e-3;
        if ground_open || (*k == 1 && n.y > 0.5) {
            assert_eq!(
                reference.ao[i], 1.0,
                "pixel {i} at {p}: nothing within the radius"
            );
            open += 1;
        }
        if reference.ao[i] < 1.0 {
            let near = if *k == 0 {
                e.scene.distance_to_box(*p) < ao_radius as f64
            } else {
                p.y < ao_radius as f64
            };
            assert!(near, "pixel {i} at {p}: occluded with nothing near");
            occluded += 1;
        }
    }
    assert!(
        open > 300 && occluded > 40,
        "open {open}, occluded {occluded}"
    );
}

/// One G-buffer encoding: (name, depth, normal, projection, 8-bit normals).
type EncodingVariant = (String, DepthInput, NormalInput, Mat4, bool);

/// Every encoding compared with the reference. A rotation whose inverse takes the ground's
/// normal to z > 0 and the box's front face to z < 0, so both branches of the octahedral decode
/// are used.
fn encoding_variants(e: &EncodingScene) -> Vec<EncodingVariant> {
    let (normal_z, reverse_z) = (e.normal_z, e.reverse_z);
    let rotated = Mat4::from_rotation_x(-2.2);
    let view_space = e.world_to_view.inverse();
    let stored_z: Vec<f64> = e
        .surfaces
        .iter()
        .flatten()
        .map(|s| rotated.as_dmat4().inverse().transform_vector3(s.1).z)
        .collect();
    assert!(
        stored_z.iter().filter(|z| **z < -0.1).count() > 50
            && stored_z.iter().filter(|z| **z > 0.1).count() > 50,
        "both octahedral hemispheres are used"
    );
    let mut variants: Vec<EncodingVariant> = Vec::new();
    for (enc, proj, proj_name) in [
        (DepthEncoding::ClipR32Float, normal_z, "normal Z"),
        (DepthEncoding::ClipR32Float, reverse_z, "reverse-Z infinite"),
        (DepthEncoding::ClipDepth32Float, normal_z, "normal Z"),
        (
            DepthEncoding::ClipDepth32Float,
            reverse_z,
            "reverse-Z infinite",
        ),
    ] {
        variants.push((
            format!("{enc:?} {proj_name}"),
            e.depth(enc, proj, 1.0),
            e.f32_normals(NormalType::RgbVector),
            proj,
            false,
        ));
    }
    for (ty, format, to_world, space) in [
        (NormalType::RgbVector, F::Rgba32Float, rotated, "rotated"),
        (
            NormalType::RgbNormalizedVector,
            F::Rgba32Float,
            rotated,
            "rotated",
        ),
        (NormalType::RgOctahedron, F::Rgba32Float, rotated, "rotated"),
        (
            NormalType::BaOctahedron,
            F::Rgba32Float,
            view_space,
            "view space",
        ),
        (
            NormalType::RgNormalizedOctahedron,
            F::Rgba32Float,
            view_space,
            "view space",
        ),
        (
            NormalType::BaNormalizedOctahedron,
            F::Rgba32Float,
            rotated,
            "rotated",
        ),
        (
            NormalType::RgbNormalizedVector,
            F::Rgba8Unorm,
            Mat4::IDENTITY,
            "world",
        ),
        (NormalType::RgOctahedron, F::Rgba8Snorm, rotated, "rotated"),
        (
            NormalType::BaNormalizedOctahedron,
            F::Rgba8Unorm,
            view_space,
            "view space",
        ),
    ] {
        variants.push((
            format!("{ty:?} {format:?} {space}"),
            e.depth(DepthEncoding::WorldPosition, normal_z, 1.0),
            e.normal(ty, format, to_world),
            normal_z,
            format != F::Rgba32Float,
        ));
    }
    // A typical engine G-buffer: a reverse-Z depth buffer and 8-bit view-space octahedral normals.
    variants.push((
        "ClipDepth32Float reverse-Z infinite + RgNormalizedOctahedron Rgba8Unorm view space".into(),
        e.depth(DepthEncoding::ClipDepth32Float, reverse_z, 1.0),
        e.normal(
            NormalType::RgNormalizedOctahedron,
            F::Rgba8Unorm,
            view_space,
        ),
        reverse_z,
        true,
    ));
    variants
}

/// Traces every variant; each may differ from the reference in at most `float_allowed` shadow
/// pixels and `float_allowed` AO pixels (by more than 2e-3), or with 8-bit normals
/// `quantised_allowed` AO pixels (by more than 0.05).
fn check_variants(
    e: &EncodingScene,
    reference: &Traced,
    variants: Vec<EncodingVariant>,
    float_allowed: usize,
    quantised_allowed: usize,
) {
    let n_surface = e.n_surface;
    for (name, d, n, proj, quantised) in variants {
        let got = e.trace(d, n, proj);
        let (ao_tol, allowed_ao) = if quantised {
            (0.05, quantised_allowed)
        } else {
            (2e-3, float_allowed)
        };
        let (ao, shadow) = differing(reference, &got, ao_tol, 2e-3);
        eprintln!("{name}: {ao} AO and {shadow} shadow pixels differ (of {n_surface})");
        assert!(
            ao <= allowed_ao && shadow <= float_allowed,
            "{name}: {ao} AO pixels (allowed {allowed_ao}) and {shadow} shadow pixels (allowed \
             {float_allowed}) differ from the reference"
        );
    }
}

/// The bounds catch wrong decodes: flipped normals, and a depth 0.5 % too far.
fn check_wrong_on_purpose_is_rejected(
    e: &EncodingScene,
    reference: &Traced,
    quantised_allowed: usize,
) {
    let normal_z = e.normal_z;
    let flipped: Vec<DVec3> = e.normals.iter().map(|n| -*n).collect();
    for (name, d, n) in [
        (
            "flipped normals",
            e.depth(DepthEncoding::WorldPosition, normal_z, 1.0),
            encode_normals(
                NormalType::RgbVector,
                F::Rgba32Float,
                Mat4::IDENTITY,
                ENC_W,
                ENC_H,
                &flipped,
            ),
        ),
        (
            "depth 0.5 % too far",
            e.depth(DepthEncoding::ClipR32Float, normal_z, 1.005),
            e.f32_normals(NormalType::RgbVector),
        ),
    ] {
        let got = e.trace(d, n, normal_z);
        let (ao, shadow) = differing(reference, &got, 0.05, 2e-3);
        eprintln!("wrong on purpose, {name}: {ao} AO and {shadow} shadow pixels differ");
        assert!(
            ao > 10 * quantised_allowed || shadow > 10 * quantised_allowed,
            "{name}: the comparison must reject it ({ao} AO, {shadow} shadow pixels differ)"
        );
    }
}

/// One camera sees a ground slab and a rotated box; the G-buffer is written once per depth
/// encoding (RgbWorldSpace; RClipSpace in R32Float and in a Depth32Float depth buffer, each with
/// a normal-Z and a reverse-Z infinite projection of the same frustum) and once per normal
/// encoding (all six NormalTypes, world-space, rotated or view-space via `normal_to_world`, in
/// Rgba32Float and in 8-bit formats). An AO task and a hard directional shadow task at a fixed
/// frame index must give every encoding the reference encoding's result per pixel.
///
/// The reference itself is checked against the CPU: its shadow (kind and distance) against an
/// analytic ray–box test away from shadow and object boundaries, its AO exactly 1 wherever
/// nothing lies within the AO radius above the surface. Two wrong G-buffers on purpose (normals
/// flipped, depth 0.5 % too far) must fail the comparison: the bounds catch wrong decodes.
#[test]
fn every_depth_and_normal_type_traces_the_same_scene_to_the_same_result() {
    let started = std::time::Instant::now();
    let e = EncodingScene::new();

    // The reference: world positions and world-space float normals.
    let reference = e.trace(
        e.depth(DepthEncoding::WorldPosition, e.normal_z, 1.0),
        e.normal(NormalType::RgbVector, F::Rgba32Float, Mat4::IDENTITY),
        e.normal_z,
    );
    check_reference_shadow(&e, &reference);
    check_reference_ao(&e, &reference);

    let variants = encoding_variants(&e);
    // Bounds. Float encodings decode to within f32 rounding of the reference surface (clip depth:
    // ~1e-5 of position, normals ~1e-7): a pixel can differ only where its AO ray grazes an
    // edge of the box, which such a shift turns from hit to miss — at most 0.25 % of the surface
    // pixels (lavapipe: none). 8-bit normals are off by up to ~0.5° (half a step of 1/255 or
    // 1/127 per component, octahedral steps up to twice that): the AO ray turns by as much, its
    // hit distance moves by ~t·0.01 and a ray near a box edge may hit or miss — at most 1 % of
    // the pixels may differ by more than 0.05 (lavapipe: 1 pixel). Shadow rays depend on the
    // normal only through the ray offset and the facing test (every face is ≥ 20° from the
    // light's direction), so the float bound holds for them with every encoding. A wrong decode
    // changes most pixels (the two wrong G-buffers below: > 90 %).
    let float_allowed = e.n_surface / 400;
    let quantised_allowed = e.n_surface / 100;
    check_variants(&e, &reference, variants, float_allowed, quantised_allowed);
    check_wrong_on_purpose_is_rejected(&e, &reference, quantised_allowed);
    eprintln!("took {:?}", started.elapsed());
}

// --- Multi-shadow trace → multi-shadow denoiser, checkerboard, viewport at an odd x ----------

/// The multi-shadow test's image size.
const CB_W: u32 = 64;
const CB_H: u32 = 64;
/// What the trace's output0 holds before the first frame: a plausible wrong value.
const GARBAGE: [f32; 4] = [0.25, 0.05, 0.05, 9.0];
/// What the denoised output holds before the first frame (every channel).
const UNTOUCHED: f32 = 7.0;

/// The multi-shadow test's analytic answer per pixel.
struct MultiShadowTruth {
    /// World position of the surface seen.
    positions: Vec<Option<DVec3>>,
    /// (object, lights visible).
    labels: Vec<(usize, u32)>,
    /// Closest occluder distance over the lights, `None` without an occluder.
    closest: Vec<Option<f32>>,
    /// Mean occluder distance over the occluded lights, `None` without an occluder.
    mean: Vec<Option<f32>>,
}

impl MultiShadowTruth {
    fn new(view: &ViewInfo, ground: Rect, occluder: Rect, to_lights: &[Vec3]) -> Self {
        let quads = [ground, occluder];
        let mut positions = Vec::new();
        let mut labels = Vec::new();
        let mut closest = Vec::new();
        let mut mean = Vec::new();
        for i in 0..CB_W * CB_H {
            let (o, d) = pixel_ray(view, CB_W, CB_H, i % CB_W, i / CB_W);
            let (o, d) = (o.as_vec3(), d.as_vec3());
            let (t, object) = cast(&quads, o, d).expect("every pixel shows the ground or the quad");
            let p = o + d * t;
            let hits: Vec<Option<f32>> = to_lights
                .iter()
                .map(|l| occluder.hit(p, *l).filter(|t| *t > 1e-3))
                .collect();
            positions.push(Some(p.as_dvec3()));
            labels.push((object, hits.iter().filter(|h| h.is_none()).count() as u32));
            closest.push(hits.iter().flatten().copied().reduce(f32::min));
            let occluded: Vec<f32> = hits.iter().flatten().copied().collect();
            mean.push(
                (!occluded.is_empty())
                    .then(|| occluded.iter().sum::<f32>() / occluded.len() as f32),
            );
        }
        MultiShadowTruth {
            positions,
            labels,
            closest,
            mean,
        }
    }
}

/// The multi-shadow test's setup: the ground and the occluder built on the device, the odd
/// viewport, the static camera, the two lights, the G-buffer and the analytic answer.
struct CheckerboardScene {
    ctx: ExecuteContext,
    vp: Viewport,
    view: ViewInfo,
    lights: Vec<LightInfo>,
    depth: DepthInput,
    normal: NormalInput,
    truth: MultiShadowTruth,
}

impl CheckerboardScene {
    fn new() -> Self {
        let vp = Viewport {
            x: 1,
            y: 0,
            width: CB_W - 1,
            height: CB_H,
        };
        let ground = Rect {
            origin: Vec3::new(-6.0, 0.0, -6.0),
            a: Vec3::new(0.0, 0.0, 12.0),
            b: Vec3::new(12.0, 0.0, 0.0),
        };
        let occluder = Rect {
            origin: Vec3::new(-0.8, 0.8, -0.5),
            a: Vec3::new(0.0, 0.0, 1.0),
            b: Vec3::new(1.6, 0.0, 0.0),
        };
        let ctx = context(4);
        let mut c = ctx.create_task_container();
        add(
            &ctx,
            &mut c,
            &ground.mesh(1, false),
            Affine3A::IDENTITY,
            Vec3::ONE,
        );
        add(
            &ctx,
            &mut c,
            &occluder.mesh(1, false),
            Affine3A::IDENTITY,
            Vec3::ONE,
        );
        build(&ctx, c);

        let to_lights = [
            Vec3::new(0.35, 1.0, -0.7).normalize(),
            Vec3::new(-0.35, 1.0, -0.7).normalize(),
        ];
        let lights: Vec<LightInfo> = to_lights
            .iter()
            .map(|l| LightInfo::Directional {
                direction: -*l,
                angular_extent: 0.01,
            })
            .collect();
        let w2v = Mat4::look_at_rh(Vec3::new(0.0, 3.2, 3.4), Vec3::new(0.0, 0.0, 0.4), Vec3::Y);
        let v2c = Mat4::perspective_rh(0.75, CB_W as f32 / CB_H as f32, 0.1, 50.0);
        let view = static_view(w2v, v2c);

        // The analytic answer per pixel: (object, lights visible, closest occluder distance).
        let truth = MultiShadowTruth::new(&view, ground, occluder, &to_lights);
        let depth = encode_depth(
            DepthEncoding::ClipR32Float,
            CB_W,
            CB_H,
            &view,
            &truth.positions,
            1.0,
        );
        let normal = encode_normals(
            NormalType::RgbVector,
            F::Rgba32Float,
            Mat4::IDENTITY,
            CB_W,
            CB_H,
            &vec![DVec3::Y; (CB_W * CB_H) as usize],
        );
        CheckerboardScene {
            ctx,
            vp,
            view,
            lights,
            depth,
            normal,
            truth,
        }
    }

    /// 12 frames of TraceMultiShadowTask and DenoiseMultiShadowTask on the checkerboard of the
    /// viewport: (the trace's output0, the denoised output).
    fn trace_and_denoise(&self) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
        let (vp, view) = (self.vp, self.view);
        let filled = |v: [f32; 4], usage| {
            let data: Vec<f32> = (0..CB_W * CB_H).flat_map(|_| v).collect();
            texture_with(
                F::Rgba32Float,
                CB_W,
                CB_H,
                usage,
                bytemuck::cast_slice(&data),
            )
        };
        let output0 = filled(
            GARBAGE,
            U::STORAGE_BINDING | U::TEXTURE_BINDING | U::COPY_SRC,
        );
        let output1 = filled([0.0; 4], U::STORAGE_BINDING | U::TEXTURE_BINDING);
        let denoised = filled([UNTOUCHED; 4], U::STORAGE_BINDING | U::COPY_SRC);
        let handle = self
            .ctx
            .create_denoising_context_handle(DenoisingContextInput {
                max_width: CB_W,
                max_height: CB_H,
                signal_type: SignalType::MultiShadow,
                method: DenoisingMethod::HighQuality,
            })
            .expect("denoising context");
        for frame in 0..12 {
            let mut common = TraceTaskCommon::new(self.depth.clone(), self.normal.clone());
            common.viewport = Some(vp);
            common.view = view;
            common.ray_offset.offset_type = RayOffsetType::WorldPosition;
            common.half_resolution_mode = HalfResolutionMode::Checkerboard;
            common.debug_parameters.frame_index = frame;
            let denoise_common = DenoiseTaskCommon {
                context: handle,
                viewport: Some(vp),
                depth: self.depth.clone(),
                normal: self.normal.clone(),
                roughness: RoughnessInput::default(),
                motion: None,
                view,
                half_resolution_mode: HalfResolutionMode::Checkerboard,
                mode: DenoiseMode::Continue,
            };
            run_tasks(
                &self.ctx,
                vec![
                    RenderTask::TraceMultiShadow(TraceMultiShadowTask {
                        common,
                        output0: output0.clone(),
                        output1: output1.clone(),
                        lights: self.lights.clone(),
                        enable_first_hit_and_end_search: false,
                    }),
                    RenderTask::DenoiseMultiShadow(DenoiseMultiShadowTask {
                        common: denoise_common,
                        input0: output0.clone(),
                        input1: output1.clone(),
                        output: denoised.clone(),
                    }),
                ],
            );
        }
        (read_rgba32(&output0), read_rgba32(&denoised))
    }

    /// Checks the trace's output0 and the denoised output against the analytic answer (see the
    /// test); returns the pixels compared per [region (visible count)][traced, untraced] and
    /// the worst denoised error.
    fn check(&self, traced_img: &[[f32; 4]], out: &[[f32; 4]]) -> ([[usize; 2]; 3], f32) {
        let vp = self.vp;
        let MultiShadowTruth {
            labels,
            closest,
            mean,
            ..
        } = &self.truth;
        // [region (visible count)][traced, untraced] pixels compared.
        let mut compared = [[0usize; 2]; 3];
        let mut worst = 0.0f32;
        for i in 0..(CB_W * CB_H) as usize {
            let (x, y) = (i as u32 % CB_W, i as u32 / CB_W);
            if x < vp.x {
                assert_eq!(
                    traced_img[i], GARBAGE,
                    "trace wrote ({x}, {y}) left of the viewport"
                );
                assert_eq!(
                    out[i], [UNTOUCHED; 4],
                    "denoiser wrote ({x}, {y}) left of the viewport"
                );
                continue;
            }
            let traced = (x - vp.x + y - vp.y).is_multiple_of(2);
            if !traced {
                assert_eq!(
                    traced_img[i], GARBAGE,
                    "trace wrote the untraced cell ({x}, {y})"
                );
            }
            if !away_from_boundaries(labels, CB_W, CB_H, x, y, 2) {
                continue;
            }
            let (object, visible) = labels[i];
            let fraction = visible as f32 / 2.0;
            if traced {
                let t = traced_img[i];
                assert_eq!(
                    t[0], fraction,
                    "trace R at ({x}, {y}), object {object}: {t:?}"
                );
                assert_eq!(t[3], 2.0, "trace A (light count) at ({x}, {y}): {t:?}");
                for (k, want, what) in [(1, closest[i], "closest"), (2, mean[i], "mean")] {
                    match want {
                        None => {
                            assert_eq!(t[k], -1.0, "trace output0[{k}] at ({x}, {y}): no occluder")
                        }
                        Some(d) => assert!(
                            (t[k] - d).abs() < 0.02 * d,
                            "trace output0[{k}] at ({x}, {y}): {what} occluder distance {d}, got \
                             {t:?}"
                        ),
                    }
                }
            }
            let o = out[i];
            let err = (0..3).map(|k| (o[k] - fraction).abs()).fold(0.0, f32::max);
            worst = worst.max(err);
            assert!(
                err <= 0.02,
                "denoised ({x}, {y}) ({}), object {object}: {o:?}, fraction visible {fraction}",
                if traced { "traced" } else { "untraced" }
            );
            compared[visible as usize][usize::from(!traced)] += 1;
        }
        (compared, worst)
    }
}

/// A ground quad and a horizontal quad above it, lit by two directional lights tilted ±x: the
/// fraction of the lights visible on the ground is 0 under both shadows, 1/2 under one and 1
/// elsewhere. TraceMultiShadowTask traces the checkerboard of a viewport at x = 1 for 12 frames
/// of a static camera, and DenoiseMultiShadowTask (same viewport and mode) denoises its output0
/// as is. Checked:
/// - the trace's output0 at traced cells (viewport-relative (x + y) even): R the analytic
///   fraction exactly, G and B the analytic closest and mean occluder distance within 2 % (the
///   lights' extent; -1 without an occluder), A the light count; untraced cells and the column
///   left of the viewport keep what they held;
/// - the denoised output, traced and untraced cells alike, 2 pixels away from every region
///   boundary: the analytic fraction within 0.02 in R, G and B (the lights are small enough
///   that visibility is deterministic once a few frames are in: lavapipe is within 5e-4, the f16
///   history's rounding); the column left of the viewport untouched.
///
/// Untraced cells hold a plausible wrong value (0.25): a denoiser that took the texel's parity
/// for the viewport's would read them as samples and miss by ≥ 0.125 everywhere.
#[test]
fn checkerboard_multi_shadow_at_an_odd_viewport_denoises_to_the_fraction_of_lights_visible() {
    let started = std::time::Instant::now();
    let s = CheckerboardScene::new();
    let (traced_img, out) = s.trace_and_denoise();
    let (compared, worst) = s.check(&traced_img, &out);
    eprintln!(
        "compared [0, 1/2, 1 visible][traced, untraced]: {compared:?}, worst {worst}, took {:?}",
        started.elapsed()
    );
    assert!(
        compared.iter().flatten().all(|&n| n >= 20),
        "too few pixels away from the boundaries: {compared:?}"
    );
}

/// Pixels a side of the cutout shadow test's floor under each card.
const CUTOUT_PIXELS: u32 = 48;

/// The raw shadow of cutout geometry: a sun straight above a checkerboard-alpha card (glTF MASK)
/// over a floor lights the floor exactly where the card's texel above is transparent (the CPU
/// alpha test, away from texel edges), and an opaque copy of the card shadows all of its floor.
#[test]
fn cutout_card_casts_the_shadow_of_its_opaque_texels_only() {
    let ctx = context(2);
    let (card_mesh, uvs) = card();
    let mut c = ctx.create_task_container();
    // The cards lie flat at height 1 (card (x, y, 0) → (x + dx, 1, y)): checkerboard over
    // x in [-1.5, -0.5], opaque over [0.5, 1.5].
    let flat = |dx: f32| {
        Affine3A::from_translation(Vec3::new(dx, 1.0, 0.0))
            * Affine3A::from_rotation_x(std::f32::consts::FRAC_PI_2)
    };
    let placed = [
        (checker_card(&card_mesh, &uvs, UvFormat::Float32x2), -1.5),
        (mesh_input("opaque card", &card_mesh, false), 0.5),
    ];
    for (input, dx) in placed {
        let g = ctx.create_geometry_handle();
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: g,
            input,
        });
        register_instance(&mut c, ctx.create_instance_handle(), g, flat(dx));
    }
    add(
        &ctx,
        &mut c,
        &Mesh::cuboid(Vec3::new(-3.0, -0.1, -1.0), Vec3::new(3.0, 0.0, 2.0)),
        Affine3A::IDENTITY,
        Vec3::ONE,
    );
    build(&ctx, c);
    // The floor under both cards: columns 0..P under the checkerboard, P..2P under the opaque
    // card, at pixel centres; (u, v) of the texel above = (x + 1.5, z) or (x - 0.5, z).
    let (w, h) = (2 * CUTOUT_PIXELS, CUTOUT_PIXELS);
    let at = |x: u32, y: u32| {
        let (card, col) = (x / CUTOUT_PIXELS, x % CUTOUT_PIXELS);
        let uv = glam::Vec2::new(
            (col as f32 + 0.5) / CUTOUT_PIXELS as f32,
            (y as f32 + 0.5) / CUTOUT_PIXELS as f32,
        );
        (card, uv)
    };
    let common = gbuffer_common(w, h, Vec3::new(0.0, 4.0, 0.5), |x, y| {
        let (card, uv) = at(x, y);
        let dx = if card == 0 { -1.5 } else { 0.5 };
        Some((Vec3::new(dx + uv.x, 0.0, uv.y), Vec3::Y))
    });
    let out = output(w, h);
    run_tasks(
        &ctx,
        vec![RenderTask::TraceShadow(TraceShadowTask {
            common,
            output: out.clone(),
            light: LightInfo::Directional {
                direction: Vec3::NEG_Y,
                angular_extent: 0.0,
            },
            enable_first_hit_and_end_search: true,
        })],
    );
    let shadow = read_rgba32(&out);
    let mut wrong = Vec::new();
    let mut lit_under_checker = 0;
    for y in 0..h {
        for x in 0..w {
            let (card, uv) = at(x, y);
            let texel = uv * CHECKER as f32;
            if card == 0 && (texel - texel.round()).abs().min_element() < 0.08 {
                continue;
            }
            let shadowed = card == 1 || checker_opaque(uv);
            let v = shadow[(y * w + x) as usize][0];
            // Shadowed: the distance to the card (1); lit: negative.
            if (v > 0.0) != shadowed || (shadowed && (v - 1.0).abs() > 0.01) {
                wrong.push(format!(
                    "pixel ({x}, {y}), uv {uv}: {v}, shadowed {shadowed}"
                ));
            }
            lit_under_checker += usize::from(!shadowed);
        }
    }
    assert!(
        wrong.is_empty(),
        "{} wrong, e.g. {:#?}",
        wrong.len(),
        &wrong[..wrong.len().min(6)]
    );
    assert!(
        lit_under_checker > 500,
        "too few lit pixels to tell: {lit_under_checker}"
    );
}
