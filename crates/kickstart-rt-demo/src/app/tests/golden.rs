//! Golden-image and analytic tests of the lit renderer (rasteriser + SDK effects + composite), at
//! small sizes with a fixed seed.
//!
//! The references are `tests/golden/<name>.png` in this crate. Regenerate them all (after a
//! deliberate change, or when the SDK gains an effect) with
//!
//! ```text
//! KSRT_BLESS=1 cargo test -p kickstart-rt-demo golden
//! ```
//!
//! and look at the new images before committing them (each file written is named on stderr,
//! with its difference from the image it replaced). With `CI` set, blessing is refused: the run
//! fails instead of passing by rewriting its own references. Comparison: [`perceptual_diff`], a
//! blurred CIELAB ΔE (the eye's low-pass at a normal viewing distance, then the colour
//! difference the eye sees): the mean ΔE must stay ≤ [`MEAN_DE`] and the 99th percentile ≤
//! [`P99_DE`]. Moving an object by a few pixels, recolouring one, losing a shadow or an effect
//! exceeds them by far (the metric's own tests show it); driver rounding does not.

use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::app::lit::{self, LitOptions, LitResult};
use crate::app::readback::{to_png, Encoding};
use crate::app::testing;
use kickstart_rt_renderer::frame::Effects;
use kickstart_rt_renderer::scene::{self, Camera, Scene};

/// Largest mean ΔE accepted.
pub const MEAN_DE: f32 = 1.0;
/// Largest 99th-percentile ΔE accepted.
pub const P99_DE: f32 = 10.0;

/// The difference of two images as the eye sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Diff {
    /// Mean ΔE76 over the pixels.
    pub mean: f32,
    /// 99th percentile ΔE76.
    pub p99: f32,
}

fn srgb_to_linear(c: u8) -> f32 {
    let c = c as f32 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear sRGB to CIELAB (D65).
fn lab(rgb: Vec3) -> Vec3 {
    let x = 0.4124 * rgb.x + 0.3576 * rgb.y + 0.1805 * rgb.z;
    let y = 0.2126 * rgb.x + 0.7152 * rgb.y + 0.0722 * rgb.z;
    let z = 0.0193 * rgb.x + 0.1192 * rgb.y + 0.9505 * rgb.z;
    let f = |t: f32| {
        if t > 0.008856 {
            t.cbrt()
        } else {
            7.787 * t + 16.0 / 116.0
        }
    };
    let (fx, fy, fz) = (f(x / 0.9505), f(y), f(z / 1.089));
    Vec3::new(116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz))
}

/// Linear colours blurred by the binomial 3×3 kernel (edges clamped).
fn blurred(img: &image::RgbImage) -> Vec<Vec3> {
    let (w, h) = (img.width() as i32, img.height() as i32);
    let lin: Vec<Vec3> = img
        .pixels()
        .map(|p| {
            Vec3::new(
                srgb_to_linear(p[0]),
                srgb_to_linear(p[1]),
                srgb_to_linear(p[2]),
            )
        })
        .collect();
    let at = |x: i32, y: i32| lin[(y.clamp(0, h - 1) * w + x.clamp(0, w - 1)) as usize];
    let mut out = Vec::with_capacity(lin.len());
    for y in 0..h {
        for x in 0..w {
            let mut s = Vec3::ZERO;
            for (dy, wy) in [(-1, 1.0), (0, 2.0), (1, 1.0)] {
                for (dx, wx) in [(-1, 1.0), (0, 2.0), (1, 1.0)] {
                    s += at(x + dx, y + dy) * (wx * wy);
                }
            }
            out.push(s / 16.0);
        }
    }
    out
}

/// The perceptual difference of two images of the same size (`None` if the sizes differ).
pub fn perceptual_diff(a: &image::RgbImage, b: &image::RgbImage) -> Option<Diff> {
    if a.dimensions() != b.dimensions() || a.width() == 0 || a.height() == 0 {
        return None;
    }
    let (la, lb) = (blurred(a), blurred(b));
    let mut de: Vec<f32> = la
        .iter()
        .zip(&lb)
        .map(|(x, y)| (lab(*x) - lab(*y)).length())
        .collect();
    let mean = de.iter().sum::<f32>() / de.len() as f32;
    de.sort_by(f32::total_cmp);
    let p99 = de[((de.len() - 1) as f32 * 0.99) as usize];
    Some(Diff { mean, p99 })
}

