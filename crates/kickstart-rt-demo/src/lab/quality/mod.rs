//! `ksrt quality`, the yardstick of every denoiser change: denoised 1-spp traces
//! against converged references along a camera pan, scored with PSNR, FLIP and the energy ratio,
//! then the flicker of a still camera.

pub mod accumulate;
pub mod capture;
pub mod ceiling;
pub mod command;
pub mod linear;
pub mod metrics;
pub mod options;
pub mod report;
pub mod run;
pub mod scores;
pub mod signal;
pub mod still;
pub mod summary;
