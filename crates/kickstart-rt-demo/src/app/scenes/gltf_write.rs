//! Writes a generated scene as a glTF 2.0 `.gltf` (JSON with one embedded base64 buffer), so
//! the built-in `dancers` go through the very loader a file does: the node hierarchy (every
//! scene node, in order, as translation/rotation/scale, or a matrix where those do not give it),
//! each rig's mesh on its node with its skin, joints (`u16`), weights (`f32`), morph targets and
//! default weights, every other instance on a root node of its own, each mesh's colour and
//! roughness as a material, and the animations (every channel its own sampler). Cameras and
//! lights are not written: the caller keeps its own.

use glam::Mat4;
use serde_json::{json, Value};

use kickstart_rt_renderer::scene::animation::{Interpolation, Property};
use kickstart_rt_renderer::scene::{Mesh, Scene};

/// glTF component types.
const FLOAT: u32 = 5126;
const UNSIGNED_SHORT: u32 = 5123;
const UNSIGNED_INT: u32 = 5125;

/// The binary buffer and the accessors into it, one buffer view each.
#[derive(Default)]
struct Blob {
    bytes: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Blob {
    /// Appends `data` (4-byte aligned) as an accessor of `count` elements of `kind` and
    /// `component`, with `min`/`max` when given; returns its index.
    fn push(
        &mut self,
        data: &[u8],
        component: u32,
        kind: &str,
        count: usize,
        bounds: Option<(Vec<f32>, Vec<f32>)>,
    ) -> usize {
        let offset = self.bytes.len();
        self.bytes.extend_from_slice(data);
        self.bytes.resize(self.bytes.len().next_multiple_of(4), 0);
        self.views
            .push(json!({"buffer": 0, "byteOffset": offset, "byteLength": data.len()}));
        let mut a = json!({
            "bufferView": self.views.len() - 1,
            "componentType": component,
            "type": kind,
            "count": count,
        });
        if let Some((min, max)) = bounds {
            a["min"] = json!(min);
            a["max"] = json!(max);
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    /// `VEC3` floats with their bounds (required of positions).
    fn vec3(&mut self, v: &[[f32; 3]]) -> usize {
        let mut min = [f32::INFINITY; 3];
        let mut max = [f32::NEG_INFINITY; 3];
        for p in v {
            for i in 0..3 {
                min[i] = min[i].min(p[i]);
                max[i] = max[i].max(p[i]);
            }
        }
        let bounds = (!v.is_empty()).then(|| (min.to_vec(), max.to_vec()));
        self.push(bytemuck::cast_slice(v), FLOAT, "VEC3", v.len(), bounds)
    }
}

/// The `.gltf` JSON of `scene`, its buffer embedded.
pub fn to_gltf(scene: &Scene) -> Result<Vec<u8>, String> {
    let mut blob = Blob::default();
    let mut nodes: Vec<Value> = scene
        .nodes
        .iter()
        .map(|n| {
            let mut v = json!({"name": n.name});
            let trs = Mat4::from_scale_rotation_translation(n.scale, n.rotation, n.translation);
            if trs.abs_diff_eq(n.matrix, 1e-6) {
                v["translation"] = json!(n.translation.to_array());
                v["rotation"] = json!(n.rotation.to_array());
                v["scale"] = json!(n.scale.to_array());
            } else {
                v["matrix"] = json!(n.matrix.to_cols_array());
            }
            if !n.weights.is_empty() {
                v["weights"] = json!(n.weights);
            }
            v
        })
        .collect();
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); nodes.len()];
    let mut roots = Vec::new();
    for (k, n) in scene.nodes.iter().enumerate() {
        match n.parent {
            Some(p) => children
                .get_mut(p)
                .ok_or(format!("node {k}: parent {p} does not exist"))?
                .push(k),
            None => roots.push(k),
        }
    }
    for (v, c) in nodes.iter_mut().zip(&children) {
        if !c.is_empty() {
            v["children"] = json!(c);
        }
    }
    let mut meshes = Vec::new();
    let mut materials = Vec::new();
    let mut rigged = vec![false; scene.instances.len()];
    for rig in &scene.rigs {
        let inst = scene
            .instances
            .get(rig.instance)
            .ok_or("a rig's instance is missing")?;
        let mesh = scene
            .meshes
            .get(inst.mesh)
            .ok_or("a rig's mesh is missing")?;
        let node = nodes.get_mut(rig.node).ok_or("a rig's node is missing")?;
        node["mesh"] = json!(meshes.len());
        if let Some(s) = rig.skin {
            node["skin"] = json!(s);
        }
        rigged[rig.instance] = true;
        meshes.push(mesh_json(&mut blob, &mut materials, mesh));
    }
    for (k, inst) in scene
        .instances
        .iter()
        .enumerate()
        .filter(|(k, _)| !rigged[*k])
    {
        let mesh = scene
            .meshes
            .get(inst.mesh)
            .ok_or("an instance's mesh is missing")?;
        roots.push(nodes.len());
        nodes.push(json!({
            "name": format!("instance {k}"),
            "matrix": Mat4::from(inst.transform).to_cols_array(),
            "mesh": meshes.len(),
        }));
        meshes.push(mesh_json(&mut blob, &mut materials, mesh));
    }
    let skins: Vec<Value> = scene
        .skins
        .iter()
        .map(|s| {
            let m: Vec<f32> = s
                .inverse_bind
                .iter()
                .flat_map(|m| m.to_cols_array())
                .collect();
            let ibm = blob.push(
                bytemuck::cast_slice(&m),
                FLOAT,
                "MAT4",
                s.joints.len(),
                None,
            );
            json!({"name": s.name, "joints": s.joints, "inverseBindMatrices": ibm})
        })
        .collect();
    let animations: Vec<Value> = scene
        .animations
        .iter()
        .map(|a| animation_json(&mut blob, a))
        .collect();
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64(&blob.bytes)
    );
    let root = json!({
        "asset": {"version": "2.0", "generator": "ksrt (kickstart-rt demo)"},
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "skins": skins,
        "animations": animations,
        "buffers": [{"byteLength": blob.bytes.len(), "uri": uri}],
        "bufferViews": blob.views,
        "accessors": blob.accessors,
    });
    serde_json::to_vec(&root).map_err(|e| e.to_string())
}

