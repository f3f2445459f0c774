//! Fuzzed scene files: glTF and OBJ built from random parameters (huge counts, offsets past their
//! buffers, indices out of range, NaN and infinite positions, cycles and bad transforms, cameras,
//! punctual lights and embedded images with bad fields or damaged bytes) or damaged bytes of a
//! valid file (truncated, bytes overwritten), and images alone. Whatever the input, loading ends in
//! a `SceneError` or in a scene every consumer can trust ([`assert_sound`]); a panic or a hang
//! fails the test. Valid files of the same generators must still load (a loader that refused
//! everything would pass the rest). The seed is fixed and printed (`PROPTEST_RNG_SEED` picks
//! another), so a run repeats and a failure replays.

use super::{gltf, obj, Scene};
use kickstart_rt_renderer::scene::Light;
use proptest::prelude::*;
use std::path::Path;

/// Cases per target: enough to reach every branch the generators aim at many times over in every
/// test run; a deeper search sets `PROPTEST_CASES` (`PROPTEST_CASES=1000000 cargo test fuzz`).
const CASES: u32 = 25_000;

/// What the demo and the SDK rely on in a loaded scene.
fn assert_sound(scene: &Scene) {
    for m in &scene.meshes {
        assert_eq!(
            m.indices.len() % 3,
            0,
            "mesh {:?}: a partial triangle",
            m.name
        );
        assert!(
            m.indices.iter().all(|&i| (i as usize) < m.positions.len()),
            "mesh {:?}: an index out of range",
            m.name
        );
        assert_eq!(
            m.normals.len(),
            m.positions.len(),
            "mesh {:?}: normals",
            m.name
        );
        assert!(
            m.uvs.is_empty() || m.uvs.len() == m.positions.len(),
            "mesh {:?}: texture coordinates",
            m.name
        );
        for t in m.indices.chunks_exact(3) {
            for &i in t {
                let p = m.positions[i as usize];
                assert!(
                    p.iter().all(|c| c.is_finite()),
                    "mesh {:?}: a triangle uses the non-finite vertex {p:?}",
                    m.name
                );
            }
        }
    }
    if let Some(c) = &scene.camera {
        assert!(
            c.fov_y_deg > 0.0 && c.fov_y_deg < 180.0,
            "camera fov {}",
            c.fov_y_deg
        );
        let forward = (c.at - c.eye).normalize_or_zero();
        assert!(
            c.eye.is_finite() && forward.cross(c.up.normalize_or_zero()).length() > 0.0,
            "a degenerate camera {c:?}"
        );
    }
    for light in &scene.lights {
        assert_light_sound(light);
    }
    for t in &scene.textures {
        let (w, h) = t.image.dimensions();
        assert!(
            (1..=super::texture::MAX_TEXTURE_SIDE).contains(&w.max(h)) && w.min(h) >= 1,
            "texture {:?}: {w}×{h}",
            t.name
        );
    }
    for inst in &scene.instances {
        assert!(
            inst.mesh < scene.meshes.len(),
            "an instance of a missing mesh"
        );
        assert!(
            inst.transform.is_finite(),
            "a non-finite instance transform"
        );
    }
}

/// What the renderer relies on in a light: finite fields, colours ≥ 0, ranges > 0, unit
/// directions and ordered spot cones.
fn assert_light_sound(light: &Light) {
    let unit = |d: glam::Vec3| (d.length() - 1.0).abs() < 1e-3;
    let ok = match *light {
        Light::Sun {
            direction,
            irradiance,
            angular_diameter,
        } => {
            unit(direction)
                && irradiance.is_finite()
                && irradiance.min_element() >= 0.0
                && angular_diameter.is_finite()
        }
        Light::Point {
            position,
            intensity,
            range,
        } => {
            position.is_finite()
                && intensity.is_finite()
                && intensity.min_element() >= 0.0
                && range > 0.0
                && range.is_finite()
        }
        Light::Spot {
            position,
            direction,
            intensity,
            range,
            inner_angle,
            outer_angle,
        } => {
            position.is_finite()
                && unit(direction)
                && intensity.is_finite()
                && intensity.min_element() >= 0.0
                && range > 0.0
                && range.is_finite()
                && 0.0 <= inner_angle
                && inner_angle < outer_angle
                && outer_angle <= std::f32::consts::FRAC_PI_2
        }
    };
    assert!(ok, "an unsound light {light:?}");
}

