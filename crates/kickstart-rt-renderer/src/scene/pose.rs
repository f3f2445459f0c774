//! A scene's pose at a time: its first animation sampled (looping), every node's world
//! transform, and per rig the joint matrices and morph weights a `SkinningTask` takes; and the
//! scene with its deformable meshes skinned on the CPU, for the CPU reference and the tests.

use glam::{Mat4, Quat, Vec3};

use super::animation::Property;
use super::rig::{skin_positions, world_transforms};
use super::{compute_normals, Scene};

/// What poses one rig's mesh at one time.
#[derive(Debug, Clone, PartialEq)]
pub struct RigPose {
    /// One matrix a joint of the rig's skin, in the mesh's space: `inverse(mesh node world at
    /// rest) · joint world · inverse bind` (empty without a skin).
    pub joint_matrices: Vec<Mat4>,
    /// One weight a morph target of the mesh.
    pub morph_weights: Vec<f32>,
}

/// The node's local transform and morph weights as the animation leaves them.
struct Animated {
    translation: Option<Vec3>,
    rotation: Option<Quat>,
    scale: Option<Vec3>,
    weights: Option<Vec<f32>>,
}

impl Scene {
    /// Length of the animation `ksrt` plays, the scene's first: seconds, 0 when there is none.
    pub fn animation_duration(&self) -> f32 {
        self.animations.first().map_or(0.0, |a| a.duration())
    }

    /// The time within the animation at scene time `t`: the animation loops, so `t` modulo its
    /// duration (0 without one or for a non-finite `t`).
    pub fn animation_time(&self, t: f32) -> f32 {
        let d = self.animation_duration();
        if d > 0.0 && t.is_finite() {
            t.rem_euclid(d)
        } else {
            0.0
        }
    }

    /// Every node's world transform at scene time `t` (the first animation applied, looping).
    pub fn node_worlds(&self, t: f32) -> Vec<Mat4> {
        let animated = self.sample_nodes(self.animation_time(t));
        world_transforms(&self.nodes, |k| {
            let n = &self.nodes[k];
            match &animated[k] {
                None => n.matrix,
                Some(a) => Mat4::from_scale_rotation_translation(
                    a.scale.unwrap_or(n.scale),
                    a.rotation.unwrap_or(n.rotation),
                    a.translation.unwrap_or(n.translation),
                ),
            }
        })
    }

    /// Per node, what the first animation sets at animation time `t` (`None`: not animated).
    fn sample_nodes(&self, t: f32) -> Vec<Option<Animated>> {
        let mut out: Vec<Option<Animated>> = (0..self.nodes.len()).map(|_| None).collect();
        let Some(animation) = self.animations.first() else {
            return out;
        };
        for c in &animation.channels {
            let Some(slot) = out.get_mut(c.node) else {
                continue;
            };
            let a = slot.get_or_insert(Animated {
                translation: None,
                rotation: None,
                scale: None,
                weights: None,
            });
            let v = c.sample(t);
            match c.property {
                Property::Translation => a.translation = Some(Vec3::from_slice(&v)),
                Property::Rotation => {
                    a.rotation = Some(Quat::from_slice(&v).normalize());
                }
                Property::Scale => a.scale = Some(Vec3::from_slice(&v)),
                Property::Weights => a.weights = Some(v),
            }
        }
        out
    }

    /// Every rig's pose at scene time `t`, in [`Scene::rigs`] order. Requires checked rigs
    /// ([`Scene::check_rigs`]).
    pub fn pose_at(&self, t: f32) -> Vec<RigPose> {
        let local_t = self.animation_time(t);
        let worlds = self.node_worlds(t);
        let animated = self.sample_nodes(local_t);
        self.rigs
            .iter()
            .map(|rig| {
                let inst = &self.instances[rig.instance];
                let mesh = &self.meshes[inst.mesh];
                let to_mesh = Mat4::from(inst.transform).inverse();
                let joint_matrices =
                    rig.skin
                        .and_then(|s| self.skins.get(s))
                        .map_or_else(Vec::new, |skin| {
                            skin.joints
                                .iter()
                                .zip(&skin.inverse_bind)
                                .map(|(&j, ibm)| to_mesh * worlds[j] * *ibm)
                                .collect()
                        });
                let node = &self.nodes[rig.node];
                let targets = mesh.deform.morph_targets.len();
                let weights = animated[rig.node]
                    .as_ref()
                    .and_then(|a| a.weights.clone())
                    .or_else(|| (!node.weights.is_empty()).then(|| node.weights.clone()))
                    .unwrap_or_else(|| mesh.deform.morph_weights.clone());
                // A file's node weights may count differently from the mesh's targets: the
                // targets decide (missing weights are 0).
                let morph_weights = (0..targets)
                    .map(|i| weights.get(i).copied().unwrap_or(0.0))
                    .collect();
                RigPose {
                    joint_matrices,
                    morph_weights,
                }
            })
            .collect()
    }

    /// Every rig's mesh posed at scene time `t` on the CPU ([`skin_positions`]): per rig, in
    /// [`Scene::rigs`] order, the index of its mesh in [`Scene::meshes`], the posed positions
    /// and the normals recomputed from them. What the renderer uploads each frame and what
    /// [`Scene::posed`] (the CPU reference's scene) is made of, so both agree exactly.
    pub fn posed_meshes(&self, t: f32) -> Vec<PosedMesh> {
        self.rigs
            .iter()
            .zip(self.pose_at(t))
            .map(|(rig, pose)| {
                let mesh = self.instances[rig.instance].mesh;
                let m = &self.meshes[mesh];
                let positions = skin_positions(
                    &m.positions,
                    &m.deform,
                    &pose.joint_matrices,
                    &pose.morph_weights,
                );
                let normals = compute_normals(&positions, &m.indices);
                PosedMesh {
                    mesh,
                    positions,
                    normals,
                }
            })
            .collect()
    }

