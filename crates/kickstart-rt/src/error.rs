//! The one error type of the SDK.

/// Everything a public call of kickstart-rt can fail with.
///
/// Every variant names what was wrong closely enough to find it in the caller's code: the task,
/// the field and the value for bad input, the handle kind for a stale handle.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A task field holds a value the SDK cannot accept. Nothing was recorded.
    #[error("{task}: field `{field}` has invalid value {value}: {reason}")]
    InvalidInput {
        /// The task or input kind, e.g. `GeometryTask` or `TraceSpecularTask`.
        task: &'static str,
        /// The field path inside the task, e.g. `input.components[1].index_buffer.offset`.
        field: String,
        /// The offending value, formatted.
        value: String,
        /// Why it is rejected and what would be accepted.
        reason: String,
    },
    /// A handle that was destroyed, never created by this context, or belongs to another context.
    #[error("invalid {kind:?} handle (index {index}, generation {generation}): destroyed or never created by this context")]
    InvalidHandle {
        /// Which kind of handle.
        kind: HandleKind,
        /// The handle's slot index.
        index: u32,
        /// The handle's generation.
        generation: u32,
    },
    /// A `GpuTaskHandle` that this context did not hand out, or that was already marked complete.
    #[error("unknown or already completed GPU task handle {0}")]
    InvalidGpuTaskHandle(u64),
    /// Building one more GPU task would exceed `InitSettings::supported_working_sets`.
    #[error("all {supported} working sets are in flight: mark a GPU task completed before building another")]
    WorkingSetsExhausted {
        /// The configured number of working sets.
        supported: u32,
    },
    /// A task type whose GPU work is not implemented yet.
    #[error("{task} is not supported yet by this version of kickstart-rt")]
    Unsupported {
        /// The task type.
        task: &'static str,
    },
    /// The wgpu device lacks a feature the SDK needs.
    #[error("the device lacks required feature(s) {0}; request kickstart_rt::required_features()")]
    MissingFeatures(String),
    /// The wgpu device's limits are below what the SDK needs.
    #[error("the device's limit `{name}` is {actual}, the SDK needs {required}; request kickstart_rt::required_limits()")]
    InsufficientLimit {
        /// The `wgpu::Limits` field name.
        name: &'static str,
        /// The device's value.
        actual: u64,
        /// The value the SDK needs.
        required: u64,
    },
    /// The application was built against an incompatible major version of the SDK.
    #[error(
        "application built against kickstart-rt {app}, library is {library}: major versions differ"
    )]
    IncompatibleVersion {
        /// The version in `InitSettings`.
        app: crate::version::Version,
        /// `kickstart_rt::VERSION`.
        library: crate::version::Version,
    },
    /// A shared pool or table would exceed what one storage binding of this device may hold.
    /// Found by `build_gpu_task`'s plan, before anything is recorded: the context is unchanged.
    #[error("{what}: {bytes} bytes would exceed the device's max_storage_buffer_binding_size ({limit} bytes)")]
    OutOfDeviceMemory {
        /// The pool or object that needed the memory.
        what: String,
        /// Bytes it would have needed.
        bytes: u64,
        /// The device's limit.
        limit: u64,
    },
    /// The device reported an error while `build_gpu_task` recorded: it was lost (removed,
    /// reset, or destroyed with `Device::destroy`), ran out of memory, or refused a command. The
    /// recorded commands must not be submitted, and the context refuses every later task with
    /// this error: create a new device and context (registering the scene again).
    #[error("{operation}: the device reported an error, so the context can no longer record ({message}); create a new device and context")]
    Device {
        /// The call that saw it.
        operation: &'static str,
        /// What the device said.
        message: String,
    },
    /// A blocking read-back (tools and tests only) failed.
    #[error("GPU read-back failed: {0}")]
    ReadBack(String),
    /// An operation that needs every GPU task completed was called while some are in flight.
    #[error("{operation} needs every GPU task marked completed, {in_flight} still in flight")]
    TasksInFlight {
        /// The refused operation.
        operation: &'static str,
        /// How many GPU tasks are outstanding.
        in_flight: usize,
    },
}

/// `Result` with the SDK's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Shorthand for [`Error::InvalidInput`].
    pub(crate) fn input(
        task: &'static str,
        field: impl Into<String>,
        value: impl std::fmt::Debug,
        reason: impl Into<String>,
    ) -> Self {
        Error::InvalidInput {
            task,
            field: field.into(),
            value: format!("{value:?}"),
            reason: reason.into(),
        }
    }
}

/// The kinds of handle an [`crate::ExecuteContext`] hands out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum HandleKind {
    /// [`crate::GeometryHandle`].
    Geometry,
    /// [`crate::InstanceHandle`].
    Instance,
    /// [`crate::DenoisingContextHandle`].
    DenoisingContext,
}