fn golden_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

/// What [`check_golden`] does with a render.
#[derive(Debug, Clone, PartialEq, Eq)]
enum GoldenMode {
    /// Compare with the reference (the default).
    Compare,
    /// Overwrite the reference (`KSRT_BLESS=1` outside CI).
    Bless,
}

/// Whether a `CI` value means "running in CI" (GitHub and most others set `CI=true`).
fn ci_is_set(ci: Option<&str>) -> bool {
    ci.is_some_and(|v| !matches!(v.trim(), "" | "0" | "false" | "False" | "FALSE"))
}

/// The mode from the values of `KSRT_BLESS` and `CI` (`None`: unset). Blessing in CI is an
/// error, not a pass: a run that rewrote its own references would accept any render. A
/// `KSRT_BLESS` other than `1`, `0` or empty is an error too, so that a misspelt switch
/// (`true`, `yes`) does not quietly compare instead of blessing.
fn golden_mode(bless: Option<&str>, ci: Option<&str>) -> Result<GoldenMode, String> {
    match bless {
        None | Some("" | "0") => Ok(GoldenMode::Compare),
        Some("1") if ci_is_set(ci) => Err(format!(
            "KSRT_BLESS=1 with CI={}: refusing to rewrite the golden references in CI (that \
             would pass any render); bless locally, look at the images and commit them",
            ci.unwrap_or_default()
        )),
        Some("1") => Ok(GoldenMode::Bless),
        Some(other) => Err(format!(
            "KSRT_BLESS={other:?}: expected 1 (bless), or 0, empty or unset (compare)"
        )),
    }
}

/// Overwrites `path` with `img` and says so on the real stderr (the harness captures
/// `eprintln!` of passing tests, so a blessing run would otherwise not show what it wrote),
/// with how far the new image is from the one it replaced.
fn bless(path: &Path, img: &image::RgbImage) {
    use std::io::Write;
    let previous = image::open(path).ok().map(|p| p.to_rgb8());
    std::fs::create_dir_all(golden_dir()).expect("create tests/golden");
    img.save(path)
        .unwrap_or_else(|e| panic!("{}: cannot write: {e}", path.display()));
    let change = match previous.as_ref().map(|p| perceptual_diff(img, p)) {
        None => "new reference".to_string(),
        Some(None) => "replaced one of another size".to_string(),
        Some(Some(d)) => format!(
            "was mean ΔE {:.2}, p99 ΔE {:.2} from the previous reference",
            d.mean, d.p99
        ),
    };
    let _ = writeln!(
        std::io::stderr(),
        "KSRT_BLESS: wrote {} ({change})",
        path.display()
    );
}

/// Compares `img` with `tests/golden/<name>.png`, or writes it there under `KSRT_BLESS=1`
/// (refused in CI, see [`golden_mode`]).
fn check_golden(name: &str, img: &image::RgbImage) {
    let path = golden_dir().join(format!("{name}.png"));
    let mode = golden_mode(
        std::env::var("KSRT_BLESS").ok().as_deref(),
        std::env::var("CI").ok().as_deref(),
    )
    .unwrap_or_else(|e| panic!("{name}: {e}"));
    if mode == GoldenMode::Bless {
        bless(&path, img);
        return;
    }
    let reference = image::open(&path)
        .unwrap_or_else(|e| {
            panic!(
                "{}: no reference image ({e}); create it with KSRT_BLESS=1 cargo test -p kickstart-rt-demo golden",
                path.display()
            )
        })
        .to_rgb8();
    let d = perceptual_diff(img, &reference).unwrap_or_else(|| {
        panic!(
            "{name}: size {:?}, reference {:?}",
            img.dimensions(),
            reference.dimensions()
        )
    });
    if d.mean > MEAN_DE || d.p99 > P99_DE {
        let failed = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../target/ksrt-test/golden-failures")
            .join(format!("{name}.png"));
        let _ = std::fs::create_dir_all(failed.parent().unwrap_or(Path::new(".")));
        let _ = img.save(&failed);
        panic!(
            "{name}: differs from {} by mean ΔE {:.2} (≤ {MEAN_DE}), p99 ΔE {:.2} (≤ {P99_DE}); this render is {}",
            path.display(),
            d.mean,
            d.p99,
            failed.display()
        );
    }
}

