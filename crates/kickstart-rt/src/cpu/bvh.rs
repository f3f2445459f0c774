//! Binned-SAH BVH build and stack-based traversal on the CPU.

use super::triangle::{offer_triangle, Hit, Ray, Shear};
use glam::Vec3;

/// SAH cost of visiting an inner node.
pub const SAH_TRAVERSAL_COST: f32 = 1.0;
/// SAH cost of one ray/triangle test.
pub const SAH_INTERSECTION_COST: f32 = 1.0;

const BINS: usize = 16;
const MAX_LEAF: usize = 4;
/// Deep enough for any tree this builder makes (it splits at least one primitive off per level).
const STACK_LIMIT: usize = 128;

/// A node: an inner node when `count == 0` (children at `first` and `first + 1`), else a leaf of
/// `count` primitives starting at `first` in [`CpuBvh::primitive_indices`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CpuBvhNode {
    /// Box minimum.
    pub min: Vec3,
    /// Box maximum.
    pub max: Vec3,
    /// First child, or first primitive slot of a leaf.
    pub first: u32,
    /// Primitives in a leaf; 0 for inner nodes.
    pub count: u32,
}

/// A binary BVH over triangles, built with a 16-bin SAH sweep on every axis.
#[derive(Debug, Clone, Default)]
pub struct CpuBvh {
    /// Nodes; the root is node 0.
    pub nodes: Vec<CpuBvhNode>,
    /// Triangle indices referenced by leaves.
    pub primitive_indices: Vec<u32>,
}

fn area(min: Vec3, max: Vec3) -> f32 {
    let d = (max - min).max(Vec3::ZERO);
    2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
}

#[derive(Clone, Copy)]
struct Bounds {
    min: Vec3,
    max: Vec3,
}

impl Bounds {
    const EMPTY: Bounds = Bounds {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };
    fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    fn merge(&mut self, o: &Bounds) {
        self.min = self.min.min(o.min);
        self.max = self.max.max(o.max);
    }
    fn area(&self) -> f32 {
        area(self.min, self.max)
    }
}

/// The cheapest binned-SAH split of `prims` (bounds `bb`, centroid bounds `cb`) over every
/// axis: (cost, axis, last bin of the left side), or `None` where no axis has extent.
fn best_split(
    prims: &[u32],
    boxes: &[Bounds],
    centroid: &impl Fn(u32) -> Vec3,
    bb: &Bounds,
    cb: &Bounds,
) -> Option<(f32, usize, usize)> {
    let extent = cb.max - cb.min;
    let mut best: Option<(f32, usize, usize)> = None; // (cost, axis, split bin)
    for axis in 0..3 {
        if extent[axis] <= 0.0 {
            continue;
        }
        let scale = BINS as f32 / extent[axis];
        let bin_of = |p: u32| (((centroid(p)[axis] - cb.min[axis]) * scale) as usize).min(BINS - 1);
        let mut bins = [(Bounds::EMPTY, 0usize); BINS];
        for &p in prims {
            let b = &mut bins[bin_of(p)];
            b.0.merge(&boxes[p as usize]);
            b.1 += 1;
        }
        let mut right = [(0.0f32, 0usize); BINS];
        let mut acc = Bounds::EMPTY;
        let mut cnt = 0;
        for i in (1..BINS).rev() {
            acc.merge(&bins[i].0);
            cnt += bins[i].1;
            right[i] = (acc.area(), cnt);
        }
        let mut acc = Bounds::EMPTY;
        let mut cnt = 0;
        for i in 0..BINS - 1 {
            acc.merge(&bins[i].0);
            cnt += bins[i].1;
            let (ra, rc) = right[i + 1];
            if cnt == 0 || rc == 0 {
                continue;
            }
            let cost = SAH_TRAVERSAL_COST
                + SAH_INTERSECTION_COST * (acc.area() * cnt as f32 + ra * rc as f32)
                    / bb.area().max(f32::MIN_POSITIVE);
            if best.is_none_or(|b| cost < b.0) {
                best = Some((cost, axis, i));
            }
        }
    }
    best
}

