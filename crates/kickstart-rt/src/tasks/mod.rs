//! Every task an application schedules into a [`crate::TaskContainer`].

mod bvh;
mod denoising;
mod opacity;
mod preset;
mod render;
mod skinning;

pub use bvh::*;
pub use denoising::*;
pub use opacity::*;
pub use preset::*;
pub use render::*;
pub use skinning::*;
