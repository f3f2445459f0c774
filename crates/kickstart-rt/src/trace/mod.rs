//! Ray tracing passes: the shared traversal module, ray batches, debug views.

// Not called from the render path until the trace tasks are wired in (the lead's merge); the
// unit tests exercise everything meanwhile.
#[allow(dead_code)]
pub(crate) mod debug_view;
#[allow(dead_code)]
pub(crate) mod rays;
#[cfg(test)]
pub(crate) mod test_scene;
