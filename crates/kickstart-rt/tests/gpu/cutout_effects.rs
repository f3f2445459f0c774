//! Cutout (alpha-tested) geometry through the lighting effects, not only through raw rays: the
//! denoised sun shadow, ambient occlusion and diffuse GI of a floor under a checkerboard-alpha
//! card (glTF MASK) and under an opaque copy of it. Each effect reads the same traversal as
//! `TraceRaysTask`, but its own rays (cosine-weighted, offset, cut at a radius) and the denoiser's
//! filtering could each lose the holes: the card would then act as opaque, which every test here
//! tells apart from the CPU's alpha test (`checker_opaque`) of the same card.

use crate::common;
use common::rt::*;
use common::trace::*;
use common::*;
use glam::{Affine3A, DVec3, Mat4, Vec2, Vec3};
use kickstart_rt::*;
use wgpu::{TextureFormat as F, TextureUsages as U};

/// A unit card lying flat at `height` over x in [dx, dx + 1], z in [0, 1], facing down (card
/// (x, y, 0) → (x + dx, height, y): its texture coordinates are (x − dx, z)).
#[derive(Clone, Copy, Debug)]
struct Card {
    dx: f32,
    height: f32,
    /// The checkerboard-alpha card (else an opaque copy).
    cutout: bool,
    /// Its lighting cache's colour.
    colour: Vec3,
}

impl Card {
    fn transform(&self) -> Affine3A {
        Affine3A::from_translation(Vec3::new(self.dx, self.height, 0.0))
            * Affine3A::from_rotation_x(std::f32::consts::FRAC_PI_2)
    }

    /// The card's texture coordinates straight above floor point `p`, if it lies over the card.
    fn uv_above(&self, p: Vec3) -> Option<Vec2> {
        let uv = Vec2::new(p.x - self.dx, p.z);
        (uv.cmpge(Vec2::ZERO).all() && uv.cmple(Vec2::ONE).all()).then_some(uv)
    }

    /// The distance along (`o`, unit `d`) to an opaque texel of the card (the CPU alpha test),
    /// `None` where the ray misses the card or passes through a hole.
    fn hit(&self, o: Vec3, d: Vec3) -> Option<f32> {
        if d.y.abs() < 1e-9 {
            return None;
        }
        let t = (self.height - o.y) / d.y;
        let uv = self.uv_above(o + d * t)?;
        (t > 0.0 && (!self.cutout || checker_opaque(uv))).then_some(t)
    }
}

/// The closest opaque card texel along (`o`, `d`), over all `cards`.
fn cast(cards: &[Card], o: Vec3, d: Vec3) -> Option<f32> {
    cards.iter().filter_map(|c| c.hit(o, d)).reduce(f32::min)
}

/// A context holding `cards` (the cutout ones with the checkerboard's opacity micro-map, each
/// instance's cache starting at its colour) and a floor slab (top at y = 0, black) under them,
/// built.
fn scene(cards: &[Card]) -> ExecuteContext {
    let ctx = context(2);
    let (card_mesh, uvs) = card();
    let floor = Mesh::cuboid(Vec3::new(-6.0, -0.1, -3.0), Vec3::new(6.0, 0.0, 4.0));
    let mut c = ctx.create_task_container();
    let mut placed: Vec<(GeometryInput, Affine3A, Vec3)> = cards
        .iter()
        .map(|card| {
            let input = if card.cutout {
                checker_card(&card_mesh, &uvs, UvFormat::Float32x2)
            } else {
                mesh_input("opaque card", &card_mesh, false)
            };
            (input, card.transform(), card.colour)
        })
        .collect();
    placed.push((
        mesh_input("floor", &floor, false),
        Affine3A::IDENTITY,
        Vec3::ZERO,
    ));
    for (input, transform, colour) in placed {
        let g = ctx.create_geometry_handle();
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: g,
            input,
        });
        let mut instance = InstanceInput::new(g, transform);
        instance.initial_tile_color = colour.extend(1.0);
        c.schedule_bvh_task(InstanceTask {
            operation: TaskOperation::Register,
            handle: ctx.create_instance_handle(),
            input: instance,
        });
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 100,
        ..Default::default()
    });
    build_submit_complete(&ctx, c);
    ctx
}

/// A static camera (previous view = current): the denoiser then reprojects every pixel onto
/// itself and accumulates.
fn static_view(world_to_view: Mat4, view_to_clip: Mat4) -> ViewInfo {
    ViewInfo {
        world_to_view,
        view_to_clip,
        prev_world_to_view: world_to_view,
        prev_view_to_clip: view_to_clip,
        ..Default::default()
    }
}

