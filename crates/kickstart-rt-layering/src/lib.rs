//! Keeps a crate's imports pointing down its layers: [`check`] reads every source file under a
//! crate's `src/`, resolves each `crate::…` and `super::…` path (grouped `use crate::{a, b::c}`
//! included) to the file it names, and reports
//!
//! - an import from a lower layer to a higher one,
//! - a module that no layer lists,
//! - an import of the crate root (`main.rs` or `lib.rs`: the root declares and dispatches, it
//!   holds nothing another module needs),
//! - a loop between files, or between folders at any depth (`a::x` → `b::y` → `a::z` is a loop
//!   between the folders `a` and `b`).
//!
//! Test code is left out: items under `#[cfg(test)]` (a test module imports its parent by design)
//! and the files such a module declares. Comments are left out too, so a doc link is not an
//! import. A parent module naming its children (`mod x; pub use x::…`) is not an import either.
//!
//! The layers are lists of module paths, lowest first; a module may import from its own layer and
//! the ones before it. An entry names a top-level module (`"scene"`) or a deeper one
//! (`"app::gpu"`); a module's layer is that of the longest entry its path starts with.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A module path from the crate root (`src/scene/lbvh/mod.rs` → `["scene", "lbvh"]`; the root
/// itself is empty).
type ModulePath = Vec<String>;

/// Checks the crate whose sources are under `src_dir` against `layers` (lowest first). `Err`
/// lists every problem found, one line each.
pub fn check(src_dir: &Path, layers: &[&[&str]]) -> Result<(), Vec<String>> {
    let graph = graph(src_dir).map_err(|e| vec![e])?;
    let mut problems = Vec::new();
    problems.extend(unlisted_modules(&graph, layers));
    problems.extend(root_imports(&graph));
    problems.extend(upward_imports(&graph, layers));
    problems.extend(loops(&graph));
    if problems.is_empty() {
        Ok(())
    } else {
        Err(problems)
    }
}

/// The layer of `module`: that of the longest entry of `layers` its path starts with.
fn layer(layers: &[&[&str]], module: &[String]) -> Option<usize> {
    let mut best: Option<(usize, usize)> = None;
    for (k, layer) in layers.iter().enumerate() {
        for entry in layer.iter() {
            let parts: Vec<&str> = entry.split("::").collect();
            let matches = parts.len() <= module.len()
                && parts.iter().zip(module).all(|(p, m)| *p == m.as_str());
            if matches && best.is_none_or(|(len, _)| parts.len() > len) {
                best = Some((parts.len(), k));
            }
        }
    }
    best.map(|(_, k)| k)
}

fn show(module: &[String]) -> String {
    if module.is_empty() {
        "crate root".to_string()
    } else {
        module.join("::")
    }
}

fn unlisted_modules(graph: &Graph, layers: &[&[&str]]) -> Vec<String> {
    graph
        .keys()
        .filter(|m| !m.is_empty() && layer(layers, m).is_none())
        .map(|m| format!("module {} has no layer", show(m)))
        .collect()
}

fn root_imports(graph: &Graph) -> Vec<String> {
    graph
        .iter()
        .filter(|(from, _)| !from.is_empty())
        .filter(|(_, targets)| targets.iter().any(|t| t.is_empty()))
        .map(|(from, _)| format!("{} imports the crate root", show(from)))
        .collect()
}

fn upward_imports(graph: &Graph, layers: &[&[&str]]) -> Vec<String> {
    let mut out = Vec::new();
    for (from, targets) in graph {
        let Some(from_layer) = layer(layers, from) else {
            continue;
        };
        for to in targets {
            if layer(layers, to).is_some_and(|l| l > from_layer) {
                out.push(format!("upward import: {} -> {}", show(from), show(to)));
            }
        }
    }
    out
}

/// Loops between files, and between folders at each depth (modules grouped by their first
/// `depth` path segments; edges inside a group left out).
fn loops(graph: &Graph) -> Vec<String> {
    let max_depth = graph.keys().map(Vec::len).max().unwrap_or(0);
    let mut found: BTreeSet<String> = BTreeSet::new();
    let mut out = Vec::new();
    for depth in (1..=max_depth).rev() {
        let group = |m: &ModulePath| show(&m[..m.len().min(depth)]);
        let mut grouped: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (from, targets) in graph {
            for to in targets {
                let (a, b) = (group(from), group(to));
                if a != b {
                    grouped.entry(a).or_default().insert(b);
                }
            }
        }
        if let Some(cycle) = find_cycle(&grouped) {
            let text = cycle.join(" -> ");
            if found.insert(text.clone()) {
                let what = if depth == max_depth {
                    "files".to_string()
                } else {
                    format!("folders (depth {depth})")
                };
                out.push(format!("import loop between {what}: {text}"));
            }
        }
    }
    out
}

/// The import graph of a crate's non-test source files: each module and the modules it imports.
pub type Graph = BTreeMap<ModulePath, BTreeSet<ModulePath>>;

