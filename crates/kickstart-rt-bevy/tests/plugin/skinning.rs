//! Skinned and morphed meshes traced at the pose Bevy draws them in: a two-joint bar and a
//! morphing box float above the floor under a sun straight overhead, so that each one's shadow
//! is its outline seen from above. Bending the bar's joint moves the shadow of its outer half,
//! a morph weight moves the box's, and the traced pose is the drawn one: the raw shadow's
//! outline matches Bevy's rasterised outline of the bar within 2 pixels.
//!
//! The camera looks straight down from far away through a narrow field of view (close to an
//! orthographic view: the bar's top, 0.6 m above the floor, lands within half a pixel of its
//! shadow). The deformed meshes are on render layer 1, which the camera does not draw unless a
//! test asks for it: the SDK traces every visible entity whatever the camera's layers, so the
//! floor under them shows their whole shadow.

use crate::harness;

use bevy::camera::visibility::{NoFrustumCulling, RenderLayers};
use bevy::light::GlobalAmbientLight;
use bevy::mesh::VertexAttributeValues;
use bevy::mesh::morph::{MeshMorphWeights, MorphAttributes};
use bevy::mesh::skinning::{SkinnedMesh, SkinnedMeshInverseBindposes};
use bevy::prelude::*;
use harness::{Frame, HEIGHT, Harness, Setup, WIDTH};
use kickstart_rt_bevy::RayTracedLighting;

/// Height of the bar's and the box's centres above the floor.
const LIFT: f32 = 0.5;
/// Where the morphing box's centre stands (its instance transform), at weight 0.
const BOX: Vec3 = Vec3::new(-1.5, LIFT, 1.2);
/// The box's morph target moves every vertex this far.
const BOX_MORPH: Vec3 = Vec3::new(0.0, 0.0, -1.0);
/// The bar's morph target moves the vertices of its tip (x = 1) this far.
const TIP_MORPH: Vec3 = Vec3::new(0.0, 0.0, 0.5);

/// The bar's joints (the root, and the outer half's joint, a child of the root at its
/// origin), the bar and the box.
#[derive(Resource)]
struct Rig {
    outer: Entity,
    bar: Entity,
    morphing_box: Entity,
}

/// Half of the bar: a 1 × 0.2 × 0.4 box from `x0` to `x0 + 1` along x, every vertex bound to
/// `joint` alone.
fn half_bar(x0: f32, joint: u16) -> Mesh {
    let mut half = Cuboid::new(1.0, 0.2, 0.4)
        .mesh()
        .build()
        .translated_by(Vec3::new(x0 + 0.5, 0.0, 0.0));
    let n = half.count_vertices();
    half.insert_attribute(
        Mesh::ATTRIBUTE_JOINT_INDEX,
        VertexAttributeValues::Uint16x4(vec![[joint, 0, 0, 0]; n]),
    );
    half.insert_attribute(
        Mesh::ATTRIBUTE_JOINT_WEIGHT,
        vec![[1.0f32, 0.0, 0.0, 0.0]; n],
    );
    half
}

/// The bar: x from -1 to 1, its inner half on joint 0 and its outer half on joint 1 (which
/// turns it about the bar's centre), with one morph target that moves its tip by
/// [`TIP_MORPH`].
fn bar_mesh() -> Mesh {
    let mut bar = half_bar(-1.0, 0);
    bar.merge(&half_bar(0.0, 1))
        .expect("the halves share a layout");
    let targets = positions(&bar)
        .iter()
        .map(|p| {
            let moved = if p.x > 0.99 { TIP_MORPH } else { Vec3::ZERO };
            MorphAttributes::new(moved, Vec3::ZERO, Vec3::ZERO)
        })
        .collect();
    bar.with_morph_targets(targets)
}

/// A 0.6 × 0.2 × 0.4 box whose one morph target moves it by [`BOX_MORPH`].
fn box_mesh() -> Mesh {
    let cuboid = Cuboid::new(0.6, 0.2, 0.4).mesh().build();
    let n = cuboid.count_vertices();
    let targets = vec![MorphAttributes::new(BOX_MORPH, Vec3::ZERO, Vec3::ZERO); n];
    cuboid.with_morph_targets(targets)
}

