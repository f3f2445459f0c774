//! The SDK's presets on `RayTracedLighting`: each traces every effect at the preset's rate. With
//! the denoisers off, a pixel shows the raw trace of its block's traced pixel, so the image of a
//! raw effect is made of blocks of the preset's size: a shadow's edge or AO's noise never
//! changes inside one, and does inside blocks twice as large.
//! Denoised, a reduced rate still puts the shadow where the sun casts it.

use crate::{harness, seed};

use bevy::prelude::*;
use harness::{Frame, HEIGHT, Harness, SETTLE_FRAMES, WIDTH};
use kickstart_rt_bevy::kickstart_rt::{Effect, HalfResolutionMode};
use kickstart_rt_bevy::{Preset, RayTracedLighting};

/// The pixels that show the floor: in `plain`, a render without shadows or AO, neutral grey
/// within 10 % of the open floor's brightness `lit`. An object's side turned away from the sun
/// is black, as dark as a shadow and as grey, so it takes a render without shadows to tell
/// the floor from it.
fn floor_mask(plain: &Frame, lit: f32) -> Vec<bool> {
    (0..WIDTH * HEIGHT)
        .map(|i| {
            let t = plain.at(i % WIDTH, i / WIDTH);
            t.max_element() - t.min_element() < 0.02 && (t.length() - lit).abs() < 0.1 * lit
        })
        .collect()
}

/// The `side`-pixel blocks (aligned to the image's corner) within `radius` pixels of `centre`
/// that show only floor (every pixel in `floor`) and whose brightest and darkest pixels differ
/// by more than a fifth of `lit`, the open floor's brightness: a raw shadow's edge or AO's
/// noise inside the block.
fn broken_blocks(
    frame: &Frame,
    floor: &[bool],
    (centre, radius): ((u32, u32), u32),
    side: u32,
    lit: f32,
) -> usize {
    let (x0, y0) = (
        centre.0.saturating_sub(radius) / side * side,
        centre.1.saturating_sub(radius) / side * side,
    );
    let (x1, y1) = (
        (centre.0 + radius).min(WIDTH),
        (centre.1 + radius).min(HEIGHT),
    );
    let mut broken = 0;
    for by in (y0..y1.saturating_sub(side - 1)).step_by(side as usize) {
        for bx in (x0..x1.saturating_sub(side - 1)).step_by(side as usize) {
            let mut pixels = (0..side * side).map(|i| (bx + i % side, by + i / side));
            let texels: Vec<Vec3> = pixels.clone().map(|(x, y)| frame.at(x, y)).collect();
            let floor = pixels.all(|(x, y)| floor[(y * WIDTH + x) as usize]);
            let (lo, hi) = texels.iter().fold((f32::MAX, f32::MIN), |(lo, hi), t| {
                (lo.min(t.length()), hi.max(t.length()))
            });
            if floor && hi - lo > 0.2 * lit {
                broken += 1;
            }
        }
    }
    broken
}

/// The floor pixel where the sphere's shadow falls (its centre's, along the seed's sun).
fn sphere_shadow() -> Vec3 {
    let to_sun = Vec3::new(4.0, 6.0, 3.0).normalize();
    let centre = seed::PLACES[0] + Vec3::Y * 0.7;
    centre - to_sun * (centre.y / to_sun.y)
}

