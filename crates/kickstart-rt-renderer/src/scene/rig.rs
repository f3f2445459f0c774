//! Skeletons and deformable meshes (glTF 2.0's model): the node hierarchy, skins (joint nodes
//! and inverse bind matrices), which instance hangs on which node with which skin, each vertex's
//! joint influences and morph targets, the checks a loaded or generated scene must pass, and CPU
//! skinning with the SDK's `SkinningTask` formula (the CPU reference and the tests use it).

use glam::{Mat4, Quat, Vec3};

use super::Scene;

/// One node of the hierarchy: a local transform under its parent.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// A name for logs (the file's, or `node N`).
    pub name: String,
    /// Index into [`Scene::nodes`] of the parent; `None` for a root.
    pub parent: Option<usize>,
    /// Translation of the rest transform (what an animation channel overrides).
    pub translation: Vec3,
    /// Rotation of the rest transform (unit).
    pub rotation: Quat,
    /// Scale of the rest transform.
    pub scale: Vec3,
    /// The local transform as the file gives it: a matrix node's exact matrix (which a shear
    /// would not survive a split into T·R·S), else T·R·S. Used while no channel animates the
    /// node; an animated node is composed from its (overridden) T, R and S, which glTF requires
    /// animated nodes to have.
    pub matrix: Mat4,
    /// The node's morph target weights (glTF `node.weights`); empty: the mesh's defaults.
    pub weights: Vec<f32>,
}

impl Node {
    /// A node with the rest transform T·R·S.
    pub fn from_trs(
        name: impl Into<String>,
        parent: Option<usize>,
        translation: Vec3,
        rotation: Quat,
        scale: Vec3,
    ) -> Node {
        Node {
            name: name.into(),
            parent,
            translation,
            rotation,
            scale,
            matrix: Mat4::from_scale_rotation_translation(scale, rotation, translation),
            weights: Vec::new(),
        }
    }
}

/// A skin: the nodes that act as its joints and, per joint, the matrix that takes the mesh from
/// its bind pose into the joint's space.
#[derive(Debug, Clone, PartialEq)]
pub struct Skin {
    /// A name for logs.
    pub name: String,
    /// Indices into [`Scene::nodes`]; a vertex's joint index `j` means `joints[j]`.
    pub joints: Vec<usize>,
    /// One per joint (glTF `inverseBindMatrices`; identity when the file has none).
    pub inverse_bind: Vec<Mat4>,
}

/// A deformable instance: the node it hangs on and the skin that poses its mesh. Its mesh is
/// used by this instance alone (the loaders copy a mesh that several deformable nodes share),
/// so that each pose has a vertex buffer of its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rig {
    /// Index into [`Scene::instances`]; its transform is the node's world transform at rest.
    pub instance: usize,
    /// Index into [`Scene::nodes`] of the node the mesh hangs on (whose weights animate).
    pub node: usize,
    /// Index into [`Scene::skins`]; `None` for a mesh that only morphs.
    pub skin: Option<usize>,
}

/// How a mesh deforms: up to four joint influences a vertex and morph targets. Empty for a rigid
/// mesh.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Deform {
    /// Per vertex, four indices into its skin's joints (glTF `JOINTS_0`); empty: not skinned.
    pub joints: Vec<[u16; 4]>,
    /// Per vertex, the four weights of `joints` (glTF `WEIGHTS_0`), used as given.
    pub weights: Vec<[f32; 4]>,
    /// Per morph target, one position delta a vertex.
    pub morph_targets: Vec<Vec<[f32; 3]>>,
    /// Default weight of each morph target (glTF `mesh.weights`; zeros when the file has none).
    pub morph_weights: Vec<f32>,
}

impl Deform {
    /// Whether the mesh has joint influences.
    pub fn is_skinned(&self) -> bool {
        !self.joints.is_empty()
    }

