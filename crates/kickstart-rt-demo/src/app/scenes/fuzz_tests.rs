//! Fuzzed scene files: glTF and OBJ built from random parameters (huge counts, offsets past their
//! buffers, indices out of range, NaN and infinite positions, cycles and bad transforms) or
//! damaged bytes of a valid file (truncated, bytes overwritten). Whatever the input, loading
//! ends in a `SceneError` or in a scene every consumer can trust ([`assert_sound`]); a panic or a
//! hang fails the test. A fixed number of cases per target keeps the run short and repeatable
//! (proptest's default seed).

use super::{gltf, obj, Scene};
use proptest::prelude::*;
use std::path::Path;

/// Cases per target: enough to reach every branch the generators aim at, seconds in CI.
const CASES: u32 = 256;

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
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
"nodes":[{{"mesh":0{matrix}{c0}}},{{"mesh":0{c1}}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1,"mode":{mode}}}]}}],
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
        12 => Just(right),
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
        prop::collection::vec([coordinate(), coordinate(), coordinate()], 0..12),
        prop_oneof![
            4 => Just(5125u32),
            2 => Just(5123u32),
            1 => Just(5121u32),
            1 => prop::sample::select(vec![5126u32, 0]),
        ],
        prop_oneof![6 => Just(4u32), 3 => 0u32..7, 1 => 7u32..9],
        prop_oneof![
            2 => Just(None),
            1 => prop::collection::vec(matrix_entry(), 16).prop_map(|v| {
                let mut m = [0.0f32; 16];
                m.copy_from_slice(&v);
                Some(m)
            }),
        ],
        prop_oneof![
            6 => Just([Vec::new(), Vec::new()]),
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
                    6 => 0..n.max(1),
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
                prop_oneof![8 => Just(0u64), 1 => 0u64..64],
                prop_oneof![8 => Just(0u64), 1 => 0u64..64],
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
                })
        })
}

/// A valid glTF file's bytes: the base of the damaged-bytes cases.
fn valid_gltf() -> Vec<u8> {
    gltf_json(&GltfCase {
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
    })
    .into_bytes()
}

thread_local! {
    /// Where this thread's panics happened (recorded by [`record_panics`]).
    static PANICS: std::cell::RefCell<Vec<String>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Chains a panic hook that records each panic's source location in [`PANICS`] (the
/// panicking thread's own list), so a test can tell a third-party reader's panic, which the
/// loader turns into an error, from one of ours.
fn record_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let at = info
                .location()
                .map_or(String::new(), |l| l.file().to_string());
            PANICS.with(|p| p.borrow_mut().push(at));
            previous(info);
        }));
    });
}

/// Loads `bytes` as the public loader does (a panic inside the gltf crate becomes an error),
/// and fails on any panic in this crate's own code.
fn load_gltf_bytes(bytes: &[u8]) -> Result<Scene, super::SceneError> {
    record_panics();
    PANICS.with(|p| p.borrow_mut().clear());
    let r = gltf::load_from_bytes(Path::new("fuzz.gltf"), bytes);
    let ours: Vec<String> = PANICS.with(|p| {
        p.borrow()
            .iter()
            .filter(|f| f.contains("kickstart-rt-demo"))
            .cloned()
            .collect()
    });
    assert!(ours.is_empty(), "the loader itself panicked at {ours:?}");
    if let Err(e) = &r {
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
    #![proptest_config(ProptestConfig { cases: CASES, ..ProptestConfig::default() })]

    #[test]
    fn gltf_of_random_parameters_loads_soundly_or_is_refused(case in gltf_case()) {
        if let Ok(scene) = load_gltf_bytes(gltf_json(&case).as_bytes()) {
            assert_sound(&scene);
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
