//! Keeps the SDK's imports pointing down its layers (listed in `lib.rs`): a test reads every
//! source file, resolves each `crate::…` and `super::…` path to the file it names, and fails on
//! an import from a lower layer to a higher one or on a loop between files. Test code is left
//! out: a test module imports its parent by design.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

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

fn layer(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

/// The source of `path` without its test code (test files, and the `#[cfg(test)]` module that
/// ends a file by convention).
fn non_test_source(path: &Path) -> Option<String> {
    let name = path.file_name()?.to_str()?;
    let in_tests_dir = path.components().any(|c| c.as_os_str() == "tests");
    if name == "tests.rs" || name == "test_scene.rs" || name == "testing.rs" || in_tests_dir {
        return None;
    }
    let text = std::fs::read_to_string(path).ok()?;
    let cut = text.find("#[cfg(test)]\nmod tests").unwrap_or(text.len());
    Some(text[..cut].to_string())
}

/// The module path of a source file (`src/scene/lbvh/mod.rs` → `["scene", "lbvh"]`).
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap_or(file).with_extension("");
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if parts.last().is_some_and(|p| p == "mod" || p == "lib") {
        parts.pop();
    }
    parts
}

/// The longest prefix of `path` that names a source file of `files`.
fn resolve(files: &BTreeMap<Vec<String>, PathBuf>, path: &[String]) -> Option<Vec<String>> {
    (1..=path.len())
        .rev()
        .map(|n| path[..n].to_vec())
        .find(|p| files.contains_key(p))
}

/// Every `crate::a::b…` and `super::…` path in `text`, as module paths from the crate root.
fn imported_paths(module: &[String], text: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let word = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == ':';
    for (i, _) in text
        .match_indices("crate::")
        .chain(text.match_indices("super::"))
    {
        if text[..i].ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_' || c == ':') {
            continue;
        }
        let rest: String = text[i..].chars().take_while(|&c| word(c)).collect();
        let mut segs: Vec<String> = rest
            .split("::")
            .filter(|s| !s.is_empty())
            .map(String::from)
            .collect();
        let mut base: Vec<String> = Vec::new();
        if segs.first().is_some_and(|s| s == "crate") {
            segs.remove(0);
        } else {
            // `super` of a file `a/b.rs` is `a`; of `a/b/mod.rs` it is `a` too (module `a::b`).
            base = module.to_vec();
            while segs.first().is_some_and(|s| s == "super") {
                segs.remove(0);
                base.pop();
            }
        }
        base.extend(segs.into_iter().take_while(|s| {
            s.chars()
                .next()
                .is_some_and(|c| c.is_ascii_lowercase() || c == '_')
        }));
        out.push(base);
    }
    out
}

/// The import graph of the crate's non-test source files.
fn graph() -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut paths = Vec::new();
    let mut dirs = vec![src.clone()];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                paths.push(p);
            }
        }
    }
    let files: BTreeMap<Vec<String>, PathBuf> = paths
        .iter()
        .map(|p| (module_of(&src, p), p.clone()))
        .collect();
    let mut edges = BTreeMap::new();
    for (module, path) in &files {
        let Some(text) = non_test_source(path) else {
            continue;
        };
        let targets: BTreeSet<Vec<String>> = imported_paths(module, &text)
            .iter()
            .filter_map(|p| resolve(&files, p))
            .filter(|t| t != module && !t.is_empty())
            // A parent module naming its children (`mod x; pub use x::…`) is not an import.
            .filter(|t| !t.starts_with(module))
            .collect();
        edges.insert(module.clone(), targets);
    }
    edges
}

#[test]
fn every_import_points_down_the_layers() {
    let mut upward = Vec::new();
    for (from, targets) in graph() {
        let Some(from_layer) = from.first().and_then(|m| layer(m)) else {
            continue;
        };
        for to in targets {
            let to_layer = to.first().and_then(|m| layer(m));
            if to_layer.is_some_and(|l| l > from_layer) {
                upward.push(format!("{} -> {}", from.join("::"), to.join("::")));
            }
        }
    }
    assert!(upward.is_empty(), "imports up the layers: {upward:#?}");
}

#[test]
fn every_top_level_module_has_a_layer() {
    let unlisted: Vec<String> = graph()
        .keys()
        .filter_map(|m| m.first())
        .filter(|m| layer(m).is_none() && *m != "layering")
        .cloned()
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    assert!(unlisted.is_empty(), "modules without a layer: {unlisted:?}");
}

#[test]
fn no_import_loop_between_files_or_folders() {
    let g = graph();
    // Folders: the graph of the first two path segments (a file of the crate root, or a
    // folder's module and its files grouped by folder).
    let folder = |m: &Vec<String>| m.first().cloned().unwrap_or_default();
    let mut folders: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (from, targets) in &g {
        for to in targets {
            if folder(from) != folder(to) {
                folders.entry(folder(from)).or_default().insert(folder(to));
            }
        }
    }
    let files: BTreeMap<String, BTreeSet<String>> = g
        .iter()
        .map(|(k, v)| (k.join("::"), v.iter().map(|t| t.join("::")).collect()))
        .collect();
    for (what, graph) in [("files", files), ("folders", folders)] {
        if let Some(cycle) = find_cycle(&graph) {
            panic!("import loop between {what}: {}", cycle.join(" -> "));
        }
    }
}

/// A cycle of `graph`, if it has one (depth-first search with colours).
fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        n: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(n.to_string(), 1);
        stack.push(n.to_string());
        for m in graph.get(n).into_iter().flatten() {
            match state.get(m.as_str()).copied().unwrap_or(0) {
                1 => {
                    let start = stack.iter().position(|s| s == m).unwrap_or(0);
                    let mut cycle = stack[start..].to_vec();
                    cycle.push(m.clone());
                    return Some(cycle);
                }
                0 => {
                    if let Some(c) = visit(m, graph, state, stack) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        stack.pop();
        state.insert(n.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for n in graph.keys() {
        if state.get(n.as_str()).copied().unwrap_or(0) == 0 {
            if let Some(c) = visit(n, graph, &mut state, &mut Vec::new()) {
                return Some(c);
            }
        }
    }
    None
}

#[test]
fn the_checks_see_an_upward_import_and_a_loop() {
    let module = vec!["scene".to_string(), "gpu_scene".to_string()];
    let paths = imported_paths(
        &module,
        "use crate::trace::rays::RayTracer;\nsuper::pool::Range",
    );
    assert_eq!(
        paths,
        vec![
            vec!["trace".to_string(), "rays".to_string()],
            vec!["scene".to_string(), "pool".to_string()],
        ]
    );
    assert!(layer("trace") > layer("scene"));
    let g: BTreeMap<String, BTreeSet<String>> = [
        ("a".to_string(), BTreeSet::from(["b".to_string()])),
        ("b".to_string(), BTreeSet::from(["a".to_string()])),
    ]
    .into();
    assert!(find_cycle(&g).is_some());
}
