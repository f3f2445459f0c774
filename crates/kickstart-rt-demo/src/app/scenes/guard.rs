//! Running third-party parsers on untrusted files: a panic inside one becomes an error message,
//! and the process-wide panic hook stays quiet for it (no message or backtrace on stderr for a
//! failure the caller reports itself).

use std::cell::{Cell, RefCell};
use std::panic::{self, AssertUnwindSafe};
use std::sync::Once;

thread_local! {
    /// Guarded calls running on this thread: while above 0, the hook prints nothing.
    static GUARDED: Cell<u32> = const { Cell::new(0) };
    /// Where the last guarded panic on this thread happened (`crate/src/file.rs:line`).
    static LOCATION: RefCell<String> = const { RefCell::new(String::new()) };
}

static INSTALL: Once = Once::new();

/// Wraps the current panic hook once, so that it is skipped for panics inside [`guarded`] on
/// the panicking thread and runs as before everywhere else (tests, other threads).
fn install_quiet_hook() {
    INSTALL.call_once(|| {
        let previous = panic::take_hook();
        panic::set_hook(Box::new(move |info| {
            if GUARDED.with(Cell::get) == 0 {
                previous(info);
            } else {
                let at = info.location().map_or(String::new(), |l| {
                    format!("{}:{}", short_path(l.file()), l.line())
                });
                LOCATION.with(|l| *l.borrow_mut() = at);
            }
        }));
    });
}

/// A source path from its crate's folder on (`gltf-json-1.4.1/src/mesh.rs`), not the registry
/// or checkout it lies in.
fn short_path(file: &str) -> String {
    let parts: Vec<&str> = file.split(['/', '\\']).collect();
    match parts.iter().rposition(|p| *p == "src") {
        Some(k) if k > 0 => parts[k - 1..].join("/"),
        _ => file.to_string(),
    }
}

/// Restores the guard count when the guarded call ends, by return or by unwinding.
struct Guard;

impl Guard {
    fn enter() -> Self {
        GUARDED.with(|g| g.set(g.get().saturating_add(1)));
        Guard
    }
}

impl Drop for Guard {
    fn drop(&mut self) {
        GUARDED.with(|g| g.set(g.get().saturating_sub(1)));
    }
}

/// Runs `f`; a panic inside it is returned as its message and where it happened
/// (`index out of bounds: … at gltf-json-1.4.1/src/mesh.rs:210`) instead of unwinding further,
/// and prints nothing. `f` must not leave shared state half-updated (the loaders only build
/// values they return).
pub(super) fn guarded<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    install_quiet_hook();
    let result = {
        let _guard = Guard::enter();
        panic::catch_unwind(AssertUnwindSafe(f))
    };
    result.map_err(|payload| {
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".to_string());
        let at = LOCATION.with(|l| std::mem::take(&mut *l.borrow_mut()));
        format!("{message} at {at}")
    })
}

#[cfg(test)]
mod tests {
    use super::guarded;

    #[test]
    fn a_panic_becomes_its_message_and_a_value_passes_through() {
        assert_eq!(guarded(|| 7), Ok(7));
        let index = 9;
        let panic_line = line!() + 1;
        let e = guarded(|| [1, 2, 3][index]).unwrap_err();
        assert!(e.contains("index out of bounds"), "{e}");
        let at = format!("at kickstart-rt-demo/src/app/scenes/guard.rs:{panic_line}");
        assert!(e.ends_with(&at), "{e}");
        let e = guarded(|| -> u8 { panic!("bad field {}", 3) }).unwrap_err();
        assert!(e.starts_with("bad field 3 at "), "{e}");
        assert_eq!(
            super::short_path("/r/registry/src/index/gltf-json-1.4.1/src/mesh.rs"),
            "gltf-json-1.4.1/src/mesh.rs"
        );
        // The count is back to zero: a later panic outside the guard still reaches the hook.
        assert_eq!(super::GUARDED.with(std::cell::Cell::get), 0);
    }
}