/// Reads the crate under `src_dir` into its import [`Graph`].
pub fn graph(src_dir: &Path) -> Result<Graph, String> {
    let mut paths = Vec::new();
    let mut dirs = vec![src_dir.to_path_buf()];
    while let Some(d) = dirs.pop() {
        let entries =
            std::fs::read_dir(&d).map_err(|e| format!("{}: cannot read: {e}", d.display()))?;
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                paths.push(p);
            }
        }
    }
    let mut files: BTreeMap<ModulePath, (PathBuf, String)> = BTreeMap::new();
    let mut test_only: Vec<ModulePath> = Vec::new();
    for p in paths {
        let text = std::fs::read_to_string(&p)
            .map_err(|e| format!("{}: cannot read: {e}", p.display()))?;
        let module = module_of(src_dir, &p);
        let (code, test_children) = strip_tests(&strip_comments(&text));
        test_only.extend(test_children.into_iter().map(|c| {
            let mut m = module.clone();
            m.push(c);
            m
        }));
        files.insert(module, (p, code));
    }
    files.retain(|m, _| !test_only.iter().any(|t| m.starts_with(t)));
    let mut edges = Graph::new();
    for (module, (_, code)) in &files {
        let targets: BTreeSet<ModulePath> = imported_paths(module, code)
            .iter()
            .filter_map(|p| resolve(&files, p))
            .filter(|t| t != module)
            // A parent module naming its children is not an import; the root stands above every
            // module, so its imports are not checked.
            .filter(|t| !module.is_empty() && !t.starts_with(module))
            .collect();
        edges.insert(module.clone(), targets);
    }
    Ok(edges)
}

/// The module path of a source file (`src/scene/lbvh/mod.rs` → `["scene", "lbvh"]`,
/// `src/main.rs` and `src/lib.rs` → `[]`).
fn module_of(src: &Path, file: &Path) -> ModulePath {
    let rel = file.strip_prefix(src).unwrap_or(file).with_extension("");
    let mut parts: ModulePath = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    let root_file = parts.len() == 1 && (parts[0] == "main" || parts[0] == "lib");
    if root_file || parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    parts
}

/// The longest prefix of `path` that names a source file of `files` (the root included).
fn resolve<V>(files: &BTreeMap<ModulePath, V>, path: &[String]) -> Option<ModulePath> {
    (0..=path.len())
        .rev()
        .map(|n| path[..n].to_vec())
        .find(|p| files.contains_key(p))
}

/// `text` without comments (doc comments included) and with every string or character literal
/// emptied.
fn strip_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let bytes = text.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        if let Some(end) = literal_end(text, i) {
            // A literal's text is no code: kept as an empty one (its line breaks kept).
            let quote = if text[i..].starts_with('\'') {
                "' '"
            } else {
                "\"\""
            };
            out.push_str(quote);
            out.extend(text[i..end].chars().filter(|&c| c == '\n'));
            i = end;
        } else if text[i..].starts_with("//") {
            let end = text[i..].find('\n').map_or(text.len(), |n| i + n);
            i = end;
        } else if text[i..].starts_with("/*") {
            let end = text[i + 2..]
                .find("*/")
                .map_or(text.len(), |n| i + 2 + n + 2);
            i = end;
        } else {
            let c = text[i..].chars().next().unwrap_or(' ');
            out.push(c);
            i += c.len_utf8();
        }
    }
    out
}

/// When a string or character literal starts at byte `i` of `text`, the byte just after it.
fn literal_end(text: &str, i: usize) -> Option<usize> {
    let rest = &text[i..];
    let prev_is_word = text[..i]
        .chars()
        .next_back()
        .is_some_and(|c| c.is_ascii_alphanumeric() || c == '_');
    // Raw strings: r"…", r#"…"#, br"…".
    let raw = rest.strip_prefix("br").or_else(|| rest.strip_prefix('r'));
    if let (Some(after_r), false) = (raw, prev_is_word) {
        let hashes = after_r.chars().take_while(|&c| c == '#').count();
        if after_r[hashes..].starts_with('"') {
            let close = format!("\"{}", "#".repeat(hashes));
            let body = i + (rest.len() - after_r.len()) + hashes + 1;
            return Some(
                text[body..]
                    .find(&close)
                    .map_or(text.len(), |n| body + n + close.len()),
            );
        }
    }
    if rest.starts_with('"') {
        let mut escaped = false;
        for (n, c) in rest.char_indices().skip(1) {
            match c {
                _ if escaped => escaped = false,
                '\\' => escaped = true,
                '"' => return Some(i + n + 1),
                _ => {}
            }
        }
        return Some(text.len());
    }
    // A character literal ('x', '\n', '{'), not a lifetime ('a).
    if rest.starts_with('\'') {
        let mut chars = rest.char_indices().skip(1);
        match chars.next() {
            Some((_, '\\')) => return rest[2..].find('\'').map(|n| i + 2 + n + 1),
            Some((_, c)) => {
                let after = 1 + c.len_utf8();
                if rest[after..].starts_with('\'') {
                    return Some(i + after + 1);
                }
            }
            None => {}
        }
    }
    None
}