/// One mesh of one primitive: positions, normals, indices, its deformation, its material.
fn mesh_json(blob: &mut Blob, materials: &mut Vec<Value>, m: &Mesh) -> Value {
    let mut attributes = json!({
        "POSITION": blob.vec3(&m.positions),
        "NORMAL": blob.vec3(&m.normals),
    });
    let d = &m.deform;
    if d.is_skinned() {
        // Each with its own count: what the loader's checks are tested on.
        let (j, w) = (d.joints.len(), d.weights.len());
        let joints = bytemuck::cast_slice(&d.joints);
        attributes["JOINTS_0"] = json!(blob.push(joints, UNSIGNED_SHORT, "VEC4", j, None));
        let weights = bytemuck::cast_slice(&d.weights);
        attributes["WEIGHTS_0"] = json!(blob.push(weights, FLOAT, "VEC4", w, None));
    }
    let indices = blob.push(
        bytemuck::cast_slice(&m.indices),
        UNSIGNED_INT,
        "SCALAR",
        m.indices.len(),
        None,
    );
    let targets: Vec<Value> = d
        .morph_targets
        .iter()
        .map(|t| json!({"POSITION": blob.vec3(t)}))
        .collect();
    let mut primitive = json!({
        "attributes": attributes,
        "indices": indices,
        "material": materials.len(),
    });
    let c = m.color;
    materials.push(json!({
        "name": m.name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [c.x, c.y, c.z, 1.0],
            "metallicFactor": m.material.metallic,
            "roughnessFactor": m.material.roughness,
        },
    }));
    let mut mesh = json!({"name": m.name});
    if !targets.is_empty() {
        primitive["targets"] = json!(targets);
        mesh["weights"] = json!(d.morph_weights);
    }
    mesh["primitives"] = json!([primitive]);
    mesh
}

/// One animation: a sampler a channel.
fn animation_json(
    blob: &mut Blob,
    a: &kickstart_rt_renderer::scene::animation::Animation,
) -> Value {
    let mut samplers = Vec::new();
    let mut channels = Vec::new();
    for c in &a.channels {
        let bounds = Some((vec![c.times[0]], vec![c.end()]));
        let input = blob.push(
            bytemuck::cast_slice(&c.times),
            FLOAT,
            "SCALAR",
            c.times.len(),
            bounds,
        );
        let (kind, width, path) = match c.property {
            Property::Translation => ("VEC3", 3, "translation"),
            Property::Rotation => ("VEC4", 4, "rotation"),
            Property::Scale => ("VEC3", 3, "scale"),
            Property::Weights => ("SCALAR", 1, "weights"),
        };
        let count = c.values.len() / width;
        let output = blob.push(bytemuck::cast_slice(&c.values), FLOAT, kind, count, None);
        let interpolation = match c.interpolation {
            Interpolation::Linear => "LINEAR",
            Interpolation::Step => "STEP",
            Interpolation::CubicSpline => "CUBICSPLINE",
        };
        channels.push(json!({
            "sampler": samplers.len(),
            "target": {"node": c.node, "path": path},
        }));
        samplers.push(json!({"input": input, "output": output, "interpolation": interpolation}));
    }
    json!({"name": a.name, "samplers": samplers, "channels": channels})
}

/// Standard base64 with padding (RFC 4648).
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trips_through_the_loaders_decoder() {
        for s in [&b""[..], b"h", b"he", b"hel", b"hello world"] {
            assert_eq!(
                super::super::gltf::decode_base64(&base64(s)).as_deref(),
                Some(s)
            );
        }
    }
}
