//! The plugin in a real Bevy app, rendered headless: the seed scene's GI carries each object's
//! colour onto the floor beside it, shadows fall where the sun casts them, the scene follows
//! entities as they are despawned, ambient occlusion darkens the floor at an object's foot, and
//! a mirror floor reflects a glowing box where the mirror image lies.
//!
//! The camera renders linear HDR (`Rgba16Float`, no tone mapping) into an image, read back
//! with Bevy's screenshot; each check compares two renders of the same view that differ in one
//! thing.

use crate::{harness, seed};

use bevy::light::GlobalAmbientLight;
use bevy::prelude::*;
use harness::{Frame, HEIGHT, Harness, SETTLE_FRAMES, Setup, WIDTH, pixel_of};
use kickstart_rt_bevy::RayTracedLighting;

/// The pixel showing world point `p` from the seed's eye.
fn seed_pixel(p: Vec3) -> (u32, u32) {
    pixel_of(
        &Transform::from_translation(seed::EYE).looking_at(seed::LOOK_AT, Vec3::Y),
        p,
    )
}

/// Radius of a circle on the floor around each coloured object, just outside its footprint.
const RING: [f32; 3] = [1.0, 1.7, 1.1];

/// `with` − `without` on the floor on the ring around object `i`, summed over the ring's half
/// that faces the camera (floor that no object hides: every object stands behind it), leaving
/// out the part of the ring that comes near another object.
fn added_on_ring(i: usize, without: &Frame, with: &Frame) -> Vec3 {
    let mut sum = Vec3::ZERO;
    for k in 0..48 {
        let a = std::f32::consts::TAU * k as f32 / 48.0;
        let offset = Vec3::new(a.cos(), 0.0, a.sin());
        let p = seed::PLACES[i] + offset * RING[i];
        let near_another = (0..3).any(|j| j != i && p.distance(seed::PLACES[j]) < RING[j] + 0.6);
        if offset.z < 0.25 || near_another {
            continue;
        }
        let px = seed_pixel(p);
        sum += with.mean(px, 0) - without.mean(px, 0);
    }
    sum
}

#[test]
fn gi_carries_each_objects_colour_onto_the_floor() {
    // GI alone: what an object adds to the floor around it is its bounce light, measured by
    // hiding it (which also checks the scene follows visibility).
    let mut h = Harness::new(RayTracedLighting {
        reflections: false,
        ao: false,
        shadows: false,
        ..default()
    });
    h.run(SETTLE_FRAMES);
    let all = h.capture();
    for i in 0..3 {
        h.set_object_visibility(i, Visibility::Hidden);
        h.run(SETTLE_FRAMES);
        let without = h.capture();
        h.set_object_visibility(i, Visibility::Inherited);

        let added = added_on_ring(i, &without, &all);
        let colour = Vec3::from(seed::COLOURS[i]);
        let dominant = colour.max_position();
        println!("object {i}: its bounce light on its ring: {added}");
        for c in (0..3).filter(|c| *c != dominant) {
            assert!(
                added[dominant] > 2.0 * added[c].max(0.0),
                "object {i}: the bounce light around a {colour} object is {added}"
            );
        }
        // More than noise would leave (the floor is lit at about 0.55 a pixel).
        assert!(
            added[dominant] > 0.03,
            "object {i}: it bounced only {added}"
        );
    }
}

/// Floor pixels within `radius` pixels of `centre` that `before` shows in shadow (neutral grey,
/// darker than a third of `lit`) and `after` shows lit (within 10 % of `lit`).
fn shadow_pixels_lifted(
    before: &Frame,
    after: &Frame,
    centre: (u32, u32),
    radius: u32,
    lit: Vec3,
) -> usize {
    let mut count = 0;
    for y in centre.1.saturating_sub(radius)..(centre.1 + radius).min(HEIGHT) {
        for x in centre.0.saturating_sub(radius)..(centre.0 + radius).min(WIDTH) {
            let b = before.mean((x, y), 0);
            let a = after.mean((x, y), 0);
            let grey = b.max_element() - b.min_element() < 0.02;
            if grey && b.length() < lit.length() / 3.0 && (a - lit).length() < 0.1 * lit.length() {
                count += 1;
            }
        }
    }
    count
}

