//! `ksrt`'s application: the `render`, `view`, `info` and `shaders` commands and what they stand
//! on here, on top of the renderer crate — scene files (glTF, OBJ), the native device, waiting for
//! the GPU and reading textures back, images written as files, progress bars and the window.
//!
//! Layers, lowest first (checked by the crate's layering test):
//! `args`, `defaults`, `progress`, `timings`, `gpu`, `memory` → `readback`, `scenes`, `frames` →
//! `frames_in_flight`, `debug_view` → `lit`, `cpu_reference`, `shaders` → `render`, `view`.

pub mod args;
pub mod cpu_reference;
pub mod debug_view;
pub mod defaults;
pub mod frames;
pub mod frames_in_flight;
pub mod gpu;
pub mod lit;
pub mod memory;
pub mod progress;
pub mod readback;
pub mod render;
pub mod scenes;
pub mod shaders;
#[cfg(test)]
pub mod testing;
#[cfg(test)]
mod tests;
pub mod timings;
pub mod view;
