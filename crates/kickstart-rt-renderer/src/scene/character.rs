//! A generated skinned character and the built-in `dancers` scene made of it.
//!
//! The character stands 1.75 m tall on y = 0 facing +z: 13 capsules (pelvis, chest, head, upper
//! arms, forearms, thighs, shins, feet) of 6,084 triangles in all, skinned to 11 joints (hips,
//! spine, head, two upper arms, two forearms, two thighs, two shins). Every vertex follows its
//! part's joint; within a blend length of the joint a part hangs from, it shares its weight
//! with the parent part's joint (half and half at the joint itself), so elbows and knees bend
//! smoothly. One morph target, `bulge`, swells the front of the chest by up to 6 cm.
//!
//! The animation loops every [`PERIOD`] s: arms swinging forward and back and out, forearms and
//! knees bending, a step in place, the hips bobbing (a `CUBICSPLINE` channel), the spine
//! twisting, the head turning in steps (`STEP`), and the chest breathing (a `LINEAR` morph
//! weight channel). Each dancer plays it at its own phase.

use glam::{Affine3A, Quat, Vec3};

use super::animation::{Animation, Channel, Interpolation, Property};
use super::rig::{Deform, Node, Rig, Skin};
use super::{Camera, Instance, Light, Mesh, Scene};

/// Length of the dance loop, seconds.
pub const PERIOD: f32 = 1.2;
/// Keyframes of each channel over a loop (the last repeats the first).
const KEYS: usize = 13;
/// Dancers in the scene.
pub const DANCERS: usize = 4;
/// Segments around each capsule.
const SEGMENTS: usize = 18;
/// Rings along a capsule's straight part.
const BODY_RINGS: usize = 6;
/// Rings over each of its end caps (the pole aside).
const CAP_RINGS: usize = 4;

/// The joints: name, parent joint, rest position in the character's space.
const JOINTS: [(&str, Option<usize>, [f32; 3]); 11] = [
    ("hips", None, [0.0, 0.95, 0.0]),
    ("spine", Some(0), [0.0, 1.18, 0.0]),
    ("head", Some(1), [0.0, 1.5, 0.0]),
    ("upper_arm_l", Some(1), [0.21, 1.44, 0.0]),
    ("forearm_l", Some(3), [0.23, 1.16, 0.0]),
    ("upper_arm_r", Some(1), [-0.21, 1.44, 0.0]),
    ("forearm_r", Some(5), [-0.23, 1.16, 0.0]),
    ("thigh_l", Some(0), [0.1, 0.9, 0.0]),
    ("shin_l", Some(7), [0.1, 0.5, 0.0]),
    ("thigh_r", Some(0), [-0.1, 0.9, 0.0]),
    ("shin_r", Some(9), [-0.1, 0.5, 0.0]),
];

/// One capsule of the body: from `a` to `b`, its radius, its joint, and the length over which
/// it blends into its parent's joint near `a` (0: none).
struct Part {
    a: [f32; 3],
    b: [f32; 3],
    radius: f32,
    joint: u16,
    blend: f32,
}

/// The body's capsules (the left side's, mirrored for the right).
fn parts() -> Vec<Part> {
    let p = |a, b, radius, joint, blend| Part {
        a,
        b,
        radius,
        joint,
        blend,
    };
    let mut parts = vec![
        p([0.0, 0.82, 0.0], [0.0, 1.08, 0.0], 0.15, 0, 0.0),
        p([0.0, 1.1, 0.0], [0.0, 1.42, 0.0], 0.17, 1, 0.1),
        p([0.0, 1.58, 0.01], [0.0, 1.7, 0.01], 0.11, 2, 0.08),
    ];
    // (upper arm, forearm, thigh, shin, foot) of the left side; the right mirrors x, joint + 2.
    let left = [
        p([0.22, 1.42, 0.0], [0.23, 1.16, 0.0], 0.055, 3, 0.06),
        p([0.23, 1.16, 0.0], [0.25, 0.9, 0.0], 0.048, 4, 0.06),
        p([0.1, 0.9, 0.0], [0.1, 0.5, 0.0], 0.075, 7, 0.08),
        p([0.1, 0.5, 0.0], [0.1, 0.11, 0.0], 0.062, 8, 0.08),
        p([0.1, 0.05, -0.03], [0.1, 0.05, 0.13], 0.05, 8, 0.0),
    ];
    for part in left {
        let mirror = |v: [f32; 3]| [-v[0], v[1], v[2]];
        parts.push(Part {
            a: mirror(part.a),
            b: mirror(part.b),
            joint: part.joint + 2,
            ..part
        });
        parts.push(part);
    }
    parts
}

