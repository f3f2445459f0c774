//! The `obvhs` crate as a CPU peer of our BVH builders (`ksrt bench --cpu-peers`): its PLOC
//! builder (with reinsertion and, in its slowest preset, spatial pre-splits) over our triangles,
//! and the SAH cost of the tree it makes, computed with the formula and constants of
//! `kickstart_rt::cpu::CpuBvh::sah_cost` so the three builders compare.

use glam::Vec3;
use kickstart_rt::cpu::{SAH_INTERSECTION_COST, SAH_TRAVERSAL_COST};
use obvhs::bvh2::Bvh2;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

/// The obvhs build presets the bench runs: its fastest and its best-quality, and the one its
/// authors pitch as "about embree's build time" in between.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Preset {
    /// `BvhBuildParams::fastest_build`: PLOC with the minimum search distance, no reinsertion.
    Fastest,
    /// `BvhBuildParams::medium_build`.
    Medium,
    /// `BvhBuildParams::very_slow_build`: spatial pre-splits, reinsertion over every node.
    VerySlow,
}

impl Preset {
    /// Every preset, fastest first.
    pub const ALL: [Preset; 3] = [Preset::Fastest, Preset::Medium, Preset::VerySlow];

    /// The name in reports (`obvhs <preset>`).
    pub fn name(self) -> &'static str {
        match self {
            Preset::Fastest => "obvhs fastest_build",
            Preset::Medium => "obvhs medium_build",
            Preset::VerySlow => "obvhs very_slow_build",
        }
    }

    /// The preset's parameters, with the leaf collapse weighing a traversal step against a
    /// triangle test as our SAH constants do (the presets use 3): obvhs then optimises the cost
    /// we measure, instead of being scored on a cost it was not tuned for.
    pub fn params(self) -> BvhBuildParams {
        let mut p = match self {
            Preset::Fastest => BvhBuildParams::fastest_build(),
            Preset::Medium => BvhBuildParams::medium_build(),
            Preset::VerySlow => BvhBuildParams::very_slow_build(),
        };
        p.collapse_traversal_cost = SAH_TRAVERSAL_COST / SAH_INTERSECTION_COST;
        p
    }
}

/// Our triangles in obvhs's layout, leaving out triangles with a non-finite vertex (they can
/// never be hit; `CpuBvh::build` leaves them out too).
pub fn to_obvhs(triangles: &[[Vec3; 3]]) -> Vec<Triangle> {
    triangles
        .iter()
        .filter(|t| t.iter().all(|v| v.is_finite()))
        .map(|[a, b, c]| Triangle {
            v0: a.to_array().into(),
            v1: b.to_array().into(),
            v2: c.to_array().into(),
        })
        .collect()
}

/// Builds obvhs's BVH2 over `triangles` with `preset` (its `build_bvh2_from_tris`: triangle
/// boxes, optional pre-splits, PLOC, reinsertion, leaf collapse). Errors on an empty input,
/// which obvhs does not accept.
pub fn build(triangles: &[Triangle], preset: Preset) -> Result<Bvh2, String> {
    build_with(triangles, preset.params())
}

/// [`build`] with any parameters.
pub fn build_with(triangles: &[Triangle], params: BvhBuildParams) -> Result<Bvh2, String> {
    if triangles.is_empty() {
        return Err("obvhs: no finite triangle to build a BVH over".into());
    }
    let mut core = std::time::Duration::ZERO;
    Ok(obvhs::bvh2::builder::build_bvh2_from_tris(
        triangles, params, &mut core,
    ))
}

fn area(min: Vec3, max: Vec3) -> f64 {
    let d = (max - min).max(Vec3::ZERO).as_dvec3();
    2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
}

/// The box of obvhs node `i` in our glam.
pub fn node_box(bvh: &Bvh2, i: usize) -> (Vec3, Vec3) {
    let b = bvh.nodes[i].aabb();
    let (min, max): ([f32; 3], [f32; 3]) = (b.min.into(), b.max.into());
    (Vec3::from(min), Vec3::from(max))
}

