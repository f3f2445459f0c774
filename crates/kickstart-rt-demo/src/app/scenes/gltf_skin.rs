//! glTF 2.0 skeletons and deformations into the renderer's model: the node hierarchy (every node
//! of the file, with its parent and rest transform), skins (joint nodes and inverse bind
//! matrices), and a primitive's joint influences (`JOINTS_0`: `u8` or `u16`; `WEIGHTS_0`:
//! float, unorm8 or unorm16) and morph targets (`POSITION` deltas). Every accessor is checked
//! for its type and its place in its buffer before it is read; counts and values are checked by
//! the renderer's [`Deform::check`] and [`Scene::check_rigs`](kickstart_rt_renderer::scene::Scene::check_rigs).

use glam::{Mat4, Quat, Vec3};
use gltf::accessor::{DataType, Dimensions};

use kickstart_rt_renderer::scene::rig::{check_hierarchy, Deform, Node, Skin};

use super::gltf_accessor::{check_accessor, typed};

/// `q` scaled to unit length, or the identity for a zero or non-finite `q`.
fn unit_or_identity(q: Quat) -> Quat {
    let len = q.length();
    if len.is_finite() && len > 0.0 {
        q / len
    } else {
        Quat::IDENTITY
    }
}

/// Every node of the file in its order: name, parent (from the children lists), rest transform
/// and morph weights. Refused: a node that is the child of two nodes, a non-finite transform or
/// weight, and a cycle.
pub fn read_nodes(file: &gltf::Document) -> Result<Vec<Node>, String> {
    let count = file.nodes().len();
    let mut parent: Vec<Option<usize>> = vec![None; count];
    for node in file.nodes() {
        for child in node.children() {
            let c = child.index();
            if let Some(p) = parent[c].replace(node.index()) {
                return Err(format!(
                    "node {c} is a child of both node {p} and node {}",
                    node.index()
                ));
            }
        }
    }
    let nodes = file
        .nodes()
        .map(|n| {
            let name = n
                .name()
                .map_or_else(|| format!("node {}", n.index()), str::to_string);
            let (translation, rotation, scale, matrix) = match n.transform() {
                gltf::scene::Transform::Decomposed {
                    translation,
                    rotation,
                    scale,
                } => {
                    let (t, r, s) = (
                        Vec3::from(translation),
                        Quat::from_array(rotation),
                        Vec3::from(scale),
                    );
                    (t, r, s, Mat4::from_scale_rotation_translation(s, r, t))
                }
                gltf::scene::Transform::Matrix { matrix } => {
                    let m = Mat4::from_cols_array_2d(&matrix);
                    let (s, r, t) = m.to_scale_rotation_translation();
                    (t, r, s, m)
                }
            };
            let weights = n.weights().map(<[f32]>::to_vec).unwrap_or_default();
            // A zero rotation, or a matrix of scale 0 (a hidden node), has no rotation to
            // split off: identity then (only an animated node uses it, with the channel's).
            let rotation = unit_or_identity(rotation);
            let finite = translation.is_finite()
                && scale.is_finite()
                && matrix.is_finite()
                && weights.iter().all(|w| w.is_finite());
            if !finite {
                return Err(format!(
                    "node {} ({name}) has a non-finite transform or weight",
                    n.index()
                ));
            }
            Ok(Node {
                name,
                parent: parent[n.index()],
                translation,
                rotation,
                scale,
                matrix,
                weights,
            })
        })
        .collect::<Result<Vec<_>, String>>()?;
    check_hierarchy(&nodes)?;
    Ok(nodes)
}

