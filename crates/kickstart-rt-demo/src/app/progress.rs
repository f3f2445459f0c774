//! Progress of `ksrt`'s long phases (scene loading, frames, the CPU reference, debug views,
//! reference samples, bench sweeps): indicatif bars and spinners on stderr, so stdout keeps only
//! results. indicatif draws nothing when stderr is not a terminal (CI logs, pipes), and callers
//! that must stay silent (tests) ask for hidden ones.

use std::borrow::Cow;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `len` steps counted in `unit` (e.g. "frames"), labelled `msg`; hidden unless `show`.
pub fn bar(show: bool, len: u64, msg: impl Into<Cow<'static, str>>, unit: &str) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    let template =
        format!("{{msg}} [{{bar:40}}] {{pos}}/{{len}} {unit} ({{elapsed}}, eta {{eta}})");
    if let Ok(style) = ProgressStyle::with_template(&template) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(msg);
    bar
}

/// A spinner for a phase whose length is unknown (loading a file, building a BVH), ticking on
/// its own so that it moves while the work blocks the thread; hidden unless `show`.
pub fn spinner(show: bool, msg: impl Into<Cow<'static, str>>) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new_spinner();
    if let Ok(style) = ProgressStyle::with_template("{spinner} {msg} ({elapsed})") {
        bar.set_style(style);
    }
    bar.set_message(msg);
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
}

/// Runs `work` under a spinner labelled `msg` (shown when `show`), cleared when it returns.
pub fn with_spinner<T>(
    show: bool,
    msg: impl Into<Cow<'static, str>>,
    work: impl FnOnce() -> T,
) -> T {
    let s = spinner(show, msg);
    let out = work();
    s.finish_and_clear();
    out
}