impl CpuBvh {
    /// Builds over `triangles`. Triangles with a non-finite vertex are left out (they can never be
    /// hit); degenerate ones are kept and never reported as hits.
    pub fn build(triangles: &[[Vec3; 3]]) -> CpuBvh {
        let mut prims: Vec<u32> = (0..triangles.len() as u32)
            .filter(|&i| triangles[i as usize].iter().all(|v| v.is_finite()))
            .collect();
        let boxes: Vec<Bounds> = triangles
            .iter()
            .map(|t| Bounds {
                min: t[0].min(t[1]).min(t[2]),
                max: t[0].max(t[1]).max(t[2]),
            })
            .collect();
        let centroid = |i: u32| {
            let b = &boxes[i as usize];
            (b.min + b.max) * 0.5
        };
        let mut nodes = vec![CpuBvhNode {
            min: Vec3::ZERO,
            max: Vec3::ZERO,
            first: 0,
            count: 0,
        }];
        if prims.is_empty() {
            return CpuBvh {
                nodes,
                primitive_indices: prims,
            };
        }
        // (node, start, end) ranges still to split.
        let mut work = vec![(0usize, 0usize, prims.len())];
        while let Some((node, start, end)) = work.pop() {
            let mut bb = Bounds::EMPTY;
            let mut cb = Bounds::EMPTY;
            for &p in &prims[start..end] {
                bb.merge(&boxes[p as usize]);
                cb.grow(centroid(p));
            }
            let n = end - start;
            let leaf = CpuBvhNode {
                min: bb.min,
                max: bb.max,
                first: start as u32,
                count: n as u32,
            };
            let leaf_cost = n as f32 * SAH_INTERSECTION_COST;
            let extent = cb.max - cb.min;
            let best = best_split(&prims[start..end], &boxes, &centroid, &bb, &cb);
            let mid = match best {
                Some((cost, axis, split)) if cost < leaf_cost || n > MAX_LEAF => {
                    let scale = BINS as f32 / extent[axis];
                    let slice = &mut prims[start..end];
                    let mut l = 0;
                    for i in 0..slice.len() {
                        let b = (((centroid(slice[i])[axis] - cb.min[axis]) * scale) as usize)
                            .min(BINS - 1);
                        if b <= split {
                            slice.swap(i, l);
                            l += 1;
                        }
                    }
                    start + l
                }
                // All centroids coincide: split by count so leaves stay small.
                None if n > MAX_LEAF => start + n / 2,
                _ => {
                    nodes[node] = leaf;
                    continue;
                }
            };
            let first = nodes.len();
            nodes.push(leaf);
            nodes.push(leaf);
            nodes[node] = CpuBvhNode {
                min: bb.min,
                max: bb.max,
                first: first as u32,
                count: 0,
            };
            work.push((first, start, mid));
            work.push((first + 1, mid, end));
        }
        CpuBvh {
            nodes,
            primitive_indices: prims,
        }
    }

    /// SAH cost of the tree (traversal and intersection costs as the constants above), relative
    /// to the root's area.
    pub fn sah_cost(&self) -> f32 {
        let root = &self.nodes[0];
        let ra = area(root.min, root.max).max(f32::MIN_POSITIVE);
        self.nodes
            .iter()
            .map(|n| {
                let a = area(n.min, n.max) / ra;
                if n.count == 0 {
                    a * SAH_TRAVERSAL_COST
                } else {
                    a * n.count as f32 * SAH_INTERSECTION_COST
                }
            })
            .sum()
    }

    /// Slab test, conservative: the far distance is widened slightly (by 2γ, after Ize 2013) so
    /// rays grazing a box's face are never culled by rounding.
    fn ray_box(n: &CpuBvhNode, o: Vec3, inv: Vec3, t_min: f32, t_max: f32) -> Option<f32> {
        slab(n.min, n.max, o, inv, t_min, t_max)
    }