/// The random choices of one glTF file (see [`gltf_json`]).
#[derive(Debug, Clone)]
struct GltfCase {
    positions: Vec<[f32; 3]>,
    indices: Vec<u32>,
    /// Accessor counts and byte offsets as written (may disagree with the data).
    position_count: u64,
    index_count: u64,
    position_offset: u64,
    index_offset: u64,
    /// 5121 / 5123 / 5125, or something else.
    index_type: u32,
    /// Primitive mode (0–6, or out of range).
    mode: u32,
    /// Node transform: 16 numbers written as they are (NaN and ∞ as huge literals).
    matrix: Option<[f32; 16]>,
    /// Child lists of the two nodes (indices may be out of range or form a cycle).
    children: [Vec<u32>; 2],
    /// The camera, light and texture of the first node and its mesh.
    extras: GltfExtras,
}

/// A perspective camera, a punctual light and a base colour image, each perhaps absent and
/// perhaps bad.
#[derive(Debug, Clone, Default)]
struct GltfExtras {
    /// The camera's `yfov` (may be 0, negative, ≥ π or overflow to ∞).
    yfov: Option<f32>,
    light: Option<LightCase>,
    /// A PNG data URI: the image's bytes (perhaps damaged or claiming a huge size), and whether
    /// they are still the valid PNG.
    image: Option<(Vec<u8>, bool)>,
}

/// A `KHR_lights_punctual` light's fields as written.
#[derive(Debug, Clone)]
struct LightCase {
    /// "directional", "point", "spot" or something else.
    kind: &'static str,
    color: [f32; 3],
    intensity: f32,
    range: Option<f32>,
    cone: [f32; 2],
}

/// A float as JSON writes it: NaN and ±∞ have no literal, so they become numbers that
/// overflow f32 (read back as ∞) or stay as they are.
fn json_f32(x: f32) -> String {
    if x.is_nan() {
        "1e999".into()
    } else if x.is_infinite() {
        if x > 0.0 { "1e999" } else { "-1e999" }.into()
    } else {
        format!("{x:?}")
    }
}

/// A `.gltf` of one mesh with one primitive, its data in one base64 buffer.
fn gltf_json(c: &GltfCase) -> String {
    let mut bin: Vec<u8> = c
        .positions
        .iter()
        .flatten()
        .flat_map(|f| f.to_le_bytes())
        .collect();
    let pos_bytes = bin.len();
    for &i in &c.indices {
        match c.index_type {
            5121 => bin.push(i as u8),
            5123 => bin.extend_from_slice(&(i as u16).to_le_bytes()),
            _ => bin.extend_from_slice(&i.to_le_bytes()),
        }
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let idx_bytes = bin.len() - pos_bytes;
    let matrix = c.matrix.map_or(String::new(), |m| {
        let m: Vec<String> = m.iter().map(|&x| json_f32(x)).collect();
        format!(r#","matrix":[{}]"#, m.join(","))
    });
    let children = |k: usize| {
        if c.children[k].is_empty() {
            String::new()
        } else {
            let v: Vec<String> = c.children[k].iter().map(u32::to_string).collect();
            format!(r#","children":[{}]"#, v.join(","))
        }
    };
    let (node_extras, top_extras, material) = extras_json(&c.extras);
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}]{top_extras},
"nodes":[{{"mesh":0{matrix}{c0}{node_extras}}},{{"mesh":0{c1}}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1,"mode":{mode}{material}}}]}}],
"accessors":[
 {{"bufferView":0,"byteOffset":{po},"componentType":5126,"count":{pc},"type":"VEC3","min":[-1,-1,-1],"max":[1,1,1]}},
 {{"bufferView":1,"byteOffset":{io},"componentType":{it},"count":{ic},"type":"SCALAR"}}],
"bufferViews":[
 {{"buffer":0,"byteOffset":0,"byteLength":{pb}}},
 {{"buffer":0,"byteOffset":{pb},"byteLength":{ib}}}],