/// The bless switch, without touching the references: unset (or `0`) compares, `KSRT_BLESS=1`
/// blesses only outside CI, and any other value is refused rather than read as either.
#[test]
fn bless_is_refused_in_ci_and_needs_exactly_1() {
    use GoldenMode::{Bless, Compare};
    for off in [None, Some("0"), Some("")] {
        assert_eq!(golden_mode(off, None), Ok(Compare), "{off:?}");
        assert_eq!(golden_mode(off, Some("true")), Ok(Compare), "{off:?} in CI");
    }
    assert_eq!(golden_mode(Some("1"), None), Ok(Bless));
    // `CI` set to something that says "not CI" is not CI.
    for not_ci in ["", "0", "false", "FALSE"] {
        assert_eq!(
            golden_mode(Some("1"), Some(not_ci)),
            Ok(Bless),
            "CI={not_ci:?}"
        );
    }
    for ci in ["true", "1", "yes", "TRUE"] {
        let e = golden_mode(Some("1"), Some(ci)).expect_err(ci);
        assert!(e.contains("refusing") && e.contains("CI"), "CI={ci}: {e}");
    }
    for bad in ["true", "yes", " 1", "2"] {
        let e = golden_mode(Some(bad), None).expect_err(bad);
        assert!(
            e.contains("KSRT_BLESS") && e.contains("expected 1"),
            "{bad:?}: {e}"
        );
        // In CI as well: a malformed switch is not silently a comparison.
        assert!(golden_mode(Some(bad), Some("true")).is_err(), "{bad:?}");
    }
}

fn render(scene: &Scene, camera: &Camera, size: (u32, u32), frames: u32) -> LitResult {
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
            seed: 7,
            progress: false,
            gpu_timing: false,
            frames_in_flight: 1,
            debug_views: Vec::new(),
            time: 0.0,
        },
    )
    .unwrap_or_else(|e| panic!("{}: {e}", scene.name))
}

/// The diffuse GI channel (denoised where the denoiser ran); a render without one fails, naming
/// what the SDK refused.
fn denoised_gi(r: &LitResult) -> &lit::Channel {
    r.channel("diffuse-denoised")
        .or_else(|| r.channel("diffuse"))
        .unwrap_or_else(|| {
            panic!(
                "no diffuse GI channel (refused: {:?}, missing: {:?})",
                r.refused, r.missing
            )
        })
}

fn final_image(r: &LitResult) -> image::RgbImage {
    let c = r.channel("final").expect("final image");
    to_png(&c.texels, Encoding::Display)
}

#[test]
fn golden_default_scene() {
    let scene = scene::builtin::default_scene();
    let r = render(&scene, &scene.camera_or_default(None), (128, 72), 4);
    check_golden("default", &final_image(&r));
}

#[test]
fn golden_cornell_box() {
    let scene = scene::builtin::cornell_box();
    let r = render(&scene, &scene.camera_or_default(None), (64, 64), 4);
    check_golden("cornell", &final_image(&r));
}

/// The camera straight above the generated textured scene (a hair off the vertical, so "up" in
/// the image is +z).
fn top_camera() -> Camera {
    Camera {
        eye: Vec3::new(0.0, 6.0, 0.01),
        at: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 50.0,
    }
}

#[test]
fn golden_textured_and_emissive() {
    let dir = testing::temp_dir("golden-textured");
    let scene = crate::app::scenes::load_file(&testing::textured_gltf(&dir)).expect("load");
    let r = render(&scene, &top_camera(), (64, 64), 2);
    check_golden("textured", &final_image(&r));
}