/// min, mean, max of `values` (NaN for none).
fn stats(values: &[f32]) -> (f32, f32, f32) {
    let n = values.len() as f32;
    (
        values.iter().copied().fold(f32::NAN, f32::min),
        values.iter().sum::<f32>() / n,
        values.iter().copied().fold(f32::NAN, f32::max),
    )
}

/// The shadow test's view of the floor: 240 × 120 pixels over x in [-1.5, 1.5], z in
/// [-0.25, 1.25], seen straight down from 6 above: 80 pixels a unit, 10 pixels a checker cell
/// (cells are 1/8 of the card), so the denoiser's kernel (a few pixels) fits inside one.
const SHADOW_W: u32 = 240;
const SHADOW_H: u32 = 120;
/// Frames of trace + denoise (static camera).
const SHADOW_FRAMES: u32 = 8;
/// How far (in texels, 10 pixels each) a checked pixel keeps from its cell's edges: 3 pixels.
const CELL_MARGIN: f32 = 0.3;

/// What the sun straight above should give floor point `p`: `Some(true)` shadowed, `Some(false)`
/// lit, `None` within [`CELL_MARGIN`] of a card's or a cell's edge (left unchecked).
fn expected_shadow(cards: &[Card], p: Vec3) -> Option<bool> {
    let margin = CELL_MARGIN / CHECKER as f32;
    for card in cards {
        let uv = Vec2::new(p.x - card.dx, p.z);
        if uv.cmplt(Vec2::splat(-margin)).any() || uv.cmpgt(Vec2::splat(1.0 + margin)).any() {
            continue;
        }
        let texel = uv * CHECKER as f32;
        let edge = (texel - texel.round()).abs().min_element();
        let inside =
            uv.cmpgt(Vec2::splat(margin)).all() && uv.cmplt(Vec2::splat(1.0 - margin)).all();
        if !inside || (card.cutout && edge < CELL_MARGIN) {
            return None;
        }
        return Some(!card.cutout || checker_opaque(uv));
    }
    Some(false)
}

/// Traces the sun's shadow (straight down, the sun's 0.53°) of the G-buffer `depth`, `normal`
/// seen by `view` and denoises it with a shadow denoising context, [`SHADOW_FRAMES`] frames of a
/// static camera; returns (the last raw trace, the last denoised output).
fn trace_and_denoise_shadow(
    ctx: &ExecuteContext,
    view: ViewInfo,
    depth: DepthInput,
    normal: NormalInput,
) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let (w, h) = (SHADOW_W, SHADOW_H);
    let raw = texture(
        F::Rgba32Float,
        w,
        h,
        U::STORAGE_BINDING | U::TEXTURE_BINDING | U::COPY_SRC,
    );
    let denoised = output(w, h);
    let handle = ctx
        .create_denoising_context_handle(DenoisingContextInput {
            max_width: w,
            max_height: h,
            signal_type: SignalType::Shadow,
            method: DenoisingMethod::HighQuality,
        })
        .expect("denoising context");
    for frame in 0..SHADOW_FRAMES {
        let mut common = TraceTaskCommon::new(depth.clone(), normal.clone());
        common.view = view;
        common.ray_offset.offset_type = RayOffsetType::WorldPosition;
        common.debug_parameters.frame_index = frame;
        let denoise_common = DenoiseTaskCommon {
            context: handle,
            viewport: None,
            depth: depth.clone(),
            normal: normal.clone(),
            roughness: RoughnessInput::default(),
            motion: None,
            view,
            half_resolution_mode: HalfResolutionMode::Off,
            mode: DenoiseMode::Continue,
        };
        run_tasks(
            ctx,
            vec![
                RenderTask::TraceShadow(TraceShadowTask {
                    common,
                    output: raw.clone(),
                    light: LightInfo::Directional {
                        direction: Vec3::NEG_Y,
                        angular_extent: 0.0093,
                    },
                    enable_first_hit_and_end_search: true,
                }),
                RenderTask::DenoiseShadow(DenoiseShadowTask {
                    common: denoise_common,
                    input: raw.clone(),
                    output: denoised.clone(),
                }),
            ],
        );
    }
    (read_rgba32(&raw), read_rgba32(&denoised))
}

