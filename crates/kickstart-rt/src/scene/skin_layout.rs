//! The skinning pass's GPU layout: one task's parameters as `shaders/scene/skinning.wgsl`
//! reads them ([`Skin`]), and the storage windows a task's ranges are bound through. Shared by
//! the pass, its batching and the task's validation.

/// Invocations of a skinning workgroup (`SKIN_WG`).
pub(crate) const WORKGROUP: u32 = 64;

/// `Skin` in `shaders/scene/skinning.wgsl`: one task of a batch.
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct Skin {
    pub(crate) vertex_count: u32,
    pub(crate) rest_word: u32,
    pub(crate) rest_stride: u32,
    pub(crate) joint_word: u32,
    pub(crate) joint_stride: u32,
    pub(crate) joint_format: u32,
    pub(crate) weight_word: u32,
    pub(crate) weight_stride: u32,
    pub(crate) weight_format: u32,
    pub(crate) joint_count: u32,
    pub(crate) morph_word: u32,
    pub(crate) morph_stride: u32,
    pub(crate) morph_target_stride: u32,
    pub(crate) morph_count: u32,
    pub(crate) morph_weight_at: u32,
    pub(crate) out_word: u32,
    pub(crate) out_stride: u32,
    pub(crate) joint_base: u32,
    /// The batch's first workgroup of this task.
    pub(crate) first_group: u32,
    pub(crate) _pad: u32,
}

impl Skin {
    /// The task placed in its batch: the word offsets of its rest positions, joints, weights,
    /// morph deltas and output within the batch's windows, and its first workgroup.
    pub(crate) fn placed(self, words: [u32; 5], first_group: u32) -> Skin {
        let [rest_word, joint_word, weight_word, morph_word, out_word] = words;
        Skin {
            rest_word,
            joint_word,
            weight_word,
            morph_word,
            out_word,
            first_group,
            ..self
        }
    }
}

/// A byte range of a caller's buffer bound as a storage window: it starts at an offset the
/// device can bind at, and `word` is the range's first word within it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Window {
    /// Bytes from the buffer's start to the window's.
    pub start: u64,
    /// Bytes the window spans (a multiple of 4).
    pub size: u64,
    /// Words from the window's start to the range's.
    pub word: u32,
}

/// The window binding bytes `offset..end` (`end > offset`, both multiples of 4) at the device's
/// storage offset alignment `align`; `None` when the word offset does not fit `u32`.
pub(crate) fn window(offset: u64, end: u64, align: u64) -> Option<Window> {
    let start = offset - offset % align.max(4);
    Some(Window {
        start,
        size: end.checked_sub(start)?.next_multiple_of(4),
        word: u32::try_from((offset - start) / 4).ok()?,
    })
}

/// The end of `count` strided values of `size` bytes from `offset` (`count > 0`; validated to
/// lie inside the buffer).
pub(crate) fn strided_end(offset: u64, stride: u64, count: u32, size: u64) -> Option<u64> {
    let last = stride.checked_mul(u64::from(count.checked_sub(1)?))?;
    offset.checked_add(last)?.checked_add(size)
}