"buffers":[{{"byteLength":{bl},"uri":"data:application/octet-stream;base64,{data}"}}]}}"#,
        c0 = children(0),
        c1 = children(1),
        mode = c.mode,
        po = c.position_offset,
        pc = c.position_count,
        io = c.index_offset,
        it = c.index_type,
        ic = c.index_count,
        pb = pos_bytes,
        ib = idx_bytes.max(1),
        bl = bin.len(),
        data = crate::app::testing::base64(&bin),
    )
}

/// The JSON of `e`: what the first node gains (camera, light), the top-level arrays
/// (cameras, lights, images), and what the primitive gains (its material).
fn extras_json(e: &GltfExtras) -> (String, String, String) {
    let (mut node, mut top, mut material) = (String::new(), String::new(), String::new());
    if let Some(yfov) = e.yfov {
        node += r#","camera":0"#;
        top += &format!(
            r#","cameras":[{{"type":"perspective","perspective":{{"yfov":{},"znear":0.1}}}}]"#,
            json_f32(yfov)
        );
    }
    if let Some(l) = &e.light {
        node += r#","extensions":{"KHR_lights_punctual":{"light":0}}"#;
        let range = l
            .range
            .map_or(String::new(), |r| format!(r#","range":{}"#, json_f32(r)));
        let c: Vec<String> = l.color.iter().map(|&x| json_f32(x)).collect();
        let spot = if l.kind == "spot" {
            format!(
                r#","spot":{{"innerConeAngle":{},"outerConeAngle":{}}}"#,
                json_f32(l.cone[0]),
                json_f32(l.cone[1])
            )
        } else {
            String::new()
        };
        top += &format!(
            r#","extensionsUsed":["KHR_lights_punctual"],"extensions":{{"KHR_lights_punctual":{{"lights":[{{"type":"{}","color":[{}],"intensity":{}{range}{spot}}}]}}}}"#,
            l.kind,
            c.join(","),
            json_f32(l.intensity),
        );
    }
    if let Some((png, _)) = &e.image {
        material += r#","material":0"#;
        top += &format!(
            r#","materials":[{{"pbrMetallicRoughness":{{"baseColorTexture":{{"index":0}}}}}}],"textures":[{{"source":0}}],"images":[{{"uri":"data:image/png;base64,{}"}}]"#,
            crate::app::testing::base64(png)
        );
    }
    (node, top, material)
}

/// A small valid PNG (`w` × `h`), then perhaps its header's size rewritten to `claim` and a
/// few bytes overwritten.
fn png_case() -> impl Strategy<Value = (Vec<u8>, bool)> {
    (
        1u32..4,
        1u32..4,
        prop_oneof![6 => Just(None), 1 => prop::sample::select(vec![8193u32, 100_000, 1 << 30]).prop_map(Some)],
        prop_oneof![6 => Just(Vec::new()), 1 => prop::collection::vec((0usize..200, any::<u8>()), 1..4)],
    )
        .prop_map(|(w, h, claim, edits)| {
            let mut png = Vec::new();
            let img = image::RgbaImage::from_pixel(w, h, image::Rgba([200, 100, 50, 255]));
            if let Err(e) = img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png) {
                panic!("encoding a test PNG: {e}");
            }
            let valid = png.clone();
            if let Some(side) = claim {
                super::texture::claim_png_size(&mut png, side, h);
            }
            for (at, b) in edits {
                let k = at % png.len();
                png[k] = b;
            }
            let intact = png == valid;
            (png, intact)
        })
}

/// A light: mostly valid, sometimes with a negative, non-finite or overflowing field, or
/// cone angles out of order.
fn light_case() -> impl Strategy<Value = LightCase> {
    let field = || prop_oneof![8 => 0.0f32..10.0, 1 => -5.0f32..0.0, 1 => Just(f32::INFINITY), 1 => Just(3.0e38f32)];
    (
        prop::sample::select(vec!["directional", "point", "spot", "area"]),
        [field(), field(), field()],
        field(),
        prop_oneof![2 => Just(None), 1 => field().prop_map(Some)],
        [
            prop_oneof![4 => 0.0f32..0.7, 1 => -1.0f32..4.0],
            prop_oneof![4 => 0.7f32..1.5, 1 => -1.0f32..4.0],
        ],
    )
        .prop_map(|(kind, color, intensity, range, cone)| LightCase {
            kind,
            color,
            intensity,
            range,
            cone,
        })
}

fn gltf_extras() -> impl Strategy<Value = GltfExtras> {
    (
        prop_oneof![
            2 => Just(None),
            2 => (0.1f32..3.0).prop_map(Some),
            1 => prop::sample::select(vec![0.0f32, -1.0, 3.2, 3.0e38, f32::INFINITY]).prop_map(Some),
        ],
        prop_oneof![2 => Just(None), 1 => light_case().prop_map(Some)],
        prop_oneof![2 => Just(None), 1 => png_case().prop_map(Some)],
    )
        .prop_map(|(yfov, light, image)| GltfExtras { yfov, light, image })
}

/// A coordinate: mostly ordinary, sometimes NaN, ±∞ or enormous.
fn coordinate() -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => -10.0f32..10.0,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
        1 => Just(3.0e38f32),
    ]
}

