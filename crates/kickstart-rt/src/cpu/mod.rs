//! CPU reference ray tracing: a binned-SAH BVH and its traversal. It is the oracle the GPU
//! builder and traversal are tested against, and the yardstick for BVH quality (SAH cost).
//! Not used in the frame path.

mod bvh;
mod readback;
mod triangle;

pub use bvh::{CpuBvh, CpuBvhNode, SAH_INTERSECTION_COST, SAH_TRAVERSAL_COST};
pub use readback::{BlasReadback, Bvh2Child, TraversalCounts};
pub use triangle::{intersect_triangle, Hit, Ray, TriangleHit};