/// The denoised sun shadow of a checkerboard-alpha card keeps the checkerboard: a sun straight
/// above a card 1 over the floor, its cells 10 pixels wide; after 8 frames of trace and shadow
/// denoising (static camera), every pixel at least 3 pixels inside a transparent cell is lit
/// (denoised visibility > 0.8), every pixel as far inside an opaque cell is shadowed (< 0.2),
/// the whole floor under an opaque copy of the card is shadowed and the open floor lit. A card
/// traced opaque shadows the transparent cells; a denoiser blurring across the 10-pixel cells
/// would pull their centres towards one half.
#[test]
fn denoised_shadow_keeps_the_cutout_pattern() {
    let cards = [
        Card {
            dx: -1.25,
            height: 1.0,
            cutout: true,
            colour: Vec3::ZERO,
        },
        Card {
            dx: 0.25,
            height: 1.0,
            cutout: false,
            colour: Vec3::ZERO,
        },
    ];
    let ctx = scene(&cards);
    let (w, h) = (SHADOW_W, SHADOW_H);
    // Straight down (screen x = world x, screen down = world z): half the height, 0.75, at 6.
    let world_to_view = Mat4::look_at_rh(
        Vec3::new(0.0, 6.0, 0.5),
        Vec3::new(0.0, 0.0, 0.5),
        Vec3::NEG_Z,
    );
    let view_to_clip = Mat4::perspective_rh(2.0 * 0.125f32.atan(), w as f32 / h as f32, 0.1, 50.0);
    let view = static_view(world_to_view, view_to_clip);
    let floor: Vec<DVec3> = (0..w * h)
        .map(|i| {
            let (o, d) = pixel_ray(&view, w, h, i % w, i / w);
            o - d * (o.y / d.y)
        })
        .collect();
    let positions: Vec<Option<DVec3>> = floor.iter().map(|p| Some(*p)).collect();
    let depth = encode_depth(DepthEncoding::ClipR32Float, w, h, &view, &positions, 1.0);
    let normals = vec![DVec3::Y; (w * h) as usize];
    let normal = encode_normals(
        NormalType::RgbVector,
        F::Rgba32Float,
        Mat4::IDENTITY,
        w,
        h,
        &normals,
    );
    let (raw, denoised) = trace_and_denoise_shadow(&ctx, view, depth, normal);
    // [under the cutout card: lit, shadowed], [under the opaque card], [open floor].
    let mut classes: [Vec<f32>; 4] = Default::default();
    let mut raw_lit_under_cutout = 0;
    let mut wrong = Vec::new();
    for (i, p) in floor.iter().enumerate() {
        let p = p.as_vec3();
        let Some(shadowed) = expected_shadow(&cards, p) else {
            continue;
        };
        let v = denoised[i][0];
        let class = match (cards[0].uv_above(p), cards[1].uv_above(p)) {
            (Some(_), _) => usize::from(shadowed),
            (None, Some(_)) => 2,
            (None, None) => 3,
        };
        raw_lit_under_cutout += usize::from(class == 0 && raw[i][0] < 0.0);
        classes[class].push(v);
        if (shadowed && v >= 0.2) || (!shadowed && v <= 0.8) {
            let (x, y) = (i as u32 % w, i as u32 / w);
            wrong.push(format!("pixel ({x}, {y}) at {p}: {v}, shadowed {shadowed}"));
        }
    }
    let names = [
        "cutout, transparent cells",
        "cutout, opaque cells",
        "opaque card",
        "open floor",
    ];
    for (name, values) in names.iter().zip(&classes) {
        let (lo, mean, hi) = stats(values);
        eprintln!(
            "{name}: {} pixels, denoised visibility min {lo:.4} mean {mean:.4} max {hi:.4}",
            values.len()
        );
    }
    eprintln!(
        "raw trace lit under transparent cells: {raw_lit_under_cutout} of {}",
        classes[0].len()
    );
    assert!(
        wrong.is_empty(),
        "{} pixels wrong, e.g. {:#?}",
        wrong.len(),
        &wrong[..wrong.len().min(8)]
    );
    // 32 cells of each kind, about 4² pixels checked in each.
    assert!(
        classes.iter().all(|c| c.len() >= 400),
        "too few pixels checked: {:?}",
        classes.each_ref().map(Vec::len)
    );
}

/// Pixels a side of each floor patch of the AO and diffuse tests.
const PATCH: u32 = 24;
/// Frames (each a new cosine-weighted ray per pixel) the AO and diffuse tests average.
const GI_FRAMES: u32 = 16;
/// Stratified directions a side the CPU estimate takes per floor point (16² = 256).
const CPU_STRATA: u32 = 16;

