//! The application's GPU tests: lit renders against golden images, the G-buffer's contents,
//! the first view of a scene (framing, lights, debug views), cutouts end to end, and the
//! dancers' animation played.

mod cutout;
mod dancers;
mod first_view;
mod gbuffer;
mod golden;
