//! The built-in "grove": cutout (alpha-tested, glTF `MASK`) geometry in every pass. Three trees
//! whose canopies are leaf cards (textured quads crossing each other) on trunks, a chain-link
//! fence behind them, a floor and a sun, so that the G-buffer, the shadow map, every SDK trace
//! and the CPU reference all have to see the floor and the light through the same holes.
//!
//! Everything is generated from a fixed recipe (below and in docs/ksrt.md): the textures are
//! drawn in code, and every random choice comes from one seed, [`GROVE_SEED`].

use std::f32::consts::{FRAC_PI_2, PI, SQRT_2};

use glam::{Affine3A, Quat, Vec3};

use super::builtin::{block, push_quad, sweep};
use super::{AlphaMode, Camera, Instance, Light, Material, Mesh, Scene, Texture};
use crate::rng::Rng;

/// The seed of every random choice of the grove (leaf shapes, card angles, tree turns and sizes).
pub const GROVE_SEED: u64 = 0x67_726f_7665;
/// Side of the leaf texture, texels: the whole texture spans each leaf card.
pub const LEAF_TEXTURE_SIDE: u32 = 64;
/// Side of the chain-link texture, texels: one tile a fence cell.
pub const FENCE_TEXTURE_SIDE: u32 = 32;
/// Leaves drawn on the leaf texture (40% of its texels end up opaque).
const LEAVES: usize = 18;
/// Half the width of a chain-link wire, texels.
const WIRE_HALF_WIDTH: f32 = 1.25;
/// Half the side of the square floor, metres: its far edge stays out of the camera's view.
const FLOOR_HALF: f32 = 12.0;
/// Where the trees stand (x, z).
pub const TREES: [[f32; 2]; 3] = [[-2.0, -0.6], [0.7, -1.9], [2.5, 0.1]];
/// Height of a trunk (before its tree's scale), metres.
const TRUNK_HEIGHT: f32 = 1.9;
/// Height of the centre of a canopy's lowest cards (before its tree's scale), metres.
const CANOPY_Y: f32 = 2.0;
/// The fence runs along x over ±`FENCE_HALF` at z = `FENCE_Z`.
pub const FENCE_Z: f32 = -3.6;
/// Half the fence's length, metres.
const FENCE_HALF: f32 = 4.0;
/// Height of the fence's mesh, metres.
const FENCE_HEIGHT: f32 = 1.6;
/// Side of a fence cell (a quad of one texture tile), metres: 40 × 8 cells. One quad a tile
/// keeps each triangle's micro-map finer than the texture (level 5, 512 texels a triangle);
/// one quad for the whole fence would tile the texture 320 times over two triangles.
const FENCE_CELL: f32 = 0.2;

/// The leaf texture: [`LEAVES`] pointed leaves (lens shapes: half-width × (1 − t²) along their
/// axis, t in −1..1) of random length, width, angle and green on a transparent background of a
/// mean leaf green (filtered sampling at a leaf's edge then bleeds no dark fringe). Alpha 255 in a
/// leaf, 0 elsewhere.
pub fn leaf_texture(rng: &mut Rng) -> image::RgbaImage {
    let n = LEAF_TEXTURE_SIDE;
    let mut img = image::RgbaImage::from_pixel(n, n, image::Rgba([60, 115, 40, 0]));
    for _ in 0..LEAVES {
        let (cx, cy) = (rng.range(10.0, 54.0), rng.range(10.0, 54.0));
        let angle = rng.range(0.0, PI);
        let (half_len, half_width) = (rng.range(8.0, 13.0), rng.range(3.5, 5.5));
        let green = [
            rng.range(40.0, 80.0) as u8,
            rng.range(100.0, 150.0) as u8,
            rng.range(25.0, 50.0) as u8,
            255,
        ];
        let (sin, cos) = angle.sin_cos();
        for y in 0..n {
            for x in 0..n {
                let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
                let t = (dx * cos + dy * sin) / half_len;
                let across = -dx * sin + dy * cos;
                if t.abs() < 1.0 && across.abs() <= half_width * (1.0 - t * t) {
                    img.put_pixel(x, y, image::Rgba(green));
                }
            }
        }
    }
    img
}

