//! A GPU BVH read back to the CPU (nodes in the BVH2 format of `docs/ray-tracing-core.md`), and
//! its SAH cost with the same constants as [`super::CpuBvh::sah_cost`], so the two compare.

use super::bvh::slab;
use super::triangle::{offer_triangle, Hit, Ray, Shear};
use super::{SAH_INTERSECTION_COST, SAH_TRAVERSAL_COST};
use glam::Vec3;

/// The work one traversal of a read-back BVH did: a measure of tree quality that does not
/// depend on the GPU (the GPU traversal visits the same nodes in the same order).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TraversalCounts {
    /// Inner nodes fetched (each tests its two child boxes).
    pub nodes: u64,
    /// Ray/triangle tests.
    pub triangles: u64,
}

impl std::ops::AddAssign for TraversalCounts {
    fn add_assign(&mut self, o: Self) {
        self.nodes += o.nodes;
        self.triangles += o.triangles;
    }
}

/// One child of a GPU BVH2 node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bvh2Child {
    /// Box minimum (an empty child has `min.x > max.x`).
    pub min: Vec3,
    /// Box maximum.
    pub max: Vec3,
    /// Child reference: bit 31 set = leaf (bits 0–27 first primitive, bits 28–30 count − 1),
    /// else an inner node index.
    pub reference: u32,
}

impl Bvh2Child {
    /// Whether the reference is a leaf.
    pub fn is_leaf(&self) -> bool {
        self.reference & 0x8000_0000 != 0
    }

    /// Whether the box is empty (never entered).
    pub fn is_empty(&self) -> bool {
        !(self.min.x <= self.max.x && self.min.y <= self.max.y && self.min.z <= self.max.z)
    }

    /// `(first, count)` of a leaf.
    pub fn leaf_range(&self) -> (u32, u32) {
        (
            self.reference & 0x0fff_ffff,
            ((self.reference >> 28) & 7) + 1,
        )
    }
}

/// A BLAS read back with [`crate::ExecuteContext::read_back_blas`].
#[derive(Debug, Clone, Default)]
pub struct BlasReadback {
    /// Nodes; node 0 is the root. Each holds its two children.
    pub nodes: Vec<[Bvh2Child; 2]>,
    /// Triangles in leaf order (geometry space).
    pub triangles: Vec<[Vec3; 3]>,
    /// Each triangle's primitive index in its geometry.
    pub primitive_indices: Vec<u32>,
    /// SAH cost relative to the root box's area (traversal cost per inner node, intersection
    /// cost per triangle), comparable to [`super::CpuBvh::sah_cost`].
    pub sah_cost: f32,
}

fn area(min: Vec3, max: Vec3) -> f32 {
    let d = (max - min).max(Vec3::ZERO);
    2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
}

impl BlasReadback {
    /// Decodes raw nodes (16 floats each) and triangles (12 floats each: three `vec4`, the
    /// primitive index in the bits of the first `w`).
    pub fn new(raw_nodes: Vec<[f32; 16]>, raw_tris: Vec<[f32; 12]>) -> Self {
        let nodes: Vec<[Bvh2Child; 2]> = raw_nodes
            .iter()
            .map(|n| {
                let child = |o: usize, r: usize| Bvh2Child {
                    min: Vec3::new(n[o], n[o + 1], n[o + 2]),
                    max: Vec3::new(n[o + 4], n[o + 5], n[o + 6]),
                    reference: n[r].to_bits(),
                };
                [child(0, 3), child(8, 7)]
            })
            .collect();
        let triangles = raw_tris
            .iter()
            .map(|t| {
                [
                    Vec3::new(t[0], t[1], t[2]),
                    Vec3::new(t[4], t[5], t[6]),
                    Vec3::new(t[8], t[9], t[10]),
                ]
            })
            .collect();
        let primitive_indices = raw_tris.iter().map(|t| t[3].to_bits()).collect();
        let mut r = BlasReadback {
            nodes,
            triangles,
            primitive_indices,
            sah_cost: 0.0,
        };
        r.sah_cost = r.compute_sah_cost();
        r
    }