    /// The scene at time `t` with every rig's mesh posed ([`Scene::posed_meshes`]): what the
    /// CPU reference traces. Rigid meshes are as they are.
    pub fn posed(&self, t: f32) -> Scene {
        let mut out = self.clone();
        for p in self.posed_meshes(t) {
            let mesh = &mut out.meshes[p.mesh];
            mesh.positions = p.positions;
            mesh.normals = p.normals;
        }
        out
    }
}

/// One rig's mesh at one time ([`Scene::posed_meshes`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PosedMesh {
    /// Index into [`Scene::meshes`].
    pub mesh: usize,
    /// Posed positions, one a vertex of the mesh.
    pub positions: Vec<[f32; 3]>,
    /// Normals of the posed triangles, one a vertex.
    pub normals: Vec<[f32; 3]>,
}

#[cfg(test)]
mod tests {
    use super::super::animation::{Animation, Channel, Interpolation};
    use super::super::rig::{Deform, Node, Rig, Skin};
    use super::super::{Instance, Mesh};
    use super::*;
    use glam::Affine3A;

    /// A two-joint arm along x (joint 1 at x = 1 under joint 0), its mesh placed at x = 5 by
    /// its node, the elbow turning 90° about z over 2 s.
    fn arm() -> Scene {
        let positions = vec![[0.5, 0.0, 0.0], [1.5, 0.0, 0.0], [2.0, 0.0, 0.0]];
        let mut mesh =
            Mesh::new("arm", positions, vec![0, 1, 2], Vec3::ONE).unwrap_or_else(|e| panic!("{e}"));
        mesh.deform = Deform {
            joints: vec![[0, 0, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0]],
            weights: vec![[1.0, 0.0, 0.0, 0.0]; 3],
            morph_targets: vec![vec![[0.0, 0.0, 1.0]; 3]],
            morph_weights: vec![0.0],
        };
        let place = Vec3::new(5.0, 0.0, 0.0);
        let id = Quat::IDENTITY;
        let mut nodes = vec![
            Node::from_trs("mesh", None, place, id, Vec3::ONE),
            Node::from_trs("shoulder", Some(0), Vec3::ZERO, id, Vec3::ONE),
            Node::from_trs("elbow", Some(1), Vec3::X, id, Vec3::ONE),
        ];
        nodes[0].weights = vec![0.5];
        let turn = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
        let mut values = id.to_array().to_vec();
        values.extend(turn.to_array());
        let channel = |p, v| {
            Channel::new(2, p, Interpolation::Linear, vec![0.0, 2.0], v, 1)
                .unwrap_or_else(|e| panic!("{e}"))
        };
        Scene {
            meshes: vec![mesh],
            instances: vec![Instance {
                mesh: 0,
                transform: Affine3A::from_translation(place),
            }],
            nodes,
            skins: vec![Skin {
                name: "arm".into(),
                joints: vec![1, 2],
                // Joint spaces at rest: the mesh's own origin and x = 1 (mesh space).
                inverse_bind: vec![Mat4::IDENTITY, Mat4::from_translation(-Vec3::X)],
            }],
            rigs: vec![Rig {
                instance: 0,
                node: 0,
                skin: Some(0),
            }],
            animations: vec![Animation {
                name: "bend".into(),
                channels: vec![channel(Property::Rotation, values)],
            }],
            ..Default::default()
        }
    }

    #[test]
    fn the_pose_bends_the_elbow_and_uses_the_node_weights() {
        let scene = arm();
        assert_eq!(scene.check_rigs(), Ok(()));
        assert_eq!(scene.animation_duration(), 2.0);
        let pose = &scene.pose_at(2.0 - 1e-4)[0];
        assert_eq!(pose.morph_weights, vec![0.5]);
        let posed = scene.posed(2.0 - 1e-4);
        let p = posed.meshes[0].positions.clone();
        // The shoulder half does not move; the forearm points up +y from x = 1 (mesh space),
        // lifted by the morph's 0.5 in z.
        let near = |a: [f32; 3], b: [f32; 3]| (Vec3::from(a) - Vec3::from(b)).length() < 1e-3;
        assert!(near(p[0], [0.5, 0.0, 0.5]), "{:?}", p[0]);
        assert!(near(p[1], [1.0, 0.5, 0.5]), "{:?}", p[1]);
        assert!(near(p[2], [1.0, 1.0, 0.5]), "{:?}", p[2]);
        // At t = 0 (and after a whole loop) the rest pose.
        let rest = scene.posed(4.0);
        assert!(near(rest.meshes[0].positions[2], [2.0, 0.0, 0.5]));
    }

    #[test]
    fn a_weights_channel_overrides_the_node_weights() {
        let mut scene = arm();
        let w = Channel::new(
            0,
            Property::Weights,
            Interpolation::Step,
            vec![0.0, 1.0],
            vec![0.25, 1.0],
            1,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        scene.animations[0].channels.push(w);
        assert_eq!(scene.pose_at(0.5)[0].morph_weights, vec![0.25]);
        assert_eq!(scene.pose_at(1.5)[0].morph_weights, vec![1.0]);
    }
}