fn positions(mesh: &Mesh) -> Vec<Vec3> {
    match mesh.attribute(Mesh::ATTRIBUTE_POSITION) {
        Some(VertexAttributeValues::Float32x3(p)) => p.iter().map(|p| Vec3::from(*p)).collect(),
        _ => panic!("the test meshes have Float32x3 positions"),
    }
}

fn scene(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut bindposes: ResMut<Assets<SkinnedMeshInverseBindposes>>,
) {
    commands.insert_resource(GlobalAmbientLight::NONE);
    commands.spawn((
        Mesh3d(meshes.add(Plane3d::default().mesh().size(16.0, 16.0))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::linear_rgb(0.75, 0.75, 0.75),
            perceptual_roughness: 1.0,
            reflectance: 0.0,
            ..default()
        })),
    ));
    // The sun, straight overhead.
    commands.spawn((
        DirectionalLight {
            illuminance: 3000.0,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::from_rotation(Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2)),
    ));
    // Glowing red, so that the drawn bar stands out from the grey floor and its shadow.
    let red = materials.add(StandardMaterial {
        base_color: Color::BLACK,
        emissive: LinearRgba::rgb(2.0, 0.0, 0.0),
        reflectance: 0.0,
        ..default()
    });
    let root = commands.spawn(Transform::from_xyz(0.0, LIFT, 0.0)).id();
    let outer = commands.spawn((Transform::IDENTITY, ChildOf(root))).id();
    let bar = commands
        .spawn((
            Mesh3d(meshes.add(bar_mesh())),
            MeshMaterial3d(red.clone()),
            SkinnedMesh {
                inverse_bindposes: bindposes.add(vec![Mat4::IDENTITY; 2]),
                joints: vec![root, outer],
            },
            MeshMorphWeights::Value { weights: vec![0.0] },
            // Bevy culls by the rest pose's bounds otherwise.
            NoFrustumCulling,
            RenderLayers::layer(1),
        ))
        .id();
    let morphing_box = commands
        .spawn((
            Mesh3d(meshes.add(box_mesh())),
            MeshMaterial3d(red),
            MeshMorphWeights::Value { weights: vec![0.0] },
            Transform::from_translation(BOX),
            NoFrustumCulling,
            RenderLayers::layer(1),
        ))
        .id();
    commands.insert_resource(Rig {
        outer,
        bar,
        morphing_box,
    });
}

/// The raw sun shadow alone, its edge sharp.
fn raw_shadow() -> RayTracedLighting {
    RayTracedLighting {
        reflections: false,
        gi: false,
        ao: false,
        denoise: false,
        sun_angular_diameter: 0.0,
        ..default()
    }
}

/// Looking straight down from 40 m, 8° of vertical field: 5.6 m of floor over 180 pixels.
fn top_down() -> Harness {
    let setup = Setup {
        camera: Transform::from_xyz(0.0, 40.0, 0.0).looking_at(Vec3::ZERO, Vec3::NEG_Z),
        projection: PerspectiveProjection {
            fov: 8f32.to_radians(),
            ..default()
        },
        ..default()
    };
    let mut h = Harness::with(setup, raw_shadow(), scene, false);
    set_camera_layers(&mut h, RenderLayers::layer(0));
    // Startup spawns the scene and its `Rig`.
    h.run(1);
    h
}

fn set_camera_layers(h: &mut Harness, layers: RenderLayers) {
    let world = h.app.world_mut();
    let camera = world
        .query_filtered::<Entity, With<Camera3d>>()
        .single(world)
        .expect("the harness has one camera");
    world.entity_mut(camera).insert(layers);
}

fn rig(h: &Harness) -> (Entity, Entity, Entity) {
    let rig = h.app.world().resource::<Rig>();
    (rig.outer, rig.bar, rig.morphing_box)
}

