//! What a new user sees first: every debug view of `ksrt render` shows what it names (traced on
//! the lit render's context), and a scene without a camera or lights is framed from the side its
//! surfaces face and lit where the camera looks.

use std::path::PathBuf;

use crate::app::debug_view::DebugView;
use crate::app::lit::{self, LitOptions, LitResult};
use crate::app::testing;
use kickstart_rt_renderer::frame::Effects;
use kickstart_rt_renderer::scene::{self, Camera, Scene};

fn scenes_dir() -> PathBuf {
    crate::app::scenes::repository_scenes_dir()
}

fn render(
    scene: &Scene,
    camera: &Camera,
    size: (u32, u32),
    frames: u32,
    views: &[DebugView],
) -> LitResult {
    let (device, queue) = testing::device();
    lit::render(
        device,
        queue,
        scene,
        camera,
        &LitOptions {
            preset: kickstart_rt::Preset::Quality,
            size,
            frames,
            effects: Effects::default(),
            seed: 3,
            progress: false,
            gpu_timing: false,
            frames_in_flight: 1,
            debug_views: views.to_vec(),
            time: 0.0,
        },
    )
    .unwrap_or_else(|e| panic!("{}: {e}", scene.name))
}

fn luminance(t: &[f32; 4]) -> f32 {
    0.2126 * t[0] + 0.7152 * t[1] + 0.0722 * t[2]
}

/// Distinct colours among the hit pixels (alpha 1) of a debug view.
fn hit_colours(texels: &[[f32; 4]]) -> usize {
    let mut c: Vec<[u32; 3]> = texels
        .iter()
        .filter(|t| t[3] > 0.5)
        .map(|t| [t[0].to_bits(), t[1].to_bits(), t[2].to_bits()])
        .collect();
    c.sort_unstable();
    c.dedup();
    c.len()
}

/// `ksrt render`'s five debug views of the default scene, traced after the lit frames on their
/// context: each shows its own content, not a constant image. The lighting cache's view shows
/// the injected light where the rasteriser lit the surface (it was all black when traced on a
/// context that never injected).
#[test]
fn every_debug_view_shows_what_it_names() {
    let scene = scene::builtin::default_scene();
    let camera = scene.camera_or_default(None);
    let (w, h) = (64, 36);
    let r = render(&scene, &camera, (w, h), 3, &DebugView::ALL);
    let view = |v: DebugView| -> &[[f32; 4]] {
        let (_, t) = r.debug.iter().find(|(k, _)| *k == v).expect("view traced");
        assert_eq!((t.width, t.height), (w, h));
        &t.data
    };
    let hits = |v: DebugView| view(v).iter().filter(|t| t[3] > 0.5).count();
    let n = (w * h) as usize;
    for v in DebugView::ALL {
        // The room fills most of the view; the same pixels hit in every view.
        assert!(hits(v) > n / 2, "{v:?}: {} of {n} pixels hit", hits(v));
        assert_eq!(hits(v), hits(DebugView::HitT), "{v:?}");
    }
    // Hit distance: finite, positive, and spread (near objects, far walls).
    let t: Vec<f32> = view(DebugView::HitT)
        .iter()
        .filter(|t| t[3] > 0.5)
        .map(|t| t[0])
        .collect();
    assert!(t.iter().all(|d| d.is_finite() && *d > 0.0));
    let (lo, hi) = t
        .iter()
        .fold((f32::MAX, 0.0f32), |(a, b), &d| (a.min(d), b.max(d)));
    assert!(hi > 2.0 * lo, "hit distances {lo}..{hi}");
    // Barycentrics: weights that sum to one and vary across triangles.
    for b in view(DebugView::Barycentrics).iter().filter(|t| t[3] > 0.5) {
        assert!((b[0] + b[1] + b[2] - 1.0).abs() < 0.01, "{b:?}");
        assert!(b[..3].iter().all(|x| (-0.01..=1.01).contains(x)), "{b:?}");
    }
    assert!(hit_colours(view(DebugView::Barycentrics)) > n / 4);
    // One colour per instance, several instances in view; many more surfels than instances.
    let instances = hit_colours(view(DebugView::MeshColor));
    assert!(
        (3..=scene.instances.len()).contains(&instances),
        "{instances} instance colours"
    );
    assert!(hit_colours(view(DebugView::Tiles)) > 4 * instances);
    // The cache holds the light the frames injected: where the direct light is bright the cache
    // is too, and it is not one constant colour.
    let direct = &r.channel("direct").expect("direct").texels.data;
    let cache = view(DebugView::Cache);
    let lit_px: Vec<usize> = (0..n)
        .filter(|&i| cache[i][3] > 0.5 && luminance(&direct[i]) > 0.1)
        .collect();
    assert!(
        lit_px.len() > n / 10,
        "{} directly lit pixels",
        lit_px.len()
    );
    let cached = lit_px
        .iter()
        .filter(|&&i| luminance(&cache[i]) > 0.01)
        .count();
    assert!(
        cached * 10 > lit_px.len() * 8,
        "the cache is dark at {} of {} directly lit pixels",
        lit_px.len() - cached,
        lit_px.len()
    );
    assert!(
        hit_colours(cache) > 16,
        "cache colours: {}",
        hit_colours(cache)
    );
}