    fn traverse(&self, triangles: &[[Vec3; 3]], ray: &Ray, any: bool) -> Option<Hit> {
        if self.primitive_indices.is_empty() {
            return None;
        }
        let sh = Shear::new(ray.dir);
        let inv = ray.dir.recip();
        let mut best: Option<Hit> = None;
        let mut t_max = ray.t_max;
        let mut stack = [0u32; STACK_LIMIT];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if Self::ray_box(node, ray.origin, inv, ray.t_min, t_max).is_none() {
                continue;
            }
            if node.count > 0 {
                for &p in
                    &self.primitive_indices[node.first as usize..(node.first + node.count) as usize]
                {
                    let r = Ray { t_max, ..*ray };
                    if offer_triangle(&mut best, &r, &sh, triangles[p as usize], p) {
                        t_max = best.map_or(t_max, |h| h.t);
                        if any {
                            return best;
                        }
                    }
                }
                continue;
            }
            let (l, r) = (node.first, node.first + 1);
            let tl = Self::ray_box(&self.nodes[l as usize], ray.origin, inv, ray.t_min, t_max);
            let tr = Self::ray_box(&self.nodes[r as usize], ray.origin, inv, ray.t_min, t_max);
            // Push the farther child first so the nearer one is visited next.
            let order = match (tl, tr) {
                (Some(a), Some(b)) if b < a => [Some(l), Some(r)],
                (Some(_), Some(_)) => [Some(r), Some(l)],
                (Some(_), None) => [None, Some(l)],
                (None, Some(_)) => [None, Some(r)],
                (None, None) => [None, None],
            };
            for c in order.into_iter().flatten() {
                if sp < STACK_LIMIT {
                    stack[sp] = c;
                    sp += 1;
                }
            }
        }
        best
    }

    /// The closest hit in `[t_min, t_max]`; ties in `t` go to the lowest primitive index.
    pub fn closest_hit(&self, triangles: &[[Vec3; 3]], ray: &Ray) -> Option<Hit> {
        self.traverse(triangles, ray, false)
    }

    /// Whether anything is hit in `[t_min, t_max]` (stops at the first hit found).
    pub fn any_hit(&self, triangles: &[[Vec3; 3]], ray: &Ray) -> bool {
        self.traverse(triangles, ray, true).is_some()
    }
}

