//! The GPU memory of one denoising context: its signal histories, allocated by its
//! first frame for that frame's grid (the viewport, or one pixel per block in a block mode) and
//! reallocated when the grid changes size. A signal's history holds 16 (radiance) or 8
//! (occlusion, shadows) bytes per pixel (see `shaders/denoise/common.wgsl` and the record
//! files); a signal's buffers are separate so that each binding stays under WebGPU's default
//! 128 MiB binding limit up to 4K. The guides (16 bytes per pixel) and the filter's intermediate
//! are not a context's own: see [`super::guides`] and [`super::scratch`].

use std::collections::HashMap;

use crate::handles::DenoisingContextHandle;
use crate::tasks::{DenoisingContextInput, SignalType, Viewport};

/// Bytes of the largest per-pixel record (a guide, a radiance signal).
pub(crate) const RECORD_BYTES: u64 = 16;

/// Bytes per pixel of a signal record of a context of `signal_type`: scalar signals keep one
/// value (`shaders/denoise/record_scalar.wgsl`).
pub(crate) fn signal_record_bytes(signal_type: SignalType) -> u64 {
    match signal_type {
        SignalType::DiffuseOcclusion | SignalType::Shadow | SignalType::MultiShadow => 8,
        _ => 16,
    }
}

/// Signals a context of `signal_type` filters in one pass.
pub(crate) fn signal_count(signal_type: SignalType) -> usize {
    match signal_type {
        SignalType::SpecularAndDiffuse => 2,
        _ => 1,
    }
}

/// Bytes of the largest per-pixel buffer (a guide) of a context of `input`'s size.
pub(crate) fn buffer_bytes(input: &DenoisingContextInput) -> u64 {
    input.max_width as u64 * input.max_height as u64 * RECORD_BYTES
}

/// The buffers of one context, sized for `pixels` grid pixels: per signal, the accumulated signal
/// ([`signal_record_bytes`] per pixel). The temporal pass reads it (the previous frame's) and
/// writes this frame's into the shared scratch ([`super::scratch::Scratch`]), which is then
/// copied into it. Its guides may be shared with other contexts: see [`super::guides`].
pub(crate) struct HistoryBuffers {
    /// Grid pixels each buffer holds.
    pub pixels: u64,
    /// One buffer per signal.
    pub history: Vec<wgpu::Buffer>,
}

impl HistoryBuffers {
    fn new(device: &wgpu::Device, signal_type: SignalType, pixels: u64) -> Self {
        let buffer = |label: &str, size: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let signal_size = pixels * signal_record_bytes(signal_type);
        HistoryBuffers {
            pixels,
            history: (0..signal_count(signal_type))
                .map(|_| buffer("kickstart-rt denoiser history", signal_size))
                .collect(),
        }
    }

    /// GPU bytes held: [`history_bytes`] of its size.
    fn bytes(&self, signal_type: SignalType) -> u64 {
        history_bytes(signal_type, self.pixels)
    }
}

/// Bytes a context of `signal_type` holds for a grid of `pixels`: per signal, one record of
/// [`signal_record_bytes`] per pixel.
pub(crate) fn history_bytes(signal_type: SignalType, pixels: u64) -> u64 {
    pixels * signal_count(signal_type) as u64 * signal_record_bytes(signal_type)
}

/// One context's buffers and the state carried between its frames.
pub(crate) struct History {
    pub input: DenoisingContextInput,
    /// Allocated by the first frame, for its grid (the viewport, or one pixel per block in a
    /// block mode); `None` before.
    buffers: Option<HistoryBuffers>,
    /// Its pair of guides (an id of [`super::guides::Guides`]), from its first frame on.
    pub guide: Option<usize>,
    /// Buffers replaced by larger or smaller ones, kept until no in-flight task uses them
    /// (`last_used` is their last task).
    replaced: Vec<(HistoryBuffers, u64)>,
    /// Frames recorded (0: the next frame starts the history).
    pub frame: u64,
    /// The viewport of the last frame: another size invalidates the history (its rows no longer
    /// line up).
    pub last_viewport: Option<Viewport>,
    /// The previous frame's camera jitter, pixels.
    pub prev_jitter: glam::Vec2,
    /// The previous frame's traced-pixel mode: its grid (block size) must match this frame's
    /// for the history to be read, and its traced pixel places the history's grid pixels.
    pub prev_mode: crate::tasks::HalfResolutionMode,
    /// Serial of the last GPU task that used it.
    pub last_used: u64,
}

impl History {
    /// A context's state before its first frame: no GPU memory yet.
    pub fn new(input: DenoisingContextInput) -> Self {
        History {
            input,
            buffers: None,
            guide: None,
            replaced: Vec::new(),
            frame: 0,
            last_viewport: None,
            prev_jitter: glam::Vec2::ZERO,
            prev_mode: Default::default(),
            last_used: 0,
        }
    }

