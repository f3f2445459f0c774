//! Every WGSL shader the SDK can create, as composed: for tools that compile the SDK's shaders
//! outside it (`ksrt shaders --dump`, a browser's WebGPU, driver statistics), and for the
//! CPU-only test that validates them all.

/// One shader the SDK can create: a pass and, where it has variants, which one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShaderVariant {
    /// The pass and its variant, e.g. `TraceShadowTask (Rgba16Float, None)` (unique).
    pub name: String,
    /// The composed WGSL, as the SDK hands it to the device.
    pub wgsl: String,
}

/// Every shader the SDK can create, each variant once: the BVH builders and the radix sort, the
/// lighting cache's passes, ray batches, debug views, the trace tasks (kind × output formats) and
/// the denoisers (signal set × output format). All are portable WGSL: where a device allows it,
/// the traversal passes are also compiled from our own SPIR-V (native only), with these as their
/// fallback.
pub fn shader_variants() -> Vec<ShaderVariant> {
    let passes = [
        crate::gpu::radix_sort::shader_variants(),
        crate::scene::ingest::shader_variants(),
        crate::scene::prims::shader_variants(),
        crate::scene::lbvh::shader_variants(),
        crate::cache::alloc::shader_variants(),
        crate::cache::inject::shader_variants(),
        crate::cache::transfer::shader_variants(),
        crate::trace::rays::shader_variants(),
        crate::trace::debug_view::shader_variants(),
        crate::trace::tasks::shader_variants(),
        crate::denoise::shader_variants(),
    ];
    passes
        .into_iter()
        .flatten()
        .map(|(name, wgsl)| ShaderVariant { name, wgsl })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every variant validates with naga (as the device would) and has a compute entry point;
    /// names are unique; every module of the library is used by some variant (a module nothing
    /// composes is dead code).
    #[test]
    fn every_shader_variant_validates_and_every_module_is_used() {
        let variants = shader_variants();
        let mut names = std::collections::BTreeSet::new();
        for v in &variants {
            assert!(names.insert(v.name.clone()), "{} twice", v.name);
            let module = crate::gpu::wgsl_check::validate(&v.name, &v.wgsl);
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
        for module in crate::shader_modules() {
            let header = crate::gpu::compose::module_header(module);
            assert!(
                variants.iter().any(|v| v.wgsl.contains(&header)),
                "no shader composes the module {module}"
            );
        }
    }
}
