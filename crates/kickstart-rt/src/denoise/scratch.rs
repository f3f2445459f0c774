//! The filter intermediate every denoising context shares: one of the two ping-pong buffers of
//! the à-trous iterations (the other is the context's own previous-frame history, dead once the
//! temporal pass has read it). Denoise tasks run one after another on the queue, so one buffer
//! serves every context and denoiser. It is sized for the largest signal buffer of the live
//! contexts, and released once none needs it (or a smaller one does).

/// The shared à-trous buffer, created by the first denoise task.
#[derive(Default)]
pub(crate) struct Scratch {
    buffer: Option<wgpu::Buffer>,
    /// Serial of the last GPU task that used `buffer`.
    last_used: u64,
    /// Buffers replaced by a larger or smaller one, with their last task, kept until no
    /// in-flight task uses them.
    replaced: Vec<(wgpu::Buffer, u64)>,
}

impl Scratch {
    /// A buffer of at least `bytes` for task `serial`: the current one, or a new one when it is
    /// smaller.
    pub fn get(&mut self, device: &wgpu::Device, bytes: u64, serial: u64) -> wgpu::Buffer {
        if let Some(b) = self.buffer.as_ref().filter(|b| b.size() >= bytes) {
            self.last_used = serial;
            return b.clone();
        }
        self.retire_current();
        self.last_used = serial;
        let b = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("kickstart-rt denoiser intermediate"),
            size: bytes.max(super::history::RECORD_BYTES),
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        self.buffer = Some(b.clone());
        b
    }

    fn retire_current(&mut self) {
        if let Some(old) = self.buffer.take() {
            self.replaced.push((old, self.last_used));
        }
    }

    /// Releases what no task from `oldest_in_flight` on uses; the current buffer too when it is
    /// larger than `needed` (the largest signal buffer of the live contexts, 0 when none).
    pub fn collect(&mut self, oldest_in_flight: u64, needed: u64) {
        if self.buffer.as_ref().is_some_and(|b| b.size() > needed) {
            self.retire_current();
        }
        self.replaced.retain(|(_, last)| *last >= oldest_in_flight);
    }

    /// GPU bytes held (the current buffer and replaced ones not yet released).
    pub fn bytes(&self) -> u64 {
        self.buffer
            .iter()
            .chain(self.replaced.iter().map(|(b, _)| b))
            .map(wgpu::Buffer::size)
            .sum()
    }
}