/// Positions and triangle indices of a capsule of `part` (outward-facing, counter-clockwise):
/// a pole, `CAP_RINGS` rings over the first cap, `BODY_RINGS` along the straight part,
/// `CAP_RINGS − 1` over the second cap, a pole.
fn capsule(part: &Part) -> (Vec<Vec3>, Vec<u32>) {
    let (a, b) = (Vec3::from(part.a), Vec3::from(part.b));
    let axis = (b - a).normalize_or(Vec3::Y);
    let u = axis.any_orthonormal_vector();
    let v = axis.cross(u);
    let r = part.radius;
    let quarter = std::f32::consts::FRAC_PI_2;
    // (centre, radius) of every ring, from the first cap to the second.
    let mut rings: Vec<(Vec3, f32)> = Vec::new();
    for k in 1..=CAP_RINGS {
        let phi = -quarter + quarter * k as f32 / CAP_RINGS as f32;
        rings.push((a + axis * r * phi.sin(), r * phi.cos()));
    }
    for k in 1..=BODY_RINGS {
        rings.push((a.lerp(b, k as f32 / BODY_RINGS as f32), r));
    }
    for k in 1..CAP_RINGS {
        let phi = quarter * k as f32 / CAP_RINGS as f32;
        rings.push((b + axis * r * phi.sin(), r * phi.cos()));
    }
    let mut positions = vec![a - axis * r];
    for (centre, radius) in &rings {
        for s in 0..SEGMENTS {
            let theta = std::f32::consts::TAU * s as f32 / SEGMENTS as f32;
            positions.push(*centre + (u * theta.cos() + v * theta.sin()) * *radius);
        }
    }
    positions.push(b + axis * r);
    let ring = |k: usize, s: usize| (1 + k * SEGMENTS + s % SEGMENTS) as u32;
    let top = (positions.len() - 1) as u32;
    let mut indices = Vec::new();
    for s in 0..SEGMENTS {
        indices.extend([0, ring(0, s + 1), ring(0, s)]);
        let last = rings.len() - 1;
        indices.extend([top, ring(last, s), ring(last, s + 1)]);
    }
    for k in 0..rings.len() - 1 {
        for s in 0..SEGMENTS {
            let (p, q, r2, t) = (
                ring(k, s),
                ring(k, s + 1),
                ring(k + 1, s + 1),
                ring(k + 1, s),
            );
            indices.extend([p, q, r2, p, r2, t]);
        }
    }
    (positions, indices)
}

/// The joint influences of a vertex at `p` on `part`: its joint, and its parent's within the
/// blend length of `a` (half at `a`, none at `a + blend` along the axis, all of it well before).
fn influences(part: &Part, p: Vec3) -> ([u16; 4], [f32; 4]) {
    let parent = JOINTS[usize::from(part.joint)].1;
    let (a, b) = (Vec3::from(part.a), Vec3::from(part.b));
    match parent {
        Some(parent) if part.blend > 0.0 => {
            let along = (p - a).dot((b - a).normalize_or(Vec3::Y));
            let w = (0.5 - 0.5 * along / part.blend).clamp(0.0, 1.0);
            ([part.joint, parent as u16, 0, 0], [1.0 - w, w, 0.0, 0.0])
        }
        _ => ([part.joint, 0, 0, 0], [1.0, 0.0, 0.0, 0.0]),
    }
}

