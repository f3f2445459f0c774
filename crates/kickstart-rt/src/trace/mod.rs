//! Ray tracing passes: the shared traversal module, G-buffer decoding, ray batches, debug views
//! and the trace tasks.

pub(crate) mod debug_view;
pub(crate) mod gbuffer;
pub(crate) mod lights;
pub(crate) mod rays;
pub(crate) mod sampling;
pub(crate) mod tasks;
#[cfg(test)]
pub(crate) mod test_scene;
