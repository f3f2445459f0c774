//! The filter intermediates every denoising context shares: two buffers, where a context's
//! temporal pass writes this frame's accumulated signals (one each; they are then copied into the
//! context's history) and between which its à-trous iterations ping-pong. Denoise tasks run one
//! after another on the queue, so one pair serves every context and denoiser. It is sized for
//! the largest signal buffer of the live contexts, and released once none needs it (or a
//! smaller one does).

/// The shared pair of buffers, created by the first denoise task.
#[derive(Default)]
pub(crate) struct Scratch {
    buffer: Option<[wgpu::Buffer; 2]>,
    /// Serial of the last GPU task that used `buffer`.
    last_used: u64,
    /// Buffers replaced by larger or smaller ones, with their last task, kept until no
    /// in-flight task uses them.
    replaced: Vec<([wgpu::Buffer; 2], u64)>,
}

impl Scratch {
    /// Two buffers of at least `bytes` each for task `serial`: the current ones, or new ones
    /// when they are smaller.
    pub fn get(&mut self, device: &wgpu::Device, bytes: u64, serial: u64) -> [wgpu::Buffer; 2] {
        if let Some(b) = self.buffer.as_ref().filter(|b| b[0].size() >= bytes) {
            self.last_used = serial;
            return b.clone();
        }
        self.retire_current();
        self.last_used = serial;
        let buffer = || {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("kickstart-rt denoiser intermediate"),
                size: bytes.max(super::history::RECORD_BYTES),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let b = [buffer(), buffer()];
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
        if self.buffer.as_ref().is_some_and(|b| b[0].size() > needed) {
            self.retire_current();
        }
        self.replaced.retain(|(_, last)| *last >= oldest_in_flight);
    }

    /// GPU bytes held (the current buffer and replaced ones not yet released).
    pub fn bytes(&self) -> u64 {
        self.buffer
            .iter()
            .chain(self.replaced.iter().map(|(b, _)| b))
            .map(|b| b[0].size() + b[1].size())
            .sum()
    }
}