    /// Whether the mesh has nothing to deform it.
    pub fn is_rigid(&self) -> bool {
        self.joints.is_empty() && self.morph_targets.is_empty()
    }

    /// What is wrong with this deformation of a mesh of `vertices` vertices whose skin has
    /// `joints` joints (`None`: unskinned), if anything: counts that differ from the vertex
    /// count, a joint index out of range, a weight or delta that is not finite.
    pub fn check(&self, vertices: usize, joints: Option<usize>) -> Result<(), String> {
        if self.joints.len() != self.weights.len() {
            return Err(format!(
                "{} joint sets but {} weight sets",
                self.joints.len(),
                self.weights.len()
            ));
        }
        if self.is_skinned() {
            if self.joints.len() != vertices {
                return Err(format!(
                    "{} joint sets for {vertices} vertices",
                    self.joints.len()
                ));
            }
            let count = joints.ok_or("joint influences without a skin")?;
            if let Some((v, j)) = self.joints.iter().enumerate().find_map(|(v, j)| {
                j.iter()
                    .find(|&&j| usize::from(j) >= count)
                    .map(|&j| (v, j))
            }) {
                return Err(format!(
                    "vertex {v} names joint {j}, the skin has {count} joints"
                ));
            }
            if let Some(v) = self
                .weights
                .iter()
                .position(|w| !w.iter().all(|x| x.is_finite()))
            {
                return Err(format!("vertex {v} has a non-finite joint weight"));
            }
        }
        if self.morph_weights.len() != self.morph_targets.len() {
            return Err(format!(
                "{} morph weights for {} morph targets",
                self.morph_weights.len(),
                self.morph_targets.len()
            ));
        }
        for (t, deltas) in self.morph_targets.iter().enumerate() {
            if deltas.len() != vertices {
                return Err(format!(
                    "morph target {t} has {} deltas for {vertices} vertices",
                    deltas.len()
                ));
            }
            if deltas.iter().flatten().any(|d| !d.is_finite()) {
                return Err(format!("morph target {t} has a non-finite delta"));
            }
        }
        if self.morph_weights.iter().any(|w| !w.is_finite()) {
            return Err("a default morph weight is not finite".into());
        }
        Ok(())
    }
}

/// The posed positions of a mesh: `rest` plus the morph targets' deltas times `morph_weights`,
/// then `Σ weight · joint_matrices[joint] · p` over the vertex's influences: the formula of the
/// SDK's `SkinningTask`, influences of weight 0 or naming a joint past `joint_matrices` ignored,
/// and a vertex with none left keeping its morphed position (as does every vertex of an
/// unskinned `deform`).
pub fn skin_positions(
    rest: &[[f32; 3]],
    deform: &Deform,
    joint_matrices: &[Mat4],
    morph_weights: &[f32],
) -> Vec<[f32; 3]> {
    let skinned = deform.joints.len() == rest.len() && deform.weights.len() == rest.len();
    (0..rest.len())
        .map(|v| {
            let mut p = Vec3::from(rest[v]);
            for (deltas, &w) in deform.morph_targets.iter().zip(morph_weights) {
                if w != 0.0 {
                    if let Some(d) = deltas.get(v) {
                        p += w * Vec3::from(*d);
                    }
                }
            }
            if !skinned {
                return p.to_array();
            }
            let (mut sum, mut used) = (Vec3::ZERO, false);
            for (&j, &w) in deform.joints[v].iter().zip(&deform.weights[v]) {
                if let (true, Some(m)) = (w != 0.0, joint_matrices.get(usize::from(j))) {
                    sum += w * m.transform_point3(p);
                    used = true;
                }
            }
            if used { sum } else { p }.to_array()
        })
        .collect()
}

