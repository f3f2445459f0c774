//! Ray tracing passes: the shared traversal module, G-buffer decoding, ray batches, debug views.

pub(crate) mod debug_view;
pub(crate) mod gbuffer;
pub(crate) mod rays;
#[cfg(test)]
pub(crate) mod test_scene;