/// Turns the bar's outer joint by `angle` about the vertical.
fn bend(h: &mut Harness, angle: f32) {
    let (outer, _, _) = rig(h);
    h.app
        .world_mut()
        .entity_mut(outer)
        .insert(Transform::from_rotation(Quat::from_rotation_y(angle)));
}

/// Marks `entity`'s transform changed. Bevy reads a mesh instance's morph descriptor when it
/// extracts the instance, which it does again only when the entity changes: until then it draws
/// a morphed mesh at weight 0 whatever its weights (seen in Bevy 0.20.1).
fn touch(h: &mut Harness, entity: Entity) {
    let mut entity = h.app.world_mut().entity_mut(entity);
    if let Some(mut transform) = entity.get_mut::<Transform>() {
        transform.set_changed();
    }
}

fn set_weight(h: &mut Harness, entity: Entity, weight: f32) {
    h.app
        .world_mut()
        .entity_mut(entity)
        .insert(MeshMorphWeights::Value {
            weights: vec![weight],
        });
}

/// Brightness of the 3 × 3 pixels around the floor point `p`.
fn floor(h: &Harness, frame: &Frame, p: Vec3) -> f32 {
    frame.mean(h.pixel_of(p.with_y(0.0)), 1).length()
}

/// Asserts that each point of `shadowed` is in shadow (under a third of `open`) and each of
/// `lit` is lit (within 10 % of it).
fn assert_shadow(
    what: &str,
    h: &Harness,
    frame: &Frame,
    open: f32,
    shadowed: &[Vec3],
    lit: &[Vec3],
) {
    for p in shadowed {
        let b = floor(h, frame, *p);
        assert!(
            b < open / 3.0,
            "{what}: the floor under {p} is lit ({b}, open {open})"
        );
    }
    for p in lit {
        let b = floor(h, frame, *p);
        assert!(
            (b - open).abs() < 0.1 * open,
            "{what}: the floor under {p} is shadowed ({b}, open {open})"
        );
    }
}

/// The open floor's brightness, far from both objects.
fn open_floor(h: &Harness, frame: &Frame) -> f32 {
    let open = floor(h, frame, Vec3::new(3.0, 0.0, 2.0));
    assert!(open > 0.3, "the open floor is {open}");
    open
}

#[test]
fn bending_a_joint_moves_the_shadow_of_what_it_carries() {
    let mut h = top_down();
    h.run(4);
    let straight = h.capture();
    let open = open_floor(&h, &straight);
    // The outer half, straight along +x, and where a quarter turn about +y takes it (-z).
    let along_x = [Vec3::new(0.5, 0.0, 0.0), Vec3::new(0.85, 0.0, 0.0)];
    let along_z = [Vec3::new(0.0, 0.0, -0.5), Vec3::new(0.0, 0.0, -0.85)];
    let inner = [Vec3::new(-0.5, 0.0, 0.0)];
    assert_shadow(
        "straight",
        &h,
        &straight,
        open,
        &[&along_x[..], &inner].concat(),
        &along_z,
    );
    bend(&mut h, std::f32::consts::FRAC_PI_2);
    h.run(4);
    let bent = h.capture();
    assert_shadow(
        "bent",
        &h,
        &bent,
        open,
        &[&along_z[..], &inner].concat(),
        &along_x,
    );
    // And back.
    bend(&mut h, 0.0);
    h.run(4);
    let back = h.capture();
    assert_shadow("straight again", &h, &back, open, &along_x, &along_z);
}

#[test]
fn a_morph_weight_moves_the_shadow_of_its_target() {
    let mut h = top_down();
    let (_, bar, morphing_box) = rig(&h);
    h.run(4);
    let rest = h.capture();
    let open = open_floor(&h, &rest);
    let at = |w: f32| BOX + BOX_MORPH * w;
    assert_shadow("weight 0", &h, &rest, open, &[at(0.0)], &[at(1.0), at(0.5)]);
    set_weight(&mut h, morphing_box, 1.0);
    h.run(4);
    let full = h.capture();
    assert_shadow("weight 1", &h, &full, open, &[at(1.0)], &[at(0.0)]);
    set_weight(&mut h, morphing_box, 0.5);
    h.run(4);
    let half = h.capture();
    assert_shadow(
        "weight 0.5",
        &h,
        &half,
        open,
        &[at(0.5)],
        &[at(0.0), at(1.0)],
    );
    // The skinned bar's morph target moves its tip's corners on top of its skin: the floor
    // just beyond the tip's far corner (at z = 0.2 + 0.5) darkens.
    let past_tip = Vec3::new(0.95, 0.0, 0.55);
    assert_shadow("bar, weight 0", &h, &half, open, &[], &[past_tip]);
    set_weight(&mut h, bar, 1.0);
    h.run(4);
    let morphed = h.capture();
    assert_shadow("bar, weight 1", &h, &morphed, open, &[past_tip], &[]);
}

