//! Watertight ray/triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
//! Intersection", JCGT 2(1)).
//!
//! **Tie rule for shared edges and vertices**: a point exactly on an edge counts as inside, so a
//! ray through a shared edge or vertex hits every triangle that shares it (never none: no gaps);
//! a closest-hit query that finds several hits at the same `t` reports the lowest primitive index.
//! Edge functions are evaluated in f32 only and an exact 0 is inside: the rule the GPU traversal
//! (`shaders/scene/traversal.wgsl`) implements too, so the two agree (up to FMA contraction on the GPU).

use glam::Vec3;

/// A ray with a parametric range: points `origin + t * dir` for `t_min <= t <= t_max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Start point.
    pub origin: Vec3,
    /// Direction (need not be normalised; `t` is in units of its length).
    pub dir: Vec3,
    /// Smallest accepted `t`.
    pub t_min: f32,
    /// Largest accepted `t` (∞ allowed).
    pub t_max: f32,
}

/// Where a ray meets one triangle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriangleHit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the third vertex.
    pub v: f32,
}

/// The closest hit of a ray in a mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter.
    pub t: f32,
    /// Index of the triangle in the input slice.
    pub primitive: u32,
    /// Barycentric weight of the second vertex.
    pub u: f32,
    /// Barycentric weight of the third vertex.
    pub v: f32,
}

/// Per-ray constants of the watertight test: the axis permutation and shear.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shear {
    k: [usize; 3],
    s: Vec3,
}

impl Shear {
    pub(crate) fn new(dir: Vec3) -> Self {
        let a = dir.abs();
        let kz = if a.x > a.y {
            if a.x > a.z {
                0
            } else {
                2
            }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding: swap when the dominant component is negative.
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let dz = dir[kz];
        Shear {
            k: [kx, ky, kz],
            s: Vec3::new(dir[kx] / dz, dir[ky] / dz, 1.0 / dz),
        }
    }
}

/// Tests triangle `tri`, primitive `primitive`, against `ray` (already clipped to the closest hit
/// so far); when it is hit closer than `best`, or at the same `t` with a lower primitive index
/// (the tie rule), it becomes `best`. Returns whether it did. Both CPU traversals use it, so they
/// keep the same rule.
pub(crate) fn offer_triangle(
    best: &mut Option<Hit>,
    ray: &Ray,
    sh: &Shear,
    [a, b, c]: [Vec3; 3],
    primitive: u32,
) -> bool {
    let Some(h) = intersect_sheared(ray, sh, a, b, c) else {
        return false;
    };
    let better = best.is_none_or(|cur| h.t < cur.t || (h.t == cur.t && primitive < cur.primitive));
    if better {
        *best = Some(Hit {
            t: h.t,
            primitive,
            u: h.u,
            v: h.v,
        });
    }
    better
}

/// Intersects `ray` with triangle `(a, b, c)`; both windings hit.
pub fn intersect_triangle(ray: &Ray, a: Vec3, b: Vec3, c: Vec3) -> Option<TriangleHit> {
    intersect_sheared(ray, &Shear::new(ray.dir), a, b, c)
}

fn intersect_sheared(ray: &Ray, sh: &Shear, a: Vec3, b: Vec3, c: Vec3) -> Option<TriangleHit> {
    let [kx, ky, kz] = sh.k;
    let (a, b, c) = (a - ray.origin, b - ray.origin, c - ray.origin);
    let ax = a[kx] - sh.s.x * a[kz];
    let ay = a[ky] - sh.s.y * a[kz];
    let bx = b[kx] - sh.s.x * b[kz];
    let by = b[ky] - sh.s.y * b[kz];
    let cx = c[kx] - sh.s.x * c[kz];
    let cy = c[ky] - sh.s.y * c[kz];
    // Edge functions in f32 only, no double-precision recomputation of zeros (the paper's
    // fallback): WGSL has no portable f64, and the GPU traversal must follow the same rule.
    // Rounding of a product is monotonic, so a non-zero value always has the exact sign; an
    // exact 0 may stand for a tiny value of either sign and counts as inside (edge-inclusive).
    // That can only add hits, never open a gap: the two triangles of a shared edge compute
    // exactly negated values from the same two vertices, so a 0 is a 0 on both sides.
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let az = sh.s.z * a[kz];
    let bz = sh.s.z * b[kz];
    let cz = sh.s.z * c[kz];
    let t_scaled = u * az + v * bz + w * cz;
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    if !(t >= ray.t_min && t <= ray.t_max) {
        return None;
    }
    Some(TriangleHit {
        t,
        u: v * inv,
        v: w * inv,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: Vec3, d: Vec3) -> Ray {
        Ray {
            origin: o,
            dir: d,
            t_min: 0.0,
            t_max: f32::INFINITY,
        }
    }

    #[test]
    fn hits_centre_with_barycentrics() {
        let h = intersect_triangle(
            &ray(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z),
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
        )
        .unwrap();
        assert!((h.t - 1.0).abs() < 1e-6);
        assert!((h.u - 0.25).abs() < 1e-6 && (h.v - 0.25).abs() < 1e-6);
    }

    #[test]
    fn shared_edge_hits_both_triangles() {
        // Quad split along the diagonal x == y; a ray exactly through the diagonal.
        let (p0, p1, p2, p3) = (Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y);
        let r = ray(Vec3::new(0.5, 0.5, 1.0), -Vec3::Z);
        assert!(intersect_triangle(&r, p0, p1, p2).is_some());
        assert!(intersect_triangle(&r, p0, p2, p3).is_some());
    }

    #[test]
    fn misses_outside_parallel_and_degenerate() {
        assert!(intersect_triangle(
            &ray(Vec3::new(1.0, 1.0, 1.0), -Vec3::Z),
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y
        )
        .is_none());
        assert!(intersect_triangle(
            &ray(Vec3::new(-1.0, 0.2, 0.0), Vec3::X),
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y
        )
        .is_none());
        assert!(intersect_triangle(
            &ray(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z),
            Vec3::ZERO,
            Vec3::X,
            Vec3::X * 2.0
        )
        .is_none());
    }

    #[test]
    fn respects_t_range() {
        let mut r = ray(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z);
        r.t_max = 0.5;
        assert!(intersect_triangle(&r, Vec3::ZERO, Vec3::X, Vec3::Y).is_none());
    }
}