/// The chest's morph target at `p` on `part`: outward from the axis, up to 6 cm at the front of
/// the chest around y = 1.3, fading with height and to nothing at the sides and back.
fn bulge(part: &Part, p: Vec3) -> Vec3 {
    if part.joint != 1 {
        return Vec3::ZERO;
    }
    let out = Vec3::new(p.x, 0.0, p.z).normalize_or_zero();
    let height = (-((p.y - 1.3) / 0.08).powi(2) * 0.5).exp();
    out * 0.06 * height * out.z.max(0.0)
}

/// The character's mesh in its own space: every part's capsule, influences and bulge.
pub fn character_mesh(name: &str, color: Vec3) -> Result<Mesh, String> {
    let (mut positions, mut indices) = (Vec::new(), Vec::new());
    let mut deform = Deform {
        morph_targets: vec![Vec::new()],
        morph_weights: vec![0.0],
        ..Default::default()
    };
    for part in parts() {
        let (p, i) = capsule(&part);
        let base = positions.len() as u32;
        indices.extend(i.iter().map(|i| i + base));
        for p in p {
            let (j, w) = influences(&part, p);
            deform.joints.push(j);
            deform.weights.push(w);
            deform.morph_targets[0].push(bulge(&part, p).to_array());
            positions.push(p.to_array());
        }
    }
    let mut mesh = Mesh::new(name, positions, indices, color)?;
    mesh.deform = deform;
    mesh.material.roughness = 0.5;
    Ok(mesh)
}

/// The skeleton's nodes under node `root` (the joints' rest transforms relative to their
/// parents), appended to `nodes`; returns the joints' node indices.
fn skeleton(nodes: &mut Vec<Node>, root: usize, prefix: &str) -> Vec<usize> {
    let first = nodes.len();
    for (name, parent, at) in JOINTS {
        let parent_at = parent.map_or(Vec3::ZERO, |p| Vec3::from(JOINTS[p].2));
        nodes.push(Node::from_trs(
            format!("{prefix} {name}"),
            Some(parent.map_or(root, |p| first + p)),
            Vec3::from(at) - parent_at,
            Quat::IDENTITY,
            Vec3::ONE,
        ));
    }
    (first..nodes.len()).collect()
}

/// One of the dance's curves: a value of `width` floats at phase `x` (0..1 over a loop).
type Curve = fn(f32) -> Vec<f32>;

/// `sin(2π x)`.
fn wave(x: f32) -> f32 {
    (std::f32::consts::TAU * x).sin()
}

/// The rotation of each animated joint (by index into [`JOINTS`]) at phase `x`.
fn joint_rotation(joint: usize, x: f32) -> Quat {
    let side = if JOINTS[joint].0.ends_with("_l") {
        1.0
    } else {
        -1.0
    };
    match JOINTS[joint].0 {
        "spine" => Quat::from_rotation_y(0.15 * wave(x)),
        "upper_arm_l" | "upper_arm_r" => {
            // Swing forward and back (opposite arms), and out to the side.
            Quat::from_rotation_z(side * (0.3 + 0.25 * wave(2.0 * x)))
                * Quat::from_rotation_x(-side * 0.9 * wave(x))
        }
        "forearm_l" | "forearm_r" => Quat::from_rotation_x(-(0.5 + 0.3 * wave(x + 0.25))),
        // Each leg steps with the opposite arm.
        "thigh_l" | "thigh_r" => Quat::from_rotation_x(-side * 0.45 * wave(x + 0.5)),
        "shin_l" | "shin_r" => Quat::from_rotation_x(0.7 * (side * wave(x + 0.5)).max(0.0)),
        _ => Quat::IDENTITY,
    }
}

