//! Loader tests on the repository's Cornell boxes and apartment (`scenes/`) and on the built-in
//! scenes.

use super::*;
use glam::{Affine3A, Vec3};
use kickstart_rt_renderer::scene::*;

fn scenes() -> PathBuf {
    let dir = super::repository_scenes_dir();
    assert!(
        dir.join("README.md").exists(),
        "the repository's scenes folder {} is missing",
        dir.display()
    );
    dir
}

fn mesh_named<'a>(scene: &'a Scene, part: &str) -> &'a Mesh {
    scene
        .meshes
        .iter()
        .find(|m| m.name.contains(part))
        .unwrap_or_else(|| {
            panic!(
                "no mesh named *{part}* in {:?}",
                scene.meshes.iter().map(|m| &m.name).collect::<Vec<_>>()
            )
        })
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).abs().max_element() < 1e-3
}

const RED: Vec3 = Vec3::new(0.63, 0.065, 0.05);
const GREEN: Vec3 = Vec3::new(0.14, 0.45, 0.091);

/// Every normal is unit, and for a convex closed block every vertex normal points away from the
/// block's centre.
fn assert_normals_face_out(mesh: &Mesh) {
    assert_normals_face_out_except(mesh, |_, _| false)
}

/// As [`assert_normals_face_out`], except for the vertices `known_inward(position, normal)`
/// accepts.
fn assert_normals_face_out_except(mesh: &Mesh, known_inward: impl Fn(Vec3, Vec3) -> bool) {
    let centre =
        mesh.positions.iter().map(|p| Vec3::from(*p)).sum::<Vec3>() / mesh.positions.len() as f32;
    for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
        let n = Vec3::from(*n);
        assert!(
            (n.length() - 1.0).abs() < 1e-4,
            "{}: normal {n} not unit",
            mesh.name
        );
        assert!(
            n.dot(Vec3::from(*p) - centre) > 0.0 || known_inward(Vec3::from(*p), n),
            "{}: normal {n} at {p:?} points inwards",
            mesh.name
        );
    }
}

#[test]
fn cornell_obj_loads_with_colours_and_outward_normals() {
    let scene = load("cornell-obj", &scenes()).expect("load");
    assert_eq!(scene.triangle_count(), 36);
    assert_eq!(scene.meshes.len(), scene.instances.len());
    assert!(close(mesh_named(&scene, "leftWall").color, RED));
    assert!(close(mesh_named(&scene, "rightWall").color, GREEN));
    // The file has no normals: these are computed. Each block face has its own four vertices,
    // so every vertex normal is its face's. The file winds each block's bottom face like its top
    // (counter-clockwise seen from above), so the bottom faces alone face into the block: that is
    // the data, and the test pins it so a change to the file or the loader shows.
    for block in ["shortBox", "tallBox"] {
        let mesh = mesh_named(&scene, block);
        assert_normals_face_out_except(mesh, |p, n| p.y == 0.0 && n.y > 0.999);
        let up_at_bottom = mesh
            .positions
            .iter()
            .zip(&mesh.normals)
            .filter(|(p, n)| p[1] == 0.0 && n[1] > 0.999)
            .count();
        assert_eq!(
            up_at_bottom, 4,
            "{block}: bottom face no longer wound like the top"
        );
    }
    assert!(scene.camera.is_none());
}

#[test]
fn cornell_gltf_loads_with_colours() {
    let scene = load("cornell-gltf", &scenes()).expect("load");
    assert_eq!(scene.triangle_count(), 32);
    assert_eq!(scene.meshes.len(), 8, "one mesh per primitive");
    assert!(close(mesh_named(&scene, "leftWall").color, RED));
    assert!(close(mesh_named(&scene, "rightWall").color, GREEN));
    for m in &scene.meshes {
        assert_eq!(m.normals.len(), m.positions.len());
    }
    // The node rotates the Z-up mesh by 90° about X: the box stands on y = 0 after it.
    let (lo, hi) = scene.bounds();
    assert!(hi.y - lo.y > 1.5 && lo.y.abs() < 0.1, "bounds {lo} {hi}");
}

