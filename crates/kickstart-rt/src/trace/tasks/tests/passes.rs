//! The passes themselves: every pipeline compiles (from SPIR-V where the device takes it), and
//! the dispatch size of the traced grid.

use super::*;

#[test]
fn every_pipeline_compiles_including_prepared_ones() {
    let g = testing::gpu();
    let mut passes = TracePasses::new(&g.device, &g.queue);
    passes.prepare(&g.device);
    assert_eq!(passes.pipelines.len(), 8);
    for f in crate::WRITABLE_OUTPUT_FORMATS {
        passes
            .pipeline(&g.device, TraceKind::AmbientOcclusion, (f, None))
            .unwrap();
    }
    assert!(passes
        .pipeline(
            &g.device,
            TraceKind::Shadow,
            (wgpu::TextureFormat::Rgba8Unorm, None)
        )
        .is_err());
    // Where the device takes our SPIR-V, every pass must come from it (a pass that silently fell
    // back to WGSL would zero-fill its stack per invocation again).
    let expected = crate::gpu::shader::spirv_accepted(&g.device);
    for p in &passes.pipelines {
        assert_eq!(p.own_spirv, expected, "{} {:?}", p.kind.label(), p.formats);
    }
}

#[test]
fn a_dispatch_has_one_workgroup_per_tile_of_the_traced_grid() {
    // 21 × 13 pixels: 3 × 2 tiles of 8; checkerboard traces a grid of 11 × 13, 2 × 2 tiles.
    assert_eq!(traced_tiles(21, 13, false), Some(6));
    assert_eq!(traced_tiles(21, 13, true), Some(4));
    assert_eq!(traced_tiles(1920, 1080, false), Some(240 * 135));
    assert_eq!(traced_tiles(8, 8, false), Some(1));
    assert_eq!(traced_tiles(0, 8, false), Some(0));
    // 2^16 × 2^16 pixels need 2^32 invocations: more than the shader's u32 index holds.
    assert_eq!(traced_tiles(65_536, 65_536, false), None);
    assert_eq!(traced_tiles(65_536, 65_528, false), Some(8192 * 8191));
}
