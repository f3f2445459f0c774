//! The GPU memory of one denoising context: guides, history and filter intermediates, sized by
//! the context's maximum resolution. Guides hold 16 bytes per pixel, a signal's history and
//! intermediates 16 (radiance) or 8 (occlusion, shadows) bytes per pixel (see
//! `shaders/denoise/common.wgsl` and the record files); a signal's buffers are separate so that
//! each binding stays under WebGPU's default 128 MiB binding limit up to 4K.

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

/// Bytes of one signal buffer (history, intermediate) of a context of `input`'s size.
fn signal_buffer_bytes(input: &DenoisingContextInput) -> u64 {
    input.max_width as u64 * input.max_height as u64 * signal_record_bytes(input.signal_type)
}

/// One context's buffers and the state carried between its frames.
pub(crate) struct History {
    pub input: DenoisingContextInput,
    /// This and the previous frame's guide, by frame parity.
    pub guides: [wgpu::Buffer; 2],
    /// `history[parity][signal]`: the accumulated signal of this and the previous frame.
    pub history: [Vec<wgpu::Buffer>; 2],
    /// `temp[k][signal]`: à-trous ping-pong buffers.
    pub temp: [Vec<wgpu::Buffer>; 2],
    /// Frames recorded (the parity picks the current buffers).
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
    /// Allocates the buffers of a context (contents undefined until the first frame, which
    /// starts without history).
    pub fn new(device: &wgpu::Device, input: DenoisingContextInput) -> Self {
        let buffer = |label: &str, size: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        };
        let n = signal_count(input.signal_type);
        let signal_size = signal_buffer_bytes(&input);
        let set = |label: &str| {
            (0..n)
                .map(|_| buffer(label, signal_size))
                .collect::<Vec<_>>()
        };
        let guide_size = buffer_bytes(&input);
        History {
            input,
            guides: [
                buffer("kickstart-rt denoiser guide", guide_size),
                buffer("kickstart-rt denoiser guide", guide_size),
            ],
            history: [
                set("kickstart-rt denoiser history"),
                set("kickstart-rt denoiser history"),
            ],
            temp: [
                set("kickstart-rt denoiser intermediate"),
                set("kickstart-rt denoiser intermediate"),
            ],
            frame: 0,
            last_viewport: None,
            prev_jitter: glam::Vec2::ZERO,
            prev_mode: Default::default(),
            last_used: 0,
        }
    }

    /// GPU bytes held.
    pub fn bytes(&self) -> u64 {
        let n = signal_count(self.input.signal_type) as u64;
        buffer_bytes(&self.input) * 2 + signal_buffer_bytes(&self.input) * 4 * n
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
        device: &wgpu::Device,
        live: impl Iterator<Item = &'a (DenoisingContextHandle, DenoisingContextInput)> + Clone,
    ) {
        self.retire_destroyed(live.clone().map(|(h, _)| *h));
        for (h, input) in live {
            if !self.live.contains_key(h) {
                self.live.insert(*h, History::new(device, *input));
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

    /// The history of a live context.
    pub fn get_mut(&mut self, context: &DenoisingContextHandle) -> Option<&mut History> {
        self.live.get_mut(context)
    }

    /// Releases retired histories whose last task is older than `oldest_in_flight`.
    pub fn collect(&mut self, oldest_in_flight: u64) {
        self.retired.retain(|h| h.last_used >= oldest_in_flight);
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