/// Least mean display value (sRGB-encoded, 0..1) of a lit interior's final image. At 48×27 and
/// two frames the apartment with the default sun alone measures 0.34 (the camera) and
/// 0.40 (the default view's); with the view's light 0.60 and 0.57. The threshold sits between:
/// the view's light must add what a visible room needs, not merely shift the image.
const MIN_MEAN_DISPLAY: f32 = 0.45;

/// The apartment's file has no camera and no light: its default view is inside (primary rays
/// meet surfaces all around) and lit by the light at the camera, which also lights the issue's
/// camera inside, where the sun alone left the room dark.
#[test]
fn a_scene_without_camera_or_lights_is_framed_from_inside_and_lit() {
    let mut scene = crate::app::scenes::load("apartment", &scenes_dir()).expect("apartment");
    assert!(scene.camera.is_none() && scene.lights.is_empty());
    let sun_only = scene.clone();
    let camera = scene.prepare_view(None);
    let (lo, hi) = scene.bounds();
    assert!(
        camera.eye.cmpgt(lo).all() && camera.eye.cmplt(hi).all(),
        "eye {} outside the bounds",
        camera.eye
    );
    let size = (48, 27);
    let r = render(&scene, &camera, size, 2, &[DebugView::HitT]);
    let hit_t = &r.debug[0].1.data;
    // Inside, surfaces all around: the sky shows at most through a window.
    let misses = hit_t.iter().filter(|t| t[3] < 0.5).count();
    assert!(
        misses * 10 < hit_t.len(),
        "{misses} of {} primary rays escape: the camera is not inside",
        hit_t.len()
    );
    let mean = |r: &LitResult| {
        let d = &r.channel("final").expect("final").texels.data;
        d.iter().map(luminance).sum::<f32>() / d.len() as f32
    };
    let lit_mean = mean(&r);
    let dark_mean = mean(&render(&sun_only, &camera, size, 2, &[]));
    // The benchmark camera, inside, where the sun alone left the room nearly black.
    let inside = scene::benchmark_camera("apartment").expect("benchmark camera");
    let mut inside_lit = sun_only.clone();
    inside_lit.light_the_view(&inside);
    let inside_mean = mean(&render(&inside_lit, &inside, size, 2, &[]));
    let inside_dark = mean(&render(&sun_only, &inside, size, 2, &[]));
    for (what, lit, dark) in [
        ("default view", lit_mean, dark_mean),
        ("benchmark camera", inside_mean, inside_dark),
    ] {
        assert!(
            lit > MIN_MEAN_DISPLAY && lit > 1.3 * dark,
            "{what}: mean display value {lit} with the view's light, {dark} with the sun alone"
        );
    }
}

/// An object (a sphere: surfaces facing away from its centre) is framed from outside, looking
/// at it, and gets the light at the camera too.
#[test]
fn an_object_is_framed_from_outside() {
    let (positions, indices) = scene::builtin::icosphere(3);
    let mesh = scene::Mesh::new("sphere", positions, indices, glam::Vec3::ONE).expect("sphere");
    let mut scene = Scene {
        name: "sphere".into(),
        meshes: vec![mesh],
        instances: vec![scene::Instance {
            mesh: 0,
            transform: glam::Affine3A::from_translation(glam::Vec3::new(0.3, 1.0, -2.0)),
        }],
        ..Default::default()
    };
    assert_eq!(scene.interior_camera(), None);
    let camera = scene.prepare_view(None);
    let (lo, hi) = scene.bounds();
    let inside = camera.eye.cmpge(lo).all() && camera.eye.cmple(hi).all();
    assert!(!inside, "eye {} inside the bounds", camera.eye);
    let centre = (lo + hi) * 0.5;
    assert!(
        (camera.at - camera.eye)
            .normalize()
            .dot((centre - camera.eye).normalize())
            > 0.99
    );
    assert_eq!(scene.lights.len(), 2, "the sun and the light at the camera");
}
