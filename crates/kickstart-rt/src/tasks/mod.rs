//! Every task an application schedules into a [`crate::TaskContainer`].

mod bvh;
mod render;

pub use bvh::*;
pub use render::*;