/// The pixel a world point lands on (unjittered), `None` outside the image.
fn pixel_of(camera: &Camera, scene: &Scene, size: (u32, u32), p: Vec3) -> Option<(u32, u32)> {
    let v = kickstart_rt_renderer::raster::FrameView::new(
        camera,
        size,
        scene.size(),
        glam::Vec2::ZERO,
        None,
    );
    let c = v.view_to_clip * v.world_to_view * p.extend(1.0);
    let (x, y) = (
        (c.x / c.w * 0.5 + 0.5) * size.0 as f32,
        (0.5 - c.y / c.w * 0.5) * size.1 as f32,
    );
    (x >= 0.0 && y >= 0.0 && x < size.0 as f32 && y < size.1 as f32).then_some((x as u32, y as u32))
}

/// The generated glTF's checker texture shows cell by cell where the UVs put it, and the emissive
/// quad shines in its colour although its base colour is black and it faces away from the sun.
#[test]
fn textures_map_by_uv_and_emission_shows_unlit() {
    let dir = testing::temp_dir("lit-textured");
    let scene = crate::app::scenes::load_file(&testing::textured_gltf(&dir)).expect("load");
    let camera = top_camera();
    let size = (128, 128);
    let r = render(&scene, &camera, size, 1);
    let img = final_image(&r);
    let mut checked = 0;
    // The floor spans −2..2 in x and z (the quad scaled by 2); u = (x + 2) / 4, v = (z + 2) / 4;
    // texel (⌊8u⌋, ⌊8v⌋) is red where their sum is even. Cells under the lamp are left out.
    for cz in 0..8 {
        for cx in 0..8 {
            let centre = Vec3::new(
                -2.0 + 0.5 * cx as f32 + 0.25,
                0.0,
                -2.0 + 0.5 * cz as f32 + 0.25,
            );
            if centre.x.abs() < 0.6 && centre.z.abs() < 0.6 {
                continue;
            }
            let Some((x, y)) = pixel_of(&camera, &scene, size, centre) else {
                continue;
            };
            let p = img.get_pixel(x, y).0;
            let red = (cx + cz) % 2 == 0;
            let (want, other) = if red { (p[0], p[2]) } else { (p[2], p[0]) };
            assert!(
                want as i32 > other as i32 + 60,
                "cell ({cx}, {cz}) at pixel ({x}, {y}) should be {}: {p:?}",
                if red { "red" } else { "blue" }
            );
            checked += 1;
        }
    }
    assert!(checked >= 40, "only {checked} cells in view");
    let (x, y) = pixel_of(&camera, &scene, size, Vec3::new(0.0, 0.5, 0.0)).expect("lamp in view");
    let p = img.get_pixel(x, y).0;
    // Emission (4, 3, 0.5) tone maps to a bright orange-yellow: R > G > B, R near white.
    assert!(
        p[0] > 220 && p[1] > 180 && p[2] < p[1] && p[1] < p[0],
        "lamp pixel {p:?}"
    );
}

/// The GI acceptance criterion: the default scene's diffuse GI shows all four object colours.
/// This SDK traces and denoises diffuse GI, so a refused diffuse task fails the test (it used
/// to pass through a "reported missing" branch whatever the GI did).
#[test]
fn default_scene_gi_holds_all_four_colours() {
    let scene = scene::builtin::default_scene();
    let r = render(&scene, &scene.camera_or_default(None), (96, 54), 8);
    let gi = denoised_gi(&r);
    let hue = |want: [f32; 3]| {
        gi.texels.data.iter().any(|t| {
            let c = Vec3::new(t[0], t[1], t[2]);
            let s = c.length();
            s > 1e-3 && (c / s).dot(Vec3::from(want).normalize()) > 0.97
        })
    };
    for (name, rgb) in [
        ("red", [0.9, 0.15, 0.1]),
        ("green", [0.1, 0.7, 0.2]),
        ("blue", [0.15, 0.3, 0.9]),
        ("yellow", [0.9, 0.8, 0.2]),
    ] {
        assert!(
            hue(rgb),
            "the default scene's diffuse GI has no {name} light"
        );
    }
}

