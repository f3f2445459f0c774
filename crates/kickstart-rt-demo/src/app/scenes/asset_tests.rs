//! Loader tests on generated assets: textures and emission read from glTF (text and binary), and
//! each broken input's message.

use super::*;
use crate::app::testing;
use glam::Vec3;
use kickstart_rt_renderer::scene::*;

#[test]
fn gltf_textures_uvs_and_emission_are_loaded() {
    let dir = testing::temp_dir("gltf-textured");
    let scene = load_file(&testing::textured_gltf(&dir)).expect("load");
    assert_eq!(scene.meshes.len(), 2);
    assert_eq!(scene.textures.len(), 1);
    let tex = &scene.textures[0].image;
    assert_eq!((tex.width(), tex.height()), (8, 8));
    assert_eq!(tex.get_pixel(0, 0).0, [230, 20, 20, 255]);
    assert_eq!(tex.get_pixel(1, 0).0, [20, 20, 230, 255]);
    let floor = &scene.meshes[0];
    assert_eq!(floor.material.base_color_texture, Some(0));
    assert_eq!(floor.uvs.len(), 4);
    assert_eq!(floor.uvs[2], [1.0, 1.0]);
    assert!((floor.material.roughness - 0.9).abs() < 1e-6);
    let lamp = &scene.meshes[1];
    assert_eq!(lamp.material.emissive, Vec3::new(4.0, 3.0, 0.5));
    assert_eq!(lamp.material.base_color_texture, None);
    assert!(lamp.uvs.is_empty());
}

#[test]
fn glb_with_an_embedded_texture_loads_like_the_gltf() {
    let dir = testing::temp_dir("glb");
    let path = dir.join("scene.glb");
    std::fs::write(&path, testing::glb_bytes()).expect("write");
    let scene = load_file(&path).expect("load glb");
    assert_eq!(scene.textures.len(), 1);
    assert_eq!(
        scene.textures[0].image.get_pixel(1, 0).0,
        [20, 20, 230, 255]
    );
    assert_eq!(scene.meshes[1].material.emissive, Vec3::new(4.0, 3.0, 0.5));
}

fn message(r: Result<Scene, SceneError>) -> String {
    match r {
        Ok(_) => panic!("a broken input loaded"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn missing_file_says_it_cannot_be_read() {
    let m = message(load_file(Path::new("/nonexistent/ksrt/scene.glb")));
    assert!(
        m.contains("/nonexistent/ksrt/scene.glb") && m.contains("cannot read"),
        "{m}"
    );
    let m = message(load("/nonexistent/ksrt/scene.obj", Path::new(".")));
    assert!(m.contains("cannot read"), "{m}");
}

#[test]
fn glb_truncated_to_half_is_an_error_naming_the_file() {
    let dir = testing::temp_dir("glb-truncated");
    let path = dir.join("half.glb");
    let bytes = testing::glb_bytes();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).expect("write");
    let m = message(load_file(&path));
    assert!(m.contains("half.glb"), "{m}");
    assert!(m.contains("not a valid glTF 2.0 file"), "{m}");
}

#[test]
fn lines_only_scene_is_an_error_saying_there_are_no_triangles() {
    let dir = testing::temp_dir("gltf-lines");
    let m = message(load_file(&testing::lines_only_gltf(&dir)));
    assert!(m.contains("lines.gltf"), "{m}");
    assert!(m.contains("no triangles to render"), "{m}");
}

#[test]
fn texture_that_fails_to_decode_is_an_error_naming_it() {
    let dir = testing::temp_dir("gltf-bad-texture");
    let m = message(load_file(&testing::bad_texture_gltf(&dir)));
    assert!(m.contains("bad-texture.gltf"), "{m}");
    assert!(
        m.contains("base colour texture image 0: cannot decode the image"),
        "{m}"
    );
}

#[test]
fn obj_mtl_colours_emission_roughness_and_diffuse_map_are_loaded() {
    let dir = testing::temp_dir("obj-mtl");
    std::fs::write(dir.join("checker.png"), testing::png(&testing::checker())).expect("write");
    std::fs::write(
        dir.join("scene.mtl"),
        "newmtl lamp\nKd 0.1 0.2 0.3\nKe 5 4 3\nNs 0\n\nnewmtl floor\nKd 1 1 1\nmap_Kd checker.png\nNs 998\n",
    )
    .expect("write");
    std::fs::write(
        dir.join("scene.obj"),
        "mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nv 1 0 1\nvt 0 0\nvt 1 0\nvt 1 1\n\
         o lamp\nusemtl lamp\nf 1/1 2/2 3/3\no floor\nusemtl floor\nf 1/1 3/3 2/2\n",
    )
    .expect("write");
    let scene = load_file(&dir.join("scene.obj")).expect("load");
    assert_eq!(scene.meshes.len(), 2);
    let lamp = &scene.meshes[0];
    assert_eq!(lamp.color, Vec3::new(0.1, 0.2, 0.3));
    assert_eq!(lamp.material.emissive, Vec3::new(5.0, 4.0, 3.0));
    // Ns 0: the roughest; Ns 998: α² = 2/1000, roughness = α^½ ≈ 0.211.
    assert!((lamp.material.roughness - 1.0).abs() < 1e-6);
    let floor = &scene.meshes[1];
    assert!((floor.material.roughness - 0.002f32.sqrt().sqrt()).abs() < 1e-4);
    assert_eq!(floor.material.base_color_texture, Some(0));
    assert_eq!(
        scene.textures[0].image.get_pixel(1, 0).0,
        [20, 20, 230, 255]
    );
    // OBJ's v runs up: stored flipped for the rasteriser.
    assert_eq!(floor.uvs.len(), 3);
    assert!(floor.uvs.contains(&[1.0, 0.0]));
}

/// A glTF file's `KHR_lights_punctual` lights are loaded, placed by their node, and light the
/// view instead of the defaults.
#[test]
fn gltf_punctual_lights_are_loaded_and_kept() {
    let dir = testing::temp_dir("gltf-lights");
    let plain = std::fs::read_to_string(testing::textured_gltf(&dir)).expect("read");
    let with_light = plain
        .replace(
            r#""scenes": [{"nodes": [0, 1]}],"#,
            r#""extensionsUsed": ["KHR_lights_punctual"],
  "extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "color": [1, 0.5, 0.25], "intensity": 4}]}},
  "scenes": [{"nodes": [0, 1, 2]}],"#,
        )
        .replace(
            r#""scale": [0.3, 1, 0.3]}
  ],"#,
            r#""scale": [0.3, 1, 0.3]},
    {"translation": [0, 2, 0.5], "extensions": {"KHR_lights_punctual": {"light": 0}}}
  ],"#,
        );
    assert_ne!(
        plain, with_light,
        "the test scene's JSON changed: update this test"
    );
    let path = dir.join("lit.gltf");
    std::fs::write(&path, with_light).expect("write");
    let mut scene = load_file(&path).expect("load");
    let [Light::Point {
        position,
        intensity,
        range,
    }] = scene.lights[..]
    else {
        panic!("lights: {:?}", scene.lights);
    };
    assert_eq!(position, Vec3::new(0.0, 2.0, 0.5));
    assert_eq!(intensity, Vec3::new(4.0, 2.0, 1.0));
    assert!(range.is_finite() && range > 0.0);
    scene.prepare_view(None);
    assert_eq!(scene.lights.len(), 1, "the file's light, no defaults");
}
