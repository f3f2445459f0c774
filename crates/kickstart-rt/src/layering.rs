//! Keeps the SDK's imports pointing down its layers (listed in `lib.rs`): a test reads every
//! source file, resolves each `crate::…` and `super::…` path (use groups expanded) to the file it
//! names, and fails on an import from a lower layer to a higher one or on a loop between files or
//! between top-level modules. Test code is left out: a test module imports its parent by design.
//! Another test fails on an item reached through the crate root (`crate::ViewInfo`, a re-export
//! of `lib.rs`) instead of the module that owns it, since such a path names no module to check.

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

/// The source of `path` without its test code (test files, and the inline `#[cfg(test)]` module
/// that ends a file by convention).
fn non_test_source(path: &Path) -> Option<String> {
    let name = path.file_name()?.to_str()?;
    let in_tests_dir = path.components().any(|c| c.as_os_str() == "tests");
    if name == "tests.rs" || name == "test_scene.rs" || name == "testing.rs" || in_tests_dir {
        return None;
    }
    let text = std::fs::read_to_string(path).ok()?;
    // An inline test module (`mod tests {`, `mod wgsl_tests {`), not a test file's `mod x;`.
    let cut = text
        .match_indices("#[cfg(test)]\nmod ")
        .map(|(i, _)| i)
        .find(|&i| text[i..].lines().nth(1).is_some_and(|l| l.ends_with('{')))
        .unwrap_or(text.len());
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

/// The paths a use tree starting at `chars[*pos]` names, each prefixed by `prefix`:
/// `a::b::{c, d::{e, f as g}}` gives `a::b::c`, `a::b::d::e` and `a::b::d::f`. An inline path
/// (`crate::a::F { … }`, `crate::a::f(…)`) is a tree of one path.
fn use_tree(chars: &[char], pos: &mut usize, prefix: Vec<String>, out: &mut Vec<Vec<String>>) {
    let skip_space = |pos: &mut usize| {
        while chars.get(*pos).is_some_and(|c| c.is_whitespace()) {
            *pos += 1;
        }
    };
    let mut path = prefix;
    loop {
        skip_space(pos);
        if chars.get(*pos) == Some(&'{') {
            *pos += 1;
            loop {
                skip_space(pos);
                match chars.get(*pos) {
                    None => return,
                    Some('}') => {
                        *pos += 1;
                        return;
                    }
                    _ => use_tree(chars, pos, path.clone(), out),
                }
                // Past a rename (`f as g`) to the next tree of the group.
                while chars.get(*pos).is_some_and(|&c| c != ',' && c != '}') {
                    *pos += 1;
                }
                if chars.get(*pos) == Some(&',') {
                    *pos += 1;
                }
            }
        }
        let ident: String = chars[*pos..]
            .iter()
            .take_while(|&&c| c.is_ascii_alphanumeric() || c == '_' || c == '*')
            .collect();
        *pos += ident.chars().count();
        if !ident.is_empty() && ident != "self" && ident != "*" {
            path.push(ident);
        }
        if chars.get(*pos..*pos + 2) == Some(&[':', ':']) {
            *pos += 2;
        } else {
            out.push(path);
            return;
        }
    }
}

/// Every path starting with `crate::` or `super::` in `text`, with use groups expanded, as
/// written (`super` kept).
fn written_paths(text: &str) -> Vec<Vec<String>> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let word = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == ':';
    for i in 0..chars.len() {
        let rest = &chars[i..];
        let starts = |s: &str| rest.iter().take(s.len()).copied().eq(s.chars());
        // `$crate::` is a macro's path, resolved where the macro is used.
        let after_word = i > 0 && (word(chars[i - 1]) || chars[i - 1] == '$');
        if !(starts("crate::") || starts("super::")) || after_word {
            continue;
        }
        let mut pos = i;
        use_tree(&chars, &mut pos, Vec::new(), &mut out);
    }
    out
}

