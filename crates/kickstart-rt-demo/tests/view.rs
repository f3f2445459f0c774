//! `ksrt view` under a virtual display: the window opens on software Vulkan, renders, and its
//! last frame (`--screenshot`) is the image `ksrt render` makes of the same view.
//!
//! Needs `xvfb-run` (Debian: `apt-get install xvfb`; `.ci/run` installs it). Without it the test
//! fails with that message: it is never skipped.

use std::path::{Path, PathBuf};
use std::process::Command;

fn out_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../target/ksrt-test")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create test folder");
    dir
}

fn run(cmd: &mut Command) -> String {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run {cmd:?}: {e}"));
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{cmd:?} failed: {text}");
    text
}

#[test]
fn view_under_xvfb_shows_what_render_writes() {
    let xvfb = Command::new("xvfb-run").arg("--help").output();
    assert!(
        xvfb.is_ok(),
        "xvfb-run not found: install xvfb (apt-get install -y xvfb) to test `ksrt view`"
    );
    let dir = out_dir("view");
    let exe = env!("CARGO_BIN_EXE_ksrt");
    let camera = "0.3,2.4,6,0.2,0.8,0,50";
    let shot = dir.join("view.png");
    let text = run(Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 640x480x24", exe, "view"])
        .args(["--size", "160x90", "--frames", "6", "--camera", camera])
        .arg("--screenshot")
        .arg(&shot));
    assert!(text.contains("wrote"), "{text}");
    run(Command::new(exe)
        .args([
            "render", "--size", "160x90", "--frames", "6", "--camera", camera,
        ])
        .args(["--debug-view", "hit-t", "--out"])
        .arg(&dir));
    let a = image::open(&shot).expect("screenshot").to_rgb8();
    let b = image::open(dir.join("final.png"))
        .expect("render")
        .to_rgb8();
    assert_eq!(a.dimensions(), (160, 90));
    assert_eq!(a.dimensions(), b.dimensions());
    let diff: f64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .sum::<f64>()
        / a.as_raw().len() as f64;
    assert!(
        diff < 2.0,
        "the window shows another image: mean |Δ| {diff:.2} of 255"
    );
    // Not a blank frame: the default scene's sky, floor and objects.
    let distinct: std::collections::HashSet<[u8; 3]> = a.pixels().map(|p| p.0).collect();
    assert!(distinct.len() > 50, "{} colours", distinct.len());
}
