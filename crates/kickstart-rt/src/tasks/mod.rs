//! Every task an application schedules into a [`crate::TaskContainer`].

mod bvh;
mod denoising;
mod preset;
mod render;

pub use bvh::*;
pub use denoising::*;
pub use preset::*;
pub use render::*;
