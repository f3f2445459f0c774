//! `ksrt`'s measurement lab: `bench` (BVH builds, rays, the trace tasks, the cache, the
//! denoisers, peers), `quality` (the denoisers' output against converged references) and `soak`
//! (a long run under scene churn). It uses the application (`crate::app`) and the renderer; the
//! application never uses it.

pub mod bench;
pub mod compare;
pub mod obvhs_peer;
pub mod quality;
pub mod soak;
