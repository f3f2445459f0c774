//! The renderer `ksrt` draws with, on wgpu and kickstart-rt's public API:
//!
//! - [`scene`]: the scene model (meshes, instances, materials, textures, lights, cameras; nodes,
//!   skins, rigs and animations) and the built-in scenes (`default`, `cornell`, `window-room`,
//!   `grove`, the `dancers`' generated character, `town`, `crowd`, `statue`);
//! - [`upload`] and [`sdk_glue`]: a scene's buffers and its registration with the SDK, and the
//!   SDK calls in one place;
//! - [`raster`]: a small deferred rasteriser (G-buffer, sun shadow map, direct lighting);
//! - [`frame`]: the SDK's part of a frame (inject, trace, denoise) and [`composite`]: the final
//!   image;
//! - [`renderer`]: one frame end to end.
//!
//! It reads no file, no clock and no window, and never waits for the GPU: it records into the
//! caller's encoder and hands back the SDK's tasks for the caller to complete, so that it can
//! build for the web (`wasm32-unknown-unknown`). The application (`ksrt`) owns devices, files,
//! waiting and read-back.
//!
//! Layers, lowest first (an import may only point down; checked by the test below):
//! `error`, `rng` → `scene` → `upload`, `sdk_glue`, `raster` → `frame`, `composite` → `renderer`.

pub mod composite;
pub mod error;
pub mod frame;
pub mod raster;
pub mod renderer;
pub mod rng;
pub mod scene;
pub mod sdk_glue;
pub mod upload;

/// The layers of this crate, lowest first.
#[cfg(test)]
const LAYERS: &[&[&str]] = &[
    &["error", "rng"],
    &["scene"],
    &["upload", "sdk_glue", "raster"],
    &["frame", "composite"],
    &["renderer"],
];

#[cfg(test)]
#[test]
fn imports_point_down_the_layers_without_loops() {
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    if let Err(problems) = kickstart_rt_layering::check(&src, LAYERS) {
        panic!(
            "layering of kickstart-rt-renderer:\n{}",
            problems.join("\n")
        );
    }
}