/// Every `crate::a::b…` and `super::…` path in `text`, as module paths from the crate root.
fn imported_paths(module: &[String], text: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    for mut segs in written_paths(text) {
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

/// `text` without its `//` comments (doc links may name the public API through the root).
fn without_comments(text: &str) -> String {
    text.lines()
        .map(|line| match line.find("//") {
            // A `//` inside a string literal (an even count of quotes before it) stays.
            Some(i) if line[..i].matches('"').count() % 2 == 0 => &line[..i],
            _ => line,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The `crate::…` paths of `text` whose first segment is not one of `modules`: an item that
/// `lib.rs` re-exports, reached through the root instead of the module that owns it.
fn root_paths(text: &str, modules: &BTreeSet<String>) -> Vec<String> {
    written_paths(&without_comments(text))
        .into_iter()
        .filter(|p| p.first().is_some_and(|s| s == "crate"))
        .filter(|p| p.get(1).is_none_or(|s| !modules.contains(s)))
        .map(|p| p.join("::"))
        .collect()
}

/// Every source file of the crate, by module path.
fn source_files() -> BTreeMap<Vec<String>, PathBuf> {
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
    paths
        .iter()
        .map(|p| (module_of(&src, p), p.clone()))
        .collect()
}

/// The import graph of the crate's non-test source files.
fn graph() -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let files = source_files();
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

/// The graph of the top-level modules (a file of the crate root, or a folder with all its
/// files): an edge where a file of one imports a file of another.
fn top_level_graph(
    g: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
) -> BTreeMap<String, BTreeSet<String>> {
    let folder = |m: &Vec<String>| m.first().cloned().unwrap_or_default();
    let mut folders: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (from, targets) in g {
        for to in targets {
            if folder(from) != folder(to) {
                folders.entry(folder(from)).or_default().insert(folder(to));
            }
        }
    }
    folders
}

#[test]
fn every_import_names_the_module_that_owns_it() {
    // An item reached as `crate::Item` hides which module the file depends on from the other
    // checks (the path names no module), so a loop between top-level modules through `lib.rs`'s
    // re-exports would go unseen. Test code is checked too.
    let files = source_files();
    let modules: BTreeSet<String> = files.keys().filter_map(|m| m.first()).cloned().collect();
    let mut through_root = Vec::new();
    for (module, path) in &files {
        // lib.rs: its `pub use` lines are the public API; this file: its examples.
        if module.is_empty() || module == &["layering"] {
            continue;
        }
        let text = std::fs::read_to_string(path).unwrap_or_default();
        for p in root_paths(&text, &modules) {
            through_root.push(format!("{}: {p}", module.join("::")));
        }
    }
    assert!(
        through_root.is_empty(),
        "items imported through the crate root instead of their module: {through_root:#?}"
    );
}

#[test]
fn no_import_loop_between_files_or_folders() {
    let g = graph();
    let folders = top_level_graph(&g);
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
    // Groups, nested groups and renames are expanded; comments are not code.
    let modules = BTreeSet::from(["tasks".to_string(), "version".to_string()]);
    let text = "use crate::{tasks::{ViewInfo, Viewport as V}, Error};\n\
                // [`crate::ExecuteContext`]\n\
                let f = crate::WRITABLE_OUTPUT_FORMATS;\n\
                let v = crate::version::VERSION;\n\
                macro_rules! m { () => { $crate::Thing } }";
    assert_eq!(
        root_paths(text, &modules),
        vec![
            "crate::Error".to_string(),
            "crate::WRITABLE_OUTPUT_FORMATS".to_string(),
        ]
    );
    assert!(root_paths("use crate::tasks::{ViewInfo, Viewport};", &modules).is_empty());
    let nested = imported_paths(&module, "use crate::{trace::rays::{A, B}, scene::pool::C};");
    assert_eq!(
        nested,
        vec![
            vec!["trace".to_string(), "rays".to_string()],
            vec!["trace".to_string(), "rays".to_string()],
            vec!["scene".to_string(), "pool".to_string()],
        ]
    );
    // Two files of different top-level modules importing each other are a loop of folders.
    let files: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = [
        (
            vec!["scene".to_string(), "a".to_string()],
            BTreeSet::from([vec!["trace".to_string(), "b".to_string()]]),
        ),
        (
            vec!["trace".to_string(), "c".to_string()],
            BTreeSet::from([vec!["scene".to_string(), "d".to_string()]]),
        ),
    ]
    .into();
    assert!(find_cycle(&top_level_graph(&files)).is_some());
    let g: BTreeMap<String, BTreeSet<String>> = [
        ("a".to_string(), BTreeSet::from(["b".to_string()])),
        ("b".to_string(), BTreeSet::from(["a".to_string()])),
    ]
    .into();
    assert!(find_cycle(&g).is_some());
}