impl Scene {
    /// Checks the hierarchy and the rigs: parents in range and no cycle, skins' joints in range
    /// with one inverse bind matrix each, every rig's instance, node and skin in range, its mesh
    /// used by no other instance, and its deformation consistent with the mesh and the skin
    /// ([`Deform::check`]). What a loader or generator must hold before the renderer poses.
    pub fn check_rigs(&self) -> Result<(), String> {
        check_hierarchy(&self.nodes)?;
        for (k, skin) in self.skins.iter().enumerate() {
            if let Some(&j) = skin.joints.iter().find(|&&j| j >= self.nodes.len()) {
                return Err(format!(
                    "skin {k} ({}): joint node {j} does not exist",
                    skin.name
                ));
            }
            if skin.inverse_bind.len() != skin.joints.len() {
                return Err(format!(
                    "skin {k} ({}): {} inverse bind matrices for {} joints",
                    skin.name,
                    skin.inverse_bind.len(),
                    skin.joints.len()
                ));
            }
            if skin.inverse_bind.iter().any(|m| !m.is_finite()) {
                return Err(format!(
                    "skin {k} ({}): a non-finite inverse bind matrix",
                    skin.name
                ));
            }
        }
        let mut users = vec![0usize; self.meshes.len()];
        for inst in &self.instances {
            if let Some(u) = users.get_mut(inst.mesh) {
                *u += 1;
            }
        }
        for (k, rig) in self.rigs.iter().enumerate() {
            let inst = self
                .instances
                .get(rig.instance)
                .ok_or(format!("rig {k}: instance {} does not exist", rig.instance))?;
            if rig.node >= self.nodes.len() {
                return Err(format!("rig {k}: node {} does not exist", rig.node));
            }
            let joints = match rig.skin {
                Some(s) => Some(
                    self.skins
                        .get(s)
                        .ok_or(format!("rig {k}: skin {s} does not exist"))?
                        .joints
                        .len(),
                ),
                None => None,
            };
            let mesh = &self.meshes[inst.mesh];
            if users[inst.mesh] != 1 {
                return Err(format!(
                    "rig {k}: mesh {:?} is used by {} instances",
                    mesh.name, users[inst.mesh]
                ));
            }
            mesh.deform
                .check(mesh.positions.len(), joints)
                .map_err(|e| format!("rig {k}: mesh {:?}: {e}", mesh.name))?;
        }
        Ok(())
    }
}

/// Checks that every parent exists and that following parents always ends at a root, in time
/// linear in the nodes (files chain tens of thousands of them).
pub fn check_hierarchy(nodes: &[Node]) -> Result<(), String> {
    // Per node: 0 not seen, 1 on the walk under way, 2 known to end at a root.
    let mut state = vec![0u8; nodes.len()];
    for k in 0..nodes.len() {
        let mut walk = Vec::new();
        let mut at = Some(k);
        while let Some(n) = at {
            match state[n] {
                2 => break,
                1 => return Err(format!("node {n} ({}) is its own ancestor", nodes[n].name)),
                _ => {}
            }
            state[n] = 1;
            walk.push(n);
            at = nodes[n].parent;
            if let Some(p) = at.filter(|&p| p >= nodes.len()) {
                return Err(format!(
                    "node {n} ({}): parent {p} does not exist",
                    nodes[n].name
                ));
            }
        }
        for n in walk {
            state[n] = 2;
        }
    }
    Ok(())
}