/// The chain-link texture: two families of diagonal wires (the lines x + y = 32k and
/// x − y = 32k, in texels), [`WIRE_HALF_WIDTH`] each side, so that the tiles join into a
/// diamond mesh. Alpha 255 on a wire, 0 elsewhere; grey throughout.
pub fn chain_link_texture() -> image::RgbaImage {
    let n = FENCE_TEXTURE_SIDE as f32;
    image::RgbaImage::from_fn(FENCE_TEXTURE_SIDE, FENCE_TEXTURE_SIDE, |x, y| {
        let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
        // Distance across the nearest wire of a family: along the diagonal coordinate, / √2.
        let across = |s: f32| {
            let m = s.rem_euclid(n);
            m.min(n - m) / SQRT_2
        };
        let on_wire = across(px + py).min(across(px - py)) <= WIRE_HALF_WIDTH;
        image::Rgba([200, 200, 205, if on_wire { 255 } else { 0 }])
    })
}

/// A mesh's positions, indices and texture coordinates.
type Uvd = (Vec<[f32; 3]>, Vec<u32>, Vec<[f32; 2]>);

/// Appends a card: a `width` × `height` quad centred on `centre`, its horizontal axis `across`
/// and its vertical axis `up`, the whole texture on it (v down from its top edge).
fn push_card(mesh: &mut Uvd, centre: Vec3, across: Vec3, up: Vec3, (width, height): (f32, f32)) {
    let (h, u) = (across * width * 0.5, up * height * 0.5);
    let base = mesh.0.len() as u32;
    for (p, uv) in [
        (centre - h + u, [0.0, 0.0]),
        (centre + h + u, [1.0, 0.0]),
        (centre + h - u, [1.0, 1.0]),
        (centre - h - u, [0.0, 1.0]),
    ] {
        mesh.0.push(p.to_array());
        mesh.2.push(uv);
    }
    mesh.1
        .extend([base, base + 2, base + 1, base, base + 3, base + 2]);
}

/// A canopy of seven leaf cards around the vertical axis: three upright cards 60° apart
/// (1.8 × 1.6 m) crossing at [`CANOPY_Y`], three smaller ones (1.3 × 1.1 m) 0.5 m higher turned
/// 30° from them and tilted up to ±25°, and one lying flat (1.2 m square) on top; each turn and
/// height jittered by `rng`.
fn canopy(rng: &mut Rng) -> Uvd {
    let mut mesh = (Vec::new(), Vec::new(), Vec::new());
    let deg = PI / 180.0;
    for k in 0..3 {
        let yaw = (k as f32 * 60.0 + rng.range(-10.0, 10.0)) * deg;
        let centre = Vec3::new(0.0, CANOPY_Y + rng.range(-0.1, 0.1), 0.0);
        let across = Quat::from_rotation_y(yaw) * Vec3::X;
        push_card(&mut mesh, centre, across, Vec3::Y, (1.8, 1.6));
    }
    for k in 0..3 {
        let yaw = (30.0 + k as f32 * 60.0 + rng.range(-10.0, 10.0)) * deg;
        let across = Quat::from_rotation_y(yaw) * Vec3::X;
        let up = Quat::from_axis_angle(across, rng.range(-25.0, 25.0) * deg) * Vec3::Y;
        let centre = Vec3::new(0.0, CANOPY_Y + 0.5 + rng.range(-0.1, 0.1), 0.0);
        push_card(&mut mesh, centre, across, up, (1.3, 1.1));
    }
    let across = Quat::from_rotation_y(rng.range(0.0, PI)) * Vec3::X;
    let flat = Quat::from_axis_angle(across, FRAC_PI_2) * Vec3::Y;
    let top = Vec3::new(0.0, CANOPY_Y + 0.75, 0.0);
    push_card(&mut mesh, top, across, flat, (1.2, 1.2));
    mesh
}

