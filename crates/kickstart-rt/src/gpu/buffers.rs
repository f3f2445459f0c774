//! Generic buffer helpers: storage buffers, scratch that only grows, and blocking read-backs for
//! tools and tests.

use crate::error::{Error, Result};

/// A STORAGE | COPY_SRC | COPY_DST buffer (at least 256 bytes, zeroed by wgpu).
pub(crate) fn storage(device: &wgpu::Device, label: &str, size: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(256).div_ceil(4) * 4,
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// A buffer of `usage` holding `contents` (padded to 4 bytes, at least 4), written at creation
/// like wgpu's `create_buffer_init`, which panics where the device is lost (its mapping fails).
/// Here the contents are then left unwritten: the device's error reaches the error scope of
/// `build_gpu_task`, which refuses the task.
pub(crate) fn buffer_init(
    device: &wgpu::Device,
    label: &str,
    contents: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    let size = (contents.len() as u64).div_ceil(4).max(1) * 4;
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage,
        mapped_at_creation: true,
    });
    if let Ok(mut view) = buffer.get_mapped_range_mut(..) {
        view.slice(..contents.len()).copy_from_slice(contents);
    }
    buffer.unmap();
    buffer
}

/// Copies `size` bytes of `buffer` to the CPU, waiting for the device.
pub(crate) fn read_back(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    offset: u64,
    size: u64,
) -> Result<Vec<u8>> {
    if size == 0 {
        return Ok(Vec::new());
    }
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("kickstart-rt read-back"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut enc = device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(buffer, offset, &staging, 0, size);
    queue.submit([enc.finish()]);
    map_and_wait(device, &staging)
}

/// Maps a `MAP_READ` buffer, waits for the device, and copies its bytes out (tools and tests
/// only: this blocks).
pub(crate) fn map_and_wait(device: &wgpu::Device, buffer: &wgpu::Buffer) -> Result<Vec<u8>> {
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| Error::ReadBack(e.to_string()))?;
    rx.recv()
        .map_err(|e| Error::ReadBack(e.to_string()))?
        .map_err(|e| Error::ReadBack(e.to_string()))?;
    let data = buffer
        .slice(..)
        .get_mapped_range()
        .map_err(|e| Error::ReadBack(e.to_string()))?
        .to_vec();
    Ok(data)
}

/// Bytes of the largest storage buffer `device` can bind whole: its storage binding limit, or
/// its buffer size limit where that is smaller.
pub(crate) fn max_binding(device: &wgpu::Device) -> u64 {
    let limits = device.limits();
    limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size)
}

/// A scratch buffer that only grows (recorded commands keep older buffers alive).
#[derive(Default)]
pub(crate) struct Grown {
    buffer: Option<wgpu::Buffer>,
}

impl Grown {
    /// A buffer of at least `size` bytes (at least 32, so every binding has a valid minimum).
    pub(crate) fn get(
        &mut self,
        device: &wgpu::Device,
        label: &'static str,
        size: u64,
    ) -> wgpu::Buffer {
        let size = size.max(32);
        if let Some(b) = &self.buffer {
            if b.size() >= size {
                return b.clone();
            }
        }
        // Round up so that slowly growing scenes do not reallocate on every build, but never
        // past the largest binding: the buffer is bound whole, and a request that fits must
        // stay bindable.
        let rounded = size.next_power_of_two().min(max_binding(device)).max(size);
        let b = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: rounded,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.buffer = Some(b.clone());
        b
    }

    /// Bytes held.
    pub(crate) fn bytes(&self) -> u64 {
        self.buffer.as_ref().map_or(0, |b| b.size())
    }

    /// Drops the buffer (the next [`Self::get`] allocates what it asks for).
    pub(crate) fn release(&mut self) {
        self.buffer = None;
    }
}

/// A 1×1 `Rgba8Unorm` texture bound where a pass's optional input is absent (the shader never
/// reads it then).
pub(crate) fn placeholder_texture(device: &wgpu::Device, label: &str) -> wgpu::TextureView {
    device
        .create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width: 1,
                height: 1,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        })
        .create_view(&Default::default())
}
