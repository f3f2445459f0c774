//! Batching of a task's skinning: tasks that read and write the same buffers are posed by one
//! dispatch, one `Skin` record each in one storage buffer, instead of a dispatch and a uniform
//! buffer a task. Tasks batch only where the order of their writes cannot matter: a task never
//! joins a batch (or moves ahead of a later one) whose ranges its output overlaps, or whose
//! outputs its inputs overlap.

use super::skin_layout::{window, Skin, Window, WORKGROUP};
use crate::gpu::recorder::MAX_DISPATCH_DIM;

/// A byte range `start..end` of a buffer that a task reads or writes.
#[derive(Clone, Copy)]
pub(crate) struct Span<'a> {
    pub buffer: &'a wgpu::Buffer,
    pub start: u64,
    pub end: u64,
}

impl<'a> Span<'a> {
    /// The span `start..end` of `buffer`.
    pub fn new(buffer: &'a wgpu::Buffer, start: u64, end: u64) -> Self {
        Span { buffer, start, end }
    }

    /// Whether the two spans share a byte of one buffer.
    fn overlaps(&self, other: &Span<'_>) -> bool {
        self.buffer == other.buffer && self.start < other.end && other.start < self.end
    }
}

/// One task ready to batch: its parameters (word offsets unset) and its spans (rest, joints,
/// weights, morphs, output).
pub(crate) struct Posing<'a> {
    skin: Skin,
    spans: [Span<'a>; 5],
    workgroups: u32,
}

impl<'a> Posing<'a> {
    /// The task of `skin` (its `vertex_count` set) reading and writing `spans`.
    pub fn new(skin: Skin, spans: [Span<'a>; 5]) -> Self {
        Posing {
            workgroups: skin.vertex_count.div_ceil(WORKGROUP),
            skin,
            spans,
        }
    }

    fn output(&self) -> &Span<'a> {
        &self.spans[4]
    }
}

/// The device's limits a batch's windows must fit.
#[derive(Clone, Copy)]
pub(crate) struct Limit {
    /// `min_storage_buffer_offset_alignment`.
    pub align: u64,
    /// `max_storage_buffer_binding_size`.
    pub binding: u64,
}

/// Tasks posed by one dispatch: they bind the same five buffers, each through the window that
/// spans every task's range in it.
pub(crate) struct Batch<'a> {
    tasks: Vec<Posing<'a>>,
    /// Per binding, the lowest start and the highest end of the tasks' spans.
    bounds: [(u64, u64); 5],
    /// Workgroups of every task, in order.
    pub workgroups: u32,
}

impl<'a> Batch<'a> {
    fn new(p: Posing<'a>) -> Self {
        Batch {
            bounds: p.spans.map(|s| (s.start, s.end)),
            workgroups: p.workgroups,
            tasks: vec![p],
        }
    }

    /// The five buffers every task of the batch binds.
    pub fn buffers(&self) -> [&'a wgpu::Buffer; 5] {
        self.tasks[0].spans.map(|s| s.buffer)
    }

    /// Whether `p`'s writes and this batch's accesses (or `p`'s reads and this batch's writes)
    /// share a byte: then `p` must be posed after this batch.
    fn conflicts(&self, p: &Posing<'_>) -> bool {
        self.tasks.iter().any(|t| {
            t.spans.iter().any(|s| s.overlaps(p.output()))
                || p.spans[..4].iter().any(|s| s.overlaps(t.output()))
        })
    }

    /// Whether `p` binds this batch's buffers, and the batch with it still fits the device: its
    /// windows within the binding size and its workgroups within one dispatch.
    fn admits(&self, p: &Posing<'_>, limit: Limit) -> bool {
        let same = self
            .buffers()
            .iter()
            .zip(&p.spans)
            .all(|(b, s)| *b == s.buffer);
        let groups = self.workgroups.checked_add(p.workgroups);
        let fits_dispatch =
            groups.is_some_and(|g| u64::from(g) <= u64::from(MAX_DISPATCH_DIM).pow(2));
        same && fits_dispatch
            && self.bounds.iter().zip(&p.spans).all(|(&(lo, hi), s)| {
                window(lo.min(s.start), hi.max(s.end), limit.align)
                    .is_some_and(|w| w.size <= limit.binding)
            })
    }

    fn push(&mut self, p: Posing<'a>) {
        for (b, s) in self.bounds.iter_mut().zip(&p.spans) {
            *b = (b.0.min(s.start), b.1.max(s.end));
        }
        self.workgroups += p.workgroups;
        self.tasks.push(p);
    }

    /// Every task's parameters placed in the batch's windows, and the windows; `None` when an
    /// offset does not fit 32-bit words (not for a batch [`Batch::admits`] built).
    pub fn skins(&self, align: u64) -> Option<(Vec<Skin>, [Window; 5])> {
        let windows: Vec<Window> = self
            .bounds
            .iter()
            .map(|&(lo, hi)| window(lo, hi, align))
            .collect::<Option<_>>()?;
        let windows: [Window; 5] = windows.try_into().ok()?;
        let mut first_group = 0u32;
        let mut skins = Vec::with_capacity(self.tasks.len());
        for t in &self.tasks {
            let mut words = [0u32; 5];
            for ((word, s), w) in words.iter_mut().zip(&t.spans).zip(&windows) {
                *word = u32::try_from((s.start - w.start) / 4).ok()?;
            }
            skins.push(t.skin.placed(words, first_group));
            first_group += t.workgroups;
        }
        Some((skins, windows))
    }
}

/// Groups `posings` (in the task's order) into batches: each joins the latest batch that binds
/// its buffers and fits, unless a batch it conflicts with lies at or after that one (its writes
/// must follow those). Batches are dispatched in order; wgpu orders those sharing a buffer.
pub(crate) fn batches<'a>(
    posings: impl Iterator<Item = Posing<'a>>,
    limit: Limit,
) -> Vec<Batch<'a>> {
    let mut batches: Vec<Batch<'a>> = Vec::new();
    for p in posings {
        let mut home = None;
        for (i, b) in batches.iter().enumerate().rev() {
            if b.conflicts(&p) {
                break;
            }
            if b.admits(&p, limit) {
                home = Some(i);
                break;
            }
        }
        match home {
            Some(i) => batches[i].push(p),
            None => batches.push(Batch::new(p)),
        }
    }
    batches
}