    /// SAH cost: the root counts as an inner node of area 1; each non-empty child adds its
    /// relative area × (traversal cost when inner, intersection cost × count when a leaf).
    fn compute_sah_cost(&self) -> f32 {
        let Some(root) = self.nodes.first() else {
            return 0.0;
        };
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for c in root.iter().filter(|c| !c.is_empty()) {
            lo = lo.min(c.min);
            hi = hi.max(c.max);
        }
        let root_area = area(lo, hi).max(f32::MIN_POSITIVE);
        let mut cost = SAH_TRAVERSAL_COST;
        let mut stack = vec![0u32];
        let mut visited = 0usize;
        while let Some(i) = stack.pop() {
            visited += 1;
            // A malformed tree (a cycle) must not hang a tool.
            if visited > self.nodes.len() {
                break;
            }
            let Some(node) = self.nodes.get(i as usize) else {
                continue;
            };
            for c in node.iter().filter(|c| !c.is_empty()) {
                let a = area(c.min, c.max) / root_area;
                if c.is_leaf() {
                    cost += a * c.leaf_range().1 as f32 * SAH_INTERSECTION_COST;
                } else {
                    cost += a * SAH_TRAVERSAL_COST;
                    stack.push(c.reference);
                }
            }
        }
        cost
    }

