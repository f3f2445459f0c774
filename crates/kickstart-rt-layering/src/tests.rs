//! The check on synthetic crates written to a temporary folder: it must pass a clean one and fail
//! on each kind of problem.

use super::*;

/// A fresh folder holding `files` (`(path under src, text)`), removed when dropped.
struct FakeCrate(PathBuf);

impl FakeCrate {
    fn new(name: &str, files: &[(&str, &str)]) -> FakeCrate {
        let dir = std::env::temp_dir().join(format!(
            "kickstart-rt-layering-{}-{name}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        for (path, text) in files {
            let p = dir.join(path);
            std::fs::create_dir_all(p.parent().expect("a parent")).expect("create folder");
            std::fs::write(&p, text).expect("write file");
        }
        FakeCrate(dir)
    }

    fn check(&self, layers: &[&[&str]]) -> Result<(), Vec<String>> {
        check(&self.0, layers)
    }
}

impl Drop for FakeCrate {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

const LAYERS: &[&[&str]] = &[&["low"], &["high"]];

#[test]
fn a_clean_crate_passes() {
    let c = FakeCrate::new(
        "clean",
        &[
            (
                "main.rs",
                "mod low;\nmod high;\nfn main() { high::run(); }\n",
            ),
            ("low.rs", "pub fn helper() {}\n"),
            (
                "high/mod.rs",
                "mod part;\nuse crate::low::helper;\npub fn run() { part::go(); helper() }\n",
            ),
            (
                "high/part.rs",
                "use super::super::low;\npub fn go() { low::helper() }\n",
            ),
        ],
    );
    assert_eq!(c.check(LAYERS), Ok(()));
}

#[test]
fn an_upward_import_fails() {
    let c = FakeCrate::new(
        "upward",
        &[
            ("main.rs", "mod low;\nmod high;\n"),
            ("low.rs", "use crate::high::Thing;\n"),
            ("high.rs", "pub struct Thing;\n"),
        ],
    );
    let err = c.check(LAYERS).expect_err("an upward import");
    assert!(
        err.iter().any(|e| e.contains("upward import: low -> high")),
        "{err:?}"
    );
}

#[test]
fn an_import_circle_fails() {
    // Both in one layer, so only the loop is wrong; the import of `b` is in a group.
    let c = FakeCrate::new(
        "circle",
        &[
            ("main.rs", "mod low;\n"),
            ("low/mod.rs", "mod a;\nmod b;\n"),
            ("low/a.rs", "use crate::{low::b::B, low};\npub struct A;\n"),
            ("low/b.rs", "use super::a::A;\npub struct B;\n"),
        ],
    );
    let err = c.check(&[&["low"]]).expect_err("a loop");
    assert!(
        err.iter()
            .any(|e| e.contains("import loop between files") && e.contains("low::a")),
        "{err:?}"
    );
}

#[test]
fn a_loop_between_folders_fails() {
    // No two files import each other, but the folders `x` and `y` do.
    let c = FakeCrate::new(
        "folders",
        &[
            ("main.rs", "mod x;\nmod y;\n"),
            ("x/mod.rs", "mod one;\nmod two;\n"),
            ("x/one.rs", "use crate::y::three;\n"),
            ("x/two.rs", "pub fn f() {}\n"),
            ("y/mod.rs", "pub mod three;\n"),
            ("y/three.rs", "pub fn g() { crate::x::two::f() }\n"),
        ],
    );
    let err = c.check(&[&["x", "y"]]).expect_err("a loop between folders");
    assert!(err.iter().any(|e| e.contains("between folders")), "{err:?}");
}

#[test]
fn importing_the_root_or_an_unlisted_module_fails() {
    let c = FakeCrate::new(
        "root",
        &[
            ("main.rs", "mod low;\nmod stray;\npub type R = ();\n"),
            ("low.rs", "use crate::R;\n"),
            ("stray.rs", "\n"),
        ],
    );
    let err = c
        .check(LAYERS)
        .expect_err("root import and unlisted module");
    assert!(
        err.iter().any(|e| e == "low imports the crate root"),
        "{err:?}"
    );
    assert!(
        err.iter().any(|e| e == "module stray has no layer"),
        "{err:?}"
    );
}

#[test]
fn test_code_and_comments_are_not_imports() {
    let c = FakeCrate::new(
        "tests",
        &[
            ("main.rs", "mod low;\nmod high;\n"),
            (
                "low.rs",
                "//! See [`crate::high`].\n/// crate::high::Thing\npub fn f() {\n    \
                 let _s = \"{ crate::high }\";\n}\n#[cfg(test)]\nmod tests {\n    \
                 use crate::high::Thing;\n}\n#[cfg(test)]\nmod more_tests;\n",
            ),
            ("low/more_tests.rs", "use crate::high::Thing;\n"),
            ("high.rs", "pub struct Thing;\n"),
        ],
    );
    assert_eq!(c.check(LAYERS), Ok(()));
}

#[test]
fn deeper_layer_entries_win_over_shorter_ones() {
    let layers: &[&[&str]] = &[&["app::base"], &["app"]];
    assert_eq!(layer(layers, &["app".into(), "base".into()]), Some(0));
    assert_eq!(layer(layers, &["app".into(), "view".into()]), Some(1));
    assert_eq!(layer(layers, &["lab".into()]), None);
}

#[test]
fn grouped_imports_give_one_path_per_member() {
    let module = vec!["a".to_string(), "b".to_string()];
    let paths = imported_paths(
        &module,
        "use crate::{x::{y, z::W}, v};\nuse super::c::D;\nsuper::super::e::f();",
    );
    let p = |s: &[&str]| s.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    assert_eq!(
        paths,
        vec![
            p(&["x", "y"]),
            p(&["x", "z"]),
            p(&["v"]),
            p(&["a", "c"]),
            p(&["e", "f"]),
        ]
    );
}