/// Where the sun's ray through the sphere's centre meets the floor (the seed's sun shines from
/// (4, 6, 3) towards the origin), and a point as far again beyond the sphere's foot on its
/// sunlit side (the shadow reaches 0.3 m sunward of the foot; this point is 1.3 m).
fn sphere_shadow_points() -> (Vec3, Vec3) {
    let to_sun = Vec3::new(4.0, 6.0, 3.0).normalize();
    let centre = seed::PLACES[0] + Vec3::Y * 0.7;
    let behind = centre - to_sun * (centre.y / to_sun.y);
    let sunlit_side = seed::PLACES[0] + (seed::PLACES[0] - behind.with_y(0.0)) * 2.2;
    (behind, sunlit_side)
}

#[test]
fn shadows_fall_where_the_sun_casts_them_and_follow_their_object() {
    let mut h = Harness::new(RayTracedLighting {
        gi: false,
        reflections: false,
        ao: false,
        ..default()
    });
    h.run(SETTLE_FRAMES);
    let before = h.capture();
    // Moved well away (an instance update), back (another), then despawned.
    let sphere = h.object(0);
    let home = h.app.world().get::<Transform>(sphere).copied().unwrap();
    let away = home.with_translation(home.translation + Vec3::new(0.0, 0.0, -6.0));
    h.app.world_mut().entity_mut(sphere).insert(away);
    h.run(SETTLE_FRAMES);
    let moved = h.capture();
    h.app.world_mut().entity_mut(sphere).insert(home);
    h.run(SETTLE_FRAMES);
    let back = h.capture();
    h.app.world_mut().despawn(sphere);
    h.run(SETTLE_FRAMES);
    let after = h.capture();

    let (behind, sunlit_side) = sphere_shadow_points();
    let lit = after.mean(seed_pixel(behind), 0);
    let lifted = |shadowed: &Frame, open: &Frame, at: Vec3| {
        shadow_pixels_lifted(shadowed, open, seed_pixel(at), 12, lit)
    };
    let (despawned, sunward) = (
        lifted(&before, &after, behind),
        lifted(&before, &after, sunlit_side),
    );
    let (moved_away, moved_back) = (
        lifted(&before, &moved, behind),
        lifted(&back, &moved, behind),
    );
    println!(
        "open floor {lit}: shadow pixels behind the sphere lifted by the despawn {despawned}, \
         by the move {moved_away}, back after moving back {moved_back}; sunward {sunward}"
    );
    // The open floor there is sunlit (the sun brings it to about 0.6)…
    assert!(
        lit.min_element() > 0.3,
        "the floor behind the sphere is {lit} without it"
    );
    // …and many floor pixels on the far side of the sphere from the sun turn from shadow into
    // sunlight when it goes (the patch is 24 × 24 pixels; the sphere hides part of it)…
    assert!(
        despawned >= 40,
        "only {despawned} shadow pixels behind the sphere"
    );
    // …none on the side facing the sun…
    assert_eq!(sunward, 0, "shadow pixels on the sphere's sunlit side");
    // …and the shadow leaves with the sphere as it moves, and comes back with it.
    assert!(
        moved_away >= 40,
        "moving the sphere away left its shadow ({moved_away} lifted)"
    );
    assert!(
        moved_back >= 40,
        "moving the sphere back left no shadow ({moved_back})"
    );
}

#[test]
fn raw_shadows_with_denoise_off_are_dark_where_the_sun_is_hidden() {
    // With the denoisers off the composite reads the shadow trace's raw output (occluder
    // distance where hidden, minus the light's angular tan where lit): read as visibility it
    // would light the shadow and darken the open floor.
    let mut h = Harness::new(RayTracedLighting {
        gi: false,
        reflections: false,
        ao: false,
        denoise: false,
        ..default()
    });
    h.run(4);
    let before = h.capture();
    let sphere = h.object(0);
    h.app.world_mut().despawn(sphere);
    h.run(4);
    let after = h.capture();

    let (behind, sunlit_side) = sphere_shadow_points();
    let lit = after.mean(seed_pixel(behind), 0);
    let sunlit_before = before.mean(seed_pixel(sunlit_side), 0);
    let despawned = shadow_pixels_lifted(&before, &after, seed_pixel(behind), 12, lit);
    let sunward = shadow_pixels_lifted(&before, &after, seed_pixel(sunlit_side), 12, lit);
    println!(
        "raw shadows: open floor {lit}, sunward floor with the sphere {sunlit_before}; shadow \
         pixels lifted by the despawn {despawned}, sunward {sunward}"
    );
    assert!(
        lit.min_element() > 0.3,
        "the open floor behind the sphere is {lit} with denoise off"
    );
    assert!(
        (sunlit_before - lit).length() < 0.1 * lit.length(),
        "the sunlit floor beside the sphere is {sunlit_before}, the open floor {lit}"
    );
    assert!(
        despawned >= 40,
        "only {despawned} raw shadow pixels behind the sphere"
    );
    assert_eq!(sunward, 0, "raw shadow pixels on the sphere's sunlit side");
}

