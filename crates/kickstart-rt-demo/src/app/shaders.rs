//! `ksrt shaders`: every WGSL shader the SDK can create, as the SDK composes it, listed or written
//! to a folder (one file per variant) for checking them outside the SDK: a browser's WebGPU
//! compiler, a driver's statistics (`shader-stats`), a diff between versions.

use std::path::Path;

/// A file name for a variant's name: ASCII letters, digits, `-` and `_` kept, runs of anything
/// else one `_` (variant names hold spaces, parentheses and commas).
fn file_name(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    for c in name.chars() {
        if c.is_ascii_alphanumeric() || c == '-' {
            out.push(c);
        } else if !out.ends_with('_') {
            out.push('_');
        }
    }
    out.trim_matches('_').to_string()
}

/// The portable variant a native one falls back to: the same pass, without the SDK's
/// ` [hardware ray query]` suffix.
fn portable_name(name: &str) -> &str {
    name.trim_end_matches(" [hardware ray query]")
}

/// Lists every variant (name, lines, and the native features it needs); with `dump`, writes each
/// to `dump/<name>.wgsl` and an `index.txt` of `file<TAB>variant name<TAB>features<TAB>fallback`
/// lines, the last two empty for portable WGSL (a native variant's fallback is the portable
/// variant of the same pass).
pub fn run(dump: Option<&Path>) -> kickstart_rt_renderer::error::AnyResult<()> {
    let variants = kickstart_rt::shader_variants();
    let mut index = String::new();
    if let Some(dir) = dump {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    }
    for v in &variants {
        let file = format!("{}.wgsl", file_name(&v.name));
        let (features, fallback) = if v.features.is_empty() {
            (String::new(), String::new())
        } else {
            let names: Vec<&str> = v.features.iter_names().map(|(n, _)| n).collect();
            (names.join("|"), portable_name(&v.name).to_string())
        };
        println!(
            "{:>6} lines  {}{}",
            v.wgsl.lines().count(),
            v.name,
            if features.is_empty() {
                String::new()
            } else {
                format!("  (native: {features})")
            }
        );
        if let Some(dir) = dump {
            let path = dir.join(&file);
            std::fs::write(&path, &v.wgsl)
                .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
            index.push_str(&format!("{file}\t{}\t{features}\t{fallback}\n", v.name));
        }
    }
    if let Some(dir) = dump {
        let path = dir.join("index.txt");
        std::fs::write(&path, index)
            .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        println!("wrote {} shaders to {}", variants.len(), dir.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variant_names_become_distinct_plain_file_names() {
        assert_eq!(
            file_name("TraceShadowTask (Rgba16Float, None)"),
            "TraceShadowTask_Rgba16Float_None"
        );
        let variants = kickstart_rt::shader_variants();
        let names: std::collections::BTreeSet<String> =
            variants.iter().map(|v| file_name(&v.name)).collect();
        assert_eq!(
            names.len(),
            variants.len(),
            "two variants share a file name"
        );
    }

    #[test]
    fn a_dump_folder_that_cannot_be_made_is_an_error_naming_it() {
        // A regular file where the folder should be: creating the folder fails.
        let file = std::env::temp_dir().join(format!("ksrt-shaders-file-{}", std::process::id()));
        std::fs::write(&file, b"not a folder").unwrap();
        let err = run(Some(&file)).unwrap_err().to_string();
        std::fs::remove_file(&file).unwrap();
        assert!(err.starts_with("cannot create "), "{err}");
        assert!(err.contains(&file.display().to_string()), "{err}");
    }

    #[test]
    fn the_dump_writes_every_variant_as_composed_and_an_index() {
        let dir = std::env::temp_dir().join(format!("ksrt-shaders-{}", std::process::id()));
        run(Some(&dir)).unwrap();
        let variants = kickstart_rt::shader_variants();
        let index = std::fs::read_to_string(dir.join("index.txt")).unwrap();
        assert_eq!(index.lines().count(), variants.len());
        for line in index.lines() {
            let [file, name, features, fallback] = line.split('\t').collect::<Vec<_>>()[..] else {
                panic!("{line}: not four columns");
            };
            let v = variants.iter().find(|v| v.name == name).unwrap();
            assert_eq!(std::fs::read_to_string(dir.join(file)).unwrap(), v.wgsl);
            assert_eq!(features.is_empty(), v.features.is_empty(), "{line}");
            // A native variant names a portable fallback that is in the dump too.
            if !features.is_empty() {
                let f = variants.iter().find(|p| p.name == fallback).unwrap();
                assert!(f.features.is_empty(), "{line}");
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
