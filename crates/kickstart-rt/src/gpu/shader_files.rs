//! The SDK's WGSL modules, compiled into the crate: one entry per file under `shaders/`, named by
//! its path without the extension (see `gpu/compose.rs`). A test checks this list against the
//! folder, so a new shader file cannot be left out.

/// `include_str!` of `shaders/<name>.wgsl` as `(name, source)`.
macro_rules! modules {
    ($($name:literal,)*) => {
        &[$(($name, include_str!(concat!("../../shaders/", $name, ".wgsl")))),*]
    };
}

/// Every module: `(name, source)`.
pub(crate) const MODULES: &[(&str, &str)] = modules![
    "cache/alloc",
    "cache/inject",
    "cache/inject_depth/depth_format",
    "cache/inject_depth/float_format",
    "cache/layout",
    "cache/resolve",
    "cache/sample",
    "cache/transfer",
    "denoise/atrous",
    "denoise/common",
    "denoise/output/none",
    "denoise/output/one",
    "denoise/record_rgba",
    "denoise/record_scalar",
    "denoise/signals",
    "denoise/temporal",
    "denoise/upsample",
    "gpu/digit_histogram",
    "gpu/radix_sort",
    "gpu/radix_sort_small",
    "gpu/uniform_branch",
    "scene/centroid_bounds",
    "scene/cutout_test",
    "scene/cutout_test_off",
    "scene/ingest",
    "scene/ingest_decode",
    "scene/lbvh/bounds",
    "scene/lbvh/climb",
    "scene/lbvh/common",
    "scene/lbvh/compact",
    "scene/lbvh/gather",
    "scene/lbvh/hierarchy",
    "scene/lbvh/hploc",
    "scene/lbvh/lbvh",
    "scene/lbvh/morton",
    "scene/lbvh/range_refit",
    "scene/opacity",
    "scene/prims",
    "scene/skinning",
    "scene/traversal",
    "scene/traversal_ray_query",
    "scene/triangle_box",
    "scene/types",
    "trace/ao",
    "trace/common",
    "trace/debug_view",
    "trace/gbuffer",
    "trace/radiance",
    "trace/rays",
    "trace/second_output/none",
    "trace/second_output/texture",
    "trace/shadow",
];

#[cfg(test)]
mod tests {
    use std::path::Path;

    /// The module names of every `.wgsl` file under `dir`, relative to `root`.
    fn files(root: &Path, dir: &Path, out: &mut Vec<String>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                files(root, &path, out);
            } else if path.extension().is_some_and(|e| e == "wgsl") {
                let name = path.strip_prefix(root).unwrap().with_extension("");
                out.push(name.to_string_lossy().replace('\\', "/"));
            }
        }
    }

    #[test]
    fn every_shader_file_is_a_module_and_every_module_a_file() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
        let mut on_disk = Vec::new();
        files(&root, &root, &mut on_disk);
        on_disk.sort();
        let listed: Vec<&str> = super::MODULES.iter().map(|&(n, _)| n).collect();
        assert_eq!(on_disk, listed);
    }
}
