//! `DirectLightTransferTask`: the target instance's cache is filled from the source's (the LOD
//! switch of the integration guide). Every surfel of the target reads the source's interpolated
//! radiance at the same primitive index and barycentrics, so the source and target geometries
//! must have the same triangle count and order (the same geometry, or LODs that keep it); the
//! layouts and resolutions may differ. Transferred surfels count as one injection.

use bytemuck::{Pod, Zeroable};

use crate::gpu::reflect::{ReflectedPipeline, ReflectedShader};
use crate::gpu::Recorder;

/// The WGSL of the transfer pass, labelled.
pub(crate) fn shader_variants() -> Vec<(String, String)> {
    vec![(
        "light transfer".into(),
        transfer_shader().source().to_string(),
    )]
}

/// The transfer pass's shader (the sampling module at group 0, its surfels writable).
fn transfer_shader() -> ReflectedShader {
    ReflectedShader::compose(&["cache/transfer"], &super::sample_params(0, true))
}

#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy)]
struct TransferParams {
    source: u32,
    target: u32,
    tri_count: u32,
    pad: u32,
}

/// The transfer pass.
#[derive(Default)]
pub(crate) struct Transferer {
    pipeline: Option<ReflectedPipeline>,
}

impl Transferer {
    fn pipeline(&mut self, device: &wgpu::Device) -> &ReflectedPipeline {
        self.pipeline.get_or_insert_with(|| {
            transfer_shader().pipeline(device, "kickstart-rt light transfer", "transfer")
        })
    }

    /// Creates the pipeline now.
    pub fn prepare(&mut self, device: &wgpu::Device) {
        self.pipeline(device);
    }

    /// Records a transfer from instance slot `source` to `target` (`tri_count` triangles each).
    pub fn record(
        &mut self,
        rec: &mut Recorder<'_>,
        (meta, surfels): (&wgpu::Buffer, &wgpu::Buffer),
        source: u32,
        target: u32,
        tri_count: u32,
    ) {
        let pipeline = self.pipeline(rec.device);
        let params = rec.uniform(
            "kickstart-rt light transfer params",
            &TransferParams {
                source,
                target,
                tri_count,
                pad: 0,
            },
        );
        let cache = pipeline.bind_group(
            rec.device,
            "kickstart-rt light transfer cache",
            0,
            &[("cache_meta", meta), ("cache_surfels", surfels)],
        );
        let io = pipeline.bind_group(
            rec.device,
            "kickstart-rt light transfer params",
            1,
            &[("params", &params)],
        );
        rec.scope = "light transfer";
        rec.dispatch(
            "cache transfer",
            &pipeline.pipeline,
            &[&cache, &io],
            tri_count.div_ceil(64),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::wgsl_check::{assert_wgsl_layout, storage_stride, validate};

    /// The pass's WGSL validated with naga without a device, and its uniform against it.
    #[test]
    fn the_wgsl_validates_and_matches_the_rust_layout() {
        let module = validate("light transfer", transfer_shader().source());
        assert!(module.entry_points.iter().any(|e| e.name == "transfer"));
        assert_wgsl_layout!(
            module,
            "TransferParams",
            TransferParams {
                source,
                target => "target_slot",
                tri_count,
                pad,
            }
        );
        assert_eq!(
            storage_stride(&module, "cache_surfels") as u64,
            crate::cache::alloc::SURFEL_BYTES
        );
    }
}
