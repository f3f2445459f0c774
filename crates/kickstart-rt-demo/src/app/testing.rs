//! Test support: the one device every GPU test of `ksrt` shares, and generated assets (glTF files
//! with textures and emission, and broken ones).
//!
//! `KSRT_TEST_MINIMAL_DEVICE=1` creates the device with `Features::empty()` and
//! `Limits::default()`, as the SDK's tests do (CI runs the suite both ways). A missing adapter
//! fails the test: a GPU test never skips.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The shared device.
pub fn device() -> &'static (wgpu::Device, wgpu::Queue) {
    static GPU: OnceLock<(wgpu::Device, wgpu::Queue)> = OnceLock::new();
    GPU.get_or_init(|| {
        let adapter = crate::app::gpu::adapter()
            .unwrap_or_else(|e| panic!("GPU tests need an adapter (mesa-vulkan-drivers): {e}"));
        if std::env::var("KSRT_TEST_MINIMAL_DEVICE").is_ok_and(|v| v == "1") {
            let desc = wgpu::DeviceDescriptor {
                label: Some("ksrt test (minimal)"),
                required_features: wgpu::Features::empty(),
                required_limits: wgpu::Limits::default(),
                ..Default::default()
            };
            pollster::block_on(adapter.request_device(&desc)).expect("minimal device")
        } else {
            crate::app::gpu::device(&adapter).expect("device")
        }
    })
}

/// A fresh, empty folder under the target directory for one test's files.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../target/ksrt-test")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create test folder");
    dir
}

/// Standard base64 with padding.
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// PNG bytes of `img`.
pub fn png(img: &image::RgbaImage) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("encode png");
    out.into_inner()
}

/// An 8×8 checker of red and blue texels (red where (x + y) is even): a base colour texture whose
/// every cell can be told apart in a render.
pub fn checker() -> image::RgbaImage {
    image::RgbaImage::from_fn(8, 8, |x, y| {
        if (x + y) % 2 == 0 {
            image::Rgba([230, 20, 20, 255])
        } else {
            image::Rgba([20, 20, 230, 255])
        }
    })
}

/// A quad in the XZ plane (y = 0, facing +y) from −1 to 1, with UVs 0..1 (u along +x, v along
/// +z), as glTF buffer bytes: positions, normals, uvs, then u16 indices.
fn quad_bytes() -> Vec<u8> {
    let p: [[f32; 3]; 4] = [
        [-1.0, 0.0, -1.0],
        [1.0, 0.0, -1.0],
        [1.0, 0.0, 1.0],
        [-1.0, 0.0, 1.0],
    ];
    let n = [[0.0f32, 1.0, 0.0]; 4];
    let uv: [[f32; 2]; 4] = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let idx: [u16; 6] = [0, 2, 1, 0, 3, 2];
    let mut b = Vec::new();
    b.extend_from_slice(bytemuck::cast_slice(&p));
    b.extend_from_slice(bytemuck::cast_slice(&n));
    b.extend_from_slice(bytemuck::cast_slice(&uv));
    b.extend_from_slice(bytemuck::cast_slice(&idx));
    b
}

/// The glTF JSON of the test scene: a textured floor quad (material 0, the checker) and, above
/// it at y = 0.5 and turned upside down (facing away from the default sun), a small emissive
/// quad (material 1: emissive factor (4, 3, 0.5), no base colour). `mode` is the primitive mode
/// of every primitive (4 = triangles, 1 = lines); `image_uri` the base colour image's URI.
fn scene_json(buffer_uri: &str, image_uri: &str, mode: u32) -> String {
    let len = quad_bytes().len();
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "scene": 0,
  "scenes": [{{"nodes": [0, 1]}}],
  "nodes": [
    {{"mesh": 0, "scale": [2, 1, 2]}},
    {{"mesh": 1, "translation": [0, 0.5, 0], "rotation": [1, 0, 0, 0], "scale": [0.3, 1, 0.3]}}
  ],
  "meshes": [
    {{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}}, "indices": 3, "material": 0, "mode": {mode}}}]}},
    {{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 3, "material": 1, "mode": {mode}}}]}}
  ],
  "materials": [
    {{"pbrMetallicRoughness": {{"baseColorTexture": {{"index": 0}}, "metallicFactor": 0.0, "roughnessFactor": 0.9}}}},
    {{"pbrMetallicRoughness": {{"baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0.0}}, "emissiveFactor": [4, 3, 0.5]}}
  ],
  "textures": [{{"source": 0, "sampler": 0}}],
  "samplers": [{{"magFilter": 9728, "minFilter": 9728}}],
  "images": [{{"uri": "{image_uri}"}}],
  "buffers": [{{"uri": "{buffer_uri}", "byteLength": {len}}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 96, "byteLength": 32}},
    {{"buffer": 0, "byteOffset": 128, "byteLength": 12}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-1, 0, -1], "max": [1, 0, 1]}},
    {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"}},
    {{"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"}},
    {{"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}}
  ]
}}"#
    )
}