/// The channels of one dancer at `phase` (0..1): rotations of the joints (`LINEAR`), the hips'
/// bob (`CUBICSPLINE`, with the curve's exact tangents), the head's turn (`STEP`), and the
/// chest's morph weight on the mesh node `mesh_node` (`LINEAR`).
fn dance(joints: &[usize], mesh_node: usize, phase: f32) -> Result<Vec<Channel>, String> {
    let times: Vec<f32> = (0..KEYS)
        .map(|k| PERIOD * k as f32 / (KEYS - 1) as f32)
        .collect();
    let x = |t: f32| t / PERIOD + phase;
    let sampled = |node, property, interpolation, curve: &dyn Fn(f32) -> Vec<f32>| {
        let values = times.iter().flat_map(|&t| curve(x(t))).collect();
        Channel::new(node, property, interpolation, times.clone(), values, 1)
    };
    let mut channels = Vec::new();
    for (k, &node) in joints.iter().enumerate() {
        if matches!(JOINTS[k].0, "hips" | "head") {
            continue;
        }
        let curve = move |x: f32| joint_rotation(k, x).to_array().to_vec();
        channels.push(sampled(
            node,
            Property::Rotation,
            Interpolation::Linear,
            &curve,
        )?);
    }
    let head: Curve = |x| {
        let turn = if wave(x) >= 0.0 { 0.3 } else { -0.3 };
        Quat::from_rotation_y(turn).to_array().to_vec()
    };
    channels.push(sampled(
        joints[2],
        Property::Rotation,
        Interpolation::Step,
        &head,
    )?);
    // The bob: y = 0.95 + 0.03 cos(4π x), tangents d/dt = −0.03 · 4π / PERIOD · sin(4π x).
    let bob: Curve = |x| {
        let four_pi = 2.0 * std::f32::consts::TAU;
        let y = 0.95 + 0.03 * (four_pi * x).cos();
        let dy = -0.03 * four_pi / PERIOD * (four_pi * x).sin();
        vec![0.0, dy, 0.0, 0.0, y, 0.0, 0.0, dy, 0.0]
    };
    channels.push(sampled(
        joints[0],
        Property::Translation,
        Interpolation::CubicSpline,
        &bob,
    )?);
    let breath: Curve = |x| vec![0.5 + 0.5 * wave(x)];
    channels.push(sampled(
        mesh_node,
        Property::Weights,
        Interpolation::Linear,
        &breath,
    )?);
    Ok(channels)
}

/// Adds one dancer at `at`, turned by `yaw`, coloured `color`, dancing at `phase`: its root
/// node, skeleton, skin, mesh, instance and rig; returns its channels.
fn add_dancer(
    scene: &mut Scene,
    k: usize,
    (at, yaw, color, phase): (Vec3, f32, Vec3, f32),
) -> Result<Vec<Channel>, String> {
    let root = scene.nodes.len();
    let name = format!("dancer {k}");
    let rotation = Quat::from_rotation_y(yaw);
    scene
        .nodes
        .push(Node::from_trs(&name, None, at, rotation, Vec3::ONE));
    let joints = skeleton(&mut scene.nodes, root, &name);
    // The mesh hangs on the root: a joint's inverse bind matrix undoes its rest position in the
    // character's (the root's) space.
    scene.skins.push(Skin {
        name: name.clone(),
        joints: joints.clone(),
        inverse_bind: JOINTS
            .iter()
            .map(|j| glam::Mat4::from_translation(-Vec3::from(j.2)))
            .collect(),
    });
    scene.meshes.push(character_mesh(&name, color)?);
    scene.instances.push(Instance {
        mesh: scene.meshes.len() - 1,
        transform: Affine3A::from_rotation_translation(rotation, at),
    });
    scene.rigs.push(Rig {
        instance: scene.instances.len() - 1,
        node: root,
        skin: Some(scene.skins.len() - 1),
    });
    dance(&joints, root, phase)
}

