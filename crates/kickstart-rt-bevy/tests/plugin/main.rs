//! The plugin's tests, one module each, in one test binary: each test binary links all of Bevy
//! and wgpu, so one binary instead of five saves their links. Every test builds a headless Bevy
//! app of its own (`harness`). Select a suite by its module: `cargo test --test plugin skinning::`.

#[path = "../../examples/seed/mod.rs"]
mod seed;

mod harness;

mod backend;
mod cutouts;
mod headless;
mod presets;
mod skinning;
