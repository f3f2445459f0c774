//! Skins, morph targets and animations through the glTF loader: the built-in dancers written
//! by [`gltf_write`](super::gltf_write) and read back equal the generator's, and malformed
//! skins, weights, counts and samplers are refused with an error that names the file and what
//! is wrong.

use std::path::Path;

use glam::Vec3;
use kickstart_rt_renderer::scene::animation::{Channel, Interpolation, Property};
use kickstart_rt_renderer::scene::{character, Scene};
use serde_json::{json, Value};

use super::{gltf, gltf_write, SceneError};

fn generated() -> Scene {
    character::dancers().unwrap_or_else(|e| panic!("{e}"))
}

fn load(bytes: &[u8]) -> Result<Scene, SceneError> {
    gltf::load_from_bytes(Path::new("test.gltf"), bytes)
}

fn write(scene: &Scene) -> Vec<u8> {
    gltf_write::to_gltf(scene).unwrap_or_else(|e| panic!("{e}"))
}

/// The error of loading `bytes`, which must fail.
fn refused(bytes: &[u8]) -> String {
    match load(bytes) {
        Ok(_) => panic!("a malformed file was accepted"),
        Err(e) => {
            assert_eq!(e.path, Path::new("test.gltf"));
            e.to_string()
        }
    }
}

#[test]
fn the_dancers_round_trip_through_the_gltf_loader() {
    let g = generated();
    let l = super::dancers().unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(l.rigs.len(), character::DANCERS);
    assert_eq!(l.rigs.len(), g.rigs.len());
    for (a, b) in l.rigs.iter().zip(&g.rigs) {
        assert_eq!((a.node, a.skin), (b.node, b.skin));
        let ma = &l.meshes[l.instances[a.instance].mesh];
        let mb = &g.meshes[g.instances[b.instance].mesh];
        assert_eq!(ma.positions, mb.positions);
        assert_eq!(ma.indices, mb.indices);
        // Joints, weights, morph targets and default weights, bit for bit.
        assert_eq!(ma.deform, mb.deform);
        assert!(ma.deform.is_skinned() && ma.deform.morph_targets.len() == 1);
        let placed = |s: &Scene, r: usize| s.instances[r].transform;
        assert!(placed(&l, a.instance).abs_diff_eq(placed(&g, b.instance), 1e-6));
    }
    assert_eq!(l.skins, g.skins);
    assert_eq!(l.animations, g.animations);
    let kinds: Vec<Interpolation> = l.animations[0]
        .channels
        .iter()
        .map(|c| c.interpolation)
        .collect();
    for k in [
        Interpolation::Linear,
        Interpolation::Step,
        Interpolation::CubicSpline,
    ] {
        assert!(kinds.contains(&k), "{k:?}");
    }
    // The generator's nodes first (the floor's node follows), same hierarchy and rest pose.
    for (a, b) in l.nodes.iter().zip(&g.nodes) {
        assert_eq!((&a.name, a.parent), (&b.name, b.parent));
        assert!(a.matrix.abs_diff_eq(b.matrix, 1e-6), "{}", a.name);
    }
    // The floor came through the file too; the sun and camera are the generator's.
    assert_eq!(l.instances.len(), g.instances.len());
    assert_eq!(l.triangle_count(), g.triangle_count());
    assert_eq!(l.lights.len(), 1);
    // Posed alike at any time.
    for t in [0.0, 0.37, 1.0] {
        for (a, b) in l.posed_meshes(t).iter().zip(g.posed_meshes(t)) {
            let most = a
                .positions
                .iter()
                .zip(&b.positions)
                .map(|(p, q)| (Vec3::from(*p) - Vec3::from(*q)).length())
                .fold(0.0, f32::max);
            assert!(most < 1e-5, "t = {t}: {most}");
        }
    }
}

#[test]
fn two_times_pose_differently_and_a_whole_loop_poses_alike() {
    let l = super::dancers().unwrap_or_else(|e| panic!("{e}"));
    let at = |t: f32| l.posed_meshes(t)[0].positions.clone();
    let moved = |a: &[[f32; 3]], b: &[[f32; 3]]| {
        a.iter()
            .zip(b)
            .map(|(p, q)| (Vec3::from(*p) - Vec3::from(*q)).length())
            .fold(0.0, f32::max)
    };
    assert!(moved(&at(0.0), &at(0.3)) > 0.2);
    assert!(moved(&at(0.0), &at(character::PERIOD)) < 1e-4);
}

/// The dancers' file as JSON, to damage.
fn dancers_json() -> Value {
    serde_json::from_slice(&write(&generated())).unwrap_or_else(|e| panic!("{e}"))
}