/// Pixels of `frame` whose `test` holds.
fn mask(frame: &Frame, test: impl Fn(Vec3) -> bool) -> Vec<bool> {
    (0..WIDTH * HEIGHT)
        .map(|i| test(frame.at(i % WIDTH, i / WIDTH)))
        .collect()
}

/// Pixels set in `a` with no pixel of `b` within `reach` pixels (a square around it).
fn farther_than(a: &[bool], b: &[bool], reach: i32) -> usize {
    let near = |x: i32, y: i32| {
        (-reach..=reach).any(|dy| {
            (-reach..=reach).any(|dx| {
                let (xx, yy) = (x + dx, y + dy);
                (0..WIDTH as i32).contains(&xx)
                    && (0..HEIGHT as i32).contains(&yy)
                    && b[(yy * WIDTH as i32 + xx) as usize]
            })
        })
    };
    (0..WIDTH * HEIGHT)
        .filter(|i| a[*i as usize] && !near((*i % WIDTH) as i32, (*i / WIDTH) as i32))
        .count()
}

#[test]
fn the_traced_pose_is_the_drawn_pose() {
    let mut h = top_down();
    let (_, bar, _) = rig(&h);
    // A pose far from the rest pose: the outer half turned, its tip morphed.
    bend(&mut h, -0.7);
    set_weight(&mut h, bar, 1.0);
    h.run(4);
    let traced = h.capture();
    let open = open_floor(&h, &traced);
    // The same pose drawn: the camera now draws layer 1 too.
    set_camera_layers(&mut h, RenderLayers::from_layers(&[0, 1]));
    h.run(2);
    touch(&mut h, bar);
    h.run(2);
    let drawn = h.capture();

    // Shadow: floor under half the open floor's light. Drawn: the red glow.
    let shadow = mask(&traced, |t| t.length() < 0.5 * open);
    let outline = mask(&drawn, |t| t.x > 0.5 && t.x > 4.0 * t.y.max(t.z));
    let (shadow_pixels, drawn_pixels) = (
        shadow.iter().filter(|s| **s).count(),
        outline.iter().filter(|s| **s).count(),
    );
    let (shadow_off, drawn_off) = (
        farther_than(&shadow, &outline, 2),
        farther_than(&outline, &shadow, 2),
    );
    println!(
        "shadow {shadow_pixels} pixels, drawn {drawn_pixels}; more than 2 pixels from the \
         other: shadow {shadow_off}, drawn {drawn_off}"
    );
    // The bar and the box cover about 1.8 m² of floor at 32 pixels a metre… (see below).
    assert!(
        drawn_pixels > 1000,
        "the drawn bar covers {drawn_pixels} pixels"
    );
    // The drawn outline is the larger by up to a pixel all round: the camera sees the tops
    // 0.6 m above the floor, 1.5 % nearer than the floor (the box, 2 m off the axis, grows by
    // most), and with them a sliver of their sides.
    assert!(
        (shadow_pixels as f32 / drawn_pixels as f32 - 1.0).abs() < 0.2,
        "shadow {shadow_pixels} pixels, drawn {drawn_pixels}"
    );
    assert_eq!(
        shadow_off, 0,
        "shadow pixels more than 2 pixels outside the drawn bar"
    );
    assert_eq!(
        drawn_off, 0,
        "drawn pixels more than 2 pixels outside the shadow"
    );
}
