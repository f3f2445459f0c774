//! The plugin in a real Bevy app, rendered headless: the seed scene's GI carries each object's
//! colour onto the floor beside it, shadows fall where the sun casts them, and the scene follows
//! entities as they are despawned.
//!
//! The camera renders linear HDR (`Rgba16Float`, no tone mapping) into an image, read back
//! with Bevy's screenshot; each check compares two renders of the same view that differ in one
//! thing.

#[path = "../examples/seed/mod.rs"]
mod seed;

use std::sync::{Arc, Mutex};

use bevy::camera::RenderTarget;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::prelude::*;
use bevy::render::RenderPlugin;
use bevy::render::pipelined_rendering::PipelinedRenderingPlugin;
use bevy::render::render_resource::TextureFormat;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};
use bevy::window::ExitCondition;
use bevy::winit::WinitPlugin;
use kickstart_rt_bevy::{KickstartRtPlugin, RayTracedLighting};

const WIDTH: u32 = 320;
const HEIGHT: u32 = 180;
/// Frames each configuration renders before it is read: the denoisers' history fills.
const SETTLE_FRAMES: u32 = 24;

/// A linear RGB image read back from the camera's target.
struct Frame {
    texels: Vec<[f32; 3]>,
}

impl Frame {
    /// Mean colour of the `radius`-pixel square around `p`.
    fn mean(&self, (x, y): (u32, u32), radius: u32) -> Vec3 {
        let mut sum = Vec3::ZERO;
        let mut n = 0.0;
        for yy in y.saturating_sub(radius)..=(y + radius).min(HEIGHT - 1) {
            for xx in x.saturating_sub(radius)..=(x + radius).min(WIDTH - 1) {
                sum += Vec3::from(self.texels[(yy * WIDTH + xx) as usize]);
                n += 1.0;
            }
        }
        sum / n
    }
}

/// The app and its camera's target image.
struct Harness {
    app: App,
    target: Handle<Image>,
}

impl Harness {
    fn new(effects: RayTracedLighting) -> Harness {
        let mut app = App::new();
        app.add_plugins((
            DefaultPlugins
                .set(WindowPlugin {
                    primary_window: None,
                    exit_condition: ExitCondition::DontExit,
                    close_when_requested: false,
                    ..default()
                })
                .set(RenderPlugin {
                    synchronous_pipeline_compilation: true,
                    ..default()
                })
                .disable::<WinitPlugin>()
                .disable::<PipelinedRenderingPlugin>()
                .disable::<bevy::log::LogPlugin>(),
            KickstartRtPlugin::default(),
        ))
        .insert_resource(seed::Matte)
        .add_systems(Startup, seed::spawn);
        let image = Image::new_target_texture(WIDTH, HEIGHT, TextureFormat::Rgba16Float, None);
        let target = app.world_mut().resource_mut::<Assets<Image>>().add(image);
        app.world_mut().spawn((
            Camera3d::default(),
            Msaa::Off,
            Tonemapping::None,
            RenderTarget::Image(target.clone().into()),
            effects,
            Transform::from_translation(seed::EYE).looking_at(seed::LOOK_AT, Vec3::Y),
        ));
        app.finish();
        app.cleanup();
        Harness { app, target }
    }

    fn run(&mut self, frames: u32) {
        for _ in 0..frames {
            self.app.update();
        }
    }

    /// Renders until a screenshot of the target arrives.
    fn capture(&mut self) -> Frame {
        let slot: Arc<Mutex<Option<Image>>> = Arc::default();
        let into = slot.clone();
        self.app
            .world_mut()
            .spawn(Screenshot::image(self.target.clone()))
            .observe(move |captured: On<ScreenshotCaptured>| {
                *into.lock().unwrap() = Some(captured.image.clone());
            });
        for _ in 0..20 {
            self.app.update();
            if let Some(image) = slot.lock().unwrap().take() {
                return decode(&image);
            }
        }
        panic!("no screenshot after 20 frames");
    }

    /// The entity of coloured object `i`.
    fn object(&mut self, i: usize) -> Entity {
        let world = self.app.world_mut();
        world
            .query::<(Entity, &seed::Object)>()
            .iter(world)
            .find(|(_, o)| o.0 == i)
            .map(|(e, _)| e)
            .expect("the seed scene has three objects")
    }

    fn set_object_visibility(&mut self, i: usize, visibility: Visibility) {
        let object = self.object(i);
        self.app.world_mut().entity_mut(object).insert(visibility);
    }
}

/// `Rgba16Float` texels to linear RGB.
fn decode(image: &Image) -> Frame {
    assert_eq!(image.texture_descriptor.format, TextureFormat::Rgba16Float);
    let data = image.data.as_ref().expect("screenshot has data");
    assert_eq!(data.len(), (WIDTH * HEIGHT * 8) as usize);
    let half = |b: &[u8]| f16_to_f32(u16::from_le_bytes([b[0], b[1]]));
    let texels = data
        .chunks_exact(8)
        .map(|t| [half(&t[0..2]), half(&t[2..4]), half(&t[4..6])])
        .collect();
    Frame { texels }
}

fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = i32::from((h >> 10) & 0x1f);
    let frac = f32::from(h & 0x3ff);
    sign * match exp {
        0 => frac * 2f32.powi(-24),
        31 => f32::INFINITY,
        e => (1.0 + frac / 1024.0) * 2f32.powi(e - 15),
    }
}

/// The pixel showing world point `p` (Bevy's default perspective camera at the seed's eye).
fn pixel_of(p: Vec3) -> (u32, u32) {
    let view = Transform::from_translation(seed::EYE)
        .looking_at(seed::LOOK_AT, Vec3::Y)
        .to_matrix()
        .inverse();
    let projection = bevy::camera::CameraProjection::get_clip_from_view(&PerspectiveProjection {
        aspect_ratio: WIDTH as f32 / HEIGHT as f32,
        ..default()
    });
    let ndc = (projection * view).project_point3(p);
    let x = (ndc.x * 0.5 + 0.5) * WIDTH as f32;
    let y = (0.5 - ndc.y * 0.5) * HEIGHT as f32;
    (x as u32, y as u32)
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
        let px = pixel_of(p);
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
    let lit = after.mean(pixel_of(behind), 0);
    let lifted = |shadowed: &Frame, open: &Frame, at: Vec3| {
        shadow_pixels_lifted(shadowed, open, pixel_of(at), 12, lit)
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
    let lit = after.mean(pixel_of(behind), 0);
    let sunlit_before = before.mean(pixel_of(sunlit_side), 0);
    let despawned = shadow_pixels_lifted(&before, &after, pixel_of(behind), 12, lit);
    let sunward = shadow_pixels_lifted(&before, &after, pixel_of(sunlit_side), 12, lit);
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