fn data_uri(mime: &str, bytes: &[u8]) -> String {
    format!("data:{mime};base64,{}", base64(bytes))
}

/// Writes the textured, emissive test scene as a self-contained `.gltf` (data URIs) into `dir`.
pub fn textured_gltf(dir: &Path) -> PathBuf {
    let path = dir.join("textured.gltf");
    let json = scene_json(
        &data_uri("application/octet-stream", &quad_bytes()),
        &data_uri("image/png", &png(&checker())),
        4,
    );
    std::fs::write(&path, json).expect("write gltf");
    path
}

/// The same scene with lines instead of triangles.
pub fn lines_only_gltf(dir: &Path) -> PathBuf {
    let path = dir.join("lines.gltf");
    let json = scene_json(
        &data_uri("application/octet-stream", &quad_bytes()),
        &data_uri("image/png", &png(&checker())),
        1,
    );
    std::fs::write(&path, json).expect("write gltf");
    path
}

/// The scene whose texture is not an image (a "PNG" of text bytes).
pub fn bad_texture_gltf(dir: &Path) -> PathBuf {
    let path = dir.join("bad-texture.gltf");
    std::fs::write(dir.join("broken.png"), b"this is not a png file").expect("write");
    let json = scene_json(
        &data_uri("application/octet-stream", &quad_bytes()),
        "broken.png",
        4,
    );
    std::fs::write(&path, json).expect("write gltf");
    path
}

/// The scene as a binary `.glb` (buffer and image in the BIN chunk).
pub fn glb_bytes() -> Vec<u8> {
    let mut bin = quad_bytes();
    let image_offset = bin.len();
    let image = png(&checker());
    bin.extend_from_slice(&image);
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let mut json = scene_json("", "", 4);
    // Point the buffer at the BIN chunk and the image at a buffer view.
    json = json
        .replace(
            &format!(
                r#""buffers": [{{"uri": "", "byteLength": {}}}]"#,
                quad_bytes().len()
            ),
            &format!(r#""buffers": [{{"byteLength": {}}}]"#, bin.len()),
        )
        .replace(
            r#""images": [{"uri": ""}]"#,
            r#""images": [{"bufferView": 4, "mimeType": "image/png"}]"#,
        )
        .replace(
            r#"{"buffer": 0, "byteOffset": 128, "byteLength": 12}"#,
            &format!(
                r#"{{"buffer": 0, "byteOffset": 128, "byteLength": 12}}, {{"buffer": 0, "byteOffset": {image_offset}, "byteLength": {}}}"#,
                image.len()
            ),
        );
    let mut json = json.into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

/// The seed of every property test when `PROPTEST_RNG_SEED` is not set: a fixed one, so that a
/// run repeats the last one and a failure in CI replays here.
const PROPTEST_SEED: u64 = 0x6b73_7274_5f66_757a;

/// A property test's configuration: `cases` cases (`PROPTEST_CASES` overrides it) from a fixed
/// seed (`PROPTEST_RNG_SEED` overrides it; the seed used is printed, shown with a failure's
/// output), and no failure files written into the source tree.
pub fn proptest_config(cases: u32) -> proptest::test_runner::Config {
    let seed = std::env::var("PROPTEST_RNG_SEED")
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(PROPTEST_SEED);
    eprintln!("property test seed {seed} (PROPTEST_RNG_SEED={seed} replays it)");
    // proptest's own knob for a longer (or shorter) search than the test's default.
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(cases);
    proptest::test_runner::Config {
        cases,
        rng_seed: proptest::test_runner::RngSeed::Fixed(seed),
        failure_persistence: None,
        ..proptest::test_runner::Config::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trips_through_the_loader_decoder() {
        assert_eq!(base64(b"hello"), "aGVsbG8=");
        assert_eq!(base64(b"hi!"), "aGkh");
        assert_eq!(base64(b""), "");
    }
}
