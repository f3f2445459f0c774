//! Upload staging for CPU-written per-task data. Each built GPU task owns the staging buffers it
//! wrote; they return to the pool when the task is marked complete and are re-mapped
//! asynchronously, so a build never waits on the GPU and never overwrites memory the GPU may read.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

pub(crate) struct StagingBuffer {
    pub buffer: wgpu::Buffer,
    /// Set by the map callback once the buffer is mapped for writing again.
    mapped: Arc<AtomicBool>,
}

#[derive(Default)]
pub(crate) struct StagingPool {
    free: Vec<StagingBuffer>,
}

impl StagingPool {
    /// A mapped buffer of at least `size` bytes: a recycled one whose re-map finished, or a new one.
    pub fn acquire(&mut self, device: &wgpu::Device, size: u64) -> StagingBuffer {
        let size = size.max(256).next_power_of_two();
        if let Some(pos) = self
            .free
            .iter()
            .position(|b| b.buffer.size() >= size && b.mapped.load(Ordering::Acquire))
        {
            return self.free.swap_remove(pos);
        }
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("kickstart-rt staging"),
            size,
            usage: wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: true,
        });
        StagingBuffer {
            buffer,
            mapped: Arc::new(AtomicBool::new(true)),
        }
    }

    /// Takes back a buffer whose GPU task completed and starts re-mapping it.
    pub fn release(&mut self, b: StagingBuffer) {
        b.mapped.store(false, Ordering::Release);
        let flag = b.mapped.clone();
        b.buffer.map_async(wgpu::MapMode::Write, .., move |r| {
            if r.is_ok() {
                flag.store(true, Ordering::Release);
            }
        });
        self.free.push(b);
    }

    /// Drops every pooled buffer.
    pub fn clear(&mut self) {
        self.free.clear();
    }

    pub fn bytes(&self) -> u64 {
        self.free.iter().map(|b| b.buffer.size()).sum()
    }
}

impl StagingBuffer {
    /// Writes `data` at `offset` (the buffer is mapped), then the caller unmaps before recording.
    /// Returns false only if the buffer is not mapped, which `acquire` rules out.
    pub fn write(&self, offset: u64, data: &[u8]) -> bool {
        match self
            .buffer
            .slice(offset..offset + data.len() as u64)
            .get_mapped_range_mut()
        {
            Ok(mut view) => {
                view.copy_from_slice(data);
                true
            }
            Err(_) => false,
        }
    }
}