/// Mean of `frame` over the floor points `points`, one pixel each.
fn mean_over(frame: &Frame, points: &[Vec3]) -> Vec3 {
    let sum: Vec3 = points.iter().map(|p| frame.mean(seed_pixel(*p), 0)).sum();
    sum / points.len() as f32
}

/// Floor points on the camera's side of the sphere, `r` from its foot (the sphere's radius is
/// 0.7: at 0.8 it overhangs them, well within the AO radius).
fn ring_in_front_of_the_sphere(r: f32) -> Vec<Vec3> {
    (0..24)
        .map(|k| std::f32::consts::PI * (0.15 + 0.7 * k as f32 / 23.0))
        .map(|a| seed::PLACES[0] + Vec3::new(a.cos(), 0.0, a.sin()) * r)
        .collect()
}

/// Open floor in front of every object, further than the AO radius (1 m) from all of them.
fn open_floor() -> Vec<Vec3> {
    (0..24)
        .map(|k| Vec3::new(-1.2 + 0.1 * k as f32, 0.0, 2.6))
        .collect()
}

#[test]
fn ambient_occlusion_darkens_the_floor_at_an_objects_foot_and_nowhere_open() {
    let off = RayTracedLighting {
        reflections: false,
        gi: false,
        ao: false,
        shadows: false,
        ..default()
    };
    let mut h = Harness::new(off.clone());
    h.run(SETTLE_FRAMES);
    let without = h.capture();
    // AO alone scales the lit image; with GI, it comes from the GI's rays and scales the GI.
    h.set_effects(RayTracedLighting {
        ao: true,
        ..off.clone()
    });
    h.run(SETTLE_FRAMES);
    let with = h.capture();
    h.set_effects(RayTracedLighting {
        gi: true,
        ..off.clone()
    });
    h.run(SETTLE_FRAMES);
    let gi = h.capture();
    h.set_effects(RayTracedLighting {
        gi: true,
        ao: true,
        ..off
    });
    h.run(SETTLE_FRAMES);
    let gi_ao = h.capture();

    let (foot, open) = (ring_in_front_of_the_sphere(0.8), open_floor());
    let ratio = |with: &Frame, without: &Frame, at: &[Vec3]| {
        mean_over(with, at).length() / mean_over(without, at).length()
    };
    let (at_foot, in_the_open) = (ratio(&with, &without, &foot), ratio(&with, &without, &open));
    let gi_lost = |at: &[Vec3]| (mean_over(&gi, at) - mean_over(&gi_ao, at)).length();
    let gi_added = mean_over(&gi, &foot) - mean_over(&without, &foot);
    println!(
        "AO alone: the floor at the sphere's foot keeps {at_foot:.3} of its light, the open \
         floor {in_the_open:.3}; with GI (which adds {gi_added} at the foot), AO takes {:.4} \
         at the foot and {:.4} in the open",
        gi_lost(&foot),
        gi_lost(&open)
    );
    // The SDK's AO is the mean over cosine-weighted rays of min(hit distance / radius, 1), not
    // the fraction of rays blocked: about a third of the rays from this ring (0.1 m outside the
    // sphere's footprint) hit the sphere, 0.36 to 1 m away, which leaves about 0.85.
    assert!(
        at_foot < 0.92,
        "AO kept {at_foot} of the light at the sphere's foot"
    );
    assert!(
        (in_the_open - 1.0).abs() < 0.02,
        "AO changed the open floor by a factor {in_the_open}"
    );
    // With GI, AO (from the GI's own rays) scales the GI at the foot by about what AO alone
    // left of the light there: it takes a share of the GI near 1 − `at_foot`.
    assert!(
        gi_lost(&foot) > 0.5 * (1.0 - at_foot) * gi_added.length(),
        "AO with GI took {} of the {gi_added} the GI added at the sphere's foot",
        gi_lost(&foot)
    );
    assert!(
        gi_lost(&open) < 0.01,
        "AO with GI took {} from the open floor",
        gi_lost(&open)
    );
}