    /// Closest hit (or, with `any`, the first hit found) of `ray` in this BLAS, traversed as the
    /// GPU traverses it (nearer child first, entries behind a closer hit skipped), and the work
    /// it took. `Hit::primitive` is the geometry's primitive index.
    pub fn trace(&self, ray: &Ray, any: bool) -> (Option<Hit>, TraversalCounts) {
        let mut counts = TraversalCounts::default();
        if self.nodes.is_empty() {
            return (None, counts);
        }
        let sh = Shear::new(ray.dir);
        let inv = ray.dir.recip();
        let mut best: Option<Hit> = None;
        let mut t_max = ray.t_max;
        // (child ref, entry distance); the root is entered as an inner ref at t_min.
        let mut stack = vec![(0u32, ray.t_min)];
        while let Some((r, entry_t)) = stack.pop() {
            if entry_t > t_max * 1.000_000_4 {
                continue;
            }
            if r & 0x8000_0000 != 0 {
                let first = (r & 0x0fff_ffff) as usize;
                let count = (((r >> 28) & 7) + 1) as usize;
                for slot in first..(first + count).min(self.triangles.len()) {
                    counts.triangles += 1;
                    let clipped = Ray { t_max, ..*ray };
                    let p = self.primitive_indices[slot];
                    if offer_triangle(&mut best, &clipped, &sh, self.triangles[slot], p) {
                        t_max = best.map_or(t_max, |h| h.t);
                        if any {
                            return (best, counts);
                        }
                    }
                }
                continue;
            }
            let Some(node) = self.nodes.get(r as usize) else {
                continue;
            };
            counts.nodes += 1;
            // A malformed tree (a cycle) must not hang a tool.
            if counts.nodes > 4 * self.nodes.len() as u64 + 4 {
                break;
            }
            let t = |c: &Bvh2Child| {
                (!c.is_empty())
                    .then(|| slab(c.min, c.max, ray.origin, inv, ray.t_min, t_max))
                    .flatten()
            };
            let (tl, tr) = (t(&node[0]), t(&node[1]));
            let (l, r) = (node[0].reference, node[1].reference);
            match (tl, tr) {
                (Some(a), Some(b)) if b < a => stack.extend([(l, a), (r, b)]),
                (Some(a), Some(b)) => stack.extend([(r, b), (l, a)]),
                (Some(a), None) => stack.push((l, a)),
                (None, Some(b)) => stack.push((r, b)),
                (None, None) => {}
            }
        }
        (best, counts)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A raw node: two children (min, max, ref).
    fn node(l: ([f32; 3], [f32; 3], u32), r: ([f32; 3], [f32; 3], u32)) -> [f32; 16] {
        let mut n = [0.0; 16];
        n[0..3].copy_from_slice(&l.0);
        n[3] = f32::from_bits(l.2);
        n[4..7].copy_from_slice(&l.1);
        n[7] = f32::from_bits(r.2);
        n[8..11].copy_from_slice(&r.0);
        n[12..15].copy_from_slice(&r.1);
        n
    }

    /// Triangle slot with vertices in the plane z = `z` and primitive index `prim`.
    fn tri(z: f32, prim: u32) -> [f32; 12] {
        [
            -1.0,
            -1.0,
            z,
            f32::from_bits(prim),
            1.0,
            -1.0,
            z,
            0.0,
            0.0,
            1.0,
            z,
            0.0,
        ]
    }

    const LEAF: u32 = 0x8000_0000;

    fn down(t_max: f32) -> Ray {
        Ray {
            origin: Vec3::new(0.0, 0.0, 5.0),
            dir: Vec3::new(0.0, 0.0, -1.0),
            t_min: 0.0,
            t_max,
        }
    }

    #[test]
    fn trace_finds_the_closest_of_a_two_triangle_leaf_and_counts_the_work() {
        // Root: left = leaf of 2 triangles (slots 0, 1; count − 1 = 1), right empty.
        let b = BlasReadback::new(
            vec![node(
                ([-1.0, -1.0, 0.0], [1.0, 1.0, 2.0], LEAF | (1 << 28)),
                ([1e30; 3], [-1e30; 3], LEAF),
            )],
            vec![tri(0.0, 7), tri(2.0, 3)],
        );
        let (hit, counts) = b.trace(&down(f32::INFINITY), false);
        let hit = hit.expect("hits the upper triangle");
        assert_eq!((hit.t, hit.primitive), (3.0, 3));
        assert_eq!(
            counts,
            TraversalCounts {
                nodes: 1,
                triangles: 2
            }
        );
        // A range starting past the upper triangle (t = 3) finds the lower one (t = 5); one
        // ending before it finds neither.
        let past = Ray {
            t_min: 4.0,
            ..down(f32::INFINITY)
        };
        let (hit, _) = b.trace(&past, false);
        assert_eq!(hit.map(|h| (h.t, h.primitive)), Some((5.0, 7)));
        let (hit, _) = b.trace(&down(2.5), false);
        assert_eq!(hit, None);
    }

    #[test]
    fn trace_survives_bad_rays_and_a_malformed_tree() {
        // Node 0's left child is node 0 itself (a cycle), the right an out-of-range node.
        let b = BlasReadback::new(
            vec![node(
                ([-1.0, -1.0, 0.0], [1.0, 1.0, 2.0], 0),
                ([-1.0, -1.0, 0.0], [1.0, 1.0, 2.0], 99),
            )],
            vec![tri(0.0, 0)],
        );
        let (hit, counts) = b.trace(&down(f32::INFINITY), false);
        assert_eq!(hit, None);
        // The guard stops after 4 × nodes + 4 visits.
        assert!(counts.nodes <= 9, "a cycle must stop: {counts:?}");
        let leaf = BlasReadback::new(
            vec![node(
                ([-1.0, -1.0, 0.0], [1.0, 1.0, 0.0], LEAF),
                ([1e30; 3], [-1e30; 3], LEAF),
            )],
            vec![tri(0.0, 0)],
        );
        for ray in [
            Ray {
                dir: Vec3::ZERO,
                ..down(f32::INFINITY)
            },
            Ray {
                origin: Vec3::NAN,
                ..down(f32::INFINITY)
            },
            Ray {
                t_min: f32::NAN,
                ..down(f32::INFINITY)
            },
        ] {
            assert_eq!(leaf.trace(&ray, true).0, None, "{ray:?}");
        }
        assert_eq!(BlasReadback::default().trace(&down(1.0), false).0, None);
    }
}
