//! The trace tasks through the public API, with the SDK's own BVH build and lighting cache:
//! furnace (a closed sphere whose cache is uniform radiance L), the four-coloured scene of
//! reference/instance-id-bug-report.ko.md, ambient occlusion of an open plane, and the bad
//! inputs the trace tasks name.

mod common;
use common::rt::*;
use common::trace::*;
use common::*;
use glam::{Affine3A, Quat, Vec3};
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