#[test]
fn missing_and_broken_files_name_the_file() {
    let dir = std::env::temp_dir().join(format!("ksrt-scene-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let missing = dir.join("nope.glb");
    let e = load(missing.to_str().expect("utf-8"), &dir).expect_err("missing");
    assert!(e.to_string().contains("nope.glb"), "{e}");
    for (name, text) in [
        ("broken.gltf", "{ not json"),
        ("broken.glb", "glTF\u{2}\0\0\0garbage"),
        (
            "truncated.gltf",
            r#"{"asset":{"version":"2.0"},"buffers":[{"byteLength":64,"uri":"absent.bin"}]}"#,
        ),
        ("bad-index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, text).expect("write");
        let e = load_file(&path).expect_err(name);
        assert!(
            e.to_string().contains(name) || e.to_string().contains("absent.bin"),
            "{e}"
        );
    }
    let e = load("no-such-scene", &dir).expect_err("unknown name");
    assert!(
        e.to_string().contains("cornell-obj"),
        "lists the names: {e}"
    );
    let e = load("dragon", &dir).expect_err("dragon not in an empty folder");
    assert!(e.to_string().contains("dragon_vrip.glb"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn camera_parsing() {
    let c = parse_camera("-0.006,0.125,0.32,-0.006,0.125,-0.005,30").expect("7 numbers");
    assert_eq!(c.eye, Vec3::new(-0.006, 0.125, 0.32));
    assert_eq!(c.at, Vec3::new(-0.006, 0.125, -0.005));
    assert_eq!(c.fov_y_deg, 30.0);
    for bad in [
        "1,2,3,4,5,6",
        "1,2,3,4,5,6,7,8",
        "",
        "1,2,3,4,5,x,30",
        "0,0,0,0,0,0,30",
        "0,0,0,0,0,1,0",
        "0,0,0,0,0,1,nan",
    ] {
        assert!(parse_camera(bad).is_err(), "{bad:?} accepted");
    }
    assert!(parse_camera("1,2,3,4,5,6").unwrap_err().contains("got 6"));
}

#[test]
fn builtin_scenes_have_outward_normals_and_cornell_colours() {
    let cornell = builtin::cornell_box();
    assert_eq!(cornell.meshes.len(), 8);
    assert!(close(mesh_named(&cornell, "red").color, RED));
    assert!(close(mesh_named(&cornell, "green").color, GREEN));
    assert_normals_face_out(mesh_named(&cornell, "short block"));
    assert_normals_face_out(mesh_named(&cornell, "tall block"));
    // The walls face into the box: the floor's normals point up.
    assert!(mesh_named(&cornell, "floor")
        .normals
        .iter()
        .all(|n| n[1] > 0.99));
    let default = builtin::default_scene();
    assert_normals_face_out(mesh_named(&default, "sphere"));
    assert!(default.camera.is_some());
}

#[test]
fn default_camera_sees_the_whole_scene() {
    let scene = builtin::cornell_box();
    let cam = scene.default_camera();
    let (lo, hi) = scene.bounds();
    let (fwd, _, _, tan) = cam.basis();
    assert!(close(cam.at, (lo + hi) * 0.5));
    assert!(
        cam.eye.y > cam.at.y && cam.eye.z > cam.at.z,
        "front-above: {cam:?}"
    );
    // Every corner of the bounds lies inside the vertical field of view.
    for k in 0..8 {
        let p = Vec3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        let d = p - cam.eye;
        let along = d.dot(fwd);
        assert!(along > 0.0);
        assert!((d - fwd * along).length() / along <= tan * 1.001);
    }
}

#[test]
fn computed_normals_are_area_weighted() {
    // Two triangles share vertex 0: a big one in z = 0 and a tiny one in x = 0.
    let positions = vec![
        [0.0, 0.0, 0.0],
        [10.0, 0.0, 0.0],
        [0.0, 10.0, 0.0],
        [0.0, 0.1, 0.0],
        [0.0, 0.0, 0.1],
    ];
    let n = compute_normals(&positions, &[0, 1, 2, 0, 3, 4]);
    assert!(Vec3::from(n[0]).dot(Vec3::Z) > 0.99);
    assert!((Vec3::from(n[1]).length() - 1.0).abs() < 1e-6);
    // An unused vertex still gets a unit normal.
    assert_eq!(compute_normals(&positions, &[]).len(), 5);
}

#[test]
fn gltf_instances_hierarchy_modes_and_camera() {
    // One mesh of three primitives (a triangle list, a strip, points) used by two nodes, the
    // second a child of the first, and a camera node.
    let dir = std::env::temp_dir().join(format!("ksrt-gltf-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut bin: Vec<u8> = Vec::new();
    for p in [
        [0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
    ] {
        bin.extend(p.iter().flat_map(|c| c.to_le_bytes()));
    }
    for i in [0u32, 1, 2, 0, 1, 2, 3] {
        bin.extend(i.to_le_bytes());
    }
    std::fs::write(dir.join("t data.bin"), &bin).expect("write bin");
    let json = r#"{
      "asset": {"version": "2.0"},
      "scene": 0,
      "scenes": [{"nodes": [0, 2]}],
      "nodes": [
        {"mesh": 0, "translation": [10, 0, 0], "children": [1]},
        {"mesh": 0, "translation": [0, 5, 0]},
        {"camera": 0, "translation": [0, 0, 10]}
      ],
      "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}],
      "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 0.6, 1]}}],
      "meshes": [{"primitives": [
        {"attributes": {"POSITION": 0}, "indices": 1, "material": 0},
        {"attributes": {"POSITION": 0}, "indices": 2, "mode": 5},
        {"attributes": {"POSITION": 0}, "mode": 0}
      ]}],
      "buffers": [{"byteLength": 76, "uri": "t%20data.bin"}],
      "bufferViews": [
        {"buffer": 0, "byteOffset": 0, "byteLength": 48},
        {"buffer": 0, "byteOffset": 48, "byteLength": 12},
        {"buffer": 0, "byteOffset": 60, "byteLength": 16}
      ],
      "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
         "min": [0, 0, 0], "max": [1, 1, 0]},
        {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"},
        {"bufferView": 2, "componentType": 5125, "count": 4, "type": "SCALAR"}
      ]
    }"#;
    let path = dir.join("t.gltf");
    std::fs::write(&path, json).expect("write gltf");
    let scene = load_file(&path).expect("load");
    let _ = std::fs::remove_dir_all(&dir);

    // Points skipped; the list and the strip are one geometry each, instanced per node.
    assert_eq!(scene.meshes.len(), 2);
    assert_eq!(scene.meshes[0].triangle_count(), 1);
    assert_eq!(scene.meshes[1].indices, vec![0, 1, 2, 2, 1, 3]);
    assert!(close(scene.meshes[0].color, Vec3::new(0.2, 0.4, 0.6)));
    assert!(
        close(scene.meshes[1].color, Vec3::ONE),
        "glTF's default material is white"
    );
    assert_eq!(scene.instances.len(), 4);
    let place = |k: usize| scene.instances[k].transform.transform_point3(Vec3::ZERO);
    assert_eq!([scene.instances[0].mesh, scene.instances[1].mesh], [0, 1]);
    assert!(close(place(0), Vec3::new(10.0, 0.0, 0.0)));
    assert!(
        close(place(2), Vec3::new(10.0, 5.0, 0.0)),
        "child composes its parent"
    );
    assert_eq!(scene.triangle_count(), 6);
    let cam = scene.camera.expect("camera node");
    assert!(close(cam.eye, Vec3::new(0.0, 0.0, 10.0)));
    assert!(close(cam.at, Vec3::new(0.0, 0.0, 9.0)), "looks down -Z");
    assert!((cam.fov_y_deg - 0.8f32.to_degrees()).abs() < 1e-3);
}

#[test]
fn a_flattened_scene_has_the_same_world_triangles_under_one_instance() {
    let tri = Mesh::new(
        "tri",
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        vec![0, 1, 2],
        Vec3::ONE,
    )
    .unwrap();
    let scene = Scene {
        name: "two".into(),
        meshes: vec![tri],
        instances: vec![
            Instance {
                mesh: 0,
                transform: Affine3A::from_translation(Vec3::new(5.0, 0.0, 0.0)),
            },
            Instance {
                mesh: 0,
                transform: Affine3A::from_scale(Vec3::splat(2.0)),
            },
        ],
        ..Default::default()
    };
    let flat = scene.flattened().unwrap();
    assert_eq!(flat.meshes.len(), 1);
    assert_eq!(flat.instances.len(), 1);
    assert_eq!(flat.instances[0].transform, Affine3A::IDENTITY);
    // Indices of the second instance point at its own (second) copy of the vertices.
    assert_eq!(flat.meshes[0].indices, vec![0, 1, 2, 3, 4, 5]);
    assert_eq!(flat.world_triangles().0, scene.world_triangles().0);
    assert_eq!(
        flat.world_triangles().0[1],
        [
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 2.0, 0.0)
        ]
    );
}

/// The window room's triangles in world space and a CPU BVH over them.
fn window_room_bvh(scene: &Scene) -> (Vec<[Vec3; 3]>, kickstart_rt::cpu::CpuBvh) {
    let tris: Vec<[Vec3; 3]> = scene
        .instances
        .iter()
        .flat_map(|i| scene.meshes[i.mesh].triangles(i.transform))
        .collect();
    let bvh = kickstart_rt::cpu::CpuBvh::build(&tris);
    (tris, bvh)
}

fn ray(origin: Vec3, dir: Vec3) -> kickstart_rt::cpu::Ray {
    kickstart_rt::cpu::Ray {
        origin,
        dir,
        t_min: 1e-4,
        t_max: f32::INFINITY,
    }
}

#[test]
fn window_room_is_lit_only_by_its_sun_and_every_face_looks_inwards() {
    let scene = load("window-room", Path::new(".")).expect("built-in scene");
    assert_eq!(scene.name, "window-room");
    // Its own sun, so the demo adds no default light; nothing glows.
    assert!(matches!(scene.lights[..], [Light::Sun { .. }]));
    assert_eq!(scene.lights_or_default(), scene.lights);
    let mut lit = scene.clone();
    lit.light_the_view(&scene.camera_or_default(None));
    assert_eq!(lit.lights, scene.lights);
    assert!(scene
        .meshes
        .iter()
        .all(|m| m.material.emissive == Vec3::ZERO));
    let centre = Vec3::new(0.0, builtin::WINDOW_ROOM_HEIGHT / 2.0, 0.0);
    for m in &scene.meshes {
        for (p, n) in m.positions.iter().zip(&m.normals) {
            let (p, n) = (Vec3::from(*p), Vec3::from(*n));
            assert!(n.dot(centre - p) > 0.0, "{}: {n} at {p} faces out", m.name);
        }
    }
    // The window is about 1/20 of the ceiling.
    let w = builtin::WINDOW_ROOM_HALF_WIDTH;
    let ceiling: f32 = mesh_named(&scene, "ceiling")
        .triangles(glam::Affine3A::IDENTITY)
        .map(|[a, b, c]| (b - a).cross(c - a).length() / 2.0)
        .sum();
    let window = 1.0 - ceiling / (4.0 * w * w);
    assert!((0.045..=0.055).contains(&window), "window {window}");
}

#[test]
fn window_room_is_closed_but_for_the_window_the_sun_shines_through_onto_the_floor() {
    let scene = builtin::window_room();
    let (tris, bvh) = window_room_bvh(&scene);
    let [x0, z0, x1, z1] = builtin::WINDOW_ROOM_WINDOW;
    let h = builtin::WINDOW_ROOM_HEIGHT;
    let through_window = |o: Vec3, d: Vec3| {
        let t = (h - o.y) / d.y;
        let p = o + d * t;
        t > 0.0 && (x0..=x1).contains(&p.x) && (z0..=z1).contains(&p.z)
    };
    // From inside, every ray meets a surface, except those that leave through the window.
    let o = Vec3::new(0.3, 1.2, 0.4);
    let n = 4000;
    let mut escaped = 0;
    for k in 0..n {
        let z = 1.0 - (2.0 * k as f32 + 1.0) / n as f32;
        let r = (1.0 - z * z).sqrt();
        let phi = k as f32 * 2.399_963;
        let d = Vec3::new(r * phi.cos(), z, r * phi.sin());
        if bvh.closest_hit(&tris, &ray(o, d)).is_none() {
            assert!(through_window(o, d), "ray {d} escapes through a wall");
            escaped += 1;
        }
    }
    assert!(escaped > 0, "no ray leaves through the window");
    // The sun reaches the floor below the window, shifted along its way, and nowhere else.
    let to_sun = -builtin::WINDOW_ROOM_SUN.normalize();
    let window_centre = Vec3::new((x0 + x1) / 2.0, h, (z0 + z1) / 2.0);
    let patch = window_centre - to_sun * (h / to_sun.y);
    assert!(patch.y.abs() < 1e-4 && patch.x > x1, "{patch}");
    assert!(bvh.closest_hit(&tris, &ray(patch, to_sun)).is_none());
    for shade in [Vec3::new(-1.5, 0.0, -1.5), window_centre.with_y(0.0)] {
        assert!(
            bvh.closest_hit(&tris, &ray(shade, to_sun)).is_some(),
            "{shade} sunlit"
        );
    }
    // The camera sees the patch, and only surfaces (no window) in a 16:9 image.
    let cam = scene.camera_or_default(None);
    for y in 0..18 {
        for x in 0..32 {
            let d = cam.primary_dir(x, y, 32, 18);
            assert!(
                bvh.closest_hit(&tris, &ray(cam.eye, d)).is_some(),
                "pixel {x},{y}"
            );
        }
    }
    let (fwd, right, up, tan) = cam.basis();
    let to_patch = (patch - cam.eye).normalize();
    let along = to_patch.dot(fwd);
    assert!(
        to_patch.dot(up).abs() / along < tan * 0.8
            && to_patch.dot(right).abs() / along < tan * 16.0 / 9.0 * 0.8,
        "the patch is not well inside the view"
    );
}

/// `--scenes` wins, then a non-empty `KSRT_SCENES`; an empty one means unset, and the default is
/// the repository's folder whatever the working directory.
#[test]
fn scenes_folder_resolution() {
    let given = Some(PathBuf::from("/given"));
    let env = Some(std::ffi::OsString::from("/env"));
    let empty = Some(std::ffi::OsString::new());
    assert_eq!(
        scenes_dir_from(given.clone(), env.clone()),
        PathBuf::from("/given")
    );
    assert_eq!(scenes_dir_from(None, env), PathBuf::from("/env"));
    assert_eq!(scenes_dir_from(None, empty), repository_scenes_dir());
    assert_eq!(scenes_dir_from(None, None), repository_scenes_dir());
    assert!(repository_scenes_dir().is_absolute());
    assert!(repository_scenes_dir().join("cornell_box").is_dir());
}

/// The named scenes a clone has load from the default folder: the repository's own files and
/// the built-in ones, with the triangle counts of their sources.
#[test]
fn repository_scenes_load_by_name() {
    let dir = repository_scenes_dir();
    for (name, triangles) in [
        ("cornell-obj", 36),
        ("cornell-gltf", 32),
        ("apartment", 177_934),
    ] {
        let scene = load(name, &dir).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(scene.triangle_count(), triangles, "{name}");
    }
    let e = load("dragon", &dir).expect_err("the dragon is not in the repository");
    assert!(e.to_string().contains("statue"), "{e}");
}