/// A count or offset: mostly small and right, sometimes past the data or enormous.
fn count(right: u64) -> impl Strategy<Value = u64> {
    prop_oneof![
        28 => Just(right),
        2 => 0u64..=right + 8,
        1 => Just(u32::MAX as u64),
        1 => Just(1u64 << 40),
    ]
}

/// A transform entry: JSON has no NaN or ∞, but entries that overflow f32 when the node
/// matrices multiply, and zeros that make a matrix singular.
fn matrix_entry() -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => -2.0f32..2.0,
        1 => Just(0.0f32),
        1 => Just(3.0e38f32),
    ]
}

fn gltf_case() -> impl Strategy<Value = GltfCase> {
    (
        // Mostly ordinary positions, so that most files have triangles to keep.
        prop_oneof![
            3 => prop::collection::vec([-10.0f32..10.0, -10.0f32..10.0, -10.0f32..10.0], 0..12),
            1 => prop::collection::vec([coordinate(), coordinate(), coordinate()], 0..12),
        ],
        prop_oneof![
            4 => Just(5125u32),
            2 => Just(5123u32),
            1 => Just(5121u32),
            1 => prop::sample::select(vec![5126u32, 0]),
        ],
        prop_oneof![12 => Just(4u32), 3 => 0u32..7, 1 => 7u32..9],
        prop_oneof![
            4 => Just(None),
            1 => prop::collection::vec(matrix_entry(), 16).prop_map(|v| {
                let mut m = [0.0f32; 16];
                m.copy_from_slice(&v);
                Some(m)
            }),
        ],
        prop_oneof![
            12 => Just([Vec::new(), Vec::new()]),
            1 => [
                prop::collection::vec(0u32..4, 0..3),
                prop::collection::vec(0u32..4, 0..3),
            ],
        ],
    )
        .prop_flat_map(|(positions, index_type, mode, matrix, children)| {
            let n = positions.len() as u32;
            let index = || {
                prop_oneof![
                    24 => 0..n.max(1),
                    1 => Just(u32::MAX),
                    1 => n..n + 3,
                ]
            };
            // Mostly whole triangles; sometimes one or two indices more.
            let indices = (
                prop::collection::vec([index(), index(), index()], 0..5),
                prop_oneof![4 => Just(Vec::new()), 1 => prop::collection::vec(index(), 1..3)],
            )
                .prop_map(|(t, extra)| t.into_iter().flatten().chain(extra).collect::<Vec<u32>>());
            (
                Just(positions),
                indices,
                Just(index_type),
                Just(mode),
                Just(matrix),
                Just(children),
            )
        })
        .prop_flat_map(|(positions, indices, index_type, mode, matrix, children)| {
            let (np, ni) = (positions.len() as u64, indices.len() as u64);
            (
                count(np),
                count(ni),
                prop_oneof![16 => Just(0u64), 1 => 0u64..64],
                prop_oneof![16 => Just(0u64), 1 => 0u64..64],
            )
                .prop_map(move |(pc, ic, po, io)| GltfCase {
                    positions: positions.clone(),
                    indices: indices.clone(),
                    position_count: pc,
                    index_count: ic,
                    position_offset: po,
                    index_offset: io,
                    index_type,
                    mode,
                    matrix,
                    children: children.clone(),
                    extras: GltfExtras::default(),
                })
        })
        .prop_flat_map(|case| {
            gltf_extras().prop_map(move |extras| GltfCase {
                extras,
                ..case.clone()
            })
        })
}