/// The built-in `dancers` as generated: [`DANCERS`] characters in a row on a 12 m floor, each at
/// its own phase of the dance, under a sun from the front left; the camera in front. `ksrt`
/// loads it through a `.glb` it writes (the demo's scene list), so its glTF loader poses what
/// this builds.
pub fn dancers() -> Result<Scene, String> {
    let mut scene = Scene {
        name: "dancers".into(),
        ..Default::default()
    };
    let h = 6.0;
    let floor = Mesh::new(
        "floor",
        vec![[-h, 0.0, -h], [h, 0.0, -h], [h, 0.0, h], [-h, 0.0, h]],
        vec![0, 2, 1, 0, 3, 2],
        Vec3::splat(0.75),
    )?;
    scene.meshes.push(floor);
    scene.instances.push(Instance {
        mesh: 0,
        transform: Affine3A::IDENTITY,
    });
    let colors = [
        Vec3::new(0.8, 0.25, 0.2),
        Vec3::new(0.25, 0.6, 0.3),
        Vec3::new(0.25, 0.35, 0.8),
        Vec3::new(0.8, 0.7, 0.25),
    ];
    let mut channels = Vec::new();
    for k in 0..DANCERS {
        let x = (k as f32 - (DANCERS - 1) as f32 * 0.5) * 1.1;
        let placement = (
            Vec3::new(x, 0.0, -0.15 * (k % 2) as f32),
            -0.1 * (k as f32 - 1.5),
            colors[k % colors.len()],
            k as f32 / DANCERS as f32,
        );
        channels.extend(add_dancer(&mut scene, k, placement)?);
    }
    scene.animations.push(Animation {
        name: "dance".into(),
        channels,
    });
    scene.lights.push(Light::Sun {
        direction: Vec3::new(0.55, -1.0, -0.35).normalize(),
        irradiance: Vec3::splat(3.0),
        angular_diameter: 0.0093,
    });
    scene.camera = Some(Camera {
        eye: Vec3::new(0.0, 1.7, 4.6),
        at: Vec3::new(0.0, 0.85, 0.0),
        up: Vec3::Y,
        fov_y_deg: 50.0,
    });
    scene.check_rigs()?;
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_character_is_closed_capsules_facing_out_with_unit_weights() {
        let mesh = character_mesh("c", Vec3::ONE).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(mesh.triangle_count(), 6084);
        let n = mesh.positions.len();
        assert_eq!(
            (mesh.deform.joints.len(), mesh.deform.weights.len()),
            (n, n)
        );
        assert_eq!(mesh.deform.check(n, Some(JOINTS.len())), Ok(()));
        for w in &mesh.deform.weights {
            assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
        // Every triangle faces away from its part's axis: the capsules' winding is outward.
        let mut start = 0;
        for part in parts() {
            let (p, i) = capsule(&part);
            let (a, b) = (Vec3::from(part.a), Vec3::from(part.b));
            for t in i.chunks_exact(3) {
                let [x, y, z] = [t[0], t[1], t[2]].map(|k| p[k as usize]);
                let c = (x + y + z) / 3.0;
                let s = ((c - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
                let out = c - a.lerp(b, s);
                assert!(
                    (y - x).cross(z - x).dot(out) > 0.0,
                    "inward triangle at {c}"
                );
            }
            start += p.len();
        }
        assert_eq!(start, n);
        // The bulge moves the chest's front only, by up to 6 cm.
        let most = mesh.deform.morph_targets[0]
            .iter()
            .map(|d| Vec3::from(*d).length())
            .fold(0.0, f32::max);
        assert!(most > 0.05 && most <= 0.06, "{most}");
    }

    #[test]
    fn the_dance_loops_and_swings_the_arms() {
        let scene = dancers().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(scene.rigs.len(), DANCERS);
        assert_eq!(scene.animation_duration(), PERIOD);
        let posed = |t: f32| scene.posed(t).meshes[1].positions.clone();
        let (a, b) = (posed(0.0), posed(PERIOD));
        assert!(a
            .iter()
            .zip(&b)
            .all(|(p, q)| (Vec3::from(*p) - Vec3::from(*q)).length() < 1e-4));
        // A quarter loop later the hands have moved by tens of centimetres.
        let c = posed(PERIOD * 0.25);
        let most = a
            .iter()
            .zip(&c)
            .map(|(p, q)| (Vec3::from(*p) - Vec3::from(*q)).length())
            .fold(0.0, f32::max);
        assert!(most > 0.3, "{most}");
        // The feet stay near the floor.
        let lowest = c.iter().map(|p| p[1]).fold(f32::INFINITY, f32::min);
        assert!((-0.1..0.1).contains(&lowest), "{lowest}");
    }
}
