//! The SDK's GPU suites, one module each, in one test binary: each integration-test binary
//! links all of wgpu, so one binary instead of eleven saves their links, and the suites share
//! the one test device (`common::gpu`) that each binary used to create for itself. A test that
//! needs the device to itself (wgpu's allocator report, device loss) makes its own
//! (`common::own_test_device`). Select a suite by its module: `cargo test --test gpu ray_tracing::`.

mod common;

mod api_surface;
mod cutout_effects;
mod debug_views;
mod denoise;
mod execution;
mod faults;
mod lighting_cache;
mod ray_tracing;
mod skinning;
mod trace_tasks;
mod validation;