/// The AO and diffuse tests' scene: cards 0.25 above the floor (so that one hides most of the
/// sky from the floor under it), the checkerboard over x in [-2, -1], the opaque copy over
/// [0.5, 1.5]; the cutout card's cache is blue, the opaque one's too (the diffuse test's sky is
/// red, so red counts the rays that escape and blue those that stop on a card).
fn low_cards() -> [Card; 2] {
    let card = |dx, cutout| Card {
        dx,
        height: 0.25,
        cutout,
        colour: Vec3::Z,
    };
    [card(-2.0, true), card(0.5, false)]
}

/// The floor patches of the AO and diffuse tests, one [`PATCH`]² block of pixels each: under
/// the cutout card's middle, under the opaque card's middle (both x, z in [0.1, 0.9] of the card)
/// and on open floor 2 beyond the opaque card. Returns the G-buffer's size and each pixel's
/// (patch, floor point).
fn patches(cards: &[Card; 2]) -> (u32, u32, Vec<(usize, Vec3)>) {
    let (w, h) = (3 * PATCH, PATCH);
    let origins = [cards[0].dx, cards[1].dx, cards[1].dx + 3.0];
    let points = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let patch = (x / PATCH) as usize;
            let f = |k: u32| 0.1 + 0.8 * (k as f32 + 0.5) / PATCH as f32;
            (patch, Vec3::new(origins[patch] + f(x % PATCH), 0.0, f(y)))
        })
        .collect();
    (w, h, points)
}

/// The G-buffer common inputs of `points` (floor, normal +y) on a `w × h` image.
fn floor_common(w: u32, h: u32, points: &[(usize, Vec3)]) -> TraceTaskCommon {
    gbuffer_common(w, h, Vec3::new(0.0, 4.0, 0.5), |x, y| {
        Some((points[(y * w + x) as usize].1, Vec3::Y))
    })
}

/// The CPU's mean of `f(closest opaque card distance along the ray)` over cosine-weighted rays
/// from each of `points` (stratified, [`CPU_STRATA`]² each), per patch: what the GPU's
/// cosine-weighted rays average to, up to their own noise.
fn cpu_patch_means(
    cards: &[Card],
    points: &[(usize, Vec3)],
    f: impl Fn(Option<f32>) -> f32,
) -> [f32; 3] {
    let mut sums = [0.0f64; 3];
    let mut counts = [0usize; 3];
    for &(patch, p) in points {
        for s in 0..CPU_STRATA * CPU_STRATA {
            let u1 = ((s / CPU_STRATA) as f32 + 0.5) / CPU_STRATA as f32;
            let u2 = ((s % CPU_STRATA) as f32 + 0.5) / CPU_STRATA as f32;
            let (r, phi) = (u1.sqrt(), std::f32::consts::TAU * u2);
            let d = Vec3::new(r * phi.cos(), (1.0 - u1).sqrt(), r * phi.sin());
            sums[patch] += f(cast(cards, p, d)) as f64;
            counts[patch] += 1;
        }
    }
    [0, 1, 2].map(|k| (sums[k] / counts[k] as f64) as f32)
}

/// Per patch, the GPU's mean of channel `channel` of `images` (one per frame).
fn gpu_patch_means(images: &[Vec<[f32; 4]>], points: &[(usize, Vec3)], channel: usize) -> [f32; 3] {
    let mut sums = [0.0f64; 3];
    let mut counts = [0usize; 3];
    for img in images {
        for (v, &(patch, _)) in img.iter().zip(points) {
            sums[patch] += v[channel] as f64;
            counts[patch] += 1;
        }
    }
    [0, 1, 2].map(|k| (sums[k] / counts[k] as f64) as f32)
}

