//! Embeds the git commit in `ksrt` (KSRT_COMMIT): benchmark reports name the commit they
//! measured, and the GPU machine that runs them has no `.git`.

use std::path::PathBuf;
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    // No optional locks: `git status` would otherwise refresh and rewrite the index, which this
    // script watches, so every build would run it again and rebuild `ksrt`.
    let out = Command::new("git")
        .args(["--no-optional-locks"])
        .args(args)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    let commit = git(&["rev-parse", "--short=12", "HEAD"]).unwrap_or_else(|| "unknown".into());
    let dirty =
        git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
    let suffix = if dirty { "-dirty" } else { "" };
    println!("cargo:rustc-env=KSRT_COMMIT={commit}{suffix}");
    // The repository's own HEAD and index (in a worktree `.git` is a file and they live under
    // the main repository's `.git/worktrees/`). A path that does not exist would make cargo run
    // this script, and rebuild `ksrt`, on every build.
    let watched: Vec<PathBuf> = git(&["rev-parse", "--absolute-git-dir"])
        .map(PathBuf::from)
        .map(|dir| vec![dir.join("HEAD"), dir.join("index")])
        .unwrap_or_default();
    println!("cargo:rerun-if-changed=build.rs");
    for path in watched.iter().filter(|p| p.exists()) {
        println!("cargo:rerun-if-changed={}", path.display());
    }
}
