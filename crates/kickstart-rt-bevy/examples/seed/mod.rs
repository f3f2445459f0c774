//! The seed scene shared by the example and the headless test: a red sphere, a green torus
//! knot and a blue tube on a light grey floor, lit by a low sun, with no ambient light (the GI
//! is the only indirect light).
//!
//! Included by `examples/seed_scene.rs` and the tests (`tests/plugin/main.rs`, `#[path]`).

#![allow(dead_code)] // each includer uses a different part

use bevy::asset::RenderAssetUsages;
use bevy::light::GlobalAmbientLight;
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;

/// The linear colours of the sphere, knot, tube and floor.
pub const COLOURS: [[f32; 3]; 4] = [
    [0.85, 0.08, 0.06],
    [0.08, 0.75, 0.08],
    [0.06, 0.12, 0.85],
    [0.75, 0.75, 0.75],
];

/// Where the sphere, knot and tube stand (their centres on the floor plane, y = 0).
pub const PLACES: [Vec3; 3] = [
    Vec3::new(-2.3, 0.0, 0.4),
    Vec3::new(0.0, 0.0, -1.2),
    Vec3::new(2.4, 0.0, 0.7),
];

/// The camera's eye and the point it looks at.
pub const EYE: Vec3 = Vec3::new(0.0, 3.2, 6.5);
pub const LOOK_AT: Vec3 = Vec3::new(0.0, 0.4, 0.0);

/// Marks the three coloured objects (index into [`COLOURS`]).
#[derive(Component)]
pub struct Object(pub usize);

/// Present before `spawn` runs: the coloured objects are matte (no specular highlights), so
/// the light they bounce is their diffuse colour alone.
#[derive(Resource)]
pub struct Matte;

/// Spawns the scene (not the camera).
pub fn spawn(
    matte: Option<Res<Matte>>,
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    commands.insert_resource(GlobalAmbientLight::NONE);
    let matte = matte.is_some();
    let material = |materials: &mut Assets<StandardMaterial>, i: usize, roughness: f32| {
        let [r, g, b] = COLOURS[i];
        materials.add(StandardMaterial {
            base_color: Color::linear_rgb(r, g, b),
            perceptual_roughness: if matte { 1.0 } else { roughness },
            reflectance: if matte { 0.0 } else { 0.5 },
            ..default()
        })
    };
    // An ico sphere of 4 subdivisions is well within Bevy's vertex limit.
    let sphere = Sphere::new(0.7)
        .mesh()
        .ico(4)
        .unwrap_or_else(|_| Sphere::new(0.7).mesh().uv(32, 18));
    let shapes = [
        meshes.add(sphere),
        meshes.add(torus_knot(0.8, 0.3, 2, 3)),
        meshes.add(tube()),
    ];
    for (i, (mesh, place)) in shapes.into_iter().zip(PLACES).enumerate() {
        let lift = [0.7, 0.95, 0.0][i];
        commands.spawn((
            Mesh3d(mesh),
            MeshMaterial3d(material(&mut materials, i, 0.5)),
            Transform::from_translation(place + Vec3::Y * lift),
            Object(i),
        ));
    }
    commands.spawn((
        Mesh3d(meshes.add(Plane3d::default().mesh().size(16.0, 16.0))),
        MeshMaterial3d(material(&mut materials, 3, 0.6)),
    ));
    commands.spawn((
        DirectionalLight {
            illuminance: 3000.0,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::from_xyz(4.0, 6.0, 3.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
}

/// A torus knot: a tube of radius `thickness` around the (p, q) knot on a torus of radius
/// `radius`, with `u32` indices.
pub fn torus_knot(radius: f32, thickness: f32, p: u32, q: u32) -> Mesh {
    let curve = |t: f32| {
        let (p, q) = (p as f32, q as f32);
        let r = radius * (2.0 + (q * t).cos()) * 0.5;
        Vec3::new(
            r * (p * t).cos(),
            radius * (q * t).sin() * 0.5,
            r * (p * t).sin(),
        )
    };
    sweep(curve, std::f32::consts::TAU, thickness, 256, 16, true)
}

/// A half-ring tube standing on the floor, with `u16` indices (Bevy allows both).
pub fn tube() -> Mesh {
    let curve = |t: f32| Vec3::new(0.8 * t.cos(), 0.8 * t.sin(), 0.0);
    sweep(curve, std::f32::consts::PI, 0.18, 48, 12, false)
}

/// A circle of radius `thickness` swept along `curve(t)`, t in [0, length): `segments` rings of
/// `sides` vertices; `closed` joins the last ring to the first.
fn sweep(
    curve: impl Fn(f32) -> Vec3,
    length: f32,
    thickness: f32,
    segments: u32,
    sides: u32,
    closed: bool,
) -> Mesh {
    let rings = if closed { segments } else { segments + 1 };
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    for i in 0..rings {
        let t = length * i as f32 / segments as f32;
        let centre = curve(t);
        let tangent = (curve(t + 1e-3) - curve(t - 1e-3)).normalize();
        let side = tangent.cross(Vec3::Y).try_normalize().unwrap_or(Vec3::X);
        let up = side.cross(tangent);
        for j in 0..sides {
            let a = std::f32::consts::TAU * j as f32 / sides as f32;
            let n = side * a.cos() + up * a.sin();
            positions.push((centre + n * thickness).to_array());
            normals.push(n.to_array());
        }
    }
    let mut indices = Vec::new();
    for i in 0..segments {
        let next = (i + 1) % rings;
        for j in 0..sides {
            let k = (j + 1) % sides;
            let [a, b, c, d] = [
                i * sides + j,
                i * sides + k,
                next * sides + j,
                next * sides + k,
            ];
            indices.extend([a, c, b, b, c, d]);
        }
    }
    let indices = if positions.len() <= u16::MAX as usize {
        Indices::U16(indices.into_iter().map(|i| i as u16).collect())
    } else {
        Indices::U32(indices)
    };
    let indices = if closed {
        // The knot keeps u32 indices, so both index sizes are exercised.
        Indices::U32(indices.iter().map(|i| i as u32).collect())
    } else {
        indices
    };
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
    .with_inserted_indices(indices)
}