/// Each node's world transform (its parents' composed with its own `local`), parents before
/// children whatever their order. Requires a checked hierarchy ([`check_hierarchy`]); a parent
/// out of range counts as none.
pub fn world_transforms(nodes: &[Node], local: impl Fn(usize) -> Mat4) -> Vec<Mat4> {
    let mut world: Vec<Option<Mat4>> = vec![None; nodes.len()];
    for k in 0..nodes.len() {
        // Walk up to the nearest node already placed, then place the chain back down.
        let mut chain = vec![k];
        while let Some(p) = nodes[*chain.last().unwrap_or(&k)].parent {
            if p >= nodes.len() || world[p].is_some() || chain.len() > nodes.len() {
                break;
            }
            chain.push(p);
        }
        for &n in chain.iter().rev() {
            if world[n].is_some() {
                continue;
            }
            let parent = nodes[n]
                .parent
                .and_then(|p| world.get(p).copied().flatten())
                .unwrap_or(Mat4::IDENTITY);
            world[n] = Some(parent * local(n));
        }
    }
    world
        .into_iter()
        .map(|m| m.unwrap_or(Mat4::IDENTITY))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn deform() -> Deform {
        Deform {
            joints: vec![[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0]],
            weights: vec![[0.25, 0.75, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0; 4]],
            morph_targets: vec![vec![[0.0, 1.0, 0.0]; 3]],
            morph_weights: vec![0.0],
        }
    }

    #[test]
    fn cpu_skinning_morphs_then_blends_the_joints() {
        let rest = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [2.0, 2.0, 2.0]];
        let m = [
            Mat4::IDENTITY,
            Mat4::from_translation(Vec3::new(0.0, 0.0, 4.0)),
        ];
        let posed = skin_positions(&rest, &deform(), &m, &[0.5]);
        // Vertex 0: morphed to (1, 0.5, 0), then 0.25 · p + 0.75 · (p + 4z).
        assert_eq!(posed[0], [1.0, 0.5, 3.0]);
        // Vertex 1: joint 1 alone.
        assert_eq!(posed[1], [0.0, 0.5, 5.0]);
        // Vertex 2: no weight: the morphed rest position.
        assert_eq!(posed[2], [2.0, 2.5, 2.0]);
        // A joint past the matrices is ignored, like a weight of 0.
        let posed = skin_positions(&rest, &deform(), &m[..1], &[0.0]);
        assert_eq!(posed[0], [0.25, 0.0, 0.0]);
        assert_eq!(posed[1], [0.0, 0.0, 1.0]);
    }

    #[test]
    fn deformations_are_checked_against_the_mesh_and_the_skin() {
        assert_eq!(deform().check(3, Some(2)), Ok(()));
        let e = deform().check(3, Some(1)).unwrap_err();
        assert!(
            e.contains("vertex 0 names joint 1, the skin has 1 joints"),
            "{e}"
        );
        assert!(deform()
            .check(4, Some(2))
            .unwrap_err()
            .contains("3 joint sets for 4"));
        assert!(deform()
            .check(3, None)
            .unwrap_err()
            .contains("without a skin"));
        let mut d = deform();
        d.weights[1][2] = f32::NAN;
        assert!(d
            .check(3, Some(2))
            .unwrap_err()
            .contains("vertex 1 has a non-finite"));
        let mut d = deform();
        d.morph_weights.push(1.0);
        assert!(d
            .check(3, Some(2))
            .unwrap_err()
            .contains("2 morph weights for 1"));
    }

    #[test]
    fn world_transforms_compose_parents_in_any_order_and_cycles_are_refused() {
        let t =
            |x: f32, parent| Node::from_trs("n", parent, Vec3::X * x, Quat::IDENTITY, Vec3::ONE);
        // The child comes first: its parent is placed on the way.
        let nodes = vec![t(1.0, Some(2)), t(10.0, None), t(100.0, Some(1))];
        assert_eq!(check_hierarchy(&nodes), Ok(()));
        let w = world_transforms(&nodes, |k| nodes[k].matrix);
        let x: Vec<f32> = w.iter().map(|m| m.w_axis.x).collect();
        assert_eq!(x, vec![111.0, 10.0, 110.0]);
        let cycle = vec![t(1.0, Some(1)), t(1.0, Some(0))];
        assert!(check_hierarchy(&cycle)
            .unwrap_err()
            .contains("its own ancestor"));
        let dangling = vec![t(1.0, Some(5))];
        assert!(check_hierarchy(&dangling)
            .unwrap_err()
            .contains("parent 5 does not exist"));
    }
}