/// The fence: a grid of [`FENCE_CELL`] quads facing +z, one texture tile each (the coordinates
/// run on across the cells: the texture repeats).
fn fence() -> Uvd {
    let columns = (2.0 * FENCE_HALF / FENCE_CELL).round() as u32;
    let rows = (FENCE_HEIGHT / FENCE_CELL).round() as u32;
    let mut mesh = (Vec::new(), Vec::new(), Vec::new());
    for j in 0..=rows {
        for i in 0..=columns {
            let (x, y) = (-FENCE_HALF + i as f32 * FENCE_CELL, j as f32 * FENCE_CELL);
            mesh.0.push([x, y, FENCE_Z]);
            mesh.2.push([i as f32, (rows - j) as f32]);
        }
    }
    let at = |i: u32, j: u32| j * (columns + 1) + i;
    for j in 0..rows {
        for i in 0..columns {
            mesh.1.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            mesh.1.extend([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    mesh
}

/// The fence's five posts, 8 cm square and 1.7 m high, every 2 m along it, as one mesh.
fn posts() -> (Vec<[f32; 3]>, Vec<u32>) {
    let mut mesh = (Vec::new(), Vec::new());
    for k in 0..5 {
        let x = -FENCE_HALF + 2.0 * k as f32;
        let (x0, x1, z0, z1) = (x - 0.04, x + 0.04, FENCE_Z - 0.04, FENCE_Z + 0.04);
        let (p, i) = block([[x0, z0], [x1, z0], [x1, z1], [x0, z1]], 1.7);
        let base = mesh.0.len() as u32;
        mesh.0.extend(p);
        mesh.1.extend(i.into_iter().map(|i| i + base));
    }
    mesh
}

/// Adds `mesh` (valid by construction: a failed check is a bug in this file, logged rather than
/// a panic) with one instance per transform.
fn add(scene: &mut Scene, mesh: Result<Mesh, String>, transforms: &[Affine3A]) {
    match mesh {
        Ok(m) => {
            let k = scene.meshes.len();
            scene.meshes.push(m);
            scene.instances.extend(
                transforms
                    .iter()
                    .map(|&transform| Instance { mesh: k, transform }),
            );
        }
        Err(e) => log::error!("built-in scene grove: {e}"),
    }
}

/// A mesh with coordinates and a material.
fn textured(name: &str, (p, i, uv): Uvd, color: Vec3, material: Material) -> Result<Mesh, String> {
    let mut m = Mesh::new(name, p, i, color)?;
    m.uvs = uv;
    m.material = material;
    Ok(m)
}

/// The grove (see the module docs): floor, three trees (trunk and a seven-card canopy each, one
/// mesh of each instanced per tree, turned and scaled by the seed), the fence and its posts,
/// a sun from the camera's left casting the canopies' dappled shadows beside the trees.
pub fn grove() -> Scene {
    let mut rng = Rng(GROVE_SEED);
    let mut scene = Scene {
        name: "grove".into(),
        textures: vec![
            Texture {
                name: "grove leaves".into(),
                image: leaf_texture(&mut rng),
                nearest: false,
            },
            Texture {
                name: "grove chain link".into(),
                image: chain_link_texture(),
                nearest: false,
            },
        ],
        ..Default::default()
    };
    let mask = AlphaMode::Mask {
        factor: 1.0,
        cutoff: 0.5,
    };
    let mut floor = (Vec::new(), Vec::new());
    let f = FLOOR_HALF;
    let corners = [(-f, -f), (f, -f), (f, f), (-f, f)].map(|(x, z)| Vec3::new(x, 0.0, z));
    push_quad(&mut floor, corners, Vec3::Y);
    let mut floor = Mesh::new("floor", floor.0, floor.1, Vec3::new(0.42, 0.36, 0.25));
    if let Ok(m) = &mut floor {
        m.material.roughness = 0.85;
    }
    add(&mut scene, floor, &[Affine3A::IDENTITY]);
    let trees: Vec<Affine3A> = TREES
        .iter()
        .map(|&[x, z]| {
            let (turn, scale) = (rng.range(0.0, 2.0 * PI), rng.range(0.85, 1.15));
            Affine3A::from_scale_rotation_translation(
                Vec3::splat(scale),
                Quat::from_rotation_y(turn),
                Vec3::new(x, 0.0, z),
            )
        })
        .collect();
    let (tp, ti) = sweep(
        |s| Vec3::new(0.0, s * TRUNK_HEIGHT, 0.0),
        0.09,
        8,
        10,
        false,
    );
    let mut trunk = Mesh::new("trunk", tp, ti, Vec3::new(0.3, 0.2, 0.12));
    if let Ok(m) = &mut trunk {
        m.material.roughness = 0.9;
    }
    add(&mut scene, trunk, &trees);
    let leaves = Material {
        base_color_texture: Some(0),
        alpha: mask,
        roughness: 0.7,
        ..Material::default()
    };
    add(
        &mut scene,
        textured("canopy", canopy(&mut rng), Vec3::ONE, leaves),
        &trees,
    );
    let wire = Material {
        base_color_texture: Some(1),
        alpha: mask,
        metallic: 0.8,
        roughness: 0.35,
        ..Material::default()
    };
    add(
        &mut scene,
        textured("chain-link fence", fence(), Vec3::splat(0.9), wire),
        &[Affine3A::IDENTITY],
    );
    let (pp, pi) = posts();
    let mut posts = Mesh::new("fence posts", pp, pi, Vec3::new(0.25, 0.25, 0.27));
    if let Ok(m) = &mut posts {
        m.material.metallic = 0.6;
        m.material.roughness = 0.5;
    }
    add(&mut scene, posts, &[Affine3A::IDENTITY]);
    scene.camera = Some(Camera {
        eye: Vec3::new(0.3, 1.8, 4.6),
        at: Vec3::new(0.3, 1.3, -1.2),
        up: Vec3::Y,
        fov_y_deg: 55.0,
    });
    scene.lights = vec![Light::Sun {
        direction: Vec3::new(0.6, -1.0, -0.25).normalize(),
        irradiance: Vec3::new(3.2, 3.0, 2.7),
        angular_diameter: 0.0093,
    }];
    scene
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opaque_share(img: &image::RgbaImage) -> f32 {
        img.pixels().filter(|p| p.0[3] == 255).count() as f32 / (img.width() * img.height()) as f32
    }

    #[test]
    fn textures_are_binary_cutouts_with_holes_and_leaves() {
        let leaves = leaf_texture(&mut Rng(GROVE_SEED));
        assert!(leaves.pixels().all(|p| p.0[3] == 0 || p.0[3] == 255));
        let share = opaque_share(&leaves);
        assert!((0.3..0.65).contains(&share), "leaves cover {share}");
        let fence = chain_link_texture();
        let share = opaque_share(&fence);
        assert!((0.1..0.4).contains(&share), "wires cover {share}");
        // The tile's centre and corners are on the wires' crossings; between them, a hole.
        assert_eq!(fence.get_pixel(16, 16).0[3], 255);
        assert_eq!(fence.get_pixel(0, 0).0[3], 255);
        assert_eq!(fence.get_pixel(16, 4).0[3], 0);
    }

    #[test]
    fn the_recipe_is_fixed_and_every_cutout_has_a_texture() {
        let (a, b) = (grove(), grove());
        assert_eq!(a.meshes.len(), 5);
        assert_eq!(a.instances.len(), 1 + 3 + 3 + 1 + 1);
        for (m, n) in a.meshes.iter().zip(&b.meshes) {
            assert_eq!(m.positions, n.positions, "{}", m.name);
        }
        assert_eq!(a.textures[0].image, b.textures[0].image);
        let cutouts: Vec<&str> = a
            .meshes
            .iter()
            .filter(|m| m.mask().is_some())
            .map(|m| m.name.as_str())
            .collect();
        assert_eq!(cutouts, ["canopy", "chain-link fence"]);
        for m in a.meshes.iter().filter(|m| m.mask().is_some()) {
            assert_eq!(m.uvs.len(), m.positions.len(), "{}", m.name);
            assert!(a.mask_texture(m).is_some(), "{}", m.name);
        }
    }
}
