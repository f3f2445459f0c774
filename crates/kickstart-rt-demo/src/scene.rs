//! The built-in default scene of the instance-id bug report: an icosahedron sphere, a torus knot,
//! a tube and a floor, each its own colour, in a room (floor and two walls).

use glam::{Affine3A, Vec3};

/// One mesh of a scene: triangle-list positions and indices, an albedo and a placement.
pub struct Mesh {
    pub name: &'static str,
    pub positions: Vec<[f32; 3]>,
    pub indices: Vec<u32>,
    pub color: Vec3,
    pub transform: Affine3A,
}

impl Mesh {
    /// World-space triangles.
    pub fn world_triangles(&self) -> impl Iterator<Item = [Vec3; 3]> + '_ {
        self.indices.chunks_exact(3).map(|t| {
            let p = |k: usize| {
                self.transform
                    .transform_point3(Vec3::from(self.positions[t[k] as usize]))
            };
            [p(0), p(1), p(2)]
        })
    }
}

fn icosphere(subdivisions: u32) -> (Vec<[f32; 3]>, Vec<u32>) {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut p: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut mid = std::collections::HashMap::new();
        let mut m = |a: u32, b: u32, p: &mut Vec<Vec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                p.push(((p[a as usize] + p[b as usize]) * 0.5).normalize());
                p.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(f.len() * 4);
        for [a, b, c] in f {
            let (ab, bc, ca) = (m(a, b, &mut p), m(b, c, &mut p), m(c, a, &mut p));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = next;
    }
    (p.iter().map(|v| v.to_array()).collect(), f.concat())
}

/// A tube of radius `r` around a closed curve, `n` segments along it and `m` around it.
fn sweep(
    curve: impl Fn(f32) -> Vec3,
    r: f32,
    n: u32,
    m: u32,
    closed: bool,
) -> (Vec<[f32; 3]>, Vec<u32>) {
    let mut p = Vec::new();
    let rings = if closed { n } else { n + 1 };
    for i in 0..rings {
        let s = i as f32 / n as f32;
        let c = curve(s);
        let tangent = (curve(s + 1e-3) - curve(s - 1e-3)).normalize();
        let side = tangent.cross(Vec3::Y).try_normalize().unwrap_or(Vec3::X);
        let up = side.cross(tangent);
        for j in 0..m {
            let a = j as f32 / m as f32 * std::f32::consts::TAU;
            p.push((c + (side * a.cos() + up * a.sin()) * r).to_array());
        }
    }
    let mut idx = Vec::new();
    for i in 0..n {
        let i1 = (i + 1) % rings;
        for j in 0..m {
            let j1 = (j + 1) % m;
            let (a, b, c, d) = (i * m + j, i * m + j1, i1 * m + j1, i1 * m + j);
            idx.extend([a, b, c, a, c, d]);
        }
    }
    (p, idx)
}

fn quad(a: Vec3, b: Vec3, c: Vec3, d: Vec3) -> (Vec<[f32; 3]>, Vec<u32>) {
    (
        vec![a.to_array(), b.to_array(), c.to_array(), d.to_array()],
        vec![0, 1, 2, 0, 2, 3],
    )
}

/// The default scene.
pub fn default_scene() -> Vec<Mesh> {
    let tau = std::f32::consts::TAU;
    let (sp, si) = icosphere(3);
    let (kp, ki) = sweep(
        |s| {
            let t = s * tau;
            let (p, q) = (2.0, 3.0);
            let r = (q * t).cos() + 2.0;
            Vec3::new(r * (p * t).cos(), -(q * t).sin(), r * (p * t).sin()) * 0.25
        },
        0.1,
        256,
        12,
        true,
    );
    let (tp, ti) = sweep(|s| Vec3::new(0.0, s * 1.6, 0.0), 0.3, 16, 24, false);
    let (fp, fi) = quad(
        Vec3::new(-4.0, 0.0, -4.0),
        Vec3::new(-4.0, 0.0, 4.0),
        Vec3::new(4.0, 0.0, 4.0),
        Vec3::new(4.0, 0.0, -4.0),
    );
    let (bp, bi) = quad(
        Vec3::new(-4.0, 0.0, -4.0),
        Vec3::new(4.0, 0.0, -4.0),
        Vec3::new(4.0, 4.0, -4.0),
        Vec3::new(-4.0, 4.0, -4.0),
    );
    let (lp, li) = quad(
        Vec3::new(-4.0, 0.0, -4.0),
        Vec3::new(-4.0, 4.0, -4.0),
        Vec3::new(-4.0, 4.0, 4.0),
        Vec3::new(-4.0, 0.0, 4.0),
    );
    vec![
        Mesh {
            name: "sphere",
            positions: sp,
            indices: si,
            color: Vec3::new(0.9, 0.15, 0.1),
            transform: Affine3A::from_scale_rotation_translation(
                Vec3::splat(0.7),
                Default::default(),
                Vec3::new(-1.4, 0.7, 0.0),
            ),
        },
        Mesh {
            name: "torus knot",
            positions: kp,
            indices: ki,
            color: Vec3::new(0.1, 0.7, 0.2),
            transform: Affine3A::from_translation(Vec3::new(0.6, 1.0, -0.6)),
        },
        Mesh {
            name: "tube",
            positions: tp,
            indices: ti,
            color: Vec3::new(0.15, 0.3, 0.9),
            transform: Affine3A::from_translation(Vec3::new(2.2, 0.0, 0.6)),
        },
        Mesh {
            name: "floor",
            positions: fp,
            indices: fi,
            color: Vec3::new(0.9, 0.8, 0.2),
            transform: Affine3A::IDENTITY,
        },
        Mesh {
            name: "back wall",
            positions: bp,
            indices: bi,
            color: Vec3::splat(0.8),
            transform: Affine3A::IDENTITY,
        },
        Mesh {
            name: "left wall",
            positions: lp,
            indices: li,
            color: Vec3::splat(0.8),
            transform: Affine3A::IDENTITY,
        },
    ]
}
