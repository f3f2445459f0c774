//! The passes themselves: every pipeline compiles (from SPIR-V where the device takes it), and
//! the dispatch size of the traced grid.

use super::*;

#[test]
fn every_pipeline_compiles_including_prepared_ones() {
    let g = testing::gpu();
    let mut passes = TracePasses::new(&g.device, &g.queue, testing::backend());
    let builds = LeafTest::all(testing::backend());
    for &leaf in builds {
        passes.prepare(&g.device, leaf);
    }
    // Eight kinds × formats, and the diffuse pass writing AO in two formats, per build.
    assert_eq!(passes.pipelines.len(), 10 * builds.len());
    for f in crate::tasks::WRITABLE_OUTPUT_FORMATS {
        passes
            .pipeline(&g.device, TraceKind::AmbientOcclusion, (f, None), builds[0])
            .unwrap();
    }
    assert!(passes
        .pipeline(
            &g.device,
            TraceKind::Shadow,
            (wgpu::TextureFormat::Rgba8Unorm, None),
            builds[0]
        )
        .is_err());
    // Where the device takes our SPIR-V, every pass must come from it (a pass that silently fell
    // back to WGSL would zero-fill its stack per invocation again). The expectation comes from
    // the test device's backend and features, not from the code that decides. The hardware
    // backend's passes keep no stack, so they have nothing to take our SPIR-V for.
    let expected = crate::gpu::spirv::test_device_takes_own_spirv(&g.device)
        && testing::backend() == crate::device::TraversalBackend::Software;
    for p in &passes.pipelines {
        let (kind, formats, leaf) = (p.kind.label(), p.formats, p.leaf);
        assert_eq!(p.own_spirv, expected, "{kind} {formats:?} {leaf:?}");
    }
}

#[test]
fn a_dispatch_has_one_workgroup_per_tile_of_the_traced_grid() {
    use crate::tasks::HalfResolutionMode::{Checkerboard, Off, OnePer2x2, OnePer4x4};
    // 21 × 13 pixels: 3 × 2 tiles of 8; checkerboard traces a grid of 11 × 13, 2 × 2 tiles;
    // one per 2×2 a grid of 11 × 7 (2 × 1 tiles), one per 4×4 6 × 4 (1 tile).
    assert_eq!(traced_tiles(21, 13, Off), Some(6));
    assert_eq!(traced_tiles(21, 13, Checkerboard), Some(4));
    assert_eq!(traced_tiles(21, 13, OnePer2x2 { phase: 3 }), Some(2));
    assert_eq!(traced_tiles(21, 13, OnePer4x4 { phase: 9 }), Some(1));
    assert_eq!(traced_tiles(1920, 1080, Off), Some(240 * 135));
    assert_eq!(
        traced_tiles(1920, 1080, OnePer2x2 { phase: 0 }),
        Some(120 * 68)
    );
    assert_eq!(traced_tiles(8, 8, Off), Some(1));
    assert_eq!(traced_tiles(0, 8, Off), Some(0));
    // 2^16 × 2^16 pixels need 2^32 invocations: more than the shader's u32 index holds.
    assert_eq!(traced_tiles(65_536, 65_536, Off), None);
    assert_eq!(traced_tiles(65_536, 65_528, Off), Some(8192 * 8191));
}
