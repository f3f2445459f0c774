//! The SDK's imports point down its layers (the list below, which `lib.rs` describes), form no
//! loop between files or folders, and name the module that owns each item rather than a
//! re-export of the crate root.

/// The layers, lowest first: a module may import from its own layer and the ones before it.
const LAYERS: &[&[&str]] = &[
    &[
        "error",
        "version",
        "handles",
        "tasks",
        "logging",
        "allocations",
        "container",
        "camera",
    ],
    &["gpu", "staging", "timing", "device"],
    &["cpu"],
    &["scene"],
    &["cache"],
    &["trace"],
    &["denoise"],
    &["context"],
];

#[test]
fn layering_imports_point_down_without_loops_or_crate_root_paths() {
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    if let Err(problems) = kickstart_rt_layering::check(&src, LAYERS) {
        panic!("layering of kickstart-rt:\n{}", problems.join("\n"));
    }
}
