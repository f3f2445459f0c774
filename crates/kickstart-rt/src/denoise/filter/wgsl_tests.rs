//! Every pass variant the denoisers can create (`Filter::prepare`, `Pipelines::chains`),
//! validated with naga without a device, and the uniforms and record strides against the WGSL.
//! The denoising method picks no variant: iterations, history length and radius are uniforms
//! or loop counts on the CPU, so Fast and HighQuality share every pipeline.

use super::*;
use crate::gpu::wgsl_check::{assert_wgsl_layout, storage_stride, validate};
use std::collections::BTreeSet;

/// Asserts the layouts a temporal pass of a context of `signal_type` shares with the Rust side.
fn check_temporal(module: &naga::Module, signal_type: SignalType) {
    assert_denoise_params(module);
    crate::trace::gbuffer::assert_wgsl_layout(module);
    let record = history::signal_record_bytes(signal_type);
    for name in ["hist_prev0", "hist_prev1", "hist_cur0", "hist_cur1"] {
        assert_eq!(storage_stride(module, name) as u64, record, "{name}");
    }
    for name in ["guide_prev", "guide_cur"] {
        assert_eq!(storage_stride(module, name) as u64, history::RECORD_BYTES);
    }
}

/// Asserts the layouts an upsample pass of a context of `signal_type` shares with the Rust
/// side.
fn check_upsample(module: &naga::Module, signal_type: SignalType) {
    assert_denoise_params(module);
    crate::trace::gbuffer::assert_wgsl_layout(module);
    let record = history::signal_record_bytes(signal_type);
    assert_eq!(storage_stride(module, "src0") as u64, record);
    assert_eq!(
        storage_stride(module, "guide") as u64,
        history::RECORD_BYTES
    );
}

/// Asserts the layouts an à-trous pass of a context of `signal_type` shares with the Rust side.
fn check_atrous(module: &naga::Module, signal_type: SignalType) {
    assert_denoise_params(module);
    assert_wgsl_layout!(
        module,
        "AtrousParams",
        StepParams {
            value => "step",
            first,
            pad => "pad0",
        }
    );
    let record = history::signal_record_bytes(signal_type);
    for name in ["src0", "src1", "dst0", "dst1"] {
        assert_eq!(storage_stride(module, name) as u64, record, "{name}");
    }
    assert_eq!(
        storage_stride(module, "guide") as u64,
        history::RECORD_BYTES
    );
}

fn assert_denoise_params(module: &naga::Module) {
    assert_wgsl_layout!(
        module,
        "DenoiseParams",
        DenoiseParams {
            viewport,
            eye,
            forward,
            prev_eye,
            prev_forward,
            jitter,
            motion_scale,
            kind0,
            kind1,
            signal_count,
            motion_type,
            max_history,
            discard_history,
            checkerboard,
            base_radius,
            grid,
            lattice,
        }
    );
}

#[test]
fn every_denoiser_variant_validates_and_matches_the_rust_layouts() {
    // Every signal type is served by exactly one denoiser.
    let denoisers = [
        super::super::radiance::new(),
        super::super::occlusion::new(),
        super::super::shadow::new(),
    ];
    for st in SIGNAL_TYPES {
        let serving = denoisers
            .iter()
            .filter(|d| d.signal_types.contains(&st))
            .count();
        assert_eq!(serving, 1, "{st:?}");
    }
    let mut seen = BTreeSet::new();
    for d in &denoisers {
        for &st in d.signal_types {
            for (label, source, pass) in variants(st) {
                if !seen.insert(source.clone()) {
                    continue; // the same pipeline as another set's (a chain of one signal)
                }
                let module = validate(&label, &source);
                assert!(module.entry_points.iter().any(|e| e.name == "main"));
                match pass {
                    Pass::Temporal => check_temporal(&module, st),
                    Pass::Atrous => check_atrous(&module, st),
                    Pass::Upsample => check_upsample(&module, st),
                }
            }
        }
    }
    // Per signal set its temporal pass; per single-signal chain an à-trous iteration, 4 last
    // iterations and 4 upsample passes (the SpecularAndDiffuse chains are the Specular and
    // Diffuse sets' own, so no two-signal à-trous exists).
    assert_eq!(seen.len(), 6 + 5 * (1 + 4 * 2));
    // Formats without a WGSL name get no pipeline.
    assert_eq!(wgsl_format(wgpu::TextureFormat::Rgba8Unorm), None);
}
