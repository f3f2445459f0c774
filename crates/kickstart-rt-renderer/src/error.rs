//! The error type of the renderer's fallible calls.

/// Any error, boxed (SDK, wgpu or a message).
pub type AnyResult<T> = Result<T, Box<dyn std::error::Error>>;