/// SAH cost of an obvhs BVH2 as `CpuBvh::sah_cost` defines it: over the nodes reachable from the
/// root (node 0), each node's area relative to the root's, times the traversal cost for an
/// inner node or the intersection cost × its primitive count for a leaf. Nodes obvhs left
/// unreachable (after reinsertion) are not counted. With spatial pre-splits a triangle counts in
/// every leaf that references it, as a ray would test it there. 0 for an empty tree.
pub fn sah_cost(bvh: &Bvh2) -> f64 {
    if bvh.nodes.is_empty() {
        return 0.0;
    }
    let (rmin, rmax) = node_box(bvh, 0);
    let root_area = area(rmin, rmax).max(f64::from(f32::MIN_POSITIVE));
    let (ct, ci) = (
        f64::from(SAH_TRAVERSAL_COST),
        f64::from(SAH_INTERSECTION_COST),
    );
    let mut cost = 0.0;
    let mut stack = vec![0usize];
    let mut visited = 0usize;
    while let Some(i) = stack.pop() {
        visited += 1;
        // A malformed tree (a cycle) must not hang the bench.
        if visited > bvh.nodes.len() {
            break;
        }
        let node = &bvh.nodes[i];
        let (min, max) = node_box(bvh, i);
        let a = area(min, max) / root_area;
        if node.is_leaf() {
            cost += a * f64::from(node.prim_count) * ci;
        } else {
            cost += a * ct;
            let first = node.first_index as usize;
            for child in [first, first + 1] {
                if child < bvh.nodes.len() {
                    stack.push(child);
                }
            }
        }
    }
    cost
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::aabb::Aabb;
    use obvhs::bvh2::node::Bvh2Node;

    fn node(min: [f32; 3], max: [f32; 3], prims: u32, first: u32) -> Bvh2Node {
        Bvh2Node::new(Aabb::new(min.into(), max.into()), prims, first)
    }

    #[test]
    fn sah_of_a_hand_made_tree() {
        // Root box 2×1×1 (area 10), two unit-cube leaves (area 6) of one and two triangles:
        // 1 (root) + 0.6 × 1 + 0.6 × 2 = 2.8.
        let bvh = Bvh2 {
            nodes: vec![
                node([0.0; 3], [2.0, 1.0, 1.0], 0, 1),
                node([0.0; 3], [1.0; 3], 1, 0),
                node([1.0, 0.0, 0.0], [2.0, 1.0, 1.0], 2, 1),
            ],
            primitive_indices: vec![0, 1, 2],
            ..Default::default()
        };
        assert!((sah_cost(&bvh) - 2.8).abs() < 1e-9, "{}", sah_cost(&bvh));
        // A lone leaf costs its triangle count.
        let leaf = Bvh2 {
            nodes: vec![node([0.0; 3], [1.0; 3], 3, 0)],
            primitive_indices: vec![0, 1, 2],
            ..Default::default()
        };
        assert!((sah_cost(&leaf) - 3.0).abs() < 1e-9);
        assert_eq!(sah_cost(&Bvh2::default()), 0.0);
    }

    /// A right triangle in the plane z = `z`, legs 1 along x and y, corner at (`x`, 0).
    fn tri(x: f32, z: f32) -> [Vec3; 3] {
        [
            Vec3::new(x, 0.0, z),
            Vec3::new(x + 1.0, 0.0, z),
            Vec3::new(x, 1.0, z),
        ]
    }

    #[test]
    fn sah_of_a_built_tree_of_two_far_triangles() {
        // Two flat unit triangles 9 apart along x: every preset puts them in two leaves
        // (one leaf of both would cost 2, two leaves 1 + 2 × (2 / 20) = 1.2). The root box is
        // 10×1×0 (area 20), each leaf 1×1×0 (area 2).
        let tris = to_obvhs(&[tri(0.0, 0.0), tri(9.0, 0.0)]);
        for preset in [Preset::Fastest, Preset::Medium] {
            let bvh = build(&tris, preset).unwrap();
            let cost = sah_cost(&bvh);
            assert!((cost - 1.2).abs() < 1e-6, "{preset:?}: {cost}");
        }
    }

    #[test]
    fn obvhs_and_our_cpu_builder_agree_on_a_simple_mesh() {
        // A row of 16 separated triangles: both builders find the same optimal tree shape up
        // to leaf sizes, so their costs are close (and both are far below one big leaf's 16).
        let ours: Vec<[Vec3; 3]> = (0..16).map(|i| tri(i as f32 * 3.0, 0.0)).collect();
        let cpu = kickstart_rt::cpu::CpuBvh::build(&ours).sah_cost() as f64;
        let theirs = sah_cost(&build(&to_obvhs(&ours), Preset::Medium).unwrap());
        assert!(theirs < 8.0 && cpu < 8.0, "obvhs {theirs}, cpu {cpu}");
        assert!(
            (theirs / cpu - 1.0).abs() < 0.5,
            "obvhs {theirs}, cpu {cpu}"
        );
    }

    #[test]
    fn non_finite_triangles_are_dropped_and_empty_input_is_an_error() {
        let nan = [Vec3::NAN, Vec3::ONE, Vec3::ZERO];
        assert_eq!(to_obvhs(&[nan, tri(0.0, 0.0)]).len(), 1);
        assert!(build(&to_obvhs(&[nan]), Preset::Fastest).is_err());
        for p in Preset::ALL {
            assert_eq!(p.params().collapse_traversal_cost, 1.0);
        }
    }
}
