//! The reference's `Log` namespace: every SDK message goes to the `log` crate and, optionally, to a
//! user callback, filtered by a minimum severity.

use std::sync::{Arc, RwLock};

/// Severity of an SDK message, lowest first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Severity {
    /// Diagnostic detail.
    Info,
    /// Something the application should look at; the SDK carried on.
    Warning,
    /// An operation failed; its `Error` is returned as well.
    Error,
}

/// A user callback that receives SDK messages at or above the minimum severity.
pub type LogCallback = Arc<dyn Fn(Severity, &str) + Send + Sync>;

/// Where an [`crate::ExecuteContext`]'s messages go.
#[derive(Clone)]
pub(crate) struct Logger {
    inner: Arc<RwLock<LoggerState>>,
}

struct LoggerState {
    callback: Option<LogCallback>,
    min_severity: Severity,
}

impl Logger {
    pub(crate) fn new(callback: Option<LogCallback>, min_severity: Severity) -> Self {
        Logger {
            inner: Arc::new(RwLock::new(LoggerState {
                callback,
                min_severity,
            })),
        }
    }

    pub(crate) fn set_callback(&self, callback: Option<LogCallback>) {
        if let Ok(mut s) = self.inner.write() {
            s.callback = callback;
        }
    }

    pub(crate) fn set_min_severity(&self, min: Severity) {
        if let Ok(mut s) = self.inner.write() {
            s.min_severity = min;
        }
    }

    pub(crate) fn message(&self, severity: Severity, msg: &str) {
        let Ok(s) = self.inner.read() else { return };
        if severity < s.min_severity {
            return;
        }
        match severity {
            Severity::Info => log::info!(target: "kickstart_rt", "{msg}"),
            Severity::Warning => log::warn!(target: "kickstart_rt", "{msg}"),
            Severity::Error => log::error!(target: "kickstart_rt", "{msg}"),
        }
        if let Some(cb) = &s.callback {
            cb(severity, msg);
        }
    }
}
