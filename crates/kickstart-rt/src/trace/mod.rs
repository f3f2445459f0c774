//! Ray tracing passes: the shared traversal module, ray batches, debug views.

pub(crate) mod rays;