fn bytes(v: &Value) -> Vec<u8> {
    serde_json::to_vec(v).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn a_skin_whose_joints_do_not_match_is_refused_by_name() {
    // Fewer joints than inverse bind matrices.
    let mut v = dancers_json();
    v["skins"][1]["joints"] = json!([13, 14, 15]);
    let e = refused(&bytes(&v));
    assert!(
        e.contains("skin 1 (dancer 1)") && e.contains("11 inverse bind matrices for 3 joints"),
        "{e}"
    );
    // Without inverse bind matrices, the vertices name joints the skin lacks.
    v["skins"][1]
        .as_object_mut()
        .map(|s| s.remove("inverseBindMatrices"));
    let e = refused(&bytes(&v));
    assert!(e.contains("test.gltf") && e.contains("dancer 1"), "{e}");
    assert!(
        e.contains("names joint") && e.contains("the skin has 3 joints"),
        "{e}"
    );
}

#[test]
fn bad_weights_and_counts_are_refused_by_mesh() {
    let mut g = generated();
    let mesh = g.instances[g.rigs[2].instance].mesh;
    g.meshes[mesh].deform.weights[5][1] = f32::NAN;
    let e = refused(&write(&g));
    assert!(
        e.contains("dancer 2") && e.contains("vertex 5 has a non-finite joint weight"),
        "{e}"
    );
    let mut g = generated();
    let n = g.meshes[mesh].positions.len();
    g.meshes[mesh].deform.weights.pop();
    let e = refused(&write(&g));
    assert!(
        e.contains(&format!("{n} joint sets but {} weight sets", n - 1)),
        "{e}"
    );
    let mut g = generated();
    g.meshes[mesh].deform.morph_targets[0].truncate(10);
    let e = refused(&write(&g));
    assert!(
        e.contains(&format!("morph target 0 has 10 deltas for {n} vertices")),
        "{e}"
    );
}

#[test]
fn a_sampler_whose_times_do_not_increase_is_refused_by_animation() {
    let mut g = generated();
    let c = &g.animations[0].channels[3];
    // Built field by field: `Channel::new` would refuse it.
    let bad = Channel {
        times: vec![0.0, 0.5, 0.25],
        values: c.values[..12].to_vec(),
        ..c.clone()
    };
    assert_eq!(bad.property, Property::Rotation);
    g.animations[0].channels[3] = bad;
    let e = refused(&write(&g));
    assert!(
        e.contains("animation 0 (dance): channel 3") && e.contains("must increase: 0.5 then 0.25"),
        "{e}"
    );
    // A value that is not finite.
    let mut g = generated();
    g.animations[0].channels[0].values[2] = f32::INFINITY;
    let e = refused(&write(&g));
    assert!(e.contains("channel 0") && e.contains("not finite"), "{e}");
}

#[test]
fn unorm_weights_and_byte_joints_are_read() {
    // Re-encode dancer 0's weights as normalised u16 and its joints as u8, in new buffers.
    let mut v = dancers_json();
    let g = generated();
    let d = &g.meshes[g.instances[g.rigs[0].instance].mesh].deform;
    let joints: Vec<u8> = d.joints.iter().flatten().map(|&j| j as u8).collect();
    let weights: Vec<u16> = d
        .weights
        .iter()
        .flatten()
        .map(|&w| (w * 65535.0).round() as u16)
        .collect();
    let n = d.joints.len();
    let push = |v: &mut Value, key: &str, item: Value| -> usize {
        let a = v[key]
            .as_array_mut()
            .unwrap_or_else(|| panic!("no {key} array"));
        a.push(item);
        a.len() - 1
    };
    let mut add = |data: &[u8], component: u32, normalized: bool| {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            crate::app::testing::base64(data)
        );
        let b = push(
            &mut v,
            "buffers",
            json!({"byteLength": data.len(), "uri": uri}),
        );
        let view = push(
            &mut v,
            "bufferViews",
            json!({"buffer": b, "byteLength": data.len()}),
        );
        let accessor = json!({"bufferView": view, "componentType": component,
            "normalized": normalized, "type": "VEC4", "count": n});
        push(&mut v, "accessors", accessor)
    };
    let j = add(&joints, 5121, false);
    let w = add(bytemuck::cast_slice(&weights), 5123, true);
    let attributes = &mut v["meshes"][0]["primitives"][0]["attributes"];
    attributes["JOINTS_0"] = json!(j);
    attributes["WEIGHTS_0"] = json!(w);
    let l = load(&bytes(&v)).unwrap_or_else(|e| panic!("{e}"));
    let ld = &l.meshes[l.instances[l.rigs[0].instance].mesh].deform;
    assert_eq!(ld.joints, d.joints);
    for (a, b) in ld.weights.iter().flatten().zip(d.weights.iter().flatten()) {
        assert!((a - b).abs() <= 0.5 / 65535.0 + 1e-7, "{a} {b}");
    }
    // The same weights as u16 not marked normalised: refused.
    v["accessors"][w]["normalized"] = Value::Bool(false);
    let e = refused(&bytes(&v));
    assert!(e.contains("WEIGHTS_0") && e.contains("(normalized)"), "{e}");
}
