//! Every pass variant the denoisers can create (`Filter::prepare`, `Pipelines::chains`),
//! validated with naga without a device, and the uniforms and record strides against the WGSL;
//! and which of them `Filter::prepare` creates (on the test device).
//! The denoising method picks no variant: iterations, history length and radius are uniforms
//! or loop counts on the CPU, so Fast and HighQuality share every pipeline.

use super::super::guides::GUIDE_BYTES;
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
        assert_eq!(storage_stride(module, name) as u64, GUIDE_BYTES);
    }
}

/// Asserts the layouts an upsample pass of a context of `signal_type` shares with the Rust
/// side.
fn check_upsample(module: &naga::Module, signal_type: SignalType) {
    assert_denoise_params(module);
    crate::trace::gbuffer::assert_wgsl_layout(module);
    let record = history::signal_record_bytes(signal_type);
    assert_eq!(storage_stride(module, "src0") as u64, record);
    assert_eq!(storage_stride(module, "guide") as u64, GUIDE_BYTES);
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
    assert_eq!(storage_stride(module, "guide") as u64, GUIDE_BYTES);
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
            clip_to_world,
            prev_clip_to_world,
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

/// What `prepare` creates per signal set: a two-signal set only its temporal pass, its chains
/// only their à-trous passes (a SpecularAndDiffuse context runs no single-signal temporal pass
/// and no two-signal à-trous); a single-signal set both, being its own chain.
#[test]
fn prepare_creates_only_the_pipelines_a_context_dispatches() {
    let g = crate::gpu::testing::gpu();
    let shared = Shared::new(&g.device);
    let mut radiance = super::super::radiance::new();
    radiance.prepare(&g.device, &shared);
    let sets = &radiance.pipelines.sets;
    let both = SignalSet::of(SignalType::SpecularAndDiffuse);
    let two = &sets[&both];
    assert!(two.temporal.is_some() && two.atrous.is_none());
    assert!(two.last.is_empty() && two.upsample.is_empty());
    // The Specular and Diffuse sets are the chains of both and contexts of their own.
    for st in [SignalType::Specular, SignalType::Diffuse] {
        let one = &sets[&SignalSet::of(st)];
        assert!(one.temporal.is_some() && one.atrous.is_some(), "{st:?}");
        assert_eq!(
            one.last.len(),
            crate::tasks::WRITABLE_OUTPUT_FORMATS.len(),
            "{st:?}"
        );
        assert_eq!(
            one.upsample.len(),
            crate::tasks::WRITABLE_OUTPUT_FORMATS.len(),
            "{st:?}"
        );
    }
    assert_eq!(sets.len(), 3);

    // A denoiser serving SpecularAndDiffuse alone: its chains' sets hold no temporal pass.
    let mut alone = Filter::new(&[SignalType::SpecularAndDiffuse]);
    alone.prepare(&g.device, &shared);
    for (_, chain) in both.atrous_chains() {
        let p = &alone.pipelines.sets[&chain];
        assert!(
            p.temporal.is_none() && p.atrous.is_some(),
            "{}",
            chain.label()
        );
    }
}
