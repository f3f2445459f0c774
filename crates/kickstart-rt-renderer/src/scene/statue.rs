//! `statue`: a generated stand-in for a scanned sculpture. The Stanford dragon's terms forbid
//! shipping it in a product, so the tests and the benchmarks' defaults use this instead: one
//! closed mesh of 800,000 triangles, about 0.29 units across, with detail at every scale (a
//! trefoil-knot tube whose radius is rippled by several waves), so that its BVH, its
//! self-occlusion and its small, densely packed triangles load the tracer as a scan does.

use glam::{Affine3A, Vec3};

use super::{Instance, Mesh, Scene};

/// Rings along the knot.
const RINGS: u32 = 1600;
/// Vertices around each ring.
const SIDES: u32 = 250;
/// Model units to scene units: the knot's core spans about ±3.3 model units.
const SCALE: f32 = 0.04;
/// The tube's mean radius, model units.
const TUBE_RADIUS: f32 = 0.45;
/// Where the statue stands: its centre, in scene units.
const CENTRE: Vec3 = Vec3::new(0.0, 0.125, 0.0);

/// The trefoil knot's centre line at parameter `t` (0..2π), model units.
fn knot(t: f32) -> Vec3 {
    let r = 2.0 + (3.0 * t).cos();
    Vec3::new(r * (2.0 * t).cos(), r * (2.0 * t).sin(), -(3.0 * t).sin())
}

/// An orthonormal frame (tangent, normal, binormal) of the centre line at `t`, from finite
/// differences. The knot's curvature never vanishes, so the normal is always defined; the frame
/// is a function of `t` alone, so the first and last rings meet and the tube closes.
fn frame(t: f32) -> (Vec3, Vec3, Vec3) {
    let h = 1e-3;
    let (a, b, c) = (knot(t - h), knot(t), knot(t + h));
    let tangent = (c - a).normalize();
    let curvature = a - 2.0 * b + c;
    let normal = (curvature - tangent * curvature.dot(tangent)).normalize();
    (tangent, normal, tangent.cross(normal))
}

/// The tube's radius at ring parameter `u` and angle `v` (both 0..2π): ripples of several
/// wavelengths, all periodic in both, so the surface stays closed and never self-intersects
/// (the radius stays within 0.6–1.4 × the mean, below the knot's distance between strands).
fn radius(u: f32, v: f32) -> f32 {
    let ripples = 0.18 * (7.0 * v + 40.0 * u).sin() * (3.0 * v).cos()
        + 0.12 * (97.0 * u).sin() * (5.0 * v).sin()
        + 0.06 * (13.0 * v - 211.0 * u).sin();
    TUBE_RADIUS * (1.0 + ripples)
}

/// The statue's positions and triangle indices, in scene units.
fn surface() -> (Vec<[f32; 3]>, Vec<u32>) {
    let tau = std::f32::consts::TAU;
    let mut positions = Vec::with_capacity((RINGS * SIDES) as usize);
    for i in 0..RINGS {
        let u = tau * i as f32 / RINGS as f32;
        let (_, normal, binormal) = frame(u);
        let centre = knot(u);
        for j in 0..SIDES {
            let v = tau * j as f32 / SIDES as f32;
            let out = normal * v.cos() + binormal * v.sin();
            let p = CENTRE + (centre + out * radius(u, v)) * SCALE;
            positions.push(p.to_array());
        }
    }
    let mut indices = Vec::with_capacity((RINGS * SIDES * 6) as usize);
    let at = |i: u32, j: u32| (i % RINGS) * SIDES + (j % SIDES);
    for i in 0..RINGS {
        for j in 0..SIDES {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            // Wound so the geometric normal points out of the tube.
            indices.extend_from_slice(&[a, c, b, a, d, c]);
        }
    }
    (positions, indices)
}

/// The `statue` scene: the generated sculpture as one mesh under one instance, no camera and
/// no lights of its own (as a scan's file has none).
pub fn statue() -> Scene {
    let (positions, indices) = surface();
    let mut scene = Scene {
        name: "statue".into(),
        ..Default::default()
    };
    match Mesh::new("statue", positions, indices, Vec3::splat(0.8)) {
        Ok(mesh) => {
            scene.instances.push(Instance {
                mesh: 0,
                transform: Affine3A::IDENTITY,
            });
            scene.meshes.push(mesh);
        }
        // Valid by construction: a failure is a bug here, reported rather than panicking.
        Err(e) => log::error!("built-in scene statue: {e}"),
    }
    scene
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 800,000 triangles, every edge shared by exactly two triangles (closed), about 0.29 units
    /// across, and outward winding: the geometric normals point away from the centre line.
    #[test]
    fn statue_is_a_closed_detailed_mesh() {
        let scene = statue();
        assert_eq!(scene.meshes.len(), 1);
        let mesh = &scene.meshes[0];
        assert_eq!(mesh.triangle_count(), 800_000);
        let mut edges = std::collections::HashMap::<(u32, u32), i32>::new();
        for t in mesh.indices.chunks(3) {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        assert!(edges.values().all(|&n| n == 2), "open or non-manifold edge");
        let (lo, hi) = scene.bounds();
        let across = (hi - lo).max_element();
        assert!((0.24..0.34).contains(&across), "{across} units across");
        // A triangle of the first ring: its normal points from the centre line outwards.
        let p = |i: u32| Vec3::from(mesh.positions[i as usize]);
        let t = &mesh.indices[..3];
        let n = (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0]));
        let out = p(t[0]) - (CENTRE + knot(0.0) * SCALE);
        assert!(n.dot(out) > 0.0, "inward winding");
    }
}
