//! `AlphaMode::Mask` materials traced as cutouts: a card with a checkerboard of alpha 0.75 and
//! 0.25 cells, held above the floor in the sun, casts a checkered ray-traced shadow (dark under
//! the cells its mask keeps, lit under those it cuts), and the plugin bakes the card again when
//! the material's cutoff, its texture's texels or its alpha mode change.
//!
//! The camera looks straight down at the shadow, the card out of its way; the effects are the
//! raw shadow alone (no denoiser blurring the cells' edges).

use crate::harness;

use bevy::asset::RenderAssetUsages;
use bevy::image::ImageSampler;
use bevy::light::GlobalAmbientLight;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use harness::{Frame, Harness, Setup};
use kickstart_rt_bevy::RayTracedLighting;

/// Cells of the card's texture a side (one texel each).
const CELLS: u32 = 4;
/// The card: a 1 m square, horizontal, its centre here.
const CARD: Vec3 = Vec3::new(0.0, 2.0, 0.0);

/// Unit vector towards the sun (it shines from (4, 6, 3) towards the origin).
fn to_sun() -> Vec3 {
    Vec3::new(4.0, 6.0, 3.0).normalize()
}

/// The floor point under the sun's ray through card point `p`.
fn on_floor(p: Vec3) -> Vec3 {
    p - to_sun() * (p.y / to_sun().y)
}

/// The card's point at texture coordinates `(u, v)` (Bevy's plane: u along +x, v along +z).
fn card_point(u: f32, v: f32) -> Vec3 {
    CARD + Vec3::new(u - 0.5, 0.0, v - 0.5)
}

/// Alpha of texel `(x, y)`: 0.75 on the even cells, 0.25 on the odd (`inverted` swaps them).
fn alpha(x: u32, y: u32, inverted: bool) -> u8 {
    if (x + y).is_multiple_of(2) != inverted {
        192
    } else {
        64
    }
}

/// The checkerboard texture's texels (white, with the cells' alpha).
fn texels(inverted: bool) -> Vec<u8> {
    (0..CELLS * CELLS)
        .flat_map(|i| [255, 255, 255, alpha(i % CELLS, i / CELLS, inverted)])
        .collect()
}

/// Marks the card.
#[derive(Component)]
struct Card;

/// The card's texture.
#[derive(Resource)]
struct Checker(Handle<Image>);

fn scene(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut images: ResMut<Assets<Image>>,
) {
    commands.insert_resource(GlobalAmbientLight::NONE);
    let mut image = Image::new(
        Extent3d {
            width: CELLS,
            height: CELLS,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        texels(false),
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::default(),
    );
    image.sampler = ImageSampler::nearest();
    let checker = images.add(image);
    commands.insert_resource(Checker(checker.clone()));
    commands.spawn((
        Mesh3d(meshes.add(Plane3d::default().mesh().size(16.0, 16.0))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::linear_rgb(0.75, 0.75, 0.75),
            perceptual_roughness: 1.0,
            reflectance: 0.0,
            ..default()
        })),
    ));
    commands.spawn((
        Mesh3d(meshes.add(Plane3d::default().mesh().size(1.0, 1.0))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color_texture: Some(checker),
            alpha_mode: AlphaMode::Mask(0.5),
            double_sided: true,
            cull_mode: None,
            ..default()
        })),
        Transform::from_translation(CARD),
        Card,
    ));
    commands.spawn((
        DirectionalLight {
            illuminance: 3000.0,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::from_translation(to_sun()).looking_at(Vec3::ZERO, Vec3::Y),
    ));
}

/// The shadow of each cell: its mean brightness over the 3 × 3 pixels at the floor point under
/// the cell's centre, row by row.
fn cell_shadows(h: &Harness, frame: &Frame) -> Vec<f32> {
    (0..CELLS * CELLS)
        .map(|i| {
            let (x, y) = (i % CELLS, i / CELLS);
            let (u, v) = (
                (x as f32 + 0.5) / CELLS as f32,
                (y as f32 + 0.5) / CELLS as f32,
            );
            frame
                .mean(h.pixel_of(on_floor(card_point(u, v))), 1)
                .length()
        })
        .collect()
}