/// As above for the Cornell box: the white floor's GI is redder near the red wall and greener
/// near the green wall than in the middle.
#[test]
fn cornell_floor_gi_bleeds_red_and_green() {
    let scene = scene::builtin::cornell_box();
    let camera = scene.camera_or_default(None);
    let size = (64, 64);
    let r = render(&scene, &camera, size, 8);
    let gi = denoised_gi(&r);
    // The mean of a 3×3 block: one pixel of one-sample-per-pixel GI is too noisy to judge hue.
    let at = |p: Vec3| {
        let (x, y) = pixel_of(&camera, &scene, size, p).expect("in view");
        let mut sum = Vec3::ZERO;
        for dy in -1i32..=1 {
            for dx in -1i32..=1 {
                let px = (x as i32 + dx).clamp(0, size.0 as i32 - 1) as u32;
                let py = (y as i32 + dy).clamp(0, size.1 as i32 - 1) as u32;
                let t = gi.texels.data[(py * size.0 + px) as usize];
                sum += Vec3::new(t[0], t[1], t[2]);
            }
        }
        sum / 9.0
    };
    // Red wall at x = 0.556, green wall at x = 0; floor points 3 cm from each and one midway,
    // in front of the blocks. The light is warm (emission 17 : 12 : 4), so the white walls'
    // bounce is itself orange: bleeding shows as the floor's chromaticity moving towards each
    // wall's colour, against the floor's middle.
    let near_red = at(Vec3::new(0.526, 0.001, 0.05));
    let middle = at(Vec3::new(0.278, 0.001, 0.05));
    let near_green = at(Vec3::new(0.03, 0.001, 0.05));
    let chroma = |c: Vec3| c / (c.x + c.y + c.z).max(1e-6);
    let (r, m, g) = (chroma(near_red), chroma(middle), chroma(near_green));
    eprintln!("floor GI chromaticity: red side {r}, middle {m}, green side {g}");
    // The red side's margin is smaller than the green's: the denoiser spreads the sparse
    // bounce light over a wider area (keeping its energy), so the floor's middle takes some of
    // the red too (measured +0.026 after 8 frames at this size, +0.10 on the green side).
    assert!(
        r.x > m.x + 0.015 && r.y < m.y,
        "floor by the red wall {near_red} is not redder than the middle {middle}"
    );
    assert!(
        g.y > m.y + 0.04 && g.x < m.x,
        "floor by the green wall {near_green} is not greener than the middle {middle}"
    );
}

#[test]
fn perceptual_diff_passes_noise_and_fails_real_changes() {
    let scene = scene::builtin::default_scene();
    let r = render(&scene, &scene.camera_or_default(None), (128, 72), 1);
    let img = final_image(&r);
    let same = perceptual_diff(&img, &img).expect("same size");
    assert_eq!(same.mean, 0.0);
    // ±1 of 255 on every channel: rounding, not a regression.
    let mut noisy = img.clone();
    for (k, p) in noisy.pixels_mut().enumerate() {
        let d = if k % 2 == 0 { 1i16 } else { -1 };
        p.0 = p.0.map(|c| (c as i16 + d).clamp(0, 255) as u8);
    }
    let d = perceptual_diff(&img, &noisy).expect("same size");
    assert!(d.mean <= MEAN_DE && d.p99 <= P99_DE, "{d:?}");
    // The red sphere turned grey: a regression.
    let mut grey = img.clone();
    for p in grey.pixels_mut() {
        if p[0] as i32 > p[1] as i32 + 60 && p[0] as i32 > p[2] as i32 + 60 {
            let g = ((p[0] as u32 + p[1] as u32 + p[2] as u32) / 3) as u8;
            p.0 = [g; 3];
        }
    }
    let d = perceptual_diff(&img, &grey).expect("same size");
    assert!(d.p99 > P99_DE, "recoloured sphere passes: {d:?}");
    // Everything moved by 3 pixels: a regression.
    let shifted = image::RgbImage::from_fn(img.width(), img.height(), |x, y| {
        *img.get_pixel(x.saturating_sub(3), y)
    });
    let d = perceptual_diff(&img, &shifted).expect("same size");
    assert!(
        d.mean > MEAN_DE || d.p99 > P99_DE,
        "shifted image passes: {d:?}"
    );
}

/// Linear radiance the lighting pass writes where the rasteriser drew nothing: the renderer's
/// `raster::gpu_scene::SKY` (private there), restated here as the test's oracle.
const SKY_RADIANCE: Vec3 = Vec3::new(0.35, 0.45, 0.6);