/// Ambient occlusion of a floor under a checkerboard-alpha card 0.25 above it, under an opaque
/// copy and on open floor, AO radius 1 (the output: hit distance / radius, 1 where nothing is
/// within it), averaged over 24² pixels × 16 frames per patch and compared with the CPU's
/// estimate of the same quantity (cosine-weighted rays against the cards, the checkerboard's
/// alpha test at each hit): within 0.03 (the GPU mean's standard error is below 0.005). The
/// opaque card hides most of the sky (CPU: about 0.5), the cutout card about half as much, the open floor
/// nothing (exactly 1). A cutout card traced opaque gives the opaque card's value.
#[test]
fn ambient_occlusion_sees_through_the_cutout_holes() {
    let cards = low_cards();
    let ctx = scene(&cards);
    let (w, h, points) = patches(&cards);
    let radius = 1.0;
    let mut common = floor_common(w, h, &points);
    let mut images = Vec::new();
    for frame in 0..GI_FRAMES {
        common.debug_parameters.frame_index = frame;
        let out = output(w, h);
        run_tasks(
            &ctx,
            vec![RenderTask::TraceAmbientOcclusion(
                TraceAmbientOcclusionTask {
                    common: common.clone(),
                    output: out.clone(),
                    ao_radius: radius,
                },
            )],
        );
        images.push(read_rgba32(&out));
    }
    let gpu = gpu_patch_means(&images, &points, 0);
    let cpu = cpu_patch_means(&cards, &points, |t| {
        t.map_or(1.0, |t| (t / radius).min(1.0))
    });
    let unoccluded = cpu_patch_means(&cards, &points, |t| f32::from(t.is_none_or(|t| t > radius)));
    eprintln!(
        "AO [cutout, opaque, open]: GPU {gpu:?}, CPU {cpu:?} (CPU fraction unoccluded within the \
         radius {unoccluded:?})"
    );
    for k in 0..3 {
        assert!(
            (gpu[k] - cpu[k]).abs() < 0.03,
            "patch {k}: GPU AO {}, CPU {}",
            gpu[k],
            cpu[k]
        );
    }
    // The geometry's margins, apart from the CPU: the cutout card lets through at least a
    // third of what the opaque one hides, and hides at least a third of it.
    let hidden = 1.0 - cpu[1];
    assert!(
        gpu[0] > gpu[1] + hidden / 3.0 && gpu[0] < gpu[2] - hidden / 3.0,
        "AO: cutout {} not clearly between opaque {} and open {}",
        gpu[0],
        gpu[1],
        gpu[2]
    );
    let open = images
        .iter()
        .flat_map(|img| img.iter().zip(&points))
        .filter(|(_, p)| p.0 == 2);
    assert!(
        open.clone().all(|(v, _)| v[0] == 1.0),
        "open floor occluded"
    );
}

/// A uniform sky of radiance (1, 0, 0): a lat-long environment map read where rays miss.
fn red_sky() -> wgpu::TextureView {
    let texels: Vec<f32> = (0..8).flat_map(|_| [1.0, 0.0, 0.0, 1.0]).collect();
    texture_with(
        F::Rgba32Float,
        4,
        2,
        U::TEXTURE_BINDING,
        bytemuck::cast_slice(&texels),
    )
}

/// Diffuse GI of a floor under a red sky, under a checkerboard-alpha card 0.25 above it, under
/// an opaque copy and on open floor; both cards' caches blue. Lambertian: each pixel's radiance
/// is the colour its cosine-weighted ray finds, so red is the fraction of the sky reaching the
/// floor and blue the fraction of the cards' light. Averaged over 24² pixels × 16 frames per
/// patch, both are compared with the CPU's estimate (the checkerboard's alpha test at each card
/// hit) within 0.03, and the cutout card lets through clearly more sky than the opaque one. A
/// cutout card traced opaque gives the opaque card's values.
#[test]
fn diffuse_gi_reaches_the_floor_through_the_cutout_holes() {
    let cards = low_cards();
    let ctx = scene(&cards);
    let (w, h, points) = patches(&cards);
    let mut common = floor_common(w, h, &points);
    common.environment_map = Some(red_sky());
    let mut images = Vec::new();
    for frame in 0..GI_FRAMES {
        common.debug_parameters.frame_index = frame;
        let out = output(w, h);
        run_tasks(
            &ctx,
            vec![RenderTask::TraceDiffuse(TraceDiffuseTask::new(
                common.clone(),
                out.clone(),
            ))],
        );
        images.push(read_rgba32(&out));
    }
    let (sky, card_light) = (
        gpu_patch_means(&images, &points, 0),
        gpu_patch_means(&images, &points, 2),
    );
    let cpu_sky = cpu_patch_means(&cards, &points, |t| f32::from(t.is_none()));
    eprintln!(
        "diffuse [cutout, opaque, open]: GPU sky (red) {sky:?}, card light (blue) {card_light:?}; \
         CPU sky {cpu_sky:?}"
    );
    for k in 0..3 {
        assert!(
            (sky[k] - cpu_sky[k]).abs() < 0.03 && (card_light[k] - (1.0 - cpu_sky[k])).abs() < 0.03,
            "patch {k}: GPU sky {} card light {}, CPU sky {}",
            sky[k],
            card_light[k],
            cpu_sky[k]
        );
    }
    let hidden = 1.0 - cpu_sky[1];
    assert!(
        sky[0] > sky[1] + hidden / 3.0 && sky[0] < sky[2] - hidden / 3.0,
        "diffuse: sky under the cutout card {} not clearly between the opaque card's {} and the \
         open floor's {}",
        sky[0],
        sky[1],
        sky[2]
    );
}
