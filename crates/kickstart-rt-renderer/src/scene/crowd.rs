//! The built-in "crowd": 100 distinct meshes of 10,092 triangles each (a box whose six faces
//! are 29 × 29 grids of quads, bumped differently on every vertex, person-sized), standing on a
//! 10 × 10 grid — the shape of a scene of skinned characters, whose BLASes are all refit every
//! frame. `ksrt bench --scene crowd` times refitting them all in one task (the refit
//! case: ingestion + refit of 100 `allow_update` meshes of about 10,000 triangles).

use glam::{Affine3A, Vec3};

use super::town::bumpy_box;
use super::{Instance, Mesh, Scene};
use crate::rng::Rng;

/// Characters.
pub const CHARACTERS: usize = 100;
/// Quads along each edge of a character's face: 12 × 29² = 10,092 triangles.
const FACE_QUADS: u32 = 29;
/// Characters along x (the rest along z).
const ROW: usize = 10;
/// Distance between neighbours, metres.
const SPACING: f32 = 2.0;

/// The crowd (see the module docs).
pub fn crowd() -> Scene {
    let mut rng = Rng(37);
    let mut scene = Scene {
        name: "crowd".into(),
        ..Default::default()
    };
    for k in 0..CHARACTERS {
        let (positions, indices) = bumpy_box(FACE_QUADS, rng.range(0.01, 0.05), &mut rng);
        let color = Vec3::new(
            rng.range(0.3, 0.8),
            rng.range(0.3, 0.8),
            rng.range(0.3, 0.8),
        );
        let mesh = match Mesh::new(format!("character {k}"), positions, indices, color) {
            Ok(m) => m,
            Err(e) => {
                log::error!("built-in scene crowd: {e}");
                continue;
            }
        };
        let size = Vec3::new(
            rng.range(0.4, 0.6),
            rng.range(1.5, 1.9),
            rng.range(0.25, 0.35),
        );
        let centre = Vec3::new(
            (k % ROW) as f32 * SPACING + rng.range(-0.3, 0.3),
            size.y * 0.5,
            (k / ROW) as f32 * SPACING + rng.range(-0.3, 0.3),
        );
        scene.instances.push(Instance {
            mesh: scene.meshes.len(),
            transform: Affine3A::from_scale_rotation_translation(
                size,
                glam::Quat::from_rotation_y(rng.range(-3.1, 3.1)),
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
    fn the_crowd_is_a_hundred_distinct_meshes_of_10092_triangles() {
        let c = crowd();
        assert_eq!(
            (c.meshes.len(), c.instances.len()),
            (CHARACTERS, CHARACTERS)
        );
        assert!(c.meshes.iter().all(|m| m.triangle_count() == 10_092));
        assert_ne!(c.meshes[0].positions, c.meshes[1].positions);
    }
}