/// Which pixels of a `size` image from `camera` see geometry, by the SDK's CPU reference BVH
/// (independent of the rasteriser under test): `Some(true)` geometry, `Some(false)` sky, `None`
/// where one of the 8 neighbours differs (a silhouette, which the raster's sub-pixel jitter may
/// put either way).
fn cpu_coverage(scene: &Scene, camera: &Camera, (w, h): (u32, u32)) -> Vec<Option<bool>> {
    use kickstart_rt::cpu::{CpuBvh, Ray};
    let (tris, _) = scene.world_triangles();
    let bvh = CpuBvh::build(&tris);
    let hit: Vec<bool> = (0..w * h)
        .map(|k| {
            let ray = Ray {
                origin: camera.eye,
                dir: camera.primary_dir(k % w, k / w, w, h),
                t_min: 0.0,
                t_max: f32::INFINITY,
            };
            bvh.closest_hit(&tris, &ray).is_some()
        })
        .collect();
    let at = |x: i64, y: i64| {
        hit[(y.clamp(0, h as i64 - 1) * w as i64 + x.clamp(0, w as i64 - 1)) as usize]
    };
    (0..w as i64 * h as i64)
        .map(|k| {
            let (x, y) = (k % w as i64, k / w as i64);
            let c = at(x, y);
            (-1..=1)
                .flat_map(|dy| (-1..=1).map(move |dx| (dx, dy)))
                .all(|(dx, dy)| at(x + dx, y + dy) == c)
                .then_some(c)
        })
        .collect()
}

/// Display luminance (Rec. 709 weights on the display values).
fn luma(t: &[f32; 4]) -> f32 {
    0.2126 * t[0] + 0.7152 * t[1] + 0.0722 * t[2]
}

/// What one scene's render is checked for, measured.
#[derive(Debug)]
struct LitStats {
    /// Pixels the CPU reference sees geometry in (away from silhouettes), and sky in.
    geometry: usize,
    sky: usize,
    /// Geometry pixels whose direct light is the sky's radiance (the raster drew nothing there).
    geometry_as_sky: usize,
    /// Sky pixels whose direct light is not the sky's radiance (the raster drew something).
    sky_not_sky: usize,
    /// Geometry pixels with some direct light.
    geometry_directly_lit: usize,
    /// Mean and standard deviation of the final image's luminance over the geometry pixels.
    geometry_mean: f32,
    geometry_std: f32,
    /// Geometry pixels that are black in the final image.
    geometry_black: usize,
    /// Geometry pixels whose final colour is the sky's (within 3 of 255 per channel).
    geometry_like_sky: usize,
}

fn lit_stats(r: &LitResult, coverage: &[Option<bool>]) -> LitStats {
    let direct = &r.channel("direct").expect("direct").texels.data;
    let fin = &r.channel("final").expect("final").texels.data;
    let is_sky = |t: &[f32; 4]| {
        (Vec3::new(t[0], t[1], t[2]) - SKY_RADIANCE)
            .abs()
            .max_element()
            < 2e-3
    };
    let px = |want: bool| (0..coverage.len()).filter(move |&k| coverage[k] == Some(want));
    let geo: Vec<usize> = px(true).collect();
    // The sky's display colour: the final image where the CPU sees sky and the raster agrees.
    let sky_display = px(false).find(|&k| is_sky(&direct[k])).map(|k| fin[k]);
    let lum: Vec<f32> = geo.iter().map(|&k| luma(&fin[k])).collect();
    let mean = lum.iter().sum::<f32>() / lum.len().max(1) as f32;
    let var = lum.iter().map(|l| (l - mean).powi(2)).sum::<f32>() / lum.len().max(1) as f32;
    LitStats {
        geometry: geo.len(),
        sky: px(false).count(),
        geometry_as_sky: geo.iter().filter(|&&k| is_sky(&direct[k])).count(),
        sky_not_sky: px(false).filter(|&k| !is_sky(&direct[k])).count(),
        geometry_directly_lit: geo.iter().filter(|&&k| luma(&direct[k]) > 1e-4).count(),
        geometry_mean: mean,
        geometry_std: var.sqrt(),
        geometry_black: geo
            .iter()
            .filter(|&&k| fin[k][..3].iter().all(|&v| v <= 1.0 / 255.0))
            .count(),
        geometry_like_sky: sky_display.map_or(0, |s| {
            geo.iter()
                .filter(|&&k| (0..3).all(|c| (fin[k][c] - s[c]).abs() <= 3.0 / 255.0))
                .count()
        }),
    }
}

