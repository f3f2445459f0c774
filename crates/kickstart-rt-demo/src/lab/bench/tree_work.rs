//! The traversal work other builders' trees would cost on the bench's own rays
//! (`ksrt bench --tree-work`): the scene's one geometry is built again on the CPU (our binned-SAH
//! builder, obvhs's PLOC presets), each tree is laid out as a GPU BVH2 and traced on the CPU
//! exactly as the GPU traverses ours. Nodes per ray against our GPU tree's says what a better
//! builder would buy the traversal before anyone writes it on the GPU.

use glam::{Affine3A, Vec3};

use super::rays::work_per_ray;
pub use super::report::{TreeWork, WorkPerRay};
use crate::lab::obvhs_peer::{self, Preset};
use kickstart_rt as ksrt;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::scene::Scene;
use kickstart_rt_renderer::sdk_glue::GpuRay;

/// Most triangles our BVH2 leaf reference can hold (3 bits of count).
const LEAF_LIMIT: u32 = 8;

/// One node of a binary tree to lay out: an inner node (`count == 0`, children at `first` and
/// `first + 1`) or a leaf of `count` entries of the primitive list from `first`.
#[derive(Debug, Clone, Copy)]
pub struct BinaryNode {
    /// Box minimum.
    pub min: Vec3,
    /// Box maximum.
    pub max: Vec3,
    /// First child, or first primitive slot.
    pub first: u32,
    /// Primitives of a leaf; 0 for an inner node.
    pub count: u32,
}

/// Raw GPU BVH2 nodes (16 floats) and triangles in leaf order (12 floats), as a BLAS reads back.
pub type RawTree = (Vec<[f32; 16]>, Vec<[f32; 12]>);

#[cfg(test)]
/// Lays out a binary tree (root at node 0) as the GPU's BVH2 and decodes it as a read-back BLAS,
/// so that [`ksrt::cpu::BlasReadback::trace`] counts its work as it counts ours. Leaves list
/// triangles through `primitives` (indices into `triangles`).
pub fn as_gpu_bvh2(
    nodes: &[BinaryNode],
    primitives: &[u32],
    triangles: &[[Vec3; 3]],
) -> Result<ksrt::cpu::BlasReadback, String> {
    let (raw_nodes, raw_tris) = gpu_bvh2_raw(nodes, primitives, triangles)?;
    Ok(ksrt::cpu::BlasReadback::new(raw_nodes, raw_tris))
}

/// [`as_gpu_bvh2`]'s raw layout (empty for an empty tree).
pub fn gpu_bvh2_raw(
    nodes: &[BinaryNode],
    primitives: &[u32],
    triangles: &[[Vec3; 3]],
) -> Result<RawTree, String> {
    let Some(root) = nodes.first() else {
        return Ok((Vec::new(), Vec::new()));
    };
    let mut raw_nodes: Vec<[f32; 16]> = Vec::new();
    let mut raw_tris: Vec<[f32; 12]> = Vec::new();
    // (source inner node, its slot in raw_nodes).
    let mut pending: Vec<(u32, usize)> = Vec::new();
    let mut reference = |node: &BinaryNode,
                         index: u32,
                         raw_nodes: &mut Vec<[f32; 16]>,
                         pending: &mut Vec<(u32, usize)>|
     -> Result<u32, String> {
        if node.count == 0 {
            let slot = raw_nodes.len();
            raw_nodes.push([0.0; 16]);
            pending.push((index, slot));
            return Ok(slot as u32);
        }
        if node.count > LEAF_LIMIT {
            return Err(format!(
                "node {index}: a leaf of {} triangles (the GPU layout holds {LEAF_LIMIT})",
                node.count
            ));
        }
        let first = raw_tris.len() as u32;
        for k in node.first..node.first + node.count {
            let prim = *primitives
                .get(k as usize)
                .ok_or_else(|| format!("node {index}: primitive slot {k} out of range"))?;
            let t = triangles
                .get(prim as usize)
                .ok_or_else(|| format!("primitive {prim} out of range"))?;
            raw_tris.push([
                t[0].x,
                t[0].y,
                t[0].z,
                f32::from_bits(prim),
                t[1].x,
                t[1].y,
                t[1].z,
                0.0,
                t[2].x,
                t[2].y,
                t[2].z,
                0.0,
            ]);
        }
        Ok(0x8000_0000 | ((node.count - 1) << 28) | first)
    };
    let empty = BinaryNode {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
        first: 0,
        count: 0,
    };
    let write_child = |raw: &mut [f32; 16], k: usize, node: &BinaryNode, r: u32| {
        let o = 8 * k;
        raw[o..o + 3].copy_from_slice(&node.min.to_array());
        raw[o + 4..o + 7].copy_from_slice(&node.max.to_array());
        raw[3 + 4 * k] = f32::from_bits(r);
    };
    if root.count != 0 {
        // A tree of one leaf: a root whose second child is empty.
        raw_nodes.push([0.0; 16]);
        let r = reference(root, 0, &mut raw_nodes, &mut pending)?;
        write_child(&mut raw_nodes[0], 0, root, r);
        write_child(&mut raw_nodes[0], 1, &empty, 0);
    } else {
        reference(root, 0, &mut raw_nodes, &mut pending)?;
    }
    while let Some((index, slot)) = pending.pop() {
        if raw_nodes.len() > 2 * nodes.len() + 1 {
            return Err("the tree has a cycle".into());
        }
        let node = nodes[index as usize];
        for k in 0..2 {
            let c = node.first + k as u32;
            let child = nodes
                .get(c as usize)
                .ok_or_else(|| format!("node {index}: child {c} out of range"))?;
            let r = reference(child, c, &mut raw_nodes, &mut pending)?;
            let mut raw = raw_nodes[slot];
            write_child(&mut raw, k, child, r);
            raw_nodes[slot] = raw;
        }
    }
    Ok((raw_nodes, raw_tris))
}

