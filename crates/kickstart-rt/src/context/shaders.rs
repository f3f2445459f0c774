//! Every WGSL shader the SDK can create, as composed: for tools that compile the SDK's shaders
//! outside it (`ksrt shaders --dump`, a browser's WebGPU, driver statistics), and for the
//! CPU-only test that validates them all.

use crate::device::TraversalBackend;

/// One shader the SDK can create: a pass and, where it has variants, which one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShaderVariant {
    /// The pass and its variant, e.g. `TraceShadowTask (Rgba16Float, None)` (unique).
    pub name: String,
    /// The composed WGSL, as the SDK hands it to the device.
    pub wgsl: String,
    /// The device features it needs: empty for portable WGSL (every device, WebGPU included);
    /// `EXPERIMENTAL_RAY_QUERY` for the hardware backend's tracing passes, whose portable
    /// fallback is the same pass with the software traversal.
    pub features: wgpu::Features,
}

/// Every shader the SDK can create, each variant once: the BVH builders and the radix sort, the
/// lighting cache's passes, ray batches, debug views, the trace tasks (kind × output formats) and
/// the denoisers (signal set × output format), then the tracing passes again for the hardware
/// backend (named with ` [hardware ray query]`; see [`ShaderVariant::features`]). The rest is
/// portable WGSL: where a device allows it, the software traversal passes are also compiled from
/// our own SPIR-V (native only), with these as their fallback.
pub fn shader_variants() -> Vec<ShaderVariant> {
    let portable = [
        crate::gpu::radix_sort::shader_variants(),
        crate::scene::ingest::shader_variants(),
        crate::scene::opacity::shader_variants(),
        crate::scene::prims::shader_variants(),
        crate::scene::skinning::shader_variants(),
        crate::scene::lbvh::shader_variants(),
        crate::cache::alloc::shader_variants(),
        crate::cache::inject::resolve_shader_variants(),
        crate::cache::transfer::shader_variants(),
        crate::denoise::shader_variants(),
    ];
    let tracing = |backend| {
        [
            crate::cache::inject::shader_variants(backend),
            crate::trace::rays::shader_variants(backend),
            crate::trace::debug_view::shader_variants(backend),
            crate::trace::tasks::shader_variants(backend),
        ]
    };
    let variant = |features| {
        move |(name, wgsl)| ShaderVariant {
            name,
            wgsl,
            features,
        }
    };
    let mut out: Vec<ShaderVariant> = portable
        .into_iter()
        .chain(tracing(TraversalBackend::Software))
        .flatten()
        .map(variant(wgpu::Features::empty()))
        .collect();
    out.extend(
        tracing(TraversalBackend::HardwareRayQuery)
            .into_iter()
            .flatten()
            .map(|(name, wgsl)| (format!("{name} [hardware ray query]"), wgsl))
            .map(variant(wgpu::Features::EXPERIMENTAL_RAY_QUERY)),
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hardware variants are exactly the tracing passes, each beside its portable fallback.
    #[test]
    fn every_hardware_variant_has_a_portable_fallback() {
        let variants = shader_variants();
        let hardware: Vec<_> = variants.iter().filter(|v| !v.features.is_empty()).collect();
        assert!(hardware.len() > 50, "{} hardware variants", hardware.len());
        for v in hardware {
            assert!(v.wgsl.contains("rayQueryInitialize"), "{}", v.name);
            let portable = v.name.trim_end_matches(" [hardware ray query]");
            let fallback = variants
                .iter()
                .find(|p| p.name == portable)
                .unwrap_or_else(|| panic!("{}: no portable fallback", v.name));
            assert!(fallback.features.is_empty() && !fallback.wgsl.contains("ray_query"));
        }
    }

    /// Every variant validates with naga (as the device would) and has a compute entry point;
    /// names are unique; every module of the library is used by some variant (a module nothing
    /// composes is dead code).
    #[test]
    fn every_shader_variant_validates_and_every_module_is_used() {
        let variants = shader_variants();
        let mut names = std::collections::BTreeSet::new();
        for v in &variants {
            assert!(names.insert(v.name.clone()), "{} twice", v.name);
            let module = crate::gpu::wgsl_check::validate_for(&v.name, &v.wgsl, v.features);
            assert!(
                module
                    .entry_points
                    .iter()
                    .any(|e| e.stage == naga::ShaderStage::Compute),
                "{}: no compute entry point",
                v.name
            );
        }
        // 2 sort + 3 scene + 4 cache + 1 rays + 4 debug views + 48 trace tasks + the denoisers.
        assert!(variants.len() > 62, "{} variants", variants.len());
        for module in crate::gpu::compose::shader_modules() {
            let header = crate::gpu::compose::module_header(module);
            assert!(
                variants.iter().any(|v| v.wgsl.contains(&header)),
                "no shader composes the module {module}"
            );
        }
    }
}