#[test]
fn each_preset_traces_shadows_and_ao_in_blocks_of_its_size() {
    let raw = |preset, ao: bool| RayTracedLighting {
        reflections: false,
        gi: false,
        ao,
        shadows: !ao,
        denoise: false,
        preset,
        ..default()
    };
    // One app, the preset changed at run time (which remakes the camera's denoisers).
    // First without shadows or AO, to find the floor.
    let mut h = Harness::new(RayTracedLighting {
        shadows: false,
        ..raw(Preset::Quality, false)
    });
    h.run(2);
    let plain = h.capture();
    let open = plain.mean(h.pixel_of(Vec3::new(0.0, 0.0, 2.6)), 2).length();
    let floor = floor_mask(&plain, open);
    let shadow = h.pixel_of(sphere_shadow());
    let foot = h.pixel_of(seed::PLACES[0] + Vec3::new(0.0, 0.0, 0.8));
    for preset in Preset::ALL {
        for (effect, centre) in [(Effect::Shadow, shadow), (Effect::AmbientOcclusion, foot)] {
            h.set_effects(raw(preset, effect == Effect::AmbientOcclusion));
            h.run(3);
            let frame = h.capture();
            let side = preset.half_resolution_mode(effect, 0).block_size();
            let broken = |side| broken_blocks(&frame, &floor, (centre, 24), side, open);
            let (inside, coarser) = (broken(side), broken(2 * side));
            println!(
                "{} {effect:?}: blocks of {side}: {inside} changing inside (open floor \
                 {open:.3}); of {}: {coarser}",
                preset.name(),
                2 * side,
            );
            assert_eq!(
                inside,
                0,
                "{} traces {effect:?} in blocks of {side}, yet {inside} of them change inside",
                preset.name()
            );
            // Blocks twice as large do change: the edge or the noise is there, at this rate.
            assert!(
                coarser >= 4,
                "{} {effect:?}: only {coarser} blocks of {} change inside",
                preset.name(),
                2 * side
            );
        }
    }
    // The rates the test expects of the SDK's presets: every effect of quality per pixel,
    // balanced per 2×2, performance's AO per 4×4 and its shadows per 2×2.
    let side = |p: Preset, e| p.half_resolution_mode(e, 0).block_size();
    assert_eq!(
        [Preset::Quality, Preset::Balanced, Preset::Performance]
            .map(|p| (side(p, Effect::Shadow), side(p, Effect::AmbientOcclusion))),
        [(1, 1), (2, 2), (2, 4)]
    );
    assert_eq!(
        Preset::Quality.half_resolution_mode(Effect::Diffuse, 3),
        HalfResolutionMode::Off
    );
}

/// Floor pixels (those `floor` marks) near `centre` dark in `shadowed` and lit (within 10 % of
/// `lit`) in `open`.
fn lifted(
    (shadowed, open): (&Frame, &Frame),
    floor: &[bool],
    centre: (u32, u32),
    lit: Vec3,
) -> usize {
    let mut count = 0;
    for y in centre.1.saturating_sub(12)..(centre.1 + 12).min(HEIGHT) {
        for x in centre.0.saturating_sub(12)..(centre.0 + 12).min(WIDTH) {
            let (b, a) = (shadowed.at(x, y), open.at(x, y));
            let on_floor = floor[(y * WIDTH + x) as usize];
            if on_floor
                && b.length() < lit.length() / 3.0
                && (a - lit).length() < 0.1 * lit.length()
            {
                count += 1;
            }
        }
    }
    count
}

#[test]
fn denoised_at_every_reduced_rate_the_shadow_falls_where_the_sun_casts_it() {
    for effects in [
        RayTracedLighting::performance(),
        RayTracedLighting::balanced(),
    ] {
        let name = effects.preset.name();
        let shadows = RayTracedLighting {
            gi: false,
            reflections: false,
            ao: false,
            ..effects
        };
        // The floor, told from the objects' dark sides without shadows.
        let mut h = Harness::new(RayTracedLighting {
            shadows: false,
            ..shadows.clone()
        });
        h.run(2);
        let plain = h.capture();
        h.set_effects(shadows);
        h.run(SETTLE_FRAMES);
        let before = h.capture();
        let sphere = h.object(0);
        h.app.world_mut().despawn(sphere);
        h.run(SETTLE_FRAMES);
        let after = h.capture();
        let behind = h.pixel_of(sphere_shadow());
        let lit = after.mean(behind, 0);
        let floor = floor_mask(&plain, lit.length());
        // Sunward of the sphere, 1.3 m from its foot: its shadow reaches 0.3 m that way, and the
        // 24-pixel patch around this point stays clear of it.
        let foot = seed::PLACES[0];
        let sunward = h.pixel_of(foot + (foot - sphere_shadow().with_y(0.0)) * 2.2);
        let (shadow, beside) = (
            lifted((&before, &after), &floor, behind, lit),
            lifted((&before, &after), &floor, sunward, lit),
        );
        println!("{name}: open floor {lit}; shadow pixels lifted {shadow}, sunward {beside}");
        assert!(lit.min_element() > 0.3, "{name}: the open floor is {lit}");
        assert!(shadow >= 40, "{name}: only {shadow} shadow pixels");
        assert_eq!(beside, 0, "{name}: shadow pixels on the sunlit side");
    }
}
