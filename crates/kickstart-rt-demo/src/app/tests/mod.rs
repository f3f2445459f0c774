//! The application's GPU tests: lit renders against golden images, the G-buffer's contents,
//! the first view of a scene (framing, lights, debug views), and cutouts end to end.

mod cutout;
mod first_view;
mod gbuffer;
mod golden;
