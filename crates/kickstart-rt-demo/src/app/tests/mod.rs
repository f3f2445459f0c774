//! The application's GPU tests: lit renders against golden images, the G-buffer's contents,
//! and the first view of a scene (framing, lights, debug views).

mod first_view;
mod gbuffer;
mod golden;