/// Every skin of the file: its joints and one inverse bind matrix each (identity when the file
/// gives none). Refused, naming the skin: an inverse bind accessor that is not `MAT4` floats,
/// lies outside its buffer, or counts other than the joints.
pub fn read_skins(file: &gltf::Document, buffers: &[Vec<u8>]) -> Result<Vec<Skin>, String> {
    file.skins()
        .map(|skin| {
            let name = skin
                .name()
                .map_or_else(|| format!("skin {}", skin.index()), str::to_string);
            let err = |e: String| format!("skin {} ({name}): {e}", skin.index());
            let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
            let inverse_bind = match skin.inverse_bind_matrices() {
                None => vec![Mat4::IDENTITY; joints.len()],
                Some(a) => {
                    typed(&a, &[DataType::F32], Dimensions::Mat4, false).map_err(err)?;
                    check_accessor(&a, buffers).map_err(err)?;
                    let reader = skin.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
                    let m: Vec<Mat4> = reader
                        .read_inverse_bind_matrices()
                        .map(|it| it.map(|m| Mat4::from_cols_array_2d(&m)).collect())
                        .unwrap_or_default();
                    if m.len() != joints.len() {
                        return Err(err(format!(
                            "{} inverse bind matrices for {} joints",
                            m.len(),
                            joints.len()
                        )));
                    }
                    m
                }
            };
            Ok(Skin {
                name,
                joints,
                inverse_bind,
            })
        })
        .collect()
}

/// The deformation of one primitive (`name` for errors): its joint influences when `skinned`
/// (the node that uses it has a skin; a mesh drawn without one ignores its `JOINTS_0`), its
/// morph targets' position deltas, and the mesh's default morph weights (`mesh.weights`,
/// zeros where missing). Counts are checked later, against the mesh and the skin
/// ([`Deform::check`]).
pub fn read_deform(
    name: &str,
    mesh: &gltf::Mesh,
    prim: &gltf::Primitive,
    buffers: &[Vec<u8>],
    skinned: bool,
) -> Result<Deform, String> {
    let reader = prim.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
    let mut deform = Deform::default();
    let joints = prim.get(&gltf::Semantic::Joints(0));
    let weights = prim.get(&gltf::Semantic::Weights(0));
    if skinned {
        if let (Some(j), Some(w)) = (&joints, &weights) {
            typed(j, &[DataType::U8, DataType::U16], Dimensions::Vec4, false)
                .map_err(|e| format!("{name}: JOINTS_0: {e}"))?;
            typed(
                w,
                &[DataType::F32, DataType::U8, DataType::U16],
                Dimensions::Vec4,
                true,
            )
            .map_err(|e| format!("{name}: WEIGHTS_0: {e}"))?;
            deform.joints = reader
                .read_joints(0)
                .map(|r| r.into_u16().collect())
                .unwrap_or_default();
            deform.weights = reader
                .read_weights(0)
                .map(|r| r.into_f32().collect())
                .unwrap_or_default();
        } else if joints.is_some() != weights.is_some() {
            return Err(format!("{name}: JOINTS_0 and WEIGHTS_0 must come together"));
        }
    }
    for (t, target) in prim.morph_targets().enumerate() {
        let deltas = match target.positions() {
            Some(a) => {
                typed(&a, &[DataType::F32], Dimensions::Vec3, false)
                    .and_then(|()| check_accessor(&a, buffers))
                    .map_err(|e| format!("{name}: morph target {t} POSITION: {e}"))?;
                reader
                    .read_morph_targets()
                    .nth(t)
                    .and_then(|(p, _, _)| p)
                    .map(|p| p.collect())
                    .unwrap_or_default()
            }
            // A target that moves normals only: no position delta.
            None => vec![[0.0; 3]; prim_vertices(prim)],
        };
        deform.morph_targets.push(deltas);
    }
    let defaults = mesh.weights().unwrap_or(&[]);
    deform.morph_weights = (0..deform.morph_targets.len())
        .map(|i| defaults.get(i).copied().unwrap_or(0.0))
        .collect();
    Ok(deform)
}

/// The vertex count of a primitive (its `POSITION` accessor's count; 0 without one).
fn prim_vertices(prim: &gltf::Primitive) -> usize {
    prim.get(&gltf::Semantic::Positions)
        .map_or(0, |a| a.count())
}

/// The count of morph targets of the mesh on `node` (glTF requires every primitive of a mesh
/// to have as many), or `None` when the node has no mesh.
pub fn morph_target_count(node: &gltf::Node) -> Option<usize> {
    node.mesh()
        .map(|m| m.primitives().next().map_or(0, |p| p.morph_targets().len()))
}