/// The mirror scene's camera: above and in front of the box, looking down at the floor
/// before it.
fn mirror_camera() -> Transform {
    Transform::from_xyz(0.0, 1.5, 5.0).looking_at(Vec3::new(0.0, 0.3, 0.0), Vec3::Y)
}

/// A mirror floor (white metal, roughness 0) and a glowing red unit box standing on it at the
/// origin; no light besides the box, so the floor shows only what it reflects.
fn mirror_scene(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    commands.insert_resource(GlobalAmbientLight::NONE);
    commands.spawn((
        Mesh3d(meshes.add(Plane3d::default().mesh().size(16.0, 16.0))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::linear_rgb(0.9, 0.9, 0.9),
            metallic: 1.0,
            perceptual_roughness: 0.0,
            ..default()
        })),
    ));
    commands.spawn((
        Mesh3d(meshes.add(Cuboid::new(1.0, 1.0, 1.0))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::BLACK,
            emissive: LinearRgba::rgb(2.0, 0.1, 0.05),
            ..default()
        })),
        Transform::from_xyz(0.0, 0.5, 0.0),
    ));
}

#[test]
fn a_mirror_floor_reflects_a_glowing_box_where_its_mirror_image_lies() {
    let setup = Setup {
        camera: mirror_camera(),
        ..default()
    };
    let only_reflections = RayTracedLighting {
        gi: false,
        ao: false,
        shadows: false,
        ..default()
    };
    let mut h = Harness::with(setup, only_reflections.clone(), mirror_scene, false);
    h.run(SETTLE_FRAMES);
    let with = h.capture();
    h.set_effects(RayTracedLighting {
        reflections: false,
        ..only_reflections
    });
    h.run(SETTLE_FRAMES);
    let without = h.capture();

    // The box's front face (z = 0.5) mirrored in the floor: the floor pixels that show it lie
    // where the mirrored points project. Beside the box (|x| ≥ 1.2) the floor mirrors nothing.
    let image = |x: f32, y: f32| h.pixel_of(Vec3::new(x, -y, 0.5));
    let mirrored: Vec<_> = [(-0.25, 0.3), (0.0, 0.5), (0.25, 0.7)]
        .map(|(x, y)| image(x, y))
        .to_vec();
    let beside: Vec<_> = [(-1.5, 0.5), (1.5, 0.5), (-2.0, 0.2), (2.0, 0.2)]
        .map(|(x, y)| image(x, y))
        .to_vec();
    let box_face = with.mean(h.pixel_of(Vec3::new(0.0, 0.5, 0.5)), 1);
    for (name, pixels) in [("mirror image", &mirrored), ("beside it", &beside)] {
        for p in pixels {
            println!(
                "{name} {p:?}: with reflections {}, without {}",
                with.mean(*p, 1),
                without.mean(*p, 1)
            );
        }
    }
    println!("the box's face: {box_face}");
    for p in &mirrored {
        let (on, off) = (with.mean(*p, 1), without.mean(*p, 1));
        // The box glows 2.0 in red; the white metal reflects about 0.9 of it.
        assert!(
            on.x > 0.25 * box_face.x && on.x > 4.0 * on.y.max(on.z),
            "the mirror image of the red box at {p:?} is {on}"
        );
        assert!(
            off.x < 0.05,
            "the floor at {p:?} is {off} with reflections off"
        );
    }
    for p in &beside {
        let (on, off) = (with.mean(*p, 1), without.mean(*p, 1));
        assert!(
            on.x < 0.1 * box_face.x && (on - off).length() < 0.05,
            "the floor beside the mirror image, at {p:?}, is {on} (without reflections {off})"
        );
    }
}