/// Builds the scene's one geometry with each CPU builder and counts the work of `batches`' rays
/// in each tree. Scenes of more than one instance are refused (use `--flatten`).
pub fn measure(
    scene: &Scene,
    batches: &[(&'static str, bool, &[GpuRay])],
    gpu_tree: Option<&ksrt::cpu::BlasReadback>,
) -> AnyResult<Vec<TreeWork>> {
    let [only] = scene.instances.as_slice() else {
        return Err(format!(
            "--tree-work: {} has {} instances; it needs one (add --flatten)",
            scene.name,
            scene.instances.len()
        )
        .into());
    };
    let triangles: Vec<[Vec3; 3]> = scene.meshes[only.mesh]
        .triangles(Affine3A::IDENTITY)
        .collect();
    let world_to_object = only.transform.inverse();
    let mut trees = Vec::new();
    for kind in TreeKind::ALL {
        let (build_s, raw) = build_tree(kind, &triangles)?;
        trees.push((kind.name(), build_s, raw));
    }
    if let Some(gpu) = gpu_tree {
        let start = std::time::Instant::now();
        let raw = reinserted(gpu)?;
        trees.push((
            "our GPU tree + obvhs reinsertion".into(),
            start.elapsed().as_secs_f64(),
            raw,
        ));
    }
    let mut out = Vec::new();
    for (tree, build_s, (raw_nodes, raw_tris)) in trees {
        let blas = ksrt::cpu::BlasReadback::new(raw_nodes, raw_tris);
        let batches = batches
            .iter()
            .map(|(kind, any, rays)| {
                (
                    kind.to_string(),
                    work_per_ray(&blas, world_to_object, rays, *any),
                )
            })
            .collect();
        out.push(TreeWork {
            tree,
            build_s,
            sah_cost: f64::from(blas.sah_cost),
            batches,
        });
    }
    Ok(out)
}

/// A CPU builder whose tree [`measure`] lays out as ours.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TreeKind {
    /// `ksrt::cpu::CpuBvh`: 16-bin SAH on every axis, leaves of ≤ 4.
    Binned,
    /// obvhs's BVH2 with a preset's parameters, leaves of ≤ 4 (as our builders make them).
    Obvhs(Preset),
    /// obvhs's `medium_build` without its reinsertion passes: PLOC alone, at that search radius.
    PlocOnly,
}

impl TreeKind {
    /// Every kind, in the order reported.
    pub const ALL: [TreeKind; 5] = [
        TreeKind::Binned,
        TreeKind::Obvhs(Preset::Fastest),
        TreeKind::PlocOnly,
        TreeKind::Obvhs(Preset::Medium),
        TreeKind::Obvhs(Preset::VerySlow),
    ];

    /// The name in reports.
    pub fn name(self) -> String {
        match self {
            TreeKind::Binned => "our CPU binned SAH".into(),
            TreeKind::Obvhs(p) => format!("{} (≤ 4 a leaf)", p.name()),
            TreeKind::PlocOnly => "obvhs medium, no reinsertion".into(),
        }
    }
}

/// Builds `kind`'s tree over `triangles` in our raw layout, with its CPU build time in seconds.
pub fn build_tree(kind: TreeKind, triangles: &[[Vec3; 3]]) -> Result<(f64, RawTree), String> {
    match kind {
        TreeKind::Binned => {
            let start = std::time::Instant::now();
            let cpu = ksrt::cpu::CpuBvh::build(triangles);
            let build_s = start.elapsed().as_secs_f64();
            Ok((
                build_s,
                gpu_bvh2_raw(&cpu_nodes(&cpu), &cpu.primitive_indices, triangles)?,
            ))
        }
        TreeKind::Obvhs(_) | TreeKind::PlocOnly => {
            // obvhs's input leaves out non-finite triangles: its indices map back through this.
            let finite: Vec<u32> = (0..triangles.len() as u32)
                .filter(|&i| triangles[i as usize].iter().all(|v| v.is_finite()))
                .collect();
            let input = obvhs_peer::to_obvhs(triangles);
            let mut params = match kind {
                TreeKind::Obvhs(preset) => preset.params(),
                _ => {
                    let mut p = Preset::Medium.params();
                    p.reinsertion_batch_ratio = 0.0;
                    p.post_collapse_reinsertion_batch_ratio_multiplier = 0.0;
                    p
                }
            };
            params.max_prims_per_leaf = 4;
            // Timed from here: obvhs's input is made outside, as `--cpu-peers` times it.
            let start = std::time::Instant::now();
            let bvh = obvhs_peer::build_with(&input, params)?;
            let build_s = start.elapsed().as_secs_f64();
            let nodes = obvhs_nodes(&bvh);
            let primitives: Vec<u32> = bvh
                .primitive_indices
                .iter()
                .map(|&p| finite.get(p as usize).copied().unwrap_or(u32::MAX))
                .collect();
            Ok((build_s, gpu_bvh2_raw(&nodes, &primitives, triangles)?))
        }
    }
}

/// Our CPU binned-SAH tree's nodes in the shape [`gpu_bvh2_raw`] reads.
fn cpu_nodes(cpu: &ksrt::cpu::CpuBvh) -> Vec<BinaryNode> {
    cpu.nodes
        .iter()
        .map(|n| BinaryNode {
            min: n.min,
            max: n.max,
            first: n.first,
            count: n.count,
        })
        .collect()
}

/// An obvhs BVH2's nodes in the shape [`gpu_bvh2_raw`] reads (obvhs also keeps a node's two
/// children adjacent).
fn obvhs_nodes(bvh: &obvhs::bvh2::Bvh2) -> Vec<BinaryNode> {
    (0..bvh.nodes.len())
        .map(|i| {
            let (min, max) = obvhs_peer::node_box(bvh, i);
            BinaryNode {
                min,
                max,
                first: bvh.nodes[i].first_index,
                count: bvh.nodes[i].prim_count,
            }
        })
        .collect()
}

/// Our read-back tree as an obvhs BVH2 (each node's two children adjacent; leaves list the
/// read-back triangle slots), run through obvhs's reinsertion as `medium_build` runs it (batch
/// 5 % of the nodes, then 10 % as after its leaf collapse), laid out as ours again: what a
/// reinsertion pass after our GPU build would make. Hits report triangle slots, not primitive
/// indices (the work counted is the same).
fn reinserted(gpu: &ksrt::cpu::BlasReadback) -> Result<RawTree, String> {
    use obvhs::aabb::Aabb;
    use obvhs::bvh2::node::Bvh2Node;
    let aabb =
        |c: &ksrt::cpu::Bvh2Child| Aabb::new(c.min.to_array().into(), c.max.to_array().into());
    let Some(root) = gpu.nodes.first() else {
        return Err("the GPU tree is empty".into());
    };
    if root.iter().any(|c| c.is_empty()) {
        return Err("the GPU tree's root has an empty child".into());
    }
    let mut whole = aabb(&root[0]);
    whole = whole.union(&aabb(&root[1]));
    let mut nodes = vec![Bvh2Node::new(whole, 0, 1)];
    let mut pending = vec![(0u32, 0usize)];
    while let Some((ours, k)) = pending.pop() {
        if nodes.len() > 2 * gpu.nodes.len() + 1 {
            return Err("the GPU tree has a cycle".into());
        }
        let node = gpu
            .nodes
            .get(ours as usize)
            .ok_or_else(|| format!("GPU node {ours} out of range"))?;
        let first = nodes.len();
        nodes[k].first_index = first as u32;
        for (j, c) in node.iter().enumerate() {
            if c.is_empty() {
                return Err(format!("GPU node {ours} has an empty child"));
            }
            if c.is_leaf() {
                let (start, count) = c.leaf_range();
                nodes.push(Bvh2Node::new(aabb(c), count, start));
            } else {
                nodes.push(Bvh2Node::new(aabb(c), 0, 0));
                pending.push((c.reference, first + j));
            }
        }
    }
    let mut bvh = obvhs::bvh2::Bvh2 {
        nodes,
        primitive_indices: (0..gpu.triangles.len() as u32).collect(),
        ..Default::default()
    };
    let mut optimizer = obvhs::bvh2::reinsertion::ReinsertionOptimizer::default();
    optimizer.run(&mut bvh, 0.05, None);
    optimizer.run(&mut bvh, 0.1, None);
    gpu_bvh2_raw(&obvhs_nodes(&bvh), &bvh.primitive_indices, &gpu.triangles)
}

/// One batch's work in the printed table.
fn cell(kind: &str, w: &WorkPerRay) -> String {
    format!("{kind} {:.1} + {:.1}", w.nodes, w.triangles)
}

/// Prints the trees' work beside our GPU tree's (`gpu`: kind and work of each batch).
pub fn print(gpu: &[(String, Option<WorkPerRay>)], trees: &[TreeWork]) {
    println!("  tree work (the same sampled rays, traced on the CPU as the GPU traverses):");
    println!(
        "    {:<34} {:>8} {:>10}  nodes + triangle tests per ray by batch",
        "tree", "SAH", "build"
    );
    let row = |name: &str, sah: String, build: String, work: Vec<String>| {
        println!("    {name:<34} {sah:>8} {build:>10}  {}", work.join("   "));
    };
    row(
        "our GPU tree",
        "—".into(),
        "—".into(),
        gpu.iter()
            .map(|(kind, w)| match w {
                Some(w) => cell(kind, w),
                None => format!("{kind} —"),
            })
            .collect(),
    );
    for t in trees {
        row(
            &t.tree,
            format!("{:.2}", t.sah_cost),
            format!("{:.3} s", t.build_s),
            t.batches.iter().map(|(kind, w)| cell(kind, w)).collect(),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(x: f32) -> [Vec3; 3] {
        [
            Vec3::new(x, 0.0, 0.0),
            Vec3::new(x + 0.5, 0.0, 0.0),
            Vec3::new(x, 0.5, 0.0),
        ]
    }

    /// A ray straight down onto `tri(x)`, from 1 above it (it hits at t = 1).
    fn down_at(x: f32) -> ksrt::cpu::Ray {
        ksrt::cpu::Ray {
            origin: Vec3::new(x + 0.1, 0.1, 1.0),
            dir: Vec3::NEG_Z,
            t_min: 0.0,
            t_max: f32::INFINITY,
        }
    }

    #[test]
    fn a_cpu_tree_laid_out_as_the_gpu_bvh2_finds_the_cpu_hits() {
        let triangles: Vec<[Vec3; 3]> = (0..40).map(|i| tri(i as f32)).collect();
        let cpu = ksrt::cpu::CpuBvh::build(&triangles);
        let blas = as_gpu_bvh2(&cpu_nodes(&cpu), &cpu.primitive_indices, &triangles).unwrap();
        assert_eq!(blas.triangles.len(), 40);
        for i in 0..40 {
            let (hit, counts) = blas.trace(&down_at(i as f32), false);
            let hit = hit.unwrap();
            assert_eq!(hit.primitive, i);
            assert!((hit.t - 1.0).abs() < 1e-6);
            // A balanced tree of 40 triangles in leaves of ≤ 4: a handful of nodes, not all 10+.
            assert!(counts.nodes >= 3 && counts.nodes < 12, "{counts:?}");
        }
        // Same SAH as the CPU tree it came from.
        assert!((blas.sah_cost - cpu.sah_cost()).abs() < 1e-4 * cpu.sah_cost());
    }

    #[test]
    fn a_one_leaf_tree_and_bad_trees() {
        let triangles = vec![tri(0.0)];
        let leaf = BinaryNode {
            min: Vec3::ZERO,
            max: Vec3::new(0.5, 0.5, 0.0),
            first: 0,
            count: 1,
        };
        let blas = as_gpu_bvh2(&[leaf], &[0], &triangles).unwrap();
        let ray = down_at(0.0);
        assert_eq!(blas.trace(&ray, false).0.unwrap().primitive, 0);
        let big = BinaryNode { count: 9, ..leaf };
        assert!(as_gpu_bvh2(&[big], &[0; 9], &triangles)
            .unwrap_err()
            .contains("9 triangles"));
        let dangling = BinaryNode {
            count: 0,
            first: 5,
            ..leaf
        };
        assert!(as_gpu_bvh2(&[dangling], &[0], &triangles)
            .unwrap_err()
            .contains("out of range"));
    }

    fn strip_scene(instances: usize) -> Scene {
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        for i in 0..64u32 {
            let t = tri(i as f32);
            positions.extend(t.iter().map(|v| v.to_array()));
            indices.extend([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        let mesh = kickstart_rt_renderer::scene::Mesh::new("strip", positions, indices, Vec3::ONE)
            .unwrap();
        Scene {
            name: "strip".into(),
            meshes: vec![mesh],
            instances: (0..instances)
                .map(|k| kickstart_rt_renderer::scene::Instance {
                    mesh: 0,
                    transform: Affine3A::from_translation(Vec3::new(0.0, 0.0, -(k as f32))),
                })
                .collect(),
            ..Default::default()
        }
    }

    #[test]
    fn every_builder_is_measured_on_every_batch_and_many_instances_are_refused() {
        // Rays down onto triangles 0, 8, 16, …: each hits, so each tree does some work.
        let rays: Vec<GpuRay> = (0..8)
            .map(|k| GpuRay {
                origin: [8.0 * k as f32 + 0.1, 0.1, 1.0],
                t_min: 0.0,
                dir: [0.0, 0.0, -1.0],
                t_max: f32::INFINITY,
            })
            .collect();
        let scene = strip_scene(1);
        let tris: Vec<[Vec3; 3]> = scene.meshes[0].triangles(Affine3A::IDENTITY).collect();
        let (_, (raw_nodes, raw_tris)) = build_tree(TreeKind::Binned, &tris).unwrap();
        let gpu = ksrt::cpu::BlasReadback::new(raw_nodes, raw_tris);
        let trees = measure(
            &scene,
            &[("primary", false, &rays), ("ao", true, &rays)],
            Some(&gpu),
        )
        .unwrap();
        // Every CPU builder, and the given tree after reinsertion.
        assert_eq!(trees.len(), TreeKind::ALL.len() + 1);
        for t in &trees {
            assert_eq!(t.batches.len(), 2, "{}", t.tree);
            for (_, w) in &t.batches {
                assert_eq!(w.sampled, 8);
                // Every ray reaches a leaf and tests at least its triangle.
                assert!(w.nodes >= 1.0 && w.triangles >= 1.0, "{}: {w:?}", t.tree);
            }
            assert!(t.sah_cost > 1.0, "{}: {}", t.tree, t.sah_cost);
        }
        let err = measure(&strip_scene(2), &[("primary", false, &rays)], None)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("2 instances") && err.contains("--flatten"),
            "{err}"
        );
    }

    #[test]
    fn reinsertion_keeps_every_hit_and_lowers_the_sah_of_a_bad_tree() {
        // A balanced tree over one-triangle leaves in a scrambled order (neighbours in the tree
        // are far apart on the line), so reinsertion has work. Heap order: node i's children
        // are 2i+1 and 2i+2; nodes 0..31 inner, 31..63 leaves.
        let triangles: Vec<[Vec3; 3]> = (0..32).map(|i| tri(((i * 13) % 32) as f32)).collect();
        let mut boxes = vec![(Vec3::ZERO, Vec3::ZERO); 63];
        for (k, t) in triangles.iter().enumerate() {
            boxes[31 + k] = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
        }
        for i in (0..31).rev() {
            let (a, b) = (boxes[2 * i + 1], boxes[2 * i + 2]);
            boxes[i] = (a.0.min(b.0), a.1.max(b.1));
        }
        let nodes: Vec<BinaryNode> = (0..63usize)
            .map(|i| BinaryNode {
                min: boxes[i].0,
                max: boxes[i].1,
                first: if i < 31 {
                    2 * i as u32 + 1
                } else {
                    i as u32 - 31
                },
                count: u32::from(i >= 31),
            })
            .collect();
        let primitives: Vec<u32> = (0..32).collect();
        let before = as_gpu_bvh2(&nodes, &primitives, &triangles).unwrap();
        let (raw_nodes, raw_tris) = reinserted(&before).unwrap();
        let after = ksrt::cpu::BlasReadback::new(raw_nodes, raw_tris);
        assert_eq!(after.triangles.len(), 32);
        // Reinsertion ran and moved something (obvhs only applies moves that lower the SAH).
        assert!(
            after.sah_cost < before.sah_cost,
            "{} >= {}",
            after.sah_cost,
            before.sah_cost
        );
        for x in 0..32 {
            let hit = after
                .trace(&down_at(x as f32), false)
                .0
                .expect("every triangle is still in the tree");
            assert!((hit.t - 1.0).abs() < 1e-6);
        }
    }
}
