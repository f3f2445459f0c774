//! `ksrt quality` (issue 7), the yardstick of every denoiser change: denoised 1-spp traces
//! against converged references along a camera pan, scored with PSNR and FLIP.

pub mod accumulate;
pub mod metrics;
pub mod run;
