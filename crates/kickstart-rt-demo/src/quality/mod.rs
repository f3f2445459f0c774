//! Image quality measurement for `ksrt quality` (issue 7): the yardstick of every denoiser change.
//! The `ksrt quality` command itself (a trace task at 1 spp, denoised, along a camera path, against
//! a converged reference) needs the trace tasks and the lighting cache; the metrics are here.

pub mod metrics;