    /// The buffers for a frame on a grid of `pixels`, and whether they were just allocated
    /// (contents undefined: the frame starts its history over). The buffers follow the grid:
    /// a larger grid gets larger ones, and one at most a quarter of the current size (a block
    /// mode after full rate, a smaller viewport) gets smaller ones; a grid of another size
    /// starts the history over anyway.
    pub fn buffers_for(&mut self, device: &wgpu::Device, pixels: u64) -> (&HistoryBuffers, bool) {
        let fits = |b: &HistoryBuffers| pixels <= b.pixels && pixels.saturating_mul(4) > b.pixels;
        let (buffers, fresh) = match self.buffers.take() {
            Some(b) if fits(&b) => (b, false),
            old => {
                if let Some(old) = old {
                    self.replaced.push((old, self.last_used));
                }
                let t = self.input.signal_type;
                (HistoryBuffers::new(device, t, pixels.max(1)), true)
            }
        };
        (self.buffers.insert(buffers), fresh)
    }

    /// Releases replaced buffers whose last task is older than `oldest_in_flight`.
    fn collect(&mut self, oldest_in_flight: u64) {
        self.replaced.retain(|(_, last)| *last >= oldest_in_flight);
    }

    /// GPU bytes held (current and replaced buffers).
    pub fn bytes(&self) -> u64 {
        let t = self.input.signal_type;
        self.buffers
            .iter()
            .chain(self.replaced.iter().map(|(b, _)| b))
            .map(|b| b.bytes(t))
            .sum()
    }

    /// Bytes of the largest signal buffer of its current buffers (what its à-trous chain needs
    /// of the shared scratch).
    pub fn signal_buffer_bytes(&self) -> u64 {
        self.buffers.as_ref().map_or(0, |b| {
            b.pixels * signal_record_bytes(self.input.signal_type)
        })
    }
}

/// The histories of the contexts one denoiser serves: live ones by handle, and those of destroyed
/// contexts until no in-flight task can use them.
#[derive(Default)]
pub(crate) struct Histories {
    live: HashMap<DenoisingContextHandle, History>,
    retired: Vec<History>,
}

impl Histories {
    /// Follows the live contexts (those this denoiser serves): creates the history of new ones,
    /// retires destroyed ones.
    pub fn sync<'a>(
        &mut self,
        live: impl Iterator<Item = &'a (DenoisingContextHandle, DenoisingContextInput)> + Clone,
    ) {
        self.retire_destroyed(live.clone().map(|(h, _)| *h));
        for (h, input) in live {
            if !self.live.contains_key(h) {
                self.live.insert(*h, History::new(*input));
            }
        }
    }

    /// Retires the histories of contexts not in `live` (destroyed ones), creating nothing.
    pub fn retire_destroyed(&mut self, live: impl Iterator<Item = DenoisingContextHandle> + Clone) {
        let dead: Vec<DenoisingContextHandle> = self
            .live
            .keys()
            .filter(|h| !live.clone().any(|l| l == **h))
            .copied()
            .collect();
        for h in dead {
            if let Some(history) = self.live.remove(&h) {
                self.retired.push(history);
            }
        }
    }

    /// The guide pairs the live contexts hold.
    pub fn guides_held(&self) -> impl Iterator<Item = usize> + '_ {
        self.live.values().filter_map(|h| h.guide)
    }

    /// GPU bytes of a live context (0 before its first frame); `None` for a context this
    /// denoiser does not serve.
    pub fn context_bytes(&self, context: &DenoisingContextHandle) -> Option<u64> {
        self.live.get(context).map(History::bytes)
    }

    /// The history of a live context.
    pub fn get_mut(&mut self, context: &DenoisingContextHandle) -> Option<&mut History> {
        self.live.get_mut(context)
    }

    /// Releases retired histories, and buffers the live ones replaced, whose last task is
    /// older than `oldest_in_flight`.
    pub fn collect(&mut self, oldest_in_flight: u64) {
        self.retired.retain(|h| h.last_used >= oldest_in_flight);
        for h in self.live.values_mut() {
            h.collect(oldest_in_flight);
        }
    }

    /// Bytes of the largest signal buffer of a live context (what the shared scratch must hold).
    pub fn largest_signal_buffer(&self) -> u64 {
        self.live
            .values()
            .map(History::signal_buffer_bytes)
            .max()
            .unwrap_or(0)
    }

    /// GPU bytes held (live and not yet released).
    pub fn bytes(&self) -> u64 {
        self.live
            .values()
            .chain(self.retired.iter())
            .map(History::bytes)
            .sum()
    }
}
