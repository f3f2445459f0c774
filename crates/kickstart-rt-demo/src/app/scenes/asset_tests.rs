//! Loader tests on generated assets: textures and emission read from glTF (text and binary),
//! alpha modes (MASK cutouts, BLEND) and texture coordinates, and each broken input's message.

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

/// The two coordinate sets of [`cutout_gltf`]'s quad: set 0 spans the texture, set 1 its
/// top-left quarter, so a test can tell which one was read.
const UV0: [[f32; 2]; 4] = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
const UV1: [[f32; 2]; 4] = [[0.0, 0.0], [0.5, 0.0], [0.5, 0.5], [0.0, 0.5]];

/// A one-quad `.gltf` (data URIs) named `name` in `dir` whose only material is `material` (its
/// JSON), with two coordinate sets ([`UV0`], [`UV1`]) and a 2×2 base colour image whose alpha is
/// 0 on the diagonal, 255 off it. `extensions_used` lists extensions the file declares.
fn cutout_gltf(dir: &Path, name: &str, material: &str, extensions_used: &str) -> PathBuf {
    let positions: [[f32; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    let indices: [u16; 6] = [0, 1, 2, 0, 2, 3];
    let mut bin = Vec::new();
    bin.extend_from_slice(bytemuck::cast_slice(&positions));
    bin.extend_from_slice(bytemuck::cast_slice(&UV0));
    bin.extend_from_slice(bytemuck::cast_slice(&UV1));
    bin.extend_from_slice(bytemuck::cast_slice(&indices));
    let image = image::RgbaImage::from_fn(2, 2, |x, y| {
        image::Rgba([40, 160, 40, if x == y { 0 } else { 255 }])
    });
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},{extensions_used}
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"mesh": 0}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1, "TEXCOORD_1": 2}}, "indices": 3, "material": 0}}]}}],
  "materials": [{material}],
  "textures": [{{"source": 0}}],
  "images": [{{"uri": "data:image/png;base64,{png}"}}],
  "buffers": [{{"uri": "data:application/octet-stream;base64,{data}", "byteLength": {len}}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 32}},
    {{"buffer": 0, "byteOffset": 80, "byteLength": 32}},
    {{"buffer": 0, "byteOffset": 112, "byteLength": 12}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"}},
    {{"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"}},
    {{"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}}
  ]
}}"#,
        png = testing::base64(&testing::png(&image)),
        data = testing::base64(&bin),
        len = bin.len(),
    );
    let path = dir.join(name);
    std::fs::write(&path, json).expect("write gltf");
    path
}

#[test]
fn gltf_mask_material_keeps_its_cutoff_factor_coordinate_set_and_texture_alpha() {
    let dir = testing::temp_dir("gltf-mask");
    let material = r#"{"name": "leaves", "alphaMode": "MASK", "alphaCutoff": 0.3,
      "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 0.8],
        "baseColorTexture": {"index": 0, "texCoord": 1}}}"#;
    let scene = load_file(&cutout_gltf(&dir, "mask.gltf", material, "")).expect("load");
    let mesh = &scene.meshes[0];
    assert_eq!(
        mesh.material.alpha,
        AlphaMode::Mask {
            factor: 0.8,
            cutoff: 0.3
        }
    );
    assert_eq!(mesh.uvs, UV1.to_vec(), "the base colour texture's set 1");
    // The texture keeps its alpha: 0 on the diagonal.
    let tex = &scene.textures[0].image;
    assert_eq!(
        (tex.get_pixel(0, 0).0[3], tex.get_pixel(1, 0).0[3]),
        (0, 255)
    );
    // Set 1 covers the top-left texel only, whose alpha is 0: the whole quad is a hole.
    assert!(!scene.opaque_at(0, 0, 0.3, 0.3));
    // Without alphaCutoff, the default 0.5; without baseColorFactor, a factor of 1.
    let plain =
        r#"{"alphaMode": "MASK", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}"#;
    let scene = load_file(&cutout_gltf(&dir, "default.gltf", plain, "")).expect("load");
    assert_eq!(
        scene.meshes[0].material.alpha,
        AlphaMode::Mask {
            factor: 1.0,
            cutoff: 0.5
        }
    );
    assert_eq!(scene.meshes[0].uvs, UV0.to_vec());
}

#[test]
fn gltf_texture_transform_moves_the_base_colour_coordinates() {
    let dir = testing::temp_dir("gltf-texture-transform");
    let used = r#" "extensionsUsed": ["KHR_texture_transform"],"#;
    // Scale 2 then offset (0.5, 0.25), on set 1.
    let material = r#"{"alphaMode": "MASK", "pbrMetallicRoughness": {"baseColorTexture":
      {"index": 0, "texCoord": 1, "extensions": {"KHR_texture_transform":
        {"offset": [0.5, 0.25], "scale": [2, 2]}}}}}"#;
    let scene = load_file(&cutout_gltf(&dir, "scaled.gltf", material, used)).expect("load");
    let want: Vec<[f32; 2]> = UV1
        .iter()
        .map(|[u, v]| [0.5 + 2.0 * u, 0.25 + 2.0 * v])
        .collect();
    assert_eq!(scene.meshes[0].uvs, want);
    // The extension's texCoord overrides the reference's.
    let material = r#"{"pbrMetallicRoughness": {"baseColorTexture":
      {"index": 0, "texCoord": 1, "extensions": {"KHR_texture_transform": {"texCoord": 0}}}}}"#;
    let scene = load_file(&cutout_gltf(&dir, "override.gltf", material, used)).expect("load");
    assert_eq!(scene.meshes[0].uvs, UV0.to_vec());
}

#[test]
fn gltf_blend_material_loads_as_opaque() {
    let dir = testing::temp_dir("gltf-blend");
    let material = r#"{"alphaMode": "BLEND", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 0.2],
      "baseColorTexture": {"index": 0}}}"#;
    let scene = load_file(&cutout_gltf(&dir, "blend.gltf", material, "")).expect("load");
    let mesh = &scene.meshes[0];
    assert_eq!(mesh.material.alpha, AlphaMode::Blend);
    assert_eq!(mesh.mask(), None, "drawn and traced opaque");
    assert!(!scene.has_cutouts());
    // Even over a texel of alpha 0.
    assert!(scene.opaque_at(0, 0, 0.1, 0.1));
}

#[test]
fn gltf_mask_with_a_bad_cutoff_or_factor_is_refused_naming_the_material() {
    let dir = testing::temp_dir("gltf-bad-cutoff");
    // A cutoff of 1e40 reads as an infinite f32 (JSON has no NaN: a NaN cutoff is refused by
    // the same check, tested in gltf_alpha).
    for (k, (cutoff, factor)) in [("-0.5", "1"), ("1.5", "1"), ("1e40", "1"), ("0.5", "-1")]
        .into_iter()
        .enumerate()
    {
        let material = format!(
            r#"{{"name": "leaves", "alphaMode": "MASK", "alphaCutoff": {cutoff},
              "pbrMetallicRoughness": {{"baseColorFactor": [1, 1, 1, {factor}]}}}}"#
        );
        let name = format!("bad-{k}.gltf");
        let m = message(load_file(&cutout_gltf(&dir, &name, &material, "")));
        assert!(m.contains(&name), "{m}");
        assert!(m.contains("material 0 (\"leaves\")"), "{m}");
        let field = if factor == "1" {
            "alphaCutoff"
        } else {
            "baseColorFactor alpha"
        };
        assert!(m.contains(field), "{m}");
    }
}
