//! Small wgpu helpers shared by every pass: buffers and read-backs, recording dispatches (with
//! optional timestamps), the shader composer and pipeline creation, and the GPU radix sort.

pub(crate) mod buffers;
pub(crate) mod compose;
pub(crate) mod layout;
pub(crate) mod radix_sort;
pub(crate) mod recorder;
pub(crate) mod reflect;
pub(crate) mod shader;
pub(crate) mod shader_files;
pub(crate) mod spirv;
#[cfg(test)]
pub(crate) mod testing;
#[cfg(test)]
pub(crate) mod wgsl_check;

pub(crate) use recorder::Recorder;
