//! The built-in "town": a game level's shape of geometry, many distinct small meshes. 1,000
//! buildings on a 40 × 25 grid of blocks, each its own mesh of 2,028 triangles (a box whose six
//! faces are 13 × 13 grids of quads), each a different size and with its own bumps on every
//! vertex, so no two BLASes are the same. `ksrt bench --scene town` times building them all in
//! one task (the many-meshes case).

use glam::{Affine3A, Vec3};

use super::{Instance, Mesh, Scene};
use crate::rng::Rng;

/// Buildings.
pub const BUILDINGS: usize = 1_000;
/// Quads along each edge of a building's face.
const FACE_QUADS: u32 = 13;
/// Blocks along x (the rest along z).
const BLOCKS_X: usize = 40;
/// Distance between block centres, metres.
const BLOCK: f32 = 30.0;

/// A unit box [-0.5, 0.5]³ whose faces are `n` × `n` grids of quads (12 n² triangles), every
/// vertex moved along its face's normal by up to `bump` (a face's border vertices are shared
/// with the next face, so the box stays closed: they are not moved).
pub(super) fn bumpy_box(n: u32, bump: f32, rng: &mut Rng) -> (Vec<[f32; 3]>, Vec<u32>) {
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    // Each face: its normal and two in-plane axes (u × v = normal, so the winding faces out).
    let faces = [
        (Vec3::X, Vec3::Y, Vec3::Z),
        (-Vec3::X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::Z, Vec3::X),
        (-Vec3::Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (-Vec3::Z, Vec3::Y, Vec3::X),
    ];
    for (normal, u, v) in faces {
        let first = positions.len() as u32;
        for j in 0..=n {
            for i in 0..=n {
                let (a, b) = (i as f32 / n as f32 - 0.5, j as f32 / n as f32 - 0.5);
                let border = i == 0 || j == 0 || i == n || j == n;
                let out = if border { 0.0 } else { rng.range(0.0, bump) };
                let p = normal * (0.5 + out) + u * a + v * b;
                positions.push(p.to_array());
            }
        }
        let at = |i: u32, j: u32| first + j * (n + 1) + i;
        for j in 0..n {
            for i in 0..n {
                indices.extend_from_slice(&[at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                indices.extend_from_slice(&[at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
    }
    (positions, indices)
}

/// The town (see the module docs).
pub fn town() -> Scene {
    let mut rng = Rng(34);
    let mut scene = Scene {
        name: "town".into(),
        ..Default::default()
    };
    for k in 0..BUILDINGS {
        let (positions, indices) = bumpy_box(FACE_QUADS, rng.range(0.005, 0.03), &mut rng);
        let color = Vec3::new(
            rng.range(0.3, 0.8),
            rng.range(0.3, 0.8),
            rng.range(0.3, 0.8),
        );
        let mesh = match Mesh::new(format!("building {k}"), positions, indices, color) {
            Ok(m) => m,
            Err(e) => {
                log::error!("built-in scene town: {e}");
                continue;
            }
        };
        let size = Vec3::new(
            rng.range(8.0, 20.0),
            rng.range(6.0, 60.0),
            rng.range(8.0, 20.0),
        );
        let centre = Vec3::new(
            (k % BLOCKS_X) as f32 * BLOCK + rng.range(-3.0, 3.0),
            size.y * 0.5,
            (k / BLOCKS_X) as f32 * BLOCK + rng.range(-3.0, 3.0),
        );
        scene.instances.push(Instance {
            mesh: scene.meshes.len(),
            transform: Affine3A::from_scale_rotation_translation(
                size,
                glam::Quat::from_rotation_y(rng.range(-0.3, 0.3)),
                centre,
            ),
        });
        scene.meshes.push(mesh);
    }
    scene
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_town_is_a_thousand_distinct_closed_meshes_of_2028_triangles() {
        let t = town();
        assert_eq!((t.meshes.len(), t.instances.len()), (BUILDINGS, BUILDINGS));
        for m in &t.meshes {
            assert_eq!(m.triangle_count(), 2028, "{}", m.name);
            // Closed: every edge is used by exactly two triangles, once in each direction.
            let mut edges = std::collections::HashMap::new();
            for tri in m.indices.chunks(3) {
                for e in 0..3 {
                    let (a, b) = (
                        m.positions[tri[e] as usize],
                        m.positions[tri[(e + 1) % 3] as usize],
                    );
                    let key = |p: [f32; 3]| p.map(f32::to_bits);
                    *edges.entry((key(a), key(b))).or_insert(0) += 1;
                }
            }
            assert!(
                edges
                    .iter()
                    .all(|(&(a, b), &c)| c == 1 && edges.get(&(b, a)) == Some(&1)),
                "{} is not closed",
                m.name
            );
        }
        assert_ne!(t.meshes[0].positions, t.meshes[1].positions);
    }
}