/// A valid glTF file's bytes: the base of the damaged-bytes cases.
fn valid_gltf() -> Vec<u8> {
    gltf_json(&valid_case()).into_bytes()
}

/// The choices of a valid glTF file: one quad.
fn valid_case() -> GltfCase {
    GltfCase {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ],
        indices: vec![0, 1, 2, 2, 1, 3],
        position_count: 4,
        index_count: 6,
        position_offset: 0,
        index_offset: 0,
        index_type: 5125,
        mode: 4,
        matrix: None,
        children: [vec![], vec![]],
        extras: GltfExtras::default(),
    }
}

/// Whether every choice of `c` is valid glTF the loader must accept (conservatively: small
/// finite positions, whole triangles in range, right counts and offsets, a triangle list, no
/// matrix or children, and a valid camera, light and image if any).
fn is_valid(c: &GltfCase) -> bool {
    let n = c.positions.len() as u64;
    let geometry = n > 0
        && c.positions.iter().flatten().all(|x| x.abs() <= 10.0)
        && c.indices.iter().all(|&i| u64::from(i) < n)
        && !c.indices.is_empty()
        && c.indices.len().is_multiple_of(3)
        && (c.position_count, c.index_count) == (n, c.indices.len() as u64)
        && (c.position_offset, c.index_offset) == (0, 0)
        && matches!(c.index_type, 5121 | 5123 | 5125)
        && c.mode == 4
        && c.matrix.is_none()
        && c.children.iter().all(Vec::is_empty);
    let e = &c.extras;
    let camera = e.yfov.is_none_or(|y| y > 0.0 && y < std::f32::consts::PI);
    let light = e.light.as_ref().is_none_or(|l| {
        let colour = l.color.iter().map(|&x| x * l.intensity);
        let cone = l.kind != "spot"
            || (0.0 <= l.cone[0]
                && l.cone[0] < l.cone[1]
                && l.cone[1] <= std::f32::consts::FRAC_PI_2);
        matches!(l.kind, "directional" | "point" | "spot")
            && l.color
                .iter()
                .chain([&l.intensity])
                .all(|x| x.is_finite() && *x >= 0.0)
            && colour.clone().all(f32::is_finite)
            && l.range.is_none_or(|r| r.is_finite() && r > 0.0)
            && cone
    });
    let image = e.image.as_ref().is_none_or(|(_, intact)| *intact);
    geometry && camera && light && image
}