/// Every channel finite, and the radiance ones non-negative (a NaN or a negative from one pass
/// spreads through the denoisers and the composite).
fn assert_channels_finite(name: &str, r: &LitResult) {
    for c in &r.channels {
        let radiance = c.encoding == Encoding::Radiance;
        let bad = c.texels.data.iter().position(|t| {
            t.iter().any(|v| !v.is_finite()) || (radiance && t[..3].iter().any(|&v| v < 0.0))
        });
        if let Some(k) = bad {
            panic!(
                "{name}: channel {} texel {k} is {:?}",
                c.name, c.texels.data[k]
            );
        }
    }
}

/// `ksrt render` renders the built-in scenes and every scene of the repository (tiny images, one
/// frame) lit: the rasteriser draws geometry exactly where the CPU reference BVH sees it and sky
/// elsewhere, the geometry is lit (its direct light and final image are neither black nor the
/// sky's colour, its luminance varies), and no channel holds a NaN or a negative radiance.
#[test]
fn lit_render_completes_on_every_scene() {
    let dir = crate::app::scenes::repository_scenes_dir();
    let size = (48, 27);
    for name in [
        "default",
        "cornell",
        "cornell-obj",
        "cornell-gltf",
        "apartment",
        "statue",
    ] {
        let mut scene =
            crate::app::scenes::load(name, &dir).unwrap_or_else(|e| panic!("{name}: {e}"));
        // As `ksrt render` views a scene: its benchmark camera or the default view, and the
        // scene lit for it when its file has no lights.
        let camera = scene.prepare_view(kickstart_rt_renderer::scene::benchmark_camera(name));
        let r = render(&scene, &camera, size, 1);
        assert_channels_finite(name, &r);
        let s = lit_stats(&r, &cpu_coverage(&scene, &camera, size));
        eprintln!("{name}: {s:?}");
        assert_lit(name, &s, size.0 as usize * size.1 as usize);
    }
}

/// The checks of [`lit_render_completes_on_every_scene`] on one scene's [`LitStats`]. Measured
/// on lavapipe (48 × 27, one frame): geometry in 6% (the statue) to 100% of the pixels away from
/// silhouettes, no pixel disagreeing with the CPU coverage, at least 66% of the geometry
/// directly lit (the built-in Cornell box's shadows; 99% or more elsewhere), mean luminance 0.23
/// to 0.74 and its deviation at least 0.13, no black pixel, none of the sky's colour. The bounds
/// leave room for driver rounding and scene edits, not for a regression that loses the
/// geometry, its light or its shading.
fn assert_lit(name: &str, s: &LitStats, pixels: usize) {
    // A camera that sees little but sky would make the rest vacuous.
    assert!(
        s.geometry * 25 >= pixels,
        "{name}: geometry in only {} of {pixels} pixels: {s:?}",
        s.geometry
    );
    // Drawn exactly where the CPU sees geometry (1% for sub-pixel details between the CPU's
    // samples).
    assert!(
        s.geometry_as_sky * 100 <= s.geometry && s.sky_not_sky * 100 <= s.sky,
        "{name}: the raster disagrees with the CPU coverage: {s:?}"
    );
    assert!(
        s.geometry_directly_lit * 2 >= s.geometry,
        "{name}: most of the geometry has no direct light: {s:?}"
    );
    assert!(
        (0.1..=0.9).contains(&s.geometry_mean),
        "{name}: geometry mean luminance {} outside 0.1..=0.9: {s:?}",
        s.geometry_mean
    );
    assert!(
        s.geometry_std >= 0.05,
        "{name}: geometry nearly uniform (luminance deviation {}): {s:?}",
        s.geometry_std
    );
    assert!(
        s.geometry_black * 100 <= s.geometry,
        "{name}: {} black holes in the geometry: {s:?}",
        s.geometry_black
    );
    assert!(
        s.geometry_like_sky * 20 <= s.geometry,
        "{name}: {} geometry pixels show the sky's colour: {s:?}",
        s.geometry_like_sky
    );
}