/// `code` without the items under `#[cfg(test)]`, and the names of the child modules declared
/// there as files (`#[cfg(test)] mod tests;`).
fn strip_tests(code: &str) -> (String, Vec<String>) {
    const ATTR: &str = "#[cfg(test)]";
    let mut out = String::with_capacity(code.len());
    let mut children = Vec::new();
    let mut rest = code;
    while let Some(at) = rest.find(ATTR) {
        out.push_str(&rest[..at]);
        let item = &rest[at + ATTR.len()..];
        let end = item_end(item);
        let words: Vec<&str> = item[..end]
            .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .filter(|w| !w.is_empty())
            .collect();
        if item[..end].trim_end().ends_with(';') {
            if let Some(k) = words.iter().position(|w| *w == "mod") {
                if let Some(name) = words.get(k + 1) {
                    children.push((*name).to_string());
                }
            }
        }
        rest = &item[end..];
    }
    out.push_str(rest);
    (out, children)
}

/// The length of the item at the start of `item`: through its first `;` or its first `{…}`
/// block, whichever comes first (literals skipped).
fn item_end(item: &str) -> usize {
    let mut depth = 0usize;
    let mut i = 0;
    while i < item.len() {
        if let Some(end) = literal_end(item, i) {
            i = end;
            continue;
        }
        let c = item[i..].chars().next().unwrap_or(' ');
        match c {
            ';' if depth == 0 => return i + 1,
            '{' => depth += 1,
            '}' => {
                depth = depth.saturating_sub(1);
                if depth == 0 {
                    return i + 1;
                }
            }
            _ => {}
        }
        i += c.len_utf8();
    }
    item.len()
}

/// Every `crate::…` and `super::…` path in `code` (the file of `module`), as module paths from
/// the crate root; a group `crate::{a, b::{c, d}}` gives one path per member.
fn imported_paths(module: &[String], code: &str) -> Vec<ModulePath> {
    let mut out = Vec::new();
    let is_word = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let mut starts: Vec<usize> = code
        .match_indices("crate::")
        .chain(code.match_indices("super::"))
        .map(|(i, _)| i)
        .collect();
    starts.sort_unstable();
    for i in starts {
        if code[..i].ends_with(|c: char| is_word(c) || c == ':') {
            continue;
        }
        let mut base: ModulePath = Vec::new();
        let mut rest = &code[i..];
        if let Some(r) = rest.strip_prefix("crate::") {
            rest = r;
        } else {
            // `super` of a file `a/b.rs` is `a`; of `a/b/mod.rs` it is `a` too (module `a::b`).
            base = module.to_vec();
            while let Some(r) = rest.strip_prefix("super::") {
                rest = r;
                base.pop();
            }
        }
        expand(&base, rest, &mut out);
    }
    out
}

/// The module paths of the path text `rest` (after `crate::` or `super::`) below `base`: the
/// leading lower-case segments, or each member of a `{…}` group.
fn expand(base: &[String], rest: &str, out: &mut Vec<ModulePath>) {
    let mut path = base.to_vec();
    let mut text = rest;
    loop {
        let seg: String = text
            .chars()
            .take_while(|&c| c.is_ascii_alphanumeric() || c == '_')
            .collect();
        if seg.is_empty() {
            break;
        }
        let lower = seg.starts_with(|c: char| c.is_ascii_lowercase() || c == '_');
        if !lower || seg == "self" {
            break;
        }
        path.push(seg.clone());
        text = &text[seg.len()..];
        match text.strip_prefix("::") {
            Some(t) => text = t,
            None => break,
        }
    }
    if let Some(group) = text.strip_prefix('{') {
        let mut depth = 1usize;
        let end = group
            .char_indices()
            .find(|&(_, c)| {
                match c {
                    '{' => depth += 1,
                    '}' => depth -= 1,
                    _ => {}
                }
                depth == 0
            })
            .map_or(group.len(), |(n, _)| n);
        let inner = &group[..end];
        for member in split_top_level(inner) {
            let member = member.trim();
            if member.starts_with("self") || member.is_empty() {
                out.push(path.clone());
            } else {
                expand(&path, member, out);
            }
        }
        return;
    }
    out.push(path);
}

/// `text` split at the commas outside braces.
fn split_top_level(text: &str) -> Vec<&str> {
    let (mut depth, mut start, mut parts) = (0usize, 0, Vec::new());
    for (i, c) in text.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth = depth.saturating_sub(1),
            ',' if depth == 0 => {
                parts.push(&text[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&text[start..]);
    parts
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

#[cfg(test)]
mod tests;