/// Slab test of the box `[min, max]` against the ray `o + t / inv`, within `[t_min, t_max]`;
/// the entry distance when hit. A ray lying in a slab's boundary plane gives 0 × ∞ = NaN: that
/// axis must not constrain the interval (NaN counts as −∞ for the near bound and +∞ for the far
/// bound).
pub(crate) fn slab(
    min: Vec3,
    max: Vec3,
    o: Vec3,
    inv: Vec3,
    t_min: f32,
    t_max: f32,
) -> Option<f32> {
    let t0 = (min - o) * inv;
    let t1 = (max - o) * inv;
    let lo = |a: f32| if a.is_nan() { f32::NEG_INFINITY } else { a };
    let hi = |a: f32| if a.is_nan() { f32::INFINITY } else { a };
    let mut near = t_min;
    let mut far = t_max;
    for k in 0..3 {
        near = near.max(lo(t0[k]).min(lo(t1[k])));
        far = far.min(hi(t0[k]).max(hi(t1[k])));
    }
    (near <= far * 1.000_000_4).then_some(near)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::intersect_triangle;

    struct Rng(u64);
    impl Rng {
        fn f(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }
        fn v(&mut self) -> Vec3 {
            Vec3::new(self.f(), self.f(), self.f()) * 2.0 - 1.0
        }
    }

    fn brute(tris: &[[Vec3; 3]], ray: &Ray) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (i, t) in tris.iter().enumerate() {
            if let Some(h) = intersect_triangle(ray, t[0], t[1], t[2]) {
                if best.is_none_or(|b| h.t < b.t) {
                    best = Some(Hit {
                        t: h.t,
                        primitive: i as u32,
                        u: h.u,
                        v: h.v,
                    });
                }
            }
        }
        best
    }

    #[test]
    fn closest_and_any_hit_equal_brute_force() {
        let mut rng = Rng(0x9e3779b97f4a7c15);
        let mut tris: Vec<[Vec3; 3]> = (0..3000)
            .map(|_| {
                let c = rng.v() * 4.0;
                [c + rng.v() * 0.3, c + rng.v() * 0.3, c + rng.v() * 0.3]
            })
            .collect();
        // Duplicates and degenerates.
        tris.extend_from_within(0..50);
        tris.push([Vec3::ONE; 3]);
        tris.push([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]);
        let bvh = CpuBvh::build(&tris);
        for _ in 0..3000 {
            let ray = Ray {
                origin: rng.v() * 6.0,
                dir: rng.v(),
                t_min: 0.0,
                t_max: f32::INFINITY,
            };
            let a = bvh.closest_hit(&tris, &ray);
            let b = brute(&tris, &ray);
            assert_eq!(a.map(|h| h.t), b.map(|h| h.t), "{ray:?}");
            assert_eq!(bvh.any_hit(&tris, &ray), b.is_some());
        }
    }

    /// A closed cube of 2×2 quads per face: rays from inside never miss, including rays aimed at
    /// the shared edges and vertices of the mesh.
    #[test]
    fn rays_from_inside_a_closed_mesh_through_edges_and_vertices_always_hit() {
        let mut tris = Vec::new();
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                for i in 0..2 {
                    for j in 0..2 {
                        let p = |a: f32, b: f32| {
                            let mut v = [0.0; 3];
                            v[axis] = sign;
                            v[(axis + 1) % 3] = a;
                            v[(axis + 2) % 3] = b;
                            Vec3::from(v)
                        };
                        let (a0, b0) = (i as f32 - 1.0, j as f32 - 1.0);
                        let (q0, q1, q2, q3) = (
                            p(a0, b0),
                            p(a0 + 1.0, b0),
                            p(a0 + 1.0, b0 + 1.0),
                            p(a0, b0 + 1.0),
                        );
                        tris.push([q0, q1, q2]);
                        tris.push([q0, q2, q3]);
                    }
                }
            }
        }
        let bvh = CpuBvh::build(&tris);
        let mut targets = Vec::new();
        for x in [-1.0f32, -0.5, 0.0, 0.5, 1.0] {
            for y in [-1.0f32, -0.5, 0.0, 0.5, 1.0] {
                for z in [-1.0f32, 1.0] {
                    targets.push(Vec3::new(x, y, z));
                    targets.push(Vec3::new(z, x, y));
                    targets.push(Vec3::new(y, z, x));
                }
            }
        }
        for origin in [Vec3::ZERO, Vec3::new(0.1, -0.2, 0.3)] {
            for t in &targets {
                let ray = Ray {
                    origin,
                    dir: *t - origin,
                    t_min: 0.0,
                    t_max: f32::INFINITY,
                };
                let h = bvh
                    .closest_hit(&tris, &ray)
                    .unwrap_or_else(|| panic!("missed towards {t}"));
                assert!((h.t - 1.0).abs() < 1e-5, "t = {} towards {t}", h.t);
            }
        }
    }

    #[test]
    fn sah_cost_beats_a_single_leaf_and_empty_input_is_fine() {
        let mut rng = Rng(7);
        let tris: Vec<[Vec3; 3]> = (0..1000)
            .map(|_| {
                let c = rng.v() * 10.0;
                [c, c + Vec3::X * 0.1, c + Vec3::Y * 0.1]
            })
            .collect();
        let bvh = CpuBvh::build(&tris);
        assert!(bvh.sah_cost() < 1000.0 / 10.0, "cost {}", bvh.sah_cost());
        let empty = CpuBvh::build(&[]);
        let ray = Ray {
            origin: Vec3::ZERO,
            dir: Vec3::X,
            t_min: 0.0,
            t_max: 1.0,
        };
        assert!(empty.closest_hit(&[], &ray).is_none());
        let nan = [[Vec3::splat(f32::NAN), Vec3::X, Vec3::Y]];
        assert!(CpuBvh::build(&nan).closest_hit(&nan, &ray).is_none());
    }
}