/// Checks that the cells `opaque` marks are in shadow (under a third of the open floor's light)
/// and the others lit (within 10 % of it).
fn assert_shadows(what: &str, shadows: &[f32], open: f32, opaque: impl Fn(u32, u32) -> bool) {
    let rows: Vec<String> = shadows
        .chunks(CELLS as usize)
        .map(|row| {
            row.iter()
                .map(|s| format!("{:.2}", s / open))
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect();
    println!(
        "{what}: cell shadows / open floor ({open:.3}): {}",
        rows.join(" | ")
    );
    for (i, s) in shadows.iter().enumerate() {
        let (x, y) = (i as u32 % CELLS, i as u32 / CELLS);
        if opaque(x, y) {
            assert!(
                *s < open / 3.0,
                "{what}: cell ({x}, {y}) is lit ({s}, open {open})"
            );
        } else {
            assert!(
                (s - open).abs() < 0.1 * open,
                "{what}: cell ({x}, {y}) is shadowed ({s}, open {open})"
            );
        }
    }
}

/// Changes the card's material with `edit`.
fn edit_card_material(h: &mut Harness, edit: impl FnOnce(&mut StandardMaterial)) {
    let world = h.app.world_mut();
    let id = world
        .query_filtered::<&MeshMaterial3d<StandardMaterial>, With<Card>>()
        .single(world)
        .expect("one card")
        .id();
    let mut materials = world.resource_mut::<Assets<StandardMaterial>>();
    edit(&mut materials.get_mut(id).expect("the card's material"));
}

#[test]
fn a_masked_card_casts_a_checkered_shadow_and_follows_its_material() {
    let shadow_centre = on_floor(CARD);
    let setup = Setup {
        camera: Transform::from_translation(shadow_centre + Vec3::Y * 5.0)
            .looking_at(shadow_centre, Vec3::NEG_Z),
        ..default()
    };
    let effects = RayTracedLighting {
        reflections: false,
        gi: false,
        ao: false,
        denoise: false,
        ..default()
    };
    let mut h = Harness::with(setup, effects, scene, false);
    h.run(4);
    let frame = h.capture();
    // Open floor beside the shadow, on the side away from the card.
    let open = frame
        .mean(h.pixel_of(shadow_centre - Vec3::new(1.5, 0.0, 0.0)), 2)
        .length();
    assert!(open > 0.3, "the open floor is {open}");
    assert_shadows("mask 0.5", &cell_shadows(&h, &frame), open, |x, y| {
        alpha(x, y, false) > 128
    });

    // A cutoff above every cell's alpha: the card lets all light through.
    edit_card_material(&mut h, |m| m.alpha_mode = AlphaMode::Mask(0.9));
    h.run(4);
    let frame = h.capture();
    assert_shadows("mask 0.9", &cell_shadows(&h, &frame), open, |_, _| false);

    // Back to 0.5, and the texture's texels inverted in place: the other cells cast shadow.
    edit_card_material(&mut h, |m| m.alpha_mode = AlphaMode::Mask(0.5));
    let checker = h.app.world().resource::<Checker>().0.clone();
    if let Some(mut image) = h
        .app
        .world_mut()
        .resource_mut::<Assets<Image>>()
        .get_mut(&checker)
    {
        image.data = Some(texels(true));
    }
    h.run(4);
    let frame = h.capture();
    assert_shadows(
        "inverted texels",
        &cell_shadows(&h, &frame),
        open,
        |x, y| alpha(x, y, true) > 128,
    );

    // Opaque: the same card shadows every cell.
    edit_card_material(&mut h, |m| m.alpha_mode = AlphaMode::Opaque);
    h.run(4);
    let frame = h.capture();
    assert_shadows("opaque", &cell_shadows(&h, &frame), open, |_, _| true);

    // Masked without a texture: the base colour's alpha alone, under the cutoff: no shadow.
    edit_card_material(&mut h, |m| {
        m.alpha_mode = AlphaMode::Mask(0.5);
        m.base_color_texture = None;
        m.base_color = Color::linear_rgba(1.0, 1.0, 1.0, 0.3);
    });
    h.run(4);
    let frame = h.capture();
    assert_shadows(
        "untextured, alpha 0.3",
        &cell_shadows(&h, &frame),
        open,
        |_, _| false,
    );
}