/// The valid files of the generators load, with what they hold: the rest of the fuzzing only
/// means something while they do.
#[test]
fn valid_files_of_every_kind_still_load() {
    let scene = load_gltf_bytes(&valid_gltf()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((scene.meshes.len(), scene.meshes[0].indices.len()), (1, 6));
    let mut png = Vec::new();
    let img = image::RgbaImage::from_pixel(2, 3, image::Rgba([1, 2, 3, 255]));
    img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap_or_else(|e| panic!("encoding a test PNG: {e}"));
    let mut case = GltfCase {
        extras: GltfExtras {
            yfov: Some(0.8),
            light: Some(LightCase {
                kind: "spot",
                color: [1.0, 0.5, 0.25],
                intensity: 4.0,
                range: Some(20.0),
                cone: [0.2, 0.6],
            }),
            image: Some((png, true)),
        },
        ..valid_case()
    };
    assert!(is_valid(&case));
    let scene = load_gltf_bytes(gltf_json(&case).as_bytes()).unwrap_or_else(|e| panic!("{e}"));
    assert_sound(&scene);
    let fov = scene.camera.map(|c| c.fov_y_deg);
    assert!(
        fov.is_some_and(|f| (f - 0.8_f32.to_degrees()).abs() < 1e-3),
        "{fov:?}"
    );
    assert!(matches!(
        scene.lights[..],
        [Light::Spot {
            range: 20.0,
            outer_angle: 0.6,
            ..
        }]
    ));
    assert_eq!(scene.textures[0].image.get_pixel(1, 2).0, [1, 2, 3, 255]);
    // The same file with its camera's yfov out of range is refused by name.
    case.extras.yfov = Some(3.5);
    let e = load_gltf_bytes(gltf_json(&case).as_bytes())
        .map(|_| ())
        .unwrap_err();
    assert!(e.to_string().contains("camera 0: yfov 3.5"), "{e}");
    let dir = std::env::temp_dir().join(format!("ksrt-valid-obj-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
    let path = dir.join("valid.obj");
    std::fs::write(&path, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap_or_else(|e| panic!("{e}"));
    let scene = obj::load(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scene.meshes[0].indices, vec![0, 1, 2]);
    for name in ["cornell-obj", "cornell-gltf"] {
        let scene =
            super::load(name, &super::repository_scenes_dir()).unwrap_or_else(|e| panic!("{e}"));
        assert_sound(&scene);
        assert!(scene.triangle_count() > 30, "{name}");
    }
}

/// A node hierarchy 20,000 deep (no recursion to overflow the stack) loads, and a cycle is
/// refused by name.
#[test]
fn deep_node_chains_load_and_cycles_are_refused() {
    let valid = String::from_utf8(valid_gltf()).unwrap_or_else(|e| panic!("{e}"));
    let two_nodes = r#""nodes":[{"mesh":0},{"mesh":0}]"#;
    assert!(valid.contains(two_nodes));
    let depth = 20_000;
    let chain: Vec<String> = (1..depth)
        .map(|k| format!(r#"{{"children":[{k}]}}"#))
        .chain([r#"{"mesh":0}"#.to_string()])
        .collect();
    let deep = valid.replace(two_nodes, &format!(r#""nodes":[{}]"#, chain.join(",")));
    let scene = load_gltf_bytes(deep.as_bytes()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scene.instances.len(), 1);
    let cycle = valid.replace(
        two_nodes,
        r#""nodes":[{"children":[1]},{"mesh":0,"children":[0]}]"#,
    );
    let e = load_gltf_bytes(cycle.as_bytes()).map(|_| ()).unwrap_err();
    assert!(e.what.contains("appears twice"), "{e}");
}

/// A POSITION accessor index past the file's accessors (the gltf crate's validator indexes
/// with it unchecked): refused naming the attribute, not a panic.
#[test]
fn an_attribute_accessor_past_the_list_is_refused_by_name() {
    let valid = String::from_utf8(valid_gltf()).unwrap_or_else(|e| panic!("{e}"));
    for index in ["2", "2147483648"] {
        let bad = valid.replace(r#""POSITION":0"#, &format!(r#""POSITION":{index}"#));
        assert_ne!(bad, valid);
        let e = load_gltf_bytes(bad.as_bytes()).map(|_| ()).unwrap_err();
        let want =
            format!("meshes[0].primitives[0].attributes.POSITION: accessor {index} does not exist");
        assert!(e.what.contains(&want), "{e}");
    }
}

/// Loads `bytes` as the public loader does (a panic inside the gltf crate becomes an error
/// naming where it happened), and fails on a panic in this crate's own code.
fn load_gltf_bytes(bytes: &[u8]) -> Result<Scene, super::SceneError> {
    let r = gltf::load_from_bytes(Path::new("fuzz.gltf"), bytes);
    if let Err(e) = &r {
        assert!(
            !e.what.contains(" at kickstart-rt"),
            "the loader itself panicked: {e}"
        );
        // A damaged data URI reads as a file next to the glTF: the error may name that file,
        // and then says whose buffer it is.
        assert!(
            e.to_string().contains("fuzz.gltf"),
            "the error does not name the glTF: {e}"
        );
    }
    r
}

proptest! {
    #![proptest_config(crate::app::testing::proptest_config(CASES))]

    #[test]
    fn gltf_of_random_parameters_loads_soundly_or_is_refused(case in gltf_case()) {
        match load_gltf_bytes(gltf_json(&case).as_bytes()) {
            Ok(scene) => assert_sound(&scene),
            Err(e) => prop_assert!(!is_valid(&case), "a valid file refused: {e}"),
        }
    }

    #[test]
    fn damaged_gltf_loads_soundly_or_is_refused(
        cut in 0usize..2000,
        edits in prop::collection::vec((0usize..2000, any::<u8>()), 0..6),
    ) {
        let mut bytes = valid_gltf();
        for (at, b) in edits {
            let k = at % bytes.len();
            bytes[k] = b;
        }
        bytes.truncate(cut.min(bytes.len()));
        if let Ok(scene) = load_gltf_bytes(&bytes) {
            assert_sound(&scene);
        }
    }

    /// Images alone, as the loaders decode them: small PNGs, some with bytes overwritten or a
    /// header claiming up to 2^30 pixels a side. An intact image decodes to its pixels; any
    /// other ends in an error or in an image within the size limit, never a panic or a huge
    /// allocation.
    #[test]
    fn images_decode_to_their_pixels_or_are_refused((png, intact) in png_case()) {
        match super::texture::decode_rgba8(&png) {
            Ok(img) => {
                let (w, h) = img.dimensions();
                prop_assert!(w.min(h) >= 1 && w.max(h) <= super::texture::MAX_TEXTURE_SIDE);
                if intact {
                    prop_assert_eq!(img.get_pixel(0, 0).0, [200, 100, 50, 255]);
                }
            }
            Err(e) => prop_assert!(!intact, "an intact PNG refused: {}", e),
        }
    }

    #[test]
    fn obj_of_random_lines_loads_soundly_or_is_refused(text in obj_file()) {
        let dir = std::env::temp_dir().join(format!("ksrt-fuzz-obj-{}", std::process::id()));
        std::fs::create_dir_all(&dir).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let path = dir.join("fuzz.obj");
        std::fs::write(&path, text).map_err(|e| TestCaseError::fail(e.to_string()))?;
        if let Ok(scene) = obj::load(&path) {
            assert_sound(&scene);
        }
    }
}

/// An OBJ file: vertices (NaN, ∞, enormous or unreadable coordinates, missing or extra
/// components), normals and texture coordinates, faces (mostly in range; sometimes out of
/// range, zero, negative or enormous indices, with and without slashes), material statements
/// naming missing files, and garbage lines, in a random order.
fn obj_file() -> impl Strategy<Value = String> {
    let num = || {
        prop_oneof![
            60 => (-10.0f32..10.0).prop_map(|x| format!("{x}")),
            1 => Just("nan".to_string()),
            1 => Just("inf".to_string()),
            1 => Just("-inf".to_string()),
            1 => Just("1e39".to_string()),
            1 => Just("x".to_string()),
        ]
    };
    let components = |n: usize| {
        prop_oneof![
            40 => prop::collection::vec(num(), n..n + 1),
            1 => prop::collection::vec(num(), 1..5),
        ]
    };
    let index = || {
        prop_oneof![
            40 => (1i64..5).prop_map(|i| i.to_string()),
            1 => Just("0".to_string()),
            1 => (-9i64..0).prop_map(|i| i.to_string()),
            1 => Just("4294967296".to_string()),
            2 => (1i64..9).prop_map(|i| format!("{i}/{i}/{i}")),
            1 => (1i64..9).prop_map(|i| format!("{i}//{i}")),
        ]
    };
    let line = prop_oneof![
        6 => components(3).prop_map(|v| format!("v {}", v.join(" "))),
        1 => components(3).prop_map(|v| format!("vn {}", v.join(" "))),
        1 => components(2).prop_map(|v| format!("vt {}", v.join(" "))),
        6 => prop::collection::vec(index(), 3..5).prop_map(|v| format!("f {}", v.join(" "))),
        1 => prop::collection::vec(index(), 1..3).prop_map(|v| format!("f {}", v.join(" "))),
        1 => Just("mtllib missing.mtl".to_string()),
        1 => Just("usemtl nothing".to_string()),
        1 => Just("o part".to_string()),
        1 => "[ -~]{0,20}",
    ];
    // Vertices first, as exporters write them, so that most faces find theirs.
    (
        prop::collection::vec(
            components(3).prop_map(|v| format!("v {}", v.join(" "))),
            0..12,
        ),
        prop::collection::vec(line, 0..16),
    )
        .prop_map(|(v, rest)| v.into_iter().chain(rest).collect::<Vec<_>>().join("\n"))
}
