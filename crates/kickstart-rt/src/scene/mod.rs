//! The scene on the GPU: shared pools, ingestion, BLAS/TLAS builds. Layouts:
//! `docs/ray-tracing-core.md`.

pub(crate) mod gpu_scene;
pub(crate) mod hardware;
pub(crate) mod ingest;
pub(crate) mod lbvh;
pub(crate) mod opacity;
pub(crate) mod pool;
pub(crate) mod prims;
pub(crate) mod reserve;
pub(crate) mod skin_batch;
pub(crate) mod skin_layout;
pub(crate) mod skinning;
pub(crate) mod strategy;
pub(crate) mod traversal;
